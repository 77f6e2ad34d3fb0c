// Output safety (docs/refusals.md, "Output safety"): output folders replace only what the tool
// wrote, no output lands onto, into or above an input or the current directory, temporaries of
// killed writers are cleaned, and every writer reports a failed write (full disk, file size limit)
// with its cause, leaving the previous file.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>

#include "digitize/image_io.h"
#include "digitize/output_dir.h"
#include "test_support.h"

namespace digitize {
namespace {

namespace fs = std::filesystem;

bool Has(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// A process id that is certainly not running: a child that has exited and been reaped.
pid_t DeadPid() {
  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);
  int status = 0;
  ::waitpid(child, &status, 0);
  return child;
}

class OutputSafetyTest : public test::ScratchDirTest {
 protected:
  OutputSafetyTest() : ScratchDirTest("digitize_output_safety") {}
  // Hidden temporaries ("." + name + ".partial-...") beside the outputs in dir_.
  std::vector<std::string> Hidden() const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(dir_))
      if (e.path().filename().string()[0] == '.') names.push_back(e.path().filename().string());
    return names;
  }
};

const FolderOutput kCanvas{"preprocess", "canvas", {}};

Status WriteA(const fs::path& out, const std::string& text, const FolderOutput& kind = kCanvas) {
  return WriteDirectoryAtomically(out, kind, [&](const fs::path& dir) {
    fs::create_directories(dir / "sub");
    std::ofstream(dir / "a.txt") << text;
    std::ofstream(dir / "sub" / "b.txt") << text;
    return Status::Ok();
  });
}

TEST_F(OutputSafetyTest, NewAndEmptyFoldersAreWrittenWithAMarker) {
  ASSERT_TRUE(WriteA(dir_ / "new", "1").ok());
  fs::create_directory(dir_ / "empty");
  ASSERT_TRUE(WriteA(dir_ / "empty", "2").ok());
  EXPECT_EQ(test::ReadFileBytes(dir_ / "empty" / "a.txt"), "2");
  const std::string marker = test::ReadFileBytes(dir_ / "new" / kOutputMarkerName);
  for (const char* part : {"digitize.output", "\"preprocess\"", "\"canvas\"", "\"a.txt\"",
                           "\"sub/\"", "\"sub/b.txt\""})
    EXPECT_TRUE(Has(marker, part)) << part << " in " << marker;
}

TEST_F(OutputSafetyTest, AnEarlierOutputOfTheSameContentIsReplaced) {
  const fs::path out = dir_ / "canvas";
  ASSERT_TRUE(WriteA(out, "first").ok());
  // Another command writing the same content (run --work DIR/canvas) may replace it.
  ASSERT_TRUE(WriteA(out, "second", FolderOutput{"run", "canvas", {}}).ok());
  EXPECT_EQ(test::ReadFileBytes(out / "a.txt"), "second");
  EXPECT_TRUE(Hidden().empty());
}

TEST_F(OutputSafetyTest, AFolderOfTheUsersFilesIsRefusedAndUntouched) {
  const fs::path out = dir_ / "museum";
  fs::create_directories(out / "notes");
  std::ofstream(out / "notes" / "condition_report.txt") << "irreplaceable";
  const Status s = WriteA(out, "x");
  ASSERT_FALSE(s.ok());
  EXPECT_TRUE(Has(s.message(), out.string())) << s.message();
  EXPECT_TRUE(Has(s.message(), "'notes/'")) << "names one thing found: " << s.message();
  EXPECT_EQ(test::ReadFileBytes(out / "notes" / "condition_report.txt"), "irreplaceable");
  EXPECT_FALSE(fs::exists(out / "a.txt"));
  EXPECT_TRUE(Hidden().empty()) << "refused before any temporary folder";
  EXPECT_FALSE(CheckReplaceable(out, "canvas").ok()) << "the check a command makes first";
}

