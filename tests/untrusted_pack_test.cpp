// Packs are shared between institutions, so a pack is untrusted input (docs/refusals.md, "Packs and
// shared files"): what `digitize inspect` / `verify` and `digitize-viewer` do with hostile packs --
// provenance that holds terminal escapes and forged lines, a forged header with a recomputed
// checksum, a pack the viewer cannot hang -- and with screenshot sizes no GL can render. The
// library-level refusals are in pack_test (bounds), viewer_test (set-up) and photo_set_test
// (paths).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "digitize/image_io.h"
#include "digitize/pack.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/truth_pack.h"
#include "pack_forge.h"
#include "test_paths.h"
#include "test_support.h"

namespace digitize {
namespace {

namespace fs = std::filesystem;

struct Output {
  int exit_code = -1;
  std::string out, err;
};

// Runs a program with stdout and stderr captured apart (the JSON must be alone on stdout).
Output RunProgram(const std::string& program, const std::string& args, const fs::path& dir) {
  const fs::path out = dir / "stdout.txt", err = dir / "stderr.txt";
  const std::string command =
      program + " " + args + " > '" + out.string() + "' 2> '" + err.string() + "'";
  const int status = std::system(command.c_str());
  Output o;
  o.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  auto read = [](const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  };
  o.out = read(out);
  o.err = read(err);
  return o;
}

// Not "'" + s + "'": GCC 12 warns on that (-Wstringop-overflow, a false positive in its inlined
// char_traits copy).
std::string Quote(const fs::path& p) {
  std::string quoted = p.string();
  quoted.insert(quoted.begin(), '\'');
  quoted.push_back('\'');
  return quoted;
}

class UntrustedPackTest : public test::ScratchDirTest {
 protected:
  UntrustedPackTest() : ScratchDirTest("digitize_untrusted") {}

