// Helpers the test files share: scratch folders and hand-made height fields.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <string>

#include "digitize/height_field.h"

namespace digitize::test {

// The running test's name (TEST(Suite, Name): "Name").
inline std::string CurrentTestName() {
  return ::testing::UnitTest::GetInstance()->current_test_info()->name();
}

// <system temp folder>/<prefix>_<pid>[_<suffix>]: the pid keeps parallel runs (ctest -j, the
// Release and sanitizer suites at once) apart.
inline std::filesystem::path ScratchPath(const std::string& prefix,
                                         const std::string& suffix = "") {
  std::string name = prefix + "_" + std::to_string(::getpid());
  if (!suffix.empty()) name += "_" + suffix;
  return std::filesystem::temp_directory_path() / name;
}

// ScratchPath(prefix, suffix), emptied: removed, then created again unless `create` is false.
inline std::filesystem::path FreshScratchDir(const std::string& prefix,
                                             const std::string& suffix = "", bool create = true) {
  const std::filesystem::path dir = ScratchPath(prefix, suffix);
  std::filesystem::remove_all(dir);
  if (create) std::filesystem::create_directories(dir);
  return dir;
}

// Removes `path` (a folder or a file) when it goes out of scope: scratch space that a test, or
// a suite's shared data, makes outside a ScratchDirTest, so that no run leaves files behind in
// the temp folder (they were piling up, one folder per run).
class RemoveOnExit {
 public:
  explicit RemoveOnExit(std::filesystem::path path) : path_(std::move(path)) {}
  ~RemoveOnExit() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  RemoveOnExit(const RemoveOnExit&) = delete;
  RemoveOnExit& operator=(const RemoveOnExit&) = delete;

 private:
  std::filesystem::path path_;
};

// A fixture with one scratch folder per test, dir_ = ScratchPath(prefix, test name) (or
// ScratchPath(prefix) when `per_test` is false), fresh before the test and removed after it.
// `create` false: the folder does not exist when the test starts (tests of writers that make it).
class ScratchDirTest : public ::testing::Test {
 protected:
  explicit ScratchDirTest(std::string prefix, bool create = true, bool per_test = true)
      : prefix_(std::move(prefix)), create_(create), per_test_(per_test) {}
  void SetUp() override {
    dir_ = FreshScratchDir(prefix_, per_test_ ? CurrentTestName() : "", create_);
  }
  void TearDown() override {
    if (!dir_.empty()) std::filesystem::remove_all(dir_);
  }
  std::filesystem::path Path(const std::string& name) const { return dir_ / name; }

  std::filesystem::path dir_;

 private:
  std::string prefix_;
  bool create_;
  bool per_test_;
};

// A file's bytes ("" when it cannot be read).
inline std::string ReadFileBytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Writes `bytes` as the whole of `path`.
inline void WriteFileBytes(const std::filesystem::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// A w x h field, every texel measured at height `fill_mm`.
inline HeightField MakeFlatField(int w, int h, double pitch_mm, float fill_mm = 0.0f) {
  HeightField field;
  field.pitch_mm = pitch_mm;
  field.height_mm = Grid<float>(w, h, fill_mm);
  field.state = Grid<TexelState>(w, h, TexelState::kMeasured);
  return field;
}

// A measured field with height f(x, y) at texel (x, y) (0 without f).
inline HeightField MakeTexelField(int w, int h, double pitch_mm,
                                  const std::function<float(int x, int y)>& f = nullptr) {
  HeightField field = MakeFlatField(w, h, pitch_mm);
  if (f)
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) field.height_mm(x, y) = f(x, y);
  return field;
}

// A measured field with height f(X, Y) at each texel centre, canvas-frame mm (0 without f).
inline HeightField MakeMmField(int w, int h, double pitch_mm,
                               const std::function<double(double X, double Y)>& f = nullptr) {
  HeightField field = MakeFlatField(w, h, pitch_mm);
  if (f)
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const Eigen::Vector2d c = field.TexelCentreMm(x, y);
        field.height_mm(x, y) = static_cast<float>(f(c.x(), c.y()));
      }
  return field;
}

}  // namespace digitize::test