TEST_F(OutputSafetyTest, AFileAddedToAnOutputOrAnotherContentIsRefused) {
  const fs::path out = dir_ / "canvas";
  ASSERT_TRUE(WriteA(out, "first").ok());
  std::ofstream(out / "sub" / "my_notes.txt") << "mine";
  Status s = WriteA(out, "second");
  ASSERT_FALSE(s.ok());
  EXPECT_TRUE(Has(s.message(), "'sub/my_notes.txt'")) << s.message();
  EXPECT_EQ(test::ReadFileBytes(out / "a.txt"), "first");
  EXPECT_EQ(test::ReadFileBytes(out / "sub" / "my_notes.txt"), "mine");
  fs::remove(out / "sub" / "my_notes.txt");

  // A fit folder is not replaced by a canvas, nor the reverse.
  s = WriteA(out, "fit maps", FolderOutput{"fit", "fit", {}});
  ASSERT_FALSE(s.ok());
  EXPECT_TRUE(Has(s.message(), "digitize preprocess")) << s.message();
  EXPECT_EQ(test::ReadFileBytes(out / "a.txt"), "first");

  // A marker that is not one (a user's file of the same name) does not make a folder ours.
  std::ofstream(out / kOutputMarkerName, std::ios::trunc) << "not json";
  EXPECT_FALSE(WriteA(out, "second").ok());
  EXPECT_EQ(test::ReadFileBytes(out / "a.txt"), "first");
}

TEST_F(OutputSafetyTest, OutputsNeverLandOnIntoOrAboveAnInput) {
  const fs::path scans = dir_ / "museum" / "scans";
  fs::create_directories(scans);
  const fs::path scan = scans / "scan.exr";
  std::ofstream(scan) << "scan";
  const fs::path canvas = dir_ / "canvas";
  fs::create_directories(canvas);
  const std::vector<fs::path> inputs = {scan, canvas};

  struct Case {
    fs::path out;
    const char* why;
  };
  for (const Case& c : {Case{scan, "is the input"}, Case{scans, "holds the input"},
                        Case{dir_ / "museum", "holds the input"},
                        Case{dir_ / "museum" / "." / "scans" / ".." / "scans/", "holds the input"},
                        Case{canvas / "height.exr", "lies inside the input"},
                        Case{canvas, "is the input"}, Case{dir_, "holds the input"}}) {
    const Status s = CheckOutputPath(c.out, inputs);
    ASSERT_FALSE(s.ok()) << c.out;
    EXPECT_TRUE(Has(s.message(), c.why)) << c.out << ": " << s.message();
    EXPECT_TRUE(Has(s.message(), c.out.string())) << s.message();
  }
  // Seen through a symlink.
  fs::create_directory_symlink(scans, dir_ / "link");
  EXPECT_FALSE(CheckOutputPath(dir_ / "link", inputs).ok());
  EXPECT_FALSE(CheckOutputPath(dir_ / "link" / "scan.exr", inputs).ok());
  // Beside the inputs is fine, also with a name that shares a prefix.
  EXPECT_TRUE(CheckOutputPath(dir_ / "museum" / "canvas", inputs).ok());
  EXPECT_TRUE(CheckOutputPath(dir_ / "canvas2", inputs).ok());
  EXPECT_TRUE(CheckOutputPath(scans / "scan.exr.pack.exr", inputs).ok());
  // The folder command refuses before touching anything.
  const Status folder = WriteA(scans, "x", FolderOutput{"preprocess", "canvas", inputs});
  EXPECT_FALSE(folder.ok());
  EXPECT_EQ(test::ReadFileBytes(scan), "scan");
}

TEST_F(OutputSafetyTest, TheCurrentDirectoryAndItsParentsAreNeverOutputs) {
  const fs::path here = dir_ / "work";
  fs::create_directories(here / "inner");
  const fs::path before = fs::current_path();
  fs::current_path(here);
  for (const fs::path& out : {fs::path("."), fs::path("./"), here, here.parent_path(),
                              fs::path(".."), fs::path("inner/..")}) {
    const Status s = CheckOutputPath(out, {});
    EXPECT_FALSE(s.ok()) << out;
    EXPECT_TRUE(Has(s.message(), "current directory")) << s.message();
    EXPECT_FALSE(WriteA(out, "x").ok()) << out;
  }
  EXPECT_TRUE(CheckOutputPath("canvas", {}).ok());
  EXPECT_TRUE(CheckOutputPath("inner", {}).ok());
  fs::current_path(before);
  EXPECT_TRUE(fs::is_directory(here / "inner"));
}

