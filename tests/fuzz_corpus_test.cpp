// The fuzz corpus (tests/fuzz/corpus/) replayed in the normal build, so that it keeps guarding the
// parsers without clang: every file must keep the contract of tests/fuzz/parser_contract.h (no
// crash; an error naming the source, or a result that holds the readers' promises), and the file
// readers must name the file in their errors too. File names say what a seed is meant to be:
// valid_* must parse, bad_* must be refused; crash_* (reproducers of fixed bugs) and anything
// else only have to keep the contract.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "digitize/photo_set.h"
#include "fuzz/parser_contract.h"

namespace digitize {
namespace {

namespace fs = std::filesystem;

fs::path CorpusDir(const std::string& target) {
  return fs::path(__FILE__).parent_path() / "fuzz" / "corpus" / target;
}

std::vector<fs::path> CorpusFiles(const std::string& target) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(CorpusDir(target))) {
    if (entry.is_regular_file()) files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  return files;
}

std::string ReadBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return bytes.str();
}

bool StartsWith(const fs::path& file, const char* prefix) {
  return file.filename().string().rfind(prefix, 0) == 0;
}

// What a corpus must hold so that the fuzzer starts from both sides of the parser's decisions.
constexpr size_t kMinValidSeeds = 2;
constexpr size_t kMinBadSeeds = 5;

struct Tally {
  size_t valid = 0, bad = 0;
};

// `parses` tells whether the parser accepts the file; `contract` checks the contract on it.
template <class Parses, class Contract>
Tally ReplayCorpus(const std::string& target, Parses parses, Contract contract) {
  Tally tally;
  const auto files = CorpusFiles(target);
  EXPECT_FALSE(files.empty()) << "no corpus in " << CorpusDir(target);
  for (const fs::path& file : files) {
    const std::string text = ReadBytes(file);
    // The real path as the source: errors must name it.
    EXPECT_EQ(contract(text, file), "") << file;
    const bool ok = parses(text, file);
    if (StartsWith(file, "valid_")) {
      ++tally.valid;
      EXPECT_TRUE(ok) << file << " is named valid_ but is refused";
    } else if (StartsWith(file, "bad_")) {
      ++tally.bad;
      EXPECT_FALSE(ok) << file << " is named bad_ but parses";
    }
  }
  return tally;
}

TEST(FuzzCorpusTest, CalibrationSeedsKeepTheContract) {
  const Tally tally = ReplayCorpus(
      "fuzz_calibration",
      [](const std::string& text, const fs::path& file) {
        return ParseCalibrationText(text, file).ok();
      },
      fuzz::CheckCalibrationText);
  EXPECT_GE(tally.valid, kMinValidSeeds);
  EXPECT_GE(tally.bad, kMinBadSeeds);
}

TEST(FuzzCorpusTest, LpSeedsKeepTheContract) {
  const Tally tally = ReplayCorpus(
      "fuzz_lp",
      [](const std::string& text, const fs::path& file) {
        return ParseRtiLightsText(text, file).ok();
      },
      fuzz::CheckLpText);
  EXPECT_GE(tally.valid, kMinValidSeeds);
  EXPECT_GE(tally.bad, kMinBadSeeds);
}

// Through the file readers (headers only): the corpus names images that do not exist, so a seed
// that parses is refused for its first image; either way the error names the file read.
TEST(FuzzCorpusTest, FileReadersNameTheFile) {
  PhotoSetOptions headers_only;
  headers_only.load_pixels = false;
  for (const fs::path& file : CorpusFiles("fuzz_calibration")) {
    const auto set = ReadCalibration(file, headers_only);
    if (!set.ok()) {
      EXPECT_EQ(fuzz::ErrorNamesSource(set.error().message, file), "");
    }
  }
  for (const fs::path& file : CorpusFiles("fuzz_lp")) {
    const auto set = ReadRtiCapture(file, headers_only);
    if (!set.ok()) {
      EXPECT_EQ(fuzz::ErrorNamesSource(set.error().message, file), "");
    }
  }
}

// The parsers and the readers agree: a text the parser refuses, the reader refuses with the same
// message (the readers add only the file read and the image checks).
TEST(FuzzCorpusTest, ReadersReportTheParsersErrors) {
  PhotoSetOptions headers_only;
  headers_only.load_pixels = false;
  for (const fs::path& file : CorpusFiles("fuzz_calibration")) {
    const auto parsed = ParseCalibrationText(ReadBytes(file), file);
    if (parsed.ok()) continue;
    const auto read = ReadCalibration(file, headers_only);
    ASSERT_FALSE(read.ok()) << file;
    EXPECT_EQ(read.error().message, parsed.error().message);
  }
  for (const fs::path& file : CorpusFiles("fuzz_lp")) {
    const auto parsed = ParseRtiLightsText(ReadBytes(file), file);
    if (parsed.ok()) continue;
    const auto read = ReadRtiCapture(file, headers_only);
    ASSERT_FALSE(read.ok()) << file;
    EXPECT_EQ(read.error().message, parsed.error().message);
  }
}

// Found while fuzzing: error messages printed the offending value with json::dump, which recurses
// once per nesting level, so a few hundred KB of nested arrays overflowed the stack. The value is
// now shown shortened; the message names the file and the key and stays short.
TEST(FuzzCorpusTest, DeeplyNestedValueIsAnErrorNotAStackOverflow) {
  constexpr int kDepth = 200000;  // 400 KB; the stack overflowed from ~30000 under ASan
  const std::string text =
      R"({"format":"digitize.calibration","version":1,"images":[{"path":"a.png","light":0,)"
      R"("camera":{"width":4,"height":4,"fx":)" +
      std::string(kDepth, '[') + std::string(kDepth, ']') + "}}]}";
  const auto set = ParseCalibrationText(text, "deep/calib.json");
  ASSERT_FALSE(set.ok());
  const std::string& message = set.error().message;
  EXPECT_NE(message.find("deep/calib.json: images[0].camera.fx must be a number, got [[[..."),
            std::string::npos)
      << message;
  EXPECT_LT(message.size(), 200u) << message;
}

}  // namespace
}  // namespace digitize
