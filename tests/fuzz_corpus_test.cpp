// The fuzz corpus (tests/fuzz/corpus/) replayed in the normal build, so that it keeps guarding the
// parsers (calibration JSON, .lp, texture packs) without clang: every file must keep the contract
// of tests/fuzz/parser_contract.h (no crash; an error naming the source, or a result that holds the
// readers' promises), and the file readers must name the file in their errors too. File names say
// what a seed is meant to be: valid_* must parse, bad_* must be refused; crash_* (reproducers of
// fixed bugs) and anything else only have to keep the contract.
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "digitize/pack.h"
#include "digitize/pack_tiled.h"
#include "digitize/photo_set.h"
#include "digitize_viewer/gallery.h"
#include "digitize_viewer/painting_setup.h"
#include "fuzz/parser_contract.h"
#include "fuzz/viewer_contract.h"
#include "pack_forge.h"
#include "test_paths.h"
#include "test_support.h"

namespace digitize {
namespace {

namespace fs = std::filesystem;

fs::path CorpusDir(const std::string& target) {
  return fs::path(DIGITIZE_SOURCE_DIR) / "tests" / "fuzz" / "corpus" / target;
}

std::vector<fs::path> CorpusFiles(const std::string& target) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(CorpusDir(target))) {
    if (entry.is_regular_file()) files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  return files;
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
    const std::string text = test::ReadFileBytes(file);
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

TEST(FuzzCorpusTest, PackSeedsKeepTheContract) {
  const Tally tally = ReplayCorpus(
      "fuzz_pack",
      [](const std::string& /*bytes*/, const fs::path& file) { return ReadPack(file).ok(); },
      [](const std::string& /*bytes*/, const fs::path& file) { return fuzz::CheckPackFile(file); });
  EXPECT_GE(tally.valid, kMinValidSeeds);
  EXPECT_GE(tally.bad, kMinBadSeeds);
}

// The viewer's load path: valid_* packs load and hang, bad_* are refused (at load or by the
// set-up), and every file keeps the contract of viewer_contract.h.
TEST(FuzzCorpusTest, ViewerLoadSeedsKeepTheContract) {
  const Tally tally = ReplayCorpus(
      "fuzz_viewer_load",
      [](const std::string& /*bytes*/, const fs::path& file) {
        auto pack = viewer::LoadPackForViewer(file);
        return pack.ok() && viewer::PreparePainting(*pack, file.string()).ok();
      },
      [](const std::string& /*bytes*/, const fs::path& file) {
        return fuzz::CheckViewerLoadFile(file);
      });
  EXPECT_GE(tally.valid, kMinValidSeeds);
  EXPECT_GE(tally.bad, kMinBadSeeds);
}

// Found by fuzz_viewer_load: an attribute name longer than OpenEXR reads (31 characters without
// the long-names flag) put our header pre-scan and OpenEXR out of step, and OpenEXR then read
// name bytes as a string's size and allocated 2 GB for a 3 KB file. Refused by the pre-scan now.
TEST(FuzzCorpusTest, LongAttributeNameIsRefusedBeforeOpenExr) {
  for (const char* target : {"fuzz_pack", "fuzz_viewer_load"}) {
    const fs::path file = CorpusDir(target) / "bad_long_attribute_name_oom.exr";
    const auto pack = ReadPack(file);
    ASSERT_FALSE(pack.ok());
    EXPECT_EQ(pack.error().message,
              file.string() +
                  ": part 0 has an attribute or type name longer than 31 characters, "
                  "OpenEXR's limit without long names");
  }
}

// A fixed-size attribute stated larger than its type (a v2f of 248 bytes): OpenEXR reads 8 and
// takes the rest for the next attribute, whose "size" then asked for 1.9 GB (the fuzzer's OOM).
TEST(FuzzCorpusTest, AttributeSizeDesyncIsRefusedBeforeOpenExr) {
  for (const char* target : {"fuzz_pack", "fuzz_viewer_load"}) {
    const fs::path file = CorpusDir(target) / "bad_attribute_size_desync_oom.exr";
    const auto pack = ReadPack(file);
    ASSERT_FALSE(pack.ok());
    EXPECT_EQ(pack.error().message,
              file.string() +
                  ": part 2 attribute 'screenWindowCenter' is 248 bytes, a v2f is 8; corrupt "
                  "OpenEXR header");
  }
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
    const auto parsed = ParseCalibrationText(test::ReadFileBytes(file), file);
    if (parsed.ok()) continue;
    const auto read = ReadCalibration(file, headers_only);
    ASSERT_FALSE(read.ok()) << file;
    EXPECT_EQ(read.error().message, parsed.error().message);
  }
  for (const fs::path& file : CorpusFiles("fuzz_lp")) {
    const auto parsed = ParseRtiLightsText(test::ReadFileBytes(file), file);
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

// ---------------------------------------------------------------------------------------------
// The pack seeds. Not a test: run by hand when the pack format changes (the valid_ seeds then fail
// PackSeedsKeepTheContract above), from the repository root:
//   build/tests/fuzz_corpus_test --gtest_also_run_disabled_tests --gtest_filter='*WritePackSeeds'
// Small on purpose (8x8 and 9x5 texels, 2-4 KB; the tiled one 70x9, 8 KB, the least that has two
// tiles): libFuzzer mutates every byte of a seed.

// An 8x8 (or any size) pack: a bump in the middle, an outside border, one relief box over the
// bump's cell, reflectance varying per texel, every fit status; with `ggx`, the right half GGX
// (varnish and gold rows, alpha 0.05 .. 0.3).
Pack TinyPack(int w, int h, bool with_box, bool ggx = false) {
  Pack p;
  p.field.pitch_mm = 0.25;
  p.field.height_mm = Grid<float>(w, h, 0.0f);
  p.field.state = Grid<TexelState>(w, h, TexelState::kMeasured);
  p.normals = Grid<Vec3f>(w, h, Vec3f::UnitZ());
  p.maps = ReflectanceMaps::Zeros(w, h);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      if (x == 0 || y == 0 || x == w - 1 || y == h - 1) {
        p.field.state(x, y) = TexelState::kOutside;
        continue;
      }
      const float dx = x - w / 2.0f, dy = y - h / 2.0f;
      p.field.height_mm(x, y) = 0.5f * std::exp(-(dx * dx + dy * dy) / 4.0f);
      p.normals(x, y) = Vec3f(0.05f * dx, -0.05f * dy, 1.0f).normalized();
      LafortuneParams lp;
      lp.rho_d = Vec3f(0.1f + 0.01f * x, 0.2f, 0.3f - 0.01f * y);
      lp.rho_s = Vec3f::Constant(0.5f + 0.1f * x);
      lp.cx = -1.1f;
      lp.cy = -0.9f;
      lp.k = 10.0f + 5.0f * y;
      p.maps.Set(x, y, lp);
      if (ggx && x >= w / 2) {
        const bool gold = y % 2 == 0;
        p.maps.SetGgx(x, y,
                      {gold ? Vec3f::Zero() : lp.rho_d,
                       gold ? Vec3f(1.0f, 0.78f, 0.34f) : Vec3f::Constant(0.04f),
                       std::min(0.3f, 0.05f + 0.05f * float(x - w / 2))});
      }
      p.maps.status(x, y) = static_cast<TexelFitStatus>((x + y) % kTexelFitStatusCount);
    }
  }
  p.cell_px = 4;
  p.max_height_mm = 0.5;
  if (with_box) {
    p.delta0_mm = 0.1;
    ReliefBox box;
    box.x0 = w / 2 / p.cell_px * p.cell_px;
    box.y0 = h / 2 / p.cell_px * p.cell_px;
    box.width = std::min(p.cell_px, w - box.x0);
    box.height = std::min(p.cell_px, h - box.y0);
    box.u_max = w / 2;
    box.v_max = h / 2;
    box.h_max_mm = p.field.height_mm(box.u_max, box.v_max);
    p.boxes = {box};
  }
  p.canvas_from_scan.rotation = Eigen::AngleAxisd(0.2, Vec3d(0, 0, 1)).toRotationMatrix();
  p.canvas_from_scan.translation = Vec3d(-1, 2, 30);
  p.provenance.tool_version = "digitize fuzz seed";
  p.provenance.created_utc = "2026-11-30T00:00:00Z";
  p.provenance.fit_brief = "seed";
  p.provenance.options_json = R"({"fit":{"k_max":5000}})";
  p.provenance.inputs = {{"scan.exr", "", 12}};
  return p;
}

// The same pack without compression: byte mutations then reach the values (ZIP data fails zlib's
// own check on any change). The checksum covers decoded pixels, so it still holds.
void RewriteUncompressed(const fs::path& from, const fs::path& to) {
  auto in = OIIO::ImageInput::open(from.string());
  ASSERT_TRUE(in) << OIIO::geterror();
  std::vector<OIIO::ImageSpec> specs;
  std::vector<std::vector<char>> pixels;
  for (int part = 0; in->seek_subimage(part, 0); ++part) {
    specs.push_back(in->spec());
    specs.back().attribute("compression", "none");
    pixels.emplace_back(specs.back().image_bytes(/*native=*/true));
    ASSERT_TRUE(in->read_image(part, 0, 0, specs.back().nchannels, OIIO::TypeDesc::UNKNOWN,
                               pixels.back().data()))
        << in->geterror();
  }
  auto out = OIIO::ImageOutput::create(to.string());
  ASSERT_TRUE(out);
  ASSERT_TRUE(out->open(to.string(), static_cast<int>(specs.size()), specs.data()))
      << out->geterror();
  for (size_t part = 0; part < specs.size(); ++part) {
    if (part > 0) {
      ASSERT_TRUE(out->open(to.string(), specs[part], OIIO::ImageOutput::AppendSubimage));
    }
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UNKNOWN, pixels[part].data())) << out->geterror();
  }
  ASSERT_TRUE(out->close());
}