TEST_F(OutputSafetyTest, StaleTemporaryFoldersOfDeadProcessesAreRemoved) {
  const fs::path out = dir_ / "fit";
  ASSERT_TRUE(WriteA(out, "first", FolderOutput{"fit", "fit", {}}).ok());
  const std::string dead = std::to_string(DeadPid()), live = std::to_string(::getpid());
  const fs::path stale_partial = dir_ / (".fit.partial-" + dead + "-0");
  const fs::path stale_old = dir_ / (".fit.old-" + dead + "-3");
  const fs::path live_partial = dir_ / (".fit.partial-" + live + "-999");
  const fs::path other = dir_ / (".fitting.partial-" + dead + "-0");  // another target's
  for (const fs::path& p : {stale_partial, stale_old, live_partial, other}) {
    fs::create_directories(p / "deep");
    std::ofstream(p / "deep" / "rho_d.exr") << "hundreds of MB";
  }
  ASSERT_TRUE(WriteA(out, "second", FolderOutput{"fit", "fit", {}}).ok());
  EXPECT_FALSE(fs::exists(stale_partial));
  EXPECT_FALSE(fs::exists(stale_old));
  EXPECT_TRUE(fs::exists(live_partial / "deep" / "rho_d.exr")) << "a running writer's folder stays";
  EXPECT_TRUE(fs::exists(other)) << "only the target's own temporaries";
  EXPECT_EQ(test::ReadFileBytes(out / "a.txt"), "second");
}

TEST_F(OutputSafetyTest, AFailedMoveAsideSaysWhy) {
  const fs::path out = dir_ / "canvas";
  ASSERT_TRUE(WriteA(out, "first").ok());
  // The aside name (".canvas.old-<pid>-<n>") taken by non-empty folders of this live process:
  // the rename fails ("Directory not empty"), and that cause must reach the message.
  for (int n = 0; n < 64; ++n) {
    const fs::path taken =
        dir_ / (".canvas.old-" + std::to_string(::getpid()) + "-" + std::to_string(n));
    fs::create_directories(taken);
    std::ofstream(taken / "x") << "x";
  }
  const Status s = WriteA(out, "second");
  ASSERT_FALSE(s.ok());
  EXPECT_TRUE(Has(s.message(), "cannot move the previous output aside")) << s.message();
  EXPECT_FALSE(Has(s.message(), "Success")) << s.message();
  EXPECT_TRUE(Has(s.message(), std::generic_category().message(ENOTEMPTY)) ||
              Has(s.message(), std::generic_category().message(EEXIST)))
      << s.message();
  EXPECT_EQ(test::ReadFileBytes(out / "a.txt"), "first");
  for (const std::string& name : Hidden()) EXPECT_FALSE(Has(name, ".partial-")) << name;
}

// Noise compresses badly: a 384x384 RGB image is ~440 kB in any format.
Grid<std::array<uint8_t, 3>> Noise(int size = 384) {
  Grid<std::array<uint8_t, 3>> img(size, size);
  std::mt19937 rng(7);
  for (auto& p : img.data)
    for (auto& c : p) c = static_cast<uint8_t>(rng());
  return img;
}

TEST_F(OutputSafetyTest, ImagesAreWrittenInTheFormatTheirExtensionNames) {
  const auto img = Noise(32);
  for (const auto& [name, format] :
       std::vector<std::pair<std::string, std::string>>{{"shot.png", "png"},
                                                        {"shot.jpg", "jpeg"},
                                                        {"shot.JPEG", "jpeg"},
                                                        {"shot.tif", "tiff"},
                                                        {"shot.exr", "openexr"}}) {
    const Status s = WriteRgb8(dir_ / name, img);
    ASSERT_TRUE(s.ok()) << s.message();
    auto header = ReadImageHeader(dir_ / name);
    ASSERT_TRUE(header.ok()) << header.error().message;
    EXPECT_EQ(header->format, format) << name;
    EXPECT_EQ(header->width, 32);
    EXPECT_EQ(header->channels, 3);
  }
  // EXR holds linear values: code 255 is 1, code 128 is 0.2158 (sRGB decoding).
  Grid<std::array<uint8_t, 3>> two(2, 1);
  two.data = {{255, 255, 255}, {128, 128, 128}};
  ASSERT_TRUE(WriteRgb8(dir_ / "two.exr", two).ok());
  auto exr = ReadImage(dir_ / "two.exr");
  ASSERT_TRUE(exr.ok());
  EXPECT_NEAR(exr->pixels[0], 1.0f, 1e-3f);
  EXPECT_NEAR(exr->pixels[3], 0.2158f, 1e-3f);

  const Status bmp = WriteRgb8(dir_ / "shot.bmp", img);
  ASSERT_FALSE(bmp.ok());
  EXPECT_TRUE(Has(bmp.message(), "shot.bmp")) << bmp.message();
  EXPECT_TRUE(Has(bmp.message(), "unknown image extension")) << bmp.message();
  EXPECT_FALSE(fs::exists(dir_ / "shot.bmp"));
  EXPECT_FALSE(WriteRgb8(dir_ / "shot", img).ok()) << "no extension";
}