  static Pack SmallPack() {
    synth::PaintingOptions po;
    po.width_mm = 60;
    po.height_mm = 40;
    po.resolution_px = 64;
    po.impasto_count = 2;
    return synth::MakeTruthPack(synth::MakePainting(po));
  }
};

bool HasControlBytes(const std::string& text) {
  return std::any_of(text.begin(), text.end(), [](char c) {
    const auto u = static_cast<unsigned char>(c);
    return (u < 0x20 && c != '\n') || u == 0x7f || (u >= 0x80 && u <= 0x9f);
  });
}

TEST(EscapeForTerminalTest, ControlsAreEscapedAndPrintableTextKept) {
  EXPECT_EQ(EscapeForTerminal("plain text, 5 mm"), "plain text, 5 mm");
  EXPECT_EQ(EscapeForTerminal("\x1b[2J"), "\\x1b[2J");
  EXPECT_EQ(EscapeForTerminal("\x1b]0;title\x07"), "\\x1b]0;title\\x07");
  EXPECT_EQ(EscapeForTerminal("a\nforged line\r\t"), "a\\nforged line\\r\\t");
  EXPECT_EQ(EscapeForTerminal(std::string("nul\0x", 5)), "nul\\x00x");
  EXPECT_EQ(EscapeForTerminal("\x7f"), "\\x7f");
  EXPECT_EQ(EscapeForTerminal("\xc2\x9b"
                              "31m"),
            "\\u{009b}31m");  // C1 CSI as UTF-8
  EXPECT_EQ(EscapeForTerminal("\x9b"
                              "31m"),
            "\\x9b31m");  // raw 8-bit CSI
  EXPECT_EQ(EscapeForTerminal("\xe2\x80\xae"
                              "txt"),
            "\\u{202e}txt");                                        // right-to-left override
  EXPECT_EQ(EscapeForTerminal("\xff\xc3"), "\\xff\\xc3");           // not UTF-8
  EXPECT_EQ(EscapeForTerminal("\xed\xa0\x80"), "\\xed\\xa0\\x80");  // a surrogate
  EXPECT_EQ(EscapeForTerminal("Mus\xc3\xa9"
                              "e \xe6\x97\xa5"),
            "Mus\xc3\xa9"
            "e \xe6\x97\xa5");
  // A backslash is escaped too: no text can pose as an escaped control.
  EXPECT_EQ(EscapeForTerminal("\\x1b"), "\\\\x1b");
}

// Provenance that would clear the screen, set the terminal's title and forge a line of the
// listing: inspect shows it escaped, and --json is valid (ASCII) JSON holding the exact strings.
TEST_F(UntrustedPackTest, InspectEscapesProvenance) {
  Pack p = SmallPack();
  p.provenance.tool_version = "digitize 0.5.0\x1b[2J";
  p.provenance.created_utc = "2026-12-01T00:00:00Z\x1b]0;title\x07";
  p.provenance.fit_brief = "99 % converged\nforged line: sha1 verified by the museum";
  p.provenance.inputs = {{"scan.exr\x1b[31m",
                          "\x9b"
                          "0m",
                          12},
                         {"\xc2\x9b"
                          "2J",
                          "", 1}};
  const fs::path pack = dir_ / "hostile.pack.exr";
  ASSERT_TRUE(WritePack(pack, p).ok());

  const Output text = RunProgram(DIGITIZE_CLI, "inspect " + Quote(pack), dir_);
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_FALSE(HasControlBytes(text.out)) << text.out;
  EXPECT_NE(text.out.find("digitize 0.5.0\\x1b[2J"), std::string::npos) << text.out;
  EXPECT_NE(text.out.find("\\x1b]0;title\\x07"), std::string::npos) << text.out;
  EXPECT_NE(text.out.find("converged\\nforged line"), std::string::npos) << text.out;
  EXPECT_EQ(text.out.find("\nforged line"), std::string::npos) << text.out;

  const Output json = RunProgram(DIGITIZE_CLI, "inspect --json " + Quote(pack), dir_);
  ASSERT_EQ(json.exit_code, 0) << json.err;
  EXPECT_TRUE(std::all_of(json.out.begin(), json.out.end(),
                          [](char c) { return static_cast<unsigned char>(c) < 0x80; }));
  EXPECT_FALSE(HasControlBytes(json.out)) << json.out;
  const auto doc = nlohmann::json::parse(json.out, nullptr, false);
  ASSERT_FALSE(doc.is_discarded()) << json.out;
  EXPECT_EQ(doc["provenance"]["tool_version"], p.provenance.tool_version);
  EXPECT_EQ(doc["provenance"]["fit_brief"], p.provenance.fit_brief);
  EXPECT_EQ(doc["provenance"]["inputs"][1]["name"],
            "\xc2\x9b"
            "2J");
  // The raw 8-bit byte was not UTF-8: the writer stored U+FFFD instead (nothing thrown).
  EXPECT_EQ(doc["provenance"]["inputs"][0]["sha1"],
            "\xef\xbf\xbd"
            "0m");

  // A file name that is not UTF-8: still valid JSON, the name with U+FFFD.
  const fs::path odd = dir_ / "caf\xe9.pack.exr";
  fs::copy_file(pack, odd);
  const Output named = RunProgram(DIGITIZE_CLI, "inspect --json " + Quote(odd), dir_);
  ASSERT_EQ(named.exit_code, 0) << named.err;
  EXPECT_FALSE(nlohmann::json::parse(named.out, nullptr, false).is_discarded()) << named.out;
  const Output verify = RunProgram(DIGITIZE_CLI, "verify " + Quote(pack), dir_);
  ASSERT_EQ(verify.exit_code, 0) << verify.err;
  EXPECT_FALSE(HasControlBytes(verify.out)) << verify.out;
}

// The forged pack of the issue: pitch_mm = 1e308 with a recomputed checksum. verify and inspect
// refuse it naming the file and the attribute (inspect no longer prints "inf x inf mm").
TEST_F(UntrustedPackTest, ForgedPitchIsRefusedByVerifyAndInspect) {
  const fs::path good = dir_ / "good.pack.exr", forged = dir_ / "forged.pack.exr";
  ASSERT_TRUE(WritePack(good, SmallPack()).ok());
  ASSERT_EQ(forge::ForgePack(good, forged, {{"digitize:pitch_mm", "1e308"}}), "");
  for (const char* command : {"verify ", "inspect ", "inspect --json "}) {
    SCOPED_TRACE(command);
    const Output o = RunProgram(DIGITIZE_CLI, command + Quote(forged), dir_);
    EXPECT_EQ(o.exit_code, 1);
    EXPECT_NE(o.err.find(forged.string() + ": digitize:pitch_mm 1e+308"), std::string::npos)
        << o.err;
    EXPECT_EQ(o.out.find("inf"), std::string::npos) << o.out;
  }
}

// Reflectance models through the tools: `inspect --json` counts the texels of each model from the
// header, `verify` lists them, and a texel naming a model no reader knows (forged with a
// recomputed checksum) is refused by verify naming the file and the texel; inspect, which reads
// no pixel, still shows the header.
TEST_F(UntrustedPackTest, ToolsReportModelsAndRefuseUnknownOnes) {
  Pack p = SmallPack();
  int64_t ggx = 0;
  for (int y = 0; y < p.height(); ++y)
    for (int x = p.width() / 2; x < p.width(); ++x) {
      if (p.field.state(x, y) == TexelState::kOutside) continue;
      p.maps.SetGgx(x, y, {Vec3f::Zero(), Vec3f(1.0f, 0.78f, 0.34f), 0.2f});
      ++ggx;
    }
  const fs::path pack = dir_ / "ggx.pack.exr";
  ASSERT_TRUE(WritePack(pack, p).ok());
  const Output json = RunProgram(DIGITIZE_CLI, "inspect --json " + Quote(pack), dir_);
  ASSERT_EQ(json.exit_code, 0) << json.err;
  const auto doc = nlohmann::json::parse(json.out, nullptr, false);
  ASSERT_FALSE(doc.is_discarded()) << json.out;
  EXPECT_EQ(doc["version"], kPackVersion);
  EXPECT_EQ(doc["models"]["ggx"], ggx);
  EXPECT_EQ(doc["models"]["lafortune"], int64_t(p.width()) * p.height() - ggx);
  const Output verify = RunProgram(DIGITIZE_CLI, "verify " + Quote(pack), dir_);
  ASSERT_EQ(verify.exit_code, 0) << verify.err;
  EXPECT_NE(verify.out.find("ok  models: " + std::to_string(p.width() * p.height() - ggx) +
                            " lafortune, " + std::to_string(ggx) + " ggx texels"),
            std::string::npos)
      << verify.out;

  const fs::path forged = dir_ / "model7.pack.exr";
  ASSERT_EQ(forge::ForgePack(pack, forged, {}, {},
                             [](int part, const OIIO::ImageSpec& spec, std::vector<char>& px) {
                               if (part == 0) {
                                 ASSERT_TRUE(forge::SetHalf(spec, px, "M", 3, 2, 7 * 64 + 1));
                               }
                             }),
            "");
  const Output refused = RunProgram(DIGITIZE_CLI, "verify " + Quote(forged), dir_);
  EXPECT_EQ(refused.exit_code, 1);
  EXPECT_NE(refused.err.find(forged.string() +
                             ": texel 3, 2: M = 449 names reflectance model 7, which this reader "
                             "does not know (lafortune = 0, ggx = 1)"),
            std::string::npos)
      << refused.err;
  EXPECT_EQ(RunProgram(DIGITIZE_CLI, "inspect " + Quote(forged), dir_).exit_code, 0);
}

#ifdef DIGITIZE_VIEWER
// The viewer never aborts on a shared pack: the forged one fails to load, a 1-texel-wide one
// (valid, but nothing the renderer can hang) fails to hang; both are listed on stderr and the
// good pack is rendered.
TEST_F(UntrustedPackTest, ViewerListsFailedPacksAndRendersTheOthers) {
  const fs::path good = dir_ / "good.pack.exr", forged = dir_ / "forged.pack.exr";
  ASSERT_TRUE(WritePack(good, SmallPack()).ok());
  ASSERT_EQ(forge::ForgePack(good, forged, {{"digitize:pitch_mm", "1e308"}}), "");
  Pack line = SmallPack();
  const int h = line.height();
  line.field.height_mm = Grid<float>(1, h, 0.0f);
  line.field.state = Grid<TexelState>(1, h, TexelState::kMeasured);
  line.normals = Grid<Vec3f>(1, h, Vec3f::UnitZ());
  line.maps = ReflectanceMaps::Zeros(1, h);
  line.boxes.clear();
  line.delta0_mm = 0;
  const fs::path thin = dir_ / "thin.pack.exr";
  ASSERT_TRUE(WritePack(thin, line).ok()) << WritePack(thin, line).message();
  const fs::path png = dir_ / "shot.png";
  const Output o = RunProgram(DIGITIZE_VIEWER,
                              Quote(forged) + " " + Quote(good) + " " + Quote(thin) +
                                  " --screenshot " + Quote(png) + " --size 96x64",
                              dir_);
  EXPECT_EQ(o.exit_code, 1) << o.err;  // some packs failed; not an abort (134)
  EXPECT_NE(o.err.find(forged.string() + ": digitize:pitch_mm 1e+308"), std::string::npos) << o.err;
  EXPECT_NE(o.err.find(thin.string() + ": the pack has 1x"), std::string::npos) << o.err;
  EXPECT_NE(o.out.find("(1 painting(s), 2 failed to load)"), std::string::npos) << o.out;
  EXPECT_TRUE(fs::exists(png));
}

TEST_F(UntrustedPackTest, ViewerRefusesScreenshotSizesTheGlCannotRender) {
  for (const char* size : {"100000x100000", "20000x100"}) {
    SCOPED_TRACE(size);
    const fs::path png = dir_ / "huge.png";
    const Output o = RunProgram(DIGITIZE_VIEWER,
                                "--synthetic --screenshot " + Quote(png) + " --size " + size, dir_);
    EXPECT_EQ(o.exit_code, 1) << o.err;
    EXPECT_NE(o.err.find(std::string("a ") + size + " image is larger than this OpenGL's maximum"),
              std::string::npos)
        << o.err;
    EXPECT_FALSE(fs::exists(png));
  }
}
#endif

}  // namespace
}  // namespace digitize