TEST(FuzzCorpusTest, DISABLED_WritePackSeeds) {
  const fs::path dir = CorpusDir("fuzz_pack");
  fs::create_directories(dir);
  ASSERT_TRUE(WritePack(dir / "valid_half_8x8_box.exr", TinyPack(8, 8, true)).ok());
  PackWriteOptions quantised;
  quantised.encoding = PackEncoding::kQuantised;
  ASSERT_TRUE(WritePack(dir / "valid_quantised_9x5.exr", TinyPack(9, 5, false), quantised).ok());

  RewriteUncompressed(dir / "valid_half_8x8_box.exr", dir / "valid_uncompressed_8x8_box.exr");
  // GGX texels (pack version 2), and a texel naming a model no reader knows (M = 2 x 64 + 1).
  // The valid_v1_* seeds are packs of version 1 (before models), kept as they were written.
  ASSERT_TRUE(WritePack(dir / "valid_ggx_8x8_box.exr", TinyPack(8, 8, true, true)).ok());
  RewriteUncompressed(dir / "valid_ggx_8x8_box.exr", dir / "valid_uncompressed_ggx_8x8_box.exr");
  {  // Version 3: two 64-texel tiles at level 0, seven levels down to 1 x 1, the checksums part.
    PackWriteOptions tiled;
    tiled.tile_size = kMinPackTileSize;
    const Status written =
        WritePack(dir / "valid_tiled_70x9.exr", TinyPack(70, 9, true, true), tiled);
    ASSERT_TRUE(written.ok()) << written.message();
  }
  ASSERT_EQ(forge::ForgePack(dir / "valid_uncompressed_ggx_8x8_box.exr",
                             dir / "bad_unknown_model.exr", {}, {},
                             [](int part, const OIIO::ImageSpec& spec, std::vector<char>& px) {
                               if (part == 0) {
                                 ASSERT_TRUE(forge::SetHalf(spec, px, "M", 2, 3, 129));
                               }
                             }),
            "");
  const std::string good = test::ReadFileBytes(dir / "valid_half_8x8_box.exr");
  ASSERT_GT(good.size(), 200u);
  test::WriteFileBytes(dir / "bad_truncated.exr", good.substr(0, good.size() * 2 / 3));
  std::string flipped = good;
  flipped[flipped.size() - 20] ^= 0x10;  // in the last part's pixel data
  test::WriteFileBytes(dir / "bad_bit_flip.exr", flipped);
  // A newer version: the digitize:version string attribute's value (one digit) becomes "9".
  const std::string key = std::string("digitize:version") + '\0' + "string" + '\0';
  const size_t at = good.find(key);
  ASSERT_NE(at, std::string::npos);
  std::string newer = good;
  ASSERT_EQ(newer[at + key.size() + 4], char('0' + kPackVersion));
  newer[at + key.size() + 4] = '9';
  test::WriteFileBytes(dir / "bad_newer_version.exr", newer);
  test::WriteFileBytes(dir / "bad_not_exr.exr", "digitize.pack, but not an OpenEXR file\n");
  // Forged headers with a recomputed checksum (pack_forge.h): physically absurd metadata that
  // every finiteness check lets through (a forged pitch_mm = 1e308 once aborted the viewer).
  const std::vector<std::pair<std::string, std::map<std::string, std::string>>> forged = {
      {"bad_forged_pitch_1e308.exr", {{"digitize:pitch_mm", "1e308"}}},
      {"bad_forged_pitch_tiny.exr", {{"digitize:pitch_mm", "1e-300"}}},
      {"bad_forged_size_mm.exr", {{"digitize:size_mm", "1e308 x 1e308"}}},
      {"bad_forged_max_height.exr", {{"digitize:max_height_mm", "1e30"}}},
      {"bad_forged_translation.exr",
       {{"digitize:canvas_from_scan",
         R"({"rotation":[[1,0,0],[0,1,0],[0,0,1]],"translation_mm":[0,0,1e300]})"}}},
  };
  for (const auto& [name, attributes] : forged)
    ASSERT_EQ(forge::ForgePack(dir / "valid_uncompressed_8x8_box.exr", dir / name, attributes), "");

  // The viewer's load path: the valid packs above, the forged ones, and packs that load but that
  // the viewer cannot hang (under 2 x 2 texels).
  const fs::path viewer_dir = CorpusDir("fuzz_viewer_load");
  fs::create_directories(viewer_dir);
  for (const char* name :
       {"valid_half_8x8_box.exr", "valid_quantised_9x5.exr", "valid_uncompressed_8x8_box.exr",
        "valid_ggx_8x8_box.exr", "valid_tiled_70x9.exr", "bad_unknown_model.exr",
        "bad_forged_pitch_1e308.exr", "bad_forged_max_height.exr", "bad_forged_translation.exr",
        "bad_truncated.exr"})
    fs::copy_file(dir / name, viewer_dir / name, fs::copy_options::overwrite_existing);
  {
    Pack line = TinyPack(1, 6, false);
    ASSERT_TRUE(WritePack(viewer_dir / "bad_one_texel_wide.exr", line).ok());
    PackWriteOptions none;
    ASSERT_TRUE(WritePack(viewer_dir / "valid_2x2.exr", TinyPack(2, 2, false), none).ok());
  }
  {  // A plain single-part EXR, 4x4 RGB.
    const std::string plain = (dir / "bad_single_part.exr").string();
    auto out = OIIO::ImageOutput::create(plain);
    ASSERT_TRUE(out);
    OIIO::ImageSpec spec(4, 4, 3, OIIO::TypeDesc::HALF);
    const std::vector<float> pixels(4 * 4 * 3, 0.5f);
    ASSERT_TRUE(out->open(plain, spec));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, pixels.data()));
    ASSERT_TRUE(out->close());
  }
}

}  // namespace
}  // namespace digitize