// Every writer under a file size limit (RLIMIT_FSIZE, no privileges needed): the write fails with
// EFBIG part way, as on a full disk. The error names the file and the cause, the previous file
// is intact, no temporary is left, and the process survives (libjpeg would exit it).
TEST_F(OutputSafetyTest, AFailedWriteIsReportedAndKeepsThePreviousFile) {
  const auto big = Noise();
  const std::string old_text = "the previous file";
  const std::vector<std::string> names = {"shot.png", "shot.jpg", "shot.tif", "shot.exr", "a.txt"};
  for (const std::string& name : names) std::ofstream(dir_ / name) << old_text;

  ::signal(SIGXFSZ, SIG_IGN);  // the write returns EFBIG instead of the signal killing us
  rlimit saved{};
  ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &saved), 0);
  rlimit limited = saved;
  limited.rlim_cur = 64 * 1024;
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &limited), 0);
  std::vector<Status> results;
  for (const std::string& name : names)
    results.push_back(name == "a.txt" ? WriteTextFile(dir_ / name, std::string(200000, 'x'))
                                      : WriteRgb8(dir_ / name, big));
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &saved), 0);
  ::signal(SIGXFSZ, SIG_DFL);

  const std::string cause = "file too large";  // strerror(EFBIG), lower-cased
  for (size_t i = 0; i < names.size(); ++i) {
    ASSERT_FALSE(results[i].ok()) << names[i];
    EXPECT_TRUE(Has(results[i].message(), (dir_ / names[i]).string())) << results[i].message();
    EXPECT_TRUE(Has(results[i].message(), cause)) << results[i].message();
    EXPECT_EQ(test::ReadFileBytes(dir_ / names[i]), old_text) << names[i];
  }
  EXPECT_TRUE(Hidden().empty()) << Hidden().front();
}

// The same on a real full disk, where mounting a small tmpfs is allowed (root); skipped elsewhere.
TEST_F(OutputSafetyTest, AFullDiskIsReportedAsSuch) {
  const fs::path disk = dir_ / "full";
  fs::create_directories(disk);
  const std::string mount = "mount -t tmpfs -o size=256k tmpfs " + disk.string() + " 2>/dev/null";
  if (::geteuid() != 0 || std::system(mount.c_str()) != 0)
    GTEST_SKIP() << "cannot mount a small tmpfs here (needs root)";
  const auto big = Noise();
  const fs::path shot = disk / "shot.png";
  ASSERT_TRUE(WriteRgb8(shot, Noise(16)).ok());
  const std::string old_bytes = test::ReadFileBytes(shot);
  const Status s = WriteRgb8(shot, big);
  const Status text = WriteTextFile(disk / "report.json", std::string(400000, 'x'));
  const std::string old_after = test::ReadFileBytes(shot);
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(disk)) left.push_back(e.path().filename().string());
  (void)std::system(("umount " + disk.string()).c_str());
  ASSERT_FALSE(s.ok());
  EXPECT_TRUE(Has(s.message(), shot.string() + ": write failed: no space left on device"))
      << s.message();
  EXPECT_TRUE(Has(text.message(), "report.json: write failed: no space left on device"))
      << text.message();
  EXPECT_EQ(old_after, old_bytes) << "the previous screenshot is intact";
  EXPECT_EQ(left, std::vector<std::string>{"shot.png"}) << "no temporary left";
}

}  // namespace
}  // namespace digitize
