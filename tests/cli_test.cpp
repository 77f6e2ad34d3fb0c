// The `digitize` command line as a user meets it: help, exit codes, error messages that name the
// file, outputs complete or absent, never partial.
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "test_paths.h"
#include "test_support.h"

namespace {

namespace fs = std::filesystem;

struct Output {
  int exit_code = -1;
  std::string text;  // stdout + stderr
};

// `digitize ARGS`, run from `cwd` when given, with `env` (NAME=VALUE ...) when given.
Output RunCli(const std::string& args, const fs::path& cwd = {}, const std::string& env = {}) {
  static int counter = 0;
  const fs::path log =
      digitize::test::ScratchPath("digitize_cli_test", std::to_string(counter++) + ".log");
  const std::string cd = cwd.empty() ? "" : "cd '" + cwd.string() + "' && ";
  const std::string command = "(" + cd + (env.empty() ? "" : "env " + env + " ") +
                              std::string(DIGITIZE_CLI) + " " + args + ") > " + log.string() +
                              " 2>&1";
  const int status = std::system(command.c_str());
  Output out;
  out.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream in(log);
  std::stringstream ss;
  ss << in.rdbuf();
  out.text = ss.str();
  fs::remove(log);
  return out;
}

class CliTest : public digitize::test::ScratchDirTest {
 protected:
  CliTest() : ScratchDirTest("digitize_cli") {}
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
};

TEST_F(CliTest, HelpForEveryCommand) {
  Output top = RunCli("--help");
  EXPECT_EQ(top.exit_code, 0);
  for (const char* cmd :
       {"synth", "preprocess", "fit", "pack", "run", "inspect", "verify", "demo"}) {
    EXPECT_NE(top.text.find(cmd), std::string::npos) << cmd;
    Output sub = RunCli(std::string(cmd) + " --help");
    EXPECT_EQ(sub.exit_code, 0) << cmd;
    EXPECT_NE(sub.text.find("--"), std::string::npos) << cmd;
  }
  // Thresholds are documented with their units.
  Output pre = RunCli("preprocess --help");
  EXPECT_NE(pre.text.find("--stop-gradient-mm"), std::string::npos);
  EXPECT_NE(pre.text.find("--delta0"), std::string::npos);
  EXPECT_NE(pre.text.find("--cell-px"), std::string::npos);
}

TEST_F(CliTest, NoCommandIsAUsageError) { EXPECT_EQ(RunCli("").exit_code, 1); }

// A build for AVX2 and FMA (DIGITIZE_SIMD) started on a CPU without them says so before any of
// its own code runs, instead of dying of SIGILL; a baseline build has no such check.
TEST_F(CliTest, AnAvx2BuildOnACpuWithoutItSaysWhatToDo) {
  const Output version = RunCli("--version");
  ASSERT_EQ(version.exit_code, 0);
  const bool v3 = version.text.find("(x86-64-v3)") != std::string::npos;
  if (!v3) {
    ASSERT_NE(version.text.find("(baseline)"), std::string::npos) << version.text;
  }
  const Output old_cpu = RunCli("--version", {}, "DIGITIZE_TEST_CPU_WITHOUT_X86_64_V3=1");
  if (!v3) {
    EXPECT_EQ(old_cpu.exit_code, 0) << old_cpu.text;
    return;
  }
  EXPECT_EQ(old_cpu.exit_code, 1);
  EXPECT_NE(old_cpu.text.find("AVX2 and FMA"), std::string::npos) << old_cpu.text;
  EXPECT_NE(old_cpu.text.find("-DDIGITIZE_SIMD=NONE"), std::string::npos) << old_cpu.text;
  EXPECT_EQ(old_cpu.text.find("digitize 0."), std::string::npos) << "ran on: " << old_cpu.text;
}

TEST_F(CliTest, MissingScanNamesTheFile) {
  Output out = RunCli("preprocess " + Path("nope.exr") + " --out " + Path("out"));
  EXPECT_NE(out.exit_code, 0);
  EXPECT_NE(out.text.find("nope.exr"), std::string::npos) << out.text;
  EXPECT_FALSE(fs::exists(Path("out")));
}

TEST_F(CliTest, CorruptScanNamesTheFileAndWritesNothing) {
  std::ofstream(Path("broken.exr")) << "this is not an OpenEXR file at all";
  Output out = RunCli("preprocess " + Path("broken.exr") + " --out " + Path("out"));
  EXPECT_EQ(out.exit_code, 1) << out.text;
  EXPECT_NE(out.text.find("broken.exr"), std::string::npos) << out.text;
  EXPECT_FALSE(fs::exists(Path("out")));
  for (const auto& entry : fs::directory_iterator(dir_))
    EXPECT_EQ(entry.path().filename().string().find(".partial"), std::string::npos) << entry.path();
}

TEST_F(CliTest, BadOptionValueNamesTheOption) {
  Output synth = RunCli("synth --out " + Path("s") + " --resolution 96 --scan-size 96 96");
  ASSERT_EQ(synth.exit_code, 0) << synth.text;
  Output out =
      RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("out") + " --cell-px 0");
  EXPECT_EQ(out.exit_code, 1) << out.text;
  EXPECT_NE(out.text.find("cell_px"), std::string::npos) << out.text;
  EXPECT_FALSE(fs::exists(Path("out")));
}

// The guard against a corrupt header's size is an option: a scan above it is refused (file named,
// nothing written), one at it is read.
TEST_F(CliTest, ScansAboveMaxScanSamplesAreRefused) {
  Output synth = RunCli("synth --out " + Path("s") + " --resolution 96 --scan-size 96 96");
  ASSERT_EQ(synth.exit_code, 0) << synth.text;
  Output refused = RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("out") +
                          " --max-scan-samples 9215");
  EXPECT_EQ(refused.exit_code, 1) << refused.text;
  EXPECT_NE(refused.text.find("scan.exr"), std::string::npos) << refused.text;
  EXPECT_NE(refused.text.find("9216"), std::string::npos) << refused.text;
  EXPECT_NE(refused.text.find("9215"), std::string::npos) << refused.text;
  EXPECT_NE(refused.text.find("--tile-texels"), std::string::npos) << "what to do";
  EXPECT_FALSE(fs::exists(Path("out")));
  Output read = RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("out") +
                       " --max-scan-samples 9216");
  EXPECT_EQ(read.exit_code, 0) << read.text;
  EXPECT_TRUE(fs::exists(Path("out/height.exr")));
}

// --tile-texels: the same canvas folder, made a tile at a time (preprocess_tiled_test.cpp
// compares it with the whole), nothing of its own left in it; what it cannot read is refused
// before anything is written.
TEST_F(CliTest, PreprocessInTilesWritesTheCanvasFolder) {
  Output synth = RunCli("synth --out " + Path("s") + " --resolution 200 --scan-size 256 192");
  ASSERT_EQ(synth.exit_code, 0) << synth.text;
  Output tiled = RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("c") +
                        " --tile-texels 64 --canvas-stride 2");
  ASSERT_EQ(tiled.exit_code, 0) << tiled.text;
  EXPECT_NE(tiled.text.find("one scan sample in 2 x 2"), std::string::npos) << tiled.text;
  EXPECT_NE(tiled.text.find("tile(s) of 64"), std::string::npos) << tiled.text;
  auto in = OIIO::ImageInput::open(Path("c/height.exr"));
  ASSERT_TRUE(in);
  EXPECT_GT(in->spec().width, 128) << "more than two tiles across";
  const auto boxes = nlohmann::json::parse(std::ifstream(Path("c/boxes.json")));
  EXPECT_FALSE(boxes.at("boxes").empty()) << "the painting has impasto";
  EXPECT_EQ(boxes.at("grid_size_texels").at(0).get<int>(), in->spec().width);
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(Path("c"))) names.push_back(e.path().filename());
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{".digitize-output", "boxes.json",
                                             "canvas_mask_scan.png", "height.exr", "mask.png",
                                             "normals.exr", "report.json", "transform.json"}));
  Output masked = RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("m") +
                         " --tile-texels 64 --mask " + Path("c/mask.png"));
  EXPECT_EQ(masked.exit_code, 1) << masked.text;
  EXPECT_NE(masked.text.find("one XYZ scan"), std::string::npos) << masked.text;
  EXPECT_FALSE(fs::exists(Path("m")));
  Output small =
      RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("m") + " --tile-texels 8");
  EXPECT_NE(small.exit_code, 0) << small.text;
  EXPECT_FALSE(fs::exists(Path("m")));
}

TEST_F(CliTest, SynthThenPreprocessWritesCompleteOutputs) {
  Output synth =
      RunCli("synth --out " + Path("s") + " --resolution 200 --scan-size 256 256 --seed 3");
  ASSERT_EQ(synth.exit_code, 0) << synth.text;
  for (const char* f :
       {"scan.exr", "truth_height.exr", "truth_normals.exr", "truth.json", "truth_mask_scan.png"})
    EXPECT_TRUE(fs::exists(Path(std::string("s/") + f))) << f;

  Output pre = RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("c"));
  ASSERT_EQ(pre.exit_code, 0) << pre.text;
  for (const char* step : {"sanitize", "canvas", "resample", "relief", "normals"})
    EXPECT_NE(pre.text.find(step), std::string::npos) << "one line per step: " << step;
  for (const char* f :
       {"height.exr", "normals.exr", "mask.png", "boxes.json", "transform.json", "report.json"})
    EXPECT_TRUE(fs::exists(Path(std::string("c/") + f))) << f;

  // The height map is a finite float image with the pitch in its header.
  auto in = OIIO::ImageInput::open(Path("c/height.exr"));
  ASSERT_TRUE(in);
  const OIIO::ImageSpec& spec = in->spec();
  EXPECT_EQ(spec.nchannels, 1);
  const std::string pitch = spec.get_string_attribute("digitize:pitch_mm");
  ASSERT_FALSE(pitch.empty()) << "the pitch travels with the height map";
  EXPECT_GT(std::stod(pitch), 0.0);
  std::vector<float> pixels(static_cast<size_t>(spec.width) * spec.height);
  ASSERT_TRUE(in->read_image(0, 0, 0, 1, OIIO::TypeDesc::FLOAT, pixels.data()));
  size_t nonzero = 0;
  for (float v : pixels) {
    ASSERT_TRUE(std::isfinite(v));
    nonzero += v != 0.0f;
  }
  EXPECT_GT(nonzero, pixels.size() / 4) << "the canvas has relief";

  // A failing re-run leaves the previous complete output in place.
  std::ofstream(Path("broken.exr")) << "garbage";
  Output again = RunCli("preprocess " + Path("broken.exr") + " --out " + Path("c"));
  EXPECT_EQ(again.exit_code, 1);
  EXPECT_TRUE(fs::exists(Path("c/height.exr")));
  EXPECT_TRUE(fs::exists(Path("c/report.json")));
}

TEST_F(CliTest, OutputPathThatIsAFileIsRefused) {
  Output synth = RunCli("synth --out " + Path("s") + " --resolution 96 --scan-size 96 96");
  ASSERT_EQ(synth.exit_code, 0) << synth.text;
  std::ofstream(Path("afile")) << "keep me";
  Output out = RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("afile"));
  EXPECT_EQ(out.exit_code, 1) << out.text;
  EXPECT_NE(out.text.find("afile"), std::string::npos) << out.text;
  std::ifstream in(Path("afile"));
  std::string content;
  std::getline(in, content);
  EXPECT_EQ(content, "keep me");
}

TEST_F(CliTest, DemoPrintsAccuracyAndWritesOutputs) {
  Output out = RunCli("demo --out " + Path("demo") + " --resolution 256 --scan-px 384");
  ASSERT_EQ(out.exit_code, 0) << out.text;
  EXPECT_NE(out.text.find("IoU"), std::string::npos) << out.text;
  EXPECT_NE(out.text.find("RMSE"), std::string::npos) << out.text;
  EXPECT_TRUE(fs::exists(Path("demo/canvas/height.exr")));
  EXPECT_TRUE(fs::exists(Path("demo/scan/scan.exr")));
  // Issue 3: the demo fits the photos on the preprocessed canvas and judges held-out relighting.
  EXPECT_NE(out.text.find("held-out PSNR"), std::string::npos) << out.text;
  // The region table: matte paint has no lobe to compare, said in words, not "nan".
  EXPECT_NE(out.text.find("parameter errors by paint region"), std::string::npos) << out.text;
  EXPECT_NE(out.text.find("n/a (no lobe)"), std::string::npos) << out.text;
  EXPECT_EQ(out.text.find("nan"), std::string::npos) << out.text;
  EXPECT_EQ(out.text.find("//"), std::string::npos) << out.text;
  for (const char* f : {"fit/rho_d.exr", "fit/rho_s.exr", "fit/lobe.exr", "fit/fit_error.exr",
                        "fit/fit_status.png", "fit/report.json", "photos/calib.json"})
    EXPECT_TRUE(fs::exists(Path(std::string("demo/") + f))) << f;
  // Issue 4: the demo ends with packs, judged from the files: size and PSNR from the pack.
  EXPECT_NE(out.text.find("bytes/texel"), std::string::npos) << out.text;
  EXPECT_NE(out.text.find("painting.pack.exr"), std::string::npos) << out.text;
  for (const char* f : {"painting.pack.exr", "painting.q.pack.exr"}) {
    ASSERT_TRUE(fs::exists(Path(std::string("demo/") + f))) << f;
    Output verify = RunCli("verify " + Path(std::string("demo/") + f));
    EXPECT_EQ(verify.exit_code, 0) << verify.text;
  }
  // The RTI part: its truth comparisons, both canvases' held-out PSNR, and its packs.
  for (const char* s : {"RTI capture", "normals median error", "height RMS error",
                        "held-out PSNR, normals", "held-out PSNR, flat"})
    EXPECT_NE(out.text.find(s), std::string::npos) << s << "\n" << out.text;
  for (const char* f : {"rti.pack.exr", "rti.flat.pack.exr", "rti/fit.lp", "rti/held_out.lp"})
    EXPECT_TRUE(fs::exists(Path(std::string("demo/") + f))) << f;
}

// Reads `inspect --json` output.
nlohmann::json InspectJson(const std::string& pack) {
  Output out = RunCli("inspect --json " + pack);
  EXPECT_EQ(out.exit_code, 0) << out.text;
  auto doc = nlohmann::json::parse(out.text, nullptr, false);
  EXPECT_FALSE(doc.is_discarded()) << out.text;
  return doc;
}

// synth --photos -> preprocess -> fit -> pack -> inspect / verify; `run` in one go; and the
// refusals a keeper of packs meets: a damaged pack, a pack of another file, mismatched folders.
TEST_F(CliTest, PackRunInspectVerify) {
  Output synth = RunCli("synth --out " + Path("s") +
                        " --resolution 128 --scan-size 160 160 --photos --lights 16 --seed 7");
  ASSERT_EQ(synth.exit_code, 0) << synth.text;
  ASSERT_EQ(RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("c")).exit_code, 0);
  Output fit = RunCli("fit --canvas " + Path("c") + " --photos " + Path("s/photos/calib.json") +
                      " --out " + Path("f"));
  ASSERT_EQ(fit.exit_code, 0) << fit.text;

  Output pack =
      RunCli("pack --canvas " + Path("c") + " --fit " + Path("f") + " --out " + Path("p.pack.exr"));
  ASSERT_EQ(pack.exit_code, 0) << pack.text;
  EXPECT_NE(pack.text.find("bytes/texel"), std::string::npos) << pack.text;
  Output q = RunCli("pack --canvas " + Path("c") + " --fit " + Path("f") + " --out " +
                    Path("q.pack.exr") + " --quantised --rho-bits 4");
  ASSERT_EQ(q.exit_code, 0) << q.text;

  const auto j = InspectJson(Path("p.pack.exr"));
  EXPECT_EQ(j.value("format", ""), "digitize.pack");
  EXPECT_EQ(j.value("encoding", ""), "half");
  EXPECT_EQ(j.value("raw_bytes_per_texel", 0), 26);
  EXPECT_LT(j.value("bytes_per_texel", 99.0), 26.0);
  EXPECT_GT(j["provenance"]["inputs"].size(), 8u);  // every file of both folders, hashed
  EXPECT_NE(j["provenance"].value("fit_brief", "").find("converged"), std::string::npos);
  EXPECT_TRUE(j["provenance"]["options"].contains("fit"));
  const auto jq = InspectJson(Path("q.pack.exr"));
  EXPECT_EQ(jq.value("encoding", ""), "quantised");
  EXPECT_EQ(jq["mantissa_bits"].value("rho", -1), 4);
  EXPECT_LT(jq.value("file_bytes", 0), j.value("file_bytes", 0));
  Output text = RunCli("inspect " + Path("p.pack.exr"));
  EXPECT_EQ(text.exit_code, 0);
  EXPECT_NE(text.text.find("sha1"), std::string::npos) << text.text;

  Output verify = RunCli("verify " + Path("p.pack.exr"));
  EXPECT_EQ(verify.exit_code, 0) << verify.text;
  EXPECT_NE(verify.text.find("valid"), std::string::npos) << verify.text;

  // The tiled, multi-resolution pack (version 3): the same level 0, its levels listed, every
  // tile verified; a tile size outside the format is refused before anything is written.
  Output tiled = RunCli("pack --canvas " + Path("c") + " --fit " + Path("f") + " --out " +
                        Path("t.pack.exr") + " --pack-tile-size 64");
  ASSERT_EQ(tiled.exit_code, 0) << tiled.text;
  const auto jt = InspectJson(Path("t.pack.exr"));
  EXPECT_EQ(jt.value("version", 0), 3);
  EXPECT_EQ(jt.value("tile_size", 0), 64);
  size_t levels = 1, tiles = 0;
  for (int w = jt["size_texels"][0], h = jt["size_texels"][1]; w > 1 || h > 1; ++levels) {
    w = (w + 1) / 2;  // ceil(w / 2) a level
    h = (h + 1) / 2;
  }
  ASSERT_EQ(jt["levels"].size(), levels);
  for (const auto& l : jt["levels"]) tiles += ((int(l[0]) + 63) / 64) * ((int(l[1]) + 63) / 64);
  EXPECT_EQ(jt["provenance"]["options"]["pack"].value("tile_size", 0), 64);
  Output vt = RunCli("verify " + Path("t.pack.exr"));
  EXPECT_EQ(vt.exit_code, 0) << vt.text;
  EXPECT_NE(vt.text.find("ok  tiles: " + std::to_string(tiles) + " tiles of 64 texels over " +
                         std::to_string(levels) + " levels"),
            std::string::npos)
      << vt.text;
  Output it = RunCli("inspect " + Path("t.pack.exr"));
  EXPECT_NE(it.text.find("tiles       64 x 64 texels, " + std::to_string(levels) + " levels"),
            std::string::npos)
      << it.text;
  Output bad = RunCli("pack --canvas " + Path("c") + " --fit " + Path("f") + " --out " +
                      Path("bad.pack.exr") + " --pack-tile-size 100");
  EXPECT_EQ(bad.exit_code, 1) << bad.text;
  EXPECT_NE(bad.text.find("power of two in [64, 4096]"), std::string::npos) << bad.text;
  EXPECT_FALSE(fs::exists(Path("bad.pack.exr")));
  // Every check `verify --help` promises is listed as done.
  Output verify_help = RunCli("verify --help");
  for (const char* check : {"header", "checksum", "boxes"}) {
    EXPECT_NE(verify_help.text.find(check), std::string::npos) << check << "\n" << verify_help.text;
    EXPECT_NE(verify.text.find("ok  " +
                               std::string(check == std::string("header") ? "container" : check)),
              std::string::npos)
        << check << "\n"
        << verify.text;
  }

  // One go: scan + photos -> pack, with held-out PSNR from the written pack. --work names a
  // folder of the user's: only its canvas/ and fit/ are written, the rest stays.
  fs::create_directories(Path("w/notes"));
  std::ofstream(Path("w/notes/todo.txt")) << "mine";
  Output run = RunCli("run " + Path("s/scan.exr") + " --photos " + Path("s/photos/calib.json") +
                      " --held-out " + Path("s/photos/held_out/calib.json") + " --out " +
                      Path("r.pack.exr") + " --work " + Path("w"));
  ASSERT_EQ(run.exit_code, 0) << run.text;
  EXPECT_NE(run.text.find("from the pack: held-out PSNR"), std::string::npos) << run.text;
  EXPECT_TRUE(fs::exists(Path("w/canvas/height.exr")));
  EXPECT_TRUE(fs::exists(Path("w/fit/rho_d.exr")));
  EXPECT_TRUE(fs::exists(Path("w/notes/todo.txt")));
  EXPECT_EQ(RunCli("verify " + Path("r.pack.exr")).exit_code, 0);
  const auto jr = InspectJson(Path("r.pack.exr"));
  EXPECT_GE(jr["provenance"]["inputs"].size(), 18u);  // scan + calibration + 16 photos
  // Named relative to the calibration file, never as this machine's absolute paths.
  std::vector<std::string> names;
  for (const auto& in : jr["provenance"]["inputs"]) names.push_back(in.value("name", ""));
  EXPECT_EQ(names[0], "../scan.exr");
  EXPECT_EQ(names[1], "calib.json");
  EXPECT_EQ(names[2].rfind("images/", 0), 0u) << names[2];
  for (const std::string& n : names) EXPECT_EQ(n.find(dir_.string()), std::string::npos) << n;

  // A damaged pack: verify and inspect fail, naming the file.
  {
    std::ifstream in(Path("p.pack.exr"), std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    bytes.resize(bytes.size() / 2);
    std::ofstream(Path("half.pack.exr"), std::ios::binary) << bytes;
  }
  Output damaged = RunCli("verify " + Path("half.pack.exr"));
  EXPECT_EQ(damaged.exit_code, 1);
  EXPECT_NE(damaged.text.find("half.pack.exr"), std::string::npos) << damaged.text;
  Output not_pack = RunCli("verify " + Path("c/height.exr"));
  EXPECT_EQ(not_pack.exit_code, 1);
  EXPECT_NE(not_pack.text.find("height.exr"), std::string::npos) << not_pack.text;
  EXPECT_EQ(RunCli("inspect " + Path("nothing.pack.exr")).exit_code, 1);

  // A fit folder from another canvas: refused, nothing written.
  ASSERT_EQ(RunCli("synth --out " + Path("s2") + " --resolution 96 --scan-size 120 120").exit_code,
            0);
  ASSERT_EQ(RunCli("preprocess " + Path("s2/scan.exr") + " --out " + Path("c2")).exit_code, 0);
  Output mismatch = RunCli("pack --canvas " + Path("c2") + " --fit " + Path("f") + " --out " +
                           Path("m.pack.exr"));
  EXPECT_EQ(mismatch.exit_code, 1);
  EXPECT_NE(mismatch.text.find("another canvas"), std::string::npos) << mismatch.text;
  EXPECT_FALSE(fs::exists(Path("m.pack.exr")));
  // Killed mid-write (SIGKILL at many moments): the pack is the old one or the new one, never a
  // mix or a torso -- the writer renames a finished temporary file into place.
  {
    const std::string target = Path("k.pack.exr");
    fs::copy_file(Path("q.pack.exr"), target);
    const auto old_size = fs::file_size(target);
    int old_seen = 0, new_seen = 0;
    for (int delay_ms : {0, 20, 40, 80, 120, 160, 240, 320, 480, 640}) {
      const std::string cmd =
          std::string(DIGITIZE_CLI) + " pack --canvas " + Path("c") + " --fit " + Path("f") +
          " --out " + target + " > /dev/null 2>&1 & pid=$!; sleep " +
          std::to_string(delay_ms / 1000.0) + "; kill -9 $pid 2>/dev/null; wait $pid";
      (void)std::system(cmd.c_str());
      ASSERT_TRUE(fs::exists(target)) << "after a kill at " << delay_ms << " ms";
      Output v = RunCli("verify " + target);
      ASSERT_EQ(v.exit_code, 0) << "after a kill at " << delay_ms << " ms: " << v.text;
      (fs::file_size(target) == old_size ? old_seen : new_seen)++;
      fs::copy_file(Path("q.pack.exr"), target, fs::copy_options::overwrite_existing);
    }
    std::printf("killed pack writes: %d left the old pack, %d finished\n", old_seen, new_seen);
    // The next complete write clears the temporaries the killed writers left.
    ASSERT_EQ(
        RunCli("pack --canvas " + Path("c") + " --fit " + Path("f") + " --out " + target).exit_code,
        0);
    for (const auto& e : fs::directory_iterator(dir_))
      EXPECT_EQ(e.path().filename().string().find(".k.pack.exr.tmp-"), std::string::npos)
          << e.path();
  }

  // A write that fails part way (file size limit; a full disk where a small tmpfs can be
  // mounted): exit 1, the file and the cause named, the previous file intact, no temporary left.
  {
    std::ofstream(Path("limited.pack.exr")) << "the previous pack";
    const std::string cmd = "trap '' XFSZ; ulimit -f 40; " + std::string(DIGITIZE_CLI) +
                            " pack --canvas " + Path("c") + " --fit " + Path("f") + " --out " +
                            Path("limited.pack.exr") + " > " + Path("limited.log") + " 2>&1";
    const int status = std::system(cmd.c_str());
    EXPECT_EQ(WIFEXITED(status) ? WEXITSTATUS(status) : -1, 1);
    const std::string log = digitize::test::ReadFileBytes(Path("limited.log"));
    EXPECT_NE(log.find("limited.pack.exr: write failed"), std::string::npos) << log;
    EXPECT_EQ(digitize::test::ReadFileBytes(Path("limited.pack.exr")), "the previous pack");
    for (const auto& e : fs::directory_iterator(dir_))
      EXPECT_EQ(e.path().filename().string().find(".limited.pack.exr.tmp-"), std::string::npos);

    fs::create_directories(Path("full"));
    if (::geteuid() == 0 &&
        std::system(
            ("mount -t tmpfs -o size=64k tmpfs " + Path("full") + " 2>/dev/null").c_str()) == 0) {
      std::ofstream(Path("full/p.pack.exr")) << "the previous pack";
      Output full = RunCli("pack --canvas " + Path("c") + " --fit " + Path("f") + " --out " +
                           Path("full/p.pack.exr"));
      const std::string kept = digitize::test::ReadFileBytes(Path("full/p.pack.exr"));
      const auto left =
          std::distance(fs::directory_iterator(Path("full")), fs::directory_iterator());
      (void)std::system(("umount " + Path("full")).c_str());
      EXPECT_EQ(full.exit_code, 1);
      EXPECT_NE(full.text.find("p.pack.exr: write failed"), std::string::npos) << full.text;
      EXPECT_NE(full.text.find("no space left on device"), std::string::npos) << full.text;
      EXPECT_EQ(kept, "the previous pack");
      EXPECT_EQ(left, 1) << "no temporary left";
    } else {
      std::printf("full-disk pack write not tried: cannot mount a small tmpfs here (needs root)\n");
    }
  }

  // A bad quantisation option names itself.
  Output bits = RunCli("pack --canvas " + Path("c") + " --fit " + Path("f") + " --out " +
                       Path("b.pack.exr") + " --quantised --rho-bits 12");
  EXPECT_EQ(bits.exit_code, 1);
  EXPECT_NE(bits.text.find("rho_bits"), std::string::npos) << bits.text;
  EXPECT_FALSE(fs::exists(Path("b.pack.exr")));
}

// synth --photos -> preprocess -> fit, as a user with files runs it; then the hostile inputs.
TEST_F(CliTest, FitFromFilesAndItsErrors) {
  Output synth = RunCli("synth --out " + Path("s") +
                        " --resolution 160 --scan-size 200 200 --photos --lights 24 --seed 5");
  ASSERT_EQ(synth.exit_code, 0) << synth.text;
  ASSERT_TRUE(fs::exists(Path("s/photos/calib.json")));
  Output pre = RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("c"));
  ASSERT_EQ(pre.exit_code, 0) << pre.text;
  const std::string base = "fit --canvas " + Path("c") + " --photos ";
  Output fit = RunCli(base + Path("s/photos/calib.json") + " --out " + Path("f") + " --held-out " +
                      Path("s/photos/held_out/calib.json"));
  ASSERT_EQ(fit.exit_code, 0) << fit.text;
  for (const char* what : {"samples:", "held-out PSNR", "converged", "outputs in"})
    EXPECT_NE(fit.text.find(what), std::string::npos) << what << "\n" << fit.text;
  for (const char* f :
       {"rho_d.exr", "rho_s.exr", "lobe.exr", "fit_error.exr", "fit_status.png", "report.json"})
    EXPECT_TRUE(fs::exists(Path(std::string("f/") + f))) << f;
  {  // lobe.exr: 4 float channels named cx, cy, cz, k, all finite
    auto in = OIIO::ImageInput::open(Path("f/lobe.exr"));
    ASSERT_TRUE(in);
    const OIIO::ImageSpec& spec = in->spec();
    ASSERT_EQ(spec.nchannels, 4);
    EXPECT_EQ(spec.channelnames[3], "k");
    std::vector<float> px(static_cast<size_t>(spec.width) * spec.height * 4);
    ASSERT_TRUE(in->read_image(0, 0, 0, 4, OIIO::TypeDesc::FLOAT, px.data()));
    for (float v : px) ASSERT_TRUE(std::isfinite(v));
  }

  // A calibration without its canvas is refused (only RTI captures fit on a flat canvas).
  Output no_canvas = RunCli("fit --photos " + Path("s/photos/calib.json") + " --out " + Path("g"));
  EXPECT_EQ(no_canvas.exit_code, 1);
  EXPECT_NE(no_canvas.text.find("--canvas"), std::string::npos) << no_canvas.text;

  // A missing image: the error names it; nothing is written.
  fs::copy(Path("s/photos"), Path("p2"), fs::copy_options::recursive);
  fs::path victim;
  for (const auto& e : fs::directory_iterator(Path("p2/images"))) victim = e.path();
  ASSERT_FALSE(victim.empty());
  fs::remove(victim);
  Output missing = RunCli(base + Path("p2/calib.json") + " --out " + Path("g"));
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.text.find(victim.filename().string()), std::string::npos) << missing.text;
  EXPECT_FALSE(fs::exists(Path("g")));

  // An image of the wrong size: named.
  fs::remove_all(Path("p2"));
  fs::copy(Path("s/photos"), Path("p2"), fs::copy_options::recursive);
  {
    std::vector<unsigned char> tiny(8 * 8 * 3, 100);
    auto out = OIIO::ImageOutput::create(victim.string());
    ASSERT_TRUE(out);
    ASSERT_TRUE(out->open((Path("p2/images") + "/" + victim.filename().string()),
                          OIIO::ImageSpec(8, 8, 3, OIIO::TypeDesc::UINT8)));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, tiny.data()));
    out->close();
  }
  Output wrong = RunCli(base + Path("p2/calib.json") + " --out " + Path("g"));
  EXPECT_EQ(wrong.exit_code, 1);
  EXPECT_NE(wrong.text.find(victim.filename().string()), std::string::npos) << wrong.text;

  // A calibration whose rotation is not a rotation (a scaled row): the error names the entry.
  {
    std::ifstream in(Path("s/photos/calib.json"));
    nlohmann::json doc = nlohmann::json::parse(in);
    ASSERT_TRUE(doc.contains("cameras"));
    doc["cameras"][0]["camera_from_scan"]["rotation"][0][0] = 2.0;
    std::ofstream(Path("s/photos/edited.json")) << doc.dump(1);
  }
  Output bad_rotation = RunCli(base + Path("s/photos/edited.json") + " --out " + Path("g"));
  EXPECT_EQ(bad_rotation.exit_code, 1);
  EXPECT_NE(bad_rotation.text.find("not a rotation"), std::string::npos) << bad_rotation.text;
  EXPECT_NE(bad_rotation.text.find("edited.json"), std::string::npos) << bad_rotation.text;
  EXPECT_FALSE(fs::exists(Path("g")));
}

// ---------------------------------------------------------------------------------------------
// Issue 10, section 3: no confident answer from an absurd input.

// Every usage error exits 1 (CLI11's own codes were 105, 106, 109, ...), with CLI11's message;
// --help and --version exit 0.
TEST_F(CliTest, UsageErrorsExitOneWithTheirMessage) {
  std::ofstream(Path("calib.json")) << "{}";
  const std::string photos = " --photos " + Path("calib.json") + " --out " + Path("out");
  struct Case {
    std::string args, says;
  };
  for (const Case& c : std::vector<Case>{
           {"fit" + photos + " --bogus", "--bogus"},
           {"fit --out " + Path("out"), "--photos is required"},
           {"fit" + photos + " --min-samples abc", "--min-samples"},
           {"fit" + photos + " --method slow", "slow"},
           {"fit --photos " + Path("absent.json") + " --out " + Path("out"), "absent.json"},
           {"pack --canvas " + Path("") + " --fit " + Path("") + " --out x --height-bits",
            "--height-bits"},
           {"frobnicate --out x", "unknown command \"frobnicate\""},
           {"--bogus", "unknown option \"--bogus\""},
       }) {
    const Output out = RunCli(c.args);
    EXPECT_EQ(out.exit_code, 1) << c.args << "\n" << out.text;
    EXPECT_NE(out.text.find(c.says), std::string::npos) << c.args << "\n" << out.text;
    EXPECT_FALSE(fs::exists(Path("out"))) << c.args;
  }
  const Output version = RunCli("--version");
  EXPECT_EQ(version.exit_code, 0) << version.text;
  EXPECT_EQ(version.text.rfind("digitize ", 0), 0u) << version.text;
  EXPECT_EQ(RunCli("fit --help").exit_code, 0);
}

// Writes a w x h mid-grey 8-bit PNG.
void WriteGreyPng(const std::string& path, int w = 8, int h = 8) {
  std::vector<unsigned char> px(static_cast<size_t>(w) * h * 3, 120);
  auto out = OIIO::ImageOutput::create(path);
  ASSERT_TRUE(out) << path;
  ASSERT_TRUE(out->open(path, OIIO::ImageSpec(w, h, 3, OIIO::TypeDesc::UINT8)));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, px.data()));
  out->close();
}

// RTI captures: one photo cannot constrain the model (it used to give 100 % "too few samples" and
// a black pack, exit 0); lights below the canvas are a warning with their count; duplicate images
// and extra columns name the line.
TEST_F(CliTest, RtiCapturesThatCannotConstrainTheModelAreRefused) {
  for (int i = 0; i < 10; ++i) WriteGreyPng(Path("img" + std::to_string(i) + ".png"));
  std::ofstream(Path("one.lp")) << "1\nimg0.png 0.1 0.2 0.9\n";
  Output one = RunCli("fit --photos " + Path("one.lp") + " --out " + Path("f"));
  EXPECT_EQ(one.exit_code, 1) << one.text;
  for (const char* words : {"one.lp", "only 1 distinct", "at least 8", "too few samples"})
    EXPECT_NE(one.text.find(words), std::string::npos) << words << "\n" << one.text;
  EXPECT_FALSE(fs::exists(Path("f")));
  Output run_one = RunCli("run --photos " + Path("one.lp") + " --out " + Path("p.pack.exr"));
  EXPECT_EQ(run_one.exit_code, 1) << run_one.text;
  EXPECT_NE(run_one.text.find("only 1 distinct"), std::string::npos) << run_one.text;
  EXPECT_FALSE(fs::exists(Path("p.pack.exr")));

  // Eight lights above the canvas and two below it: fitted, with a warning and its count.
  {
    std::ofstream lp(Path("ten.lp"));
    lp << "10\n";
    for (int i = 0; i < 10; ++i) {
      const double a = 0.7 * i, z = i < 8 ? 0.5 + 0.05 * i : -0.3;
      lp << "img" << i << ".png " << std::cos(a) << " " << std::sin(a) << " " << z << "\n";
    }
  }
  Output ten = RunCli("fit --photos " + Path("ten.lp") + " --out " + Path("f"));
  ASSERT_EQ(ten.exit_code, 0) << ten.text;
  EXPECT_NE(ten.text.find("digitize fit: warning: 2 of 10 photos have their light at or below the "
                          "canvas plane"),
            std::string::npos)
      << ten.text;
  EXPECT_NE(ten.text.find("ten.lp, line 10"), std::string::npos) << ten.text;
  {
    std::ifstream in(Path("f/report.json"));
    const auto report = nlohmann::json::parse(in);
    EXPECT_EQ(report["photos"]["light_below_canvas"], 2);
    EXPECT_EQ(report["photos"]["count"], 10);
    EXPECT_EQ(report["warnings"].size(), 1u);
  }
  Output run = RunCli("run --photos " + Path("ten.lp") + " --out " + Path("p.pack.exr"));
  ASSERT_EQ(run.exit_code, 0) << run.text;
  EXPECT_NE(run.text.find("digitize run: warning: 2 of 10 photos"), std::string::npos) << run.text;

  // The same image twice, and a line with a fourth number.
  std::ofstream(Path("dup.lp")) << "2\nimg1.png 0 0 1\n./img1.png 0 1 1\n";
  Output dup = RunCli("fit --photos " + Path("dup.lp") + " --out " + Path("g"));
  EXPECT_EQ(dup.exit_code, 1) << dup.text;
  EXPECT_NE(dup.text.find("dup.lp, line 3"), std::string::npos) << dup.text;
  EXPECT_NE(dup.text.find("same image as " + Path("dup.lp") + ", line 2"), std::string::npos)
      << dup.text;
  std::ofstream(Path("cols.lp")) << "1\nimg1.png 0.1 0.2 0.9 0.5\n";
  Output cols = RunCli("fit --photos " + Path("cols.lp") + " --out " + Path("g"));
  EXPECT_EQ(cols.exit_code, 1) << cols.text;
  EXPECT_NE(cols.text.find("cols.lp, line 2: expected \"filename x y z\""), std::string::npos)
      << cols.text;
  EXPECT_FALSE(fs::exists(Path("g")));
}

// One definition of a canvas folder (kCanvasFolderFiles): `fit --canvas` and `pack --canvas`
// refuse the same incomplete folder with the same message; absurd intrinsics and duplicate
// entries in a calibration name the file and the entry.
TEST_F(CliTest, CanvasFolderIsOneDefinitionAndCalibrationsAreChecked) {
  ASSERT_EQ(RunCli("synth --out " + Path("s") +
                   " --resolution 96 --scan-size 120 120 --photos --lights 8 --seed 5")
                .exit_code,
            0);
  ASSERT_EQ(RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("c")).exit_code, 0);
  const std::string photos = " --photos " + Path("s/photos/calib.json");
  Output fit = RunCli("fit --canvas " + Path("c") + photos + " --out " + Path("f"));
  ASSERT_EQ(fit.exit_code, 0) << fit.text;
  for (const char* file :
       {"height.exr", "mask.png", "normals.exr", "transform.json", "boxes.json", "report.json"}) {
    fs::remove_all(Path("c2"));
    fs::copy(Path("c"), Path("c2"));
    fs::remove(Path("c2") + "/" + file);
    const std::string says = Path("c2") +
                             ": not a canvas folder (written by `digitize preprocess`): " + file +
                             " is missing";
    Output f = RunCli("fit --canvas " + Path("c2") + photos + " --out " + Path("g"));
    EXPECT_EQ(f.exit_code, 1) << f.text;
    EXPECT_NE(f.text.find(says), std::string::npos) << file << "\n" << f.text;
    Output p = RunCli("pack --canvas " + Path("c2") + " --fit " + Path("f") + " --out " +
                      Path("p.pack.exr"));
    EXPECT_EQ(p.exit_code, 1) << p.text;
    EXPECT_NE(p.text.find(says), std::string::npos) << file << "\n" << p.text;
  }
  EXPECT_FALSE(fs::exists(Path("g")));
  EXPECT_FALSE(fs::exists(Path("p.pack.exr")));
  // canvas_mask_scan.png is written for the user, required by nobody.
  fs::remove_all(Path("c2"));
  fs::copy(Path("c"), Path("c2"));
  fs::remove(Path("c2/canvas_mask_scan.png"));
  const std::string pack = "pack --canvas " + Path("c2") + " --fit " + Path("f") + " --out ";
  EXPECT_EQ(RunCli(pack + Path("p.pack.exr")).exit_code, 0);

  std::ifstream in(Path("s/photos/calib.json"));
  const nlohmann::json doc = nlohmann::json::parse(in);
  nlohmann::json edited = doc;
  edited["cameras"][0]["fx"] = 1e-300;  // "76.9 % converged" before
  std::ofstream(Path("s/photos/edited.json")) << edited.dump(1);
  Output fx = RunCli("fit --canvas " + Path("c") + " --photos " + Path("s/photos/edited.json") +
                     " --out " + Path("g"));
  EXPECT_EQ(fx.exit_code, 1) << fx.text;
  EXPECT_NE(fx.text.find(
                "edited.json: cameras[0].fx 1e-300 px gives a horizontal field of view of 180 deg"),
            std::string::npos)
      << fx.text;
  edited = doc;
  edited["images"].push_back(doc["images"][3]);
  std::ofstream(Path("s/photos/edited.json")) << edited.dump(1);
  Output dup = RunCli("fit --canvas " + Path("c") + " --photos " + Path("s/photos/edited.json") +
                      " --out " + Path("g"));
  EXPECT_EQ(dup.exit_code, 1) << dup.text;
  EXPECT_NE(dup.text.find("edited.json: images[8]"), std::string::npos) << dup.text;
  EXPECT_NE(dup.text.find("same image as " + Path("s/photos/edited.json") + ": images[3]"),
            std::string::npos)
      << dup.text;
  EXPECT_FALSE(fs::exists(Path("g")));
}

// Issue 10, section 1: a folder given as --out is replaced only when it is new, empty or an
// earlier output of the same kind; a folder of the user's files survives every command.
TEST_F(CliTest, AFolderOfTheUsersFilesSurvivesEveryCommand) {
  ASSERT_EQ(RunCli("synth --out " + Path("s") +
                   " --resolution 96 --scan-size 96 96 --photos "
                   "--lights 8 --seed 2")
                .exit_code,
            0);
  ASSERT_EQ(RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("c")).exit_code, 0);
  fs::create_directories(Path("docs/notes"));
  std::ofstream(Path("docs/notes/condition_report.txt")) << "irreplaceable";
  const std::string docs = Path("docs");
  for (const std::string& cmd :
       {"synth --resolution 96 --scan-size 96 96 --out " + docs,
        "preprocess " + Path("s/scan.exr") + " --out " + docs,
        "fit --canvas " + Path("c") + " --photos " + Path("s/photos/calib.json") + " --out " + docs,
        "demo --resolution 96 --scan-px 96 --out " + docs,
        "run " + Path("s/scan.exr") + " --photos " + Path("s/photos/calib.json") + " --out " +
            Path("r.pack.exr") + " --work " + Path("work")}) {
    // run --work replaces only work/canvas and work/fit: here a folder of the user's.
    fs::create_directories(Path("work/canvas"));
    std::ofstream(Path("work/canvas/mine.txt")) << "mine";
    Output out = RunCli(cmd);
    EXPECT_EQ(out.exit_code, 1) << cmd << "\n" << out.text;
    EXPECT_NE(out.text.find("refusing"), std::string::npos) << out.text;
    EXPECT_EQ(digitize::test::ReadFileBytes(Path("docs/notes/condition_report.txt")),
              "irreplaceable")
        << cmd;
    EXPECT_EQ(std::distance(fs::directory_iterator(dir_ / "docs"), fs::directory_iterator()), 1)
        << cmd << ": nothing added";
  }
  Output pre = RunCli("preprocess " + Path("s/scan.exr") + " --out " + docs);
  EXPECT_NE(pre.text.find(docs + ": holds 'notes/'"), std::string::npos)
      << "names the folder and one thing in it: " << pre.text;
  EXPECT_EQ(digitize::test::ReadFileBytes(Path("work/canvas/mine.txt")), "mine");
  EXPECT_FALSE(fs::exists(Path("work/fit")));
  EXPECT_FALSE(fs::exists(Path("r.pack.exr")));

  // An output of another kind is not replaced either: a canvas over a fit folder.
  ASSERT_EQ(RunCli("fit --canvas " + Path("c") + " --photos " + Path("s/photos/calib.json") +
                   " --out " + Path("f"))
                .exit_code,
            0);
  Output kind = RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("f"));
  EXPECT_EQ(kind.exit_code, 1);
  EXPECT_NE(kind.text.find("fit output of `digitize fit`"), std::string::npos) << kind.text;
  EXPECT_TRUE(fs::exists(Path("f/rho_d.exr")));
}

// An earlier output of the same command is replaced on a re-run; an empty folder is accepted; a
// file added to an output makes it the user's.
TEST_F(CliTest, EarlierOutputsAndEmptyFoldersAreReplaced) {
  ASSERT_EQ(RunCli("synth --out " + Path("s") + " --resolution 96 --scan-size 96 96").exit_code, 0);
  ASSERT_EQ(
      RunCli("synth --out " + Path("s") + " --resolution 96 --scan-size 96 96 --seed 4").exit_code,
      0);
  fs::create_directories(Path("empty"));
  Output pre = RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("empty"));
  ASSERT_EQ(pre.exit_code, 0) << pre.text;
  EXPECT_TRUE(fs::exists(Path("empty/height.exr")));
  EXPECT_TRUE(fs::exists(Path("empty/.digitize-output")));
  const auto marker = nlohmann::json::parse(
      digitize::test::ReadFileBytes(Path("empty/.digitize-output")), nullptr, false);
  EXPECT_EQ(marker.value("format", ""), "digitize.output");
  EXPECT_EQ(marker.value("command", ""), "preprocess");
  EXPECT_EQ(marker.value("content", ""), "canvas");
  Output again =
      RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("empty") + " --cell-px 8");
  ASSERT_EQ(again.exit_code, 0) << again.text;
  std::ofstream(Path("empty/my_notes.txt")) << "mine";
  Output mine = RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("empty"));
  EXPECT_EQ(mine.exit_code, 1);
  EXPECT_NE(mine.text.find("my_notes.txt"), std::string::npos) << mine.text;
  EXPECT_EQ(digitize::test::ReadFileBytes(Path("empty/my_notes.txt")), "mine");
}

// No output onto, into or above an input, the current directory or its parents.
TEST_F(CliTest, InputsAndTheCurrentDirectoryAreNeverOutputs) {
  ASSERT_EQ(RunCli("synth --out " + Path("s") +
                   " --resolution 96 --scan-size 96 96 --photos "
                   "--lights 8 --seed 2")
                .exit_code,
            0);
  fs::create_directories(Path("museum/scans"));
  fs::copy_file(Path("s/scan.exr"), Path("museum/scans/scan.exr"));
  std::ofstream(Path("museum/notes.txt")) << "irreplaceable";
  const std::string scan_bytes = digitize::test::ReadFileBytes(Path("museum/scans/scan.exr"));
  const std::string scan = Path("museum/scans/scan.exr");
  for (const std::string& out : {Path("museum"), Path("museum/scans"), scan, Path("museum/scans/"),
                                 Path("museum/scans/../scans"), dir_.string()}) {
    Output o = RunCli("preprocess " + scan + " --out " + out);
    EXPECT_EQ(o.exit_code, 1) << out << "\n" << o.text;
    EXPECT_NE(o.text.find("input"), std::string::npos) << o.text;
    EXPECT_EQ(digitize::test::ReadFileBytes(Path("museum/scans/scan.exr")), scan_bytes) << out;
  }
  // The current directory, however it is spelled, and its parent.
  for (const std::string& out : {std::string("."), std::string("./"), Path("museum/scans"),
                                 std::string(".."), std::string("\"$PWD\"")}) {
    Output o = RunCli("preprocess scan.exr --out " + out, Path("museum/scans"));
    EXPECT_EQ(o.exit_code, 1) << out << "\n" << o.text;
    EXPECT_EQ(o.text.find("Success"), std::string::npos) << o.text;
    EXPECT_EQ(digitize::test::ReadFileBytes(Path("museum/scans/scan.exr")), scan_bytes) << out;
  }
  Output synth_here = RunCli("synth --resolution 96 --scan-size 96 96 --out .", Path("museum"));
  EXPECT_EQ(synth_here.exit_code, 1);
  EXPECT_NE(synth_here.text.find("current directory"), std::string::npos) << synth_here.text;
  EXPECT_EQ(digitize::test::ReadFileBytes(Path("museum/notes.txt")), "irreplaceable");

  // pack onto a file of its canvas folder; fit into its canvas; run onto one of its photos.
  ASSERT_EQ(RunCli("preprocess " + scan + " --out " + Path("c")).exit_code, 0);
  ASSERT_EQ(RunCli("fit --canvas " + Path("c") + " --photos " + Path("s/photos/calib.json") +
                   " --out " + Path("f"))
                .exit_code,
            0);
  const std::string height = digitize::test::ReadFileBytes(Path("c/height.exr"));
  Output pack = RunCli("pack --canvas " + Path("c") + " --fit " + Path("f") + " --out " +
                       Path("c/height.exr"));
  EXPECT_EQ(pack.exit_code, 1) << pack.text;
  EXPECT_NE(pack.text.find("c/height.exr: lies inside the input"), std::string::npos) << pack.text;
  EXPECT_EQ(digitize::test::ReadFileBytes(Path("c/height.exr")), height);
  Output fit = RunCli("fit --canvas " + Path("c") + " --photos " + Path("s/photos/calib.json") +
                      " --out " + Path("c"));
  EXPECT_EQ(fit.exit_code, 1) << fit.text;
  EXPECT_EQ(digitize::test::ReadFileBytes(Path("c/height.exr")), height);
  fs::path photo;
  for (const auto& e : fs::directory_iterator(Path("s/photos/images"))) photo = e.path();
  const std::string photo_bytes = digitize::test::ReadFileBytes(photo);
  Output run = RunCli("run --photos " + Path("s/photos/calib.json") + " " + scan + " --out " +
                      photo.string());
  EXPECT_EQ(run.exit_code, 1) << run.text;
  EXPECT_NE(run.text.find("is the input"), std::string::npos) << run.text;
  EXPECT_EQ(digitize::test::ReadFileBytes(photo), photo_bytes);
}

// A killed folder command leaves ".NAME.partial-PID-N/"; the next run removes those of dead
// processes and keeps a live one's.
TEST_F(CliTest, StaleTemporaryFoldersAreRemoved) {
  ASSERT_EQ(RunCli("synth --out " + Path("s") + " --resolution 96 --scan-size 96 96").exit_code, 0);
  ASSERT_EQ(RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("c")).exit_code, 0);
  // A pid that is certainly not running: a child that has exited and been reaped.
  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);
  ::waitpid(child, nullptr, 0);
  const std::string pid = std::to_string(child);
  const std::string live = std::to_string(::getpid());
  for (const std::string& name :
       {".c.partial-" + pid + "-0", ".c.old-" + pid + "-1", ".c.partial-" + live + "-7"}) {
    fs::create_directories(dir_ / name / "deep");
    std::ofstream(dir_ / name / "deep" / "height.exr") << "hundreds of MB";
  }
  ASSERT_EQ(RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("c")).exit_code, 0);
  EXPECT_FALSE(fs::exists(dir_ / (".c.partial-" + pid + "-0")));
  EXPECT_FALSE(fs::exists(dir_ / (".c.old-" + pid + "-1")));
  EXPECT_TRUE(fs::exists(dir_ / (".c.partial-" + live + "-7"))) << "a running writer's";
}

// Help reads as documentation: no CLI11 internals (an enum map printed as "{ceres->,fast-> }").
TEST_F(CliTest, HelpShowsChoicesInWords) {
  Output demo = RunCli("demo --help");
  ASSERT_EQ(demo.exit_code, 0) << demo.text;
  const size_t at = demo.text.find("--fit-method");
  ASSERT_NE(at, std::string::npos) << demo.text;
  const std::string line = demo.text.substr(at, demo.text.find('\n', at) - at);
  EXPECT_EQ(line.find("->"), std::string::npos) << line;
  EXPECT_EQ(line.find("OR"), std::string::npos) << line;
  EXPECT_NE(line.find("fast"), std::string::npos) << line;
  EXPECT_NE(line.find("ceres"), std::string::npos) << line;
  for (const char* cmd : {"synth", "preprocess", "fit", "pack", "run", "demo", "verify"}) {
    Output help = RunCli(std::string(cmd) + " --help");
    for (const char* internal : {"ENUM", "->,", "OR {"})
      EXPECT_EQ(help.text.find(internal), std::string::npos) << cmd << "\n" << help.text;
  }
  // Wrong method: refused, named.
  Output bad = RunCli("demo --out " + Path("d") + " --fit-method slow");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.text.find("slow"), std::string::npos) << bad.text;
  EXPECT_FALSE(fs::exists(Path("d")));
}

// The percentages of "<title>: NN%" progress lines, in order.
std::vector<int> ProgressPercents(const std::string& text, const std::string& title) {
  std::vector<int> out;
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind(title + ": ", 0) != 0) continue;
    int percent = -1;
    if (std::sscanf(line.c_str() + title.size() + 2, "%d%%", &percent) == 1) out.push_back(percent);
  }
  return out;
}

// Progress into a log file (not a terminal): lines with the real, rising percentages, also
// inside the long render stage of `synth --photos` (once 27 % then 87 %, nothing between); and
// an output folder given with a trailing slash is printed without a doubled one.
TEST_F(CliTest, ProgressInALogRisesAndPathsHaveSingleSlashes) {
  Output synth = RunCli("synth --out " + Path("s") +
                        "/ --resolution 128 --scan-size 160 160 "
                        "--photos --lights 16 --seed 7");
  ASSERT_EQ(synth.exit_code, 0) << synth.text;
  const std::vector<int> p = ProgressPercents(synth.text, "synth");
  ASSERT_GE(p.size(), 5u) << synth.text;
  for (size_t i = 1; i < p.size(); ++i) EXPECT_GE(p[i], p[i - 1]) << synth.text;
  int in_render = 0;  // the render stage spans 28 % .. 88 % of the bar
  for (int v : p) in_render += v > 30 && v < 85;
  EXPECT_GE(in_render, 3) << synth.text;
  EXPECT_EQ(synth.text.find("//"), std::string::npos) << synth.text;
  EXPECT_NE(synth.text.find(Path("s") + "/photos/"), std::string::npos) << synth.text;

  Output pre = RunCli("preprocess " + Path("s/scan.exr") + " --out " + Path("c") + "//");
  ASSERT_EQ(pre.exit_code, 0) << pre.text;
  EXPECT_EQ(pre.text.find("//"), std::string::npos) << pre.text;
  EXPECT_TRUE(fs::exists(Path("c/height.exr")));
  Output fit = RunCli("fit --canvas " + Path("c") + " --photos " + Path("s/photos/calib.json") +
                      " --out " + Path("f") + "/");
  ASSERT_EQ(fit.exit_code, 0) << fit.text;
  EXPECT_EQ(fit.text.find("//"), std::string::npos) << fit.text;
  const std::vector<int> pf = ProgressPercents(fit.text, "fit");
  ASSERT_GE(pf.size(), 3u) << fit.text;
  EXPECT_GT(*std::max_element(pf.begin(), pf.end()), 50) << fit.text;
}

// Writes a 1-channel 16-bit PNG depth map (counts rising along x), for the reader's tests.
void WriteDepthPng16(const std::string& path, int w, int h) {
  std::vector<uint16_t> counts(static_cast<size_t>(w) * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      counts[static_cast<size_t>(y) * w + x] = uint16_t(1000 + 37 * x + 11 * y);
  auto out = OIIO::ImageOutput::create(path);
  ASSERT_TRUE(out);
  ASSERT_TRUE(out->open(path, OIIO::ImageSpec(w, h, 1, OIIO::TypeDesc::UINT16)));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT16, counts.data()));
  ASSERT_TRUE(out->close());
}

// A 16-bit depth PNG cut short (a copy interrupted): reported as truncated, not as an 8-bit image.
TEST_F(CliTest, TruncatedDepthPngIsReportedAsTruncated) {
  WriteDepthPng16(Path("depth.png"), 256, 256);
  {
    std::ifstream in(Path("depth.png"), std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    bytes.resize(bytes.size() / 2);
    std::ofstream(Path("cut.png"), std::ios::binary) << bytes;
  }
  const std::string flags = " --pixel-pitch-mm 0.5 --height-scale-mm 0.001 --out ";
  Output out = RunCli("preprocess " + Path("cut.png") + flags + Path("c"));
  EXPECT_EQ(out.exit_code, 1) << out.text;
  EXPECT_NE(out.text.find("cut.png"), std::string::npos) << out.text;
  EXPECT_NE(out.text.find("truncated"), std::string::npos) << out.text;
  EXPECT_EQ(out.text.find("8-bit"), std::string::npos) << out.text;
  EXPECT_FALSE(fs::exists(Path("c")));
}

// `run` reads depth images as `preprocess` does, --height-offset-mm included.
TEST_F(CliTest, RunTakesTheDepthFlagsOfPreprocess) {
  Output help = RunCli("run --help");
  for (const char* flag : {"--pixel-pitch-mm", "--height-scale-mm", "--height-offset-mm"})
    EXPECT_NE(help.text.find(flag), std::string::npos) << flag;
  // The value reaches the scan reader: an infinite offset is its error, not an unknown option.
  Output synth = RunCli("synth --out " + Path("s") +
                        " --resolution 96 --scan-size 96 96 --photos "
                        "--lights 8");
  ASSERT_EQ(synth.exit_code, 0) << synth.text;
  WriteDepthPng16(Path("depth.png"), 64, 64);
  Output out =
      RunCli("run " + Path("depth.png") + " --photos " + Path("s/photos/calib.json") +
             " --pixel-pitch-mm 0.5 --height-scale-mm 0.001 --height-offset-mm inf --out " +
             Path("p.pack.exr"));
  EXPECT_EQ(out.exit_code, 1) << out.text;
  EXPECT_NE(out.text.find("height_offset_mm"), std::string::npos) << out.text;
  EXPECT_FALSE(fs::exists(Path("p.pack.exr")));
}

// Writes an RTI capture of `n` flat grey 24x18 images (TIFF, with a resolution tag of
// `per_inch` when > 0) and its .lp file; returns the .lp path.
std::string WriteRtiCapture(const fs::path& dir, int n, float per_inch) {
  fs::create_directories(dir);
  std::ofstream lp(dir / "dirs.lp");
  lp << n << "\n";
  constexpr int w = 24, h = 18;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * 3.14159265358979 * i / n, elevation = 0.5 + 0.4 * (i % 3) / 2.0;
    const double x = std::cos(a) * std::cos(elevation), y = std::sin(a) * std::cos(elevation),
                 z = std::sin(elevation);
    const std::string name = "img" + std::to_string(i) + ".tif";
    // A Lambertian grey (rho 0.5) under this light, as 8-bit sRGB.
    const double linear = 0.5 * z;
    const double srgb =
        linear <= 0.0031308 ? 12.92 * linear : 1.055 * std::pow(linear, 1 / 2.4) - 0.055;
    std::vector<uint8_t> px(w * h * 3, static_cast<uint8_t>(std::lround(255 * srgb)));
    OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::UINT8);
    if (per_inch > 0) {
      spec.attribute("XResolution", per_inch);
      spec.attribute("YResolution", per_inch);
      spec.attribute("ResolutionUnit", "in");
    }
    auto out = OIIO::ImageOutput::create((dir / name).string());
    EXPECT_TRUE(out && out->open((dir / name).string(), spec) &&
                out->write_image(OIIO::TypeDesc::UINT8, px.data()) && out->close());
    lp << name << " " << x << " " << y << " " << z << "\n";
  }
  return (dir / "dirs.lp").string();
}

// An RTI capture's physical size: from the images' resolution tags, else assumed and said so
// (a warning, and the pack's provenance), and --rti-pitch-mm overrides both.
TEST_F(CliTest, RtiPitchFromTagsOrSaidToBeAssumed) {
  const std::string tagged = WriteRtiCapture(dir_ / "tagged", 12, 254.0f);  // 0.1 mm per pixel
  Output run = RunCli("run --photos " + tagged + " --out " + Path("t.pack.exr"));
  ASSERT_EQ(run.exit_code, 0) << run.text;
  EXPECT_NE(run.text.find("RTI pixel pitch: 0.1 mm"), std::string::npos) << run.text;
  EXPECT_NE(run.text.find("254 per inch"), std::string::npos) << run.text;
  EXPECT_EQ(run.text.find("warning"), std::string::npos) << run.text;
  auto j = InspectJson(Path("t.pack.exr"));
  EXPECT_NEAR(j.value("pitch_mm", 0.0), 0.1, 1e-6) << j.dump();
  EXPECT_EQ(j["provenance"]["options"]["fit"]["rti_pitch"].value("assumed", true), false);

  const std::string bare = WriteRtiCapture(dir_ / "bare", 12, 0);
  Output assumed = RunCli("run --photos " + bare + " --out " + Path("b.pack.exr"));
  ASSERT_EQ(assumed.exit_code, 0) << assumed.text;
  EXPECT_NE(assumed.text.find("warning: RTI pixel pitch 1 mm assumed"), std::string::npos)
      << assumed.text;
  EXPECT_NE(assumed.text.find("24 x 18 mm"), std::string::npos) << assumed.text;
  EXPECT_NE(assumed.text.find("--rti-pitch-mm"), std::string::npos) << assumed.text;
  j = InspectJson(Path("b.pack.exr"));
  EXPECT_NEAR(j.value("pitch_mm", 0.0), 1.0, 1e-9);
  EXPECT_EQ(j["provenance"]["options"]["fit"]["rti_pitch"].value("assumed", false), true);
  Output fit = RunCli("fit --photos " + bare + " --out " + Path("f"));
  ASSERT_EQ(fit.exit_code, 0) << fit.text;
  EXPECT_NE(fit.text.find("assumed"), std::string::npos) << fit.text;

  Output given =
      RunCli("run --photos " + tagged + " --rti-pitch-mm 0.25 --out " + Path("g.pack.exr"));
  ASSERT_EQ(given.exit_code, 0) << given.text;
  EXPECT_NE(given.text.find("RTI pixel pitch: 0.25 mm, given"), std::string::npos) << given.text;
  EXPECT_NEAR(InspectJson(Path("g.pack.exr")).value("pitch_mm", 0.0), 0.25, 1e-6);
}

// `run` on an RTI capture with a held-out split: the relit held-out photos land in
// --held-out-out under the photos' stems, and the flat canvas (--rti-flat) scores differently.
TEST_F(CliTest, RunRtiHeldOutOutAndFlatCanvas) {
  Output synth = RunCli("synth --out " + Path("s") +
                        " --width-mm 24 --height-mm 18 --resolution 96 --scan-size 48 48 --rti "
                        "--rti-lights 16");
  ASSERT_EQ(synth.exit_code, 0) << synth.text;
  // Every 4th line of dirs.lp held out.
  std::ifstream in(Path("s/rti/dirs.lp"));
  std::string line;
  std::getline(in, line);
  std::vector<std::string> fit, held;
  for (size_t i = 0; std::getline(in, line); ++i)
    if (!line.empty()) (i % 4 == 3 ? held : fit).push_back(line);
  ASSERT_EQ(held.size(), 4u);
  for (const auto& [name, lines] : {std::pair{"s/rti/fit.lp", &fit}, {"s/rti/held.lp", &held}}) {
    std::ofstream out(Path(name));
    out << lines->size() << "\n";
    for (const std::string& l : *lines) out << l << "\n";
  }
  const std::string common = "run --photos " + Path("s/rti/fit.lp") + " --held-out " +
                             Path("s/rti/held.lp") + " --rti-pitch-mm 0.25";
  Output run = RunCli(common + " --held-out-out " + Path("relit") + " --out " + Path("r.pack.exr"));
  ASSERT_EQ(run.exit_code, 0) << run.text;
  std::vector<std::string> want, got;
  for (const std::string& l : held)
    want.push_back(fs::path(l.substr(0, l.find(' '))).stem().string());
  for (const auto& entry : fs::directory_iterator(Path("relit"))) {
    if (entry.path().filename().string().front() == '.') continue;  // the output marker
    EXPECT_EQ(entry.path().extension(), ".png") << entry.path();
    got.push_back(entry.path().stem().string());
    auto image = OIIO::ImageInput::open(entry.path().string());
    ASSERT_TRUE(image) << entry.path();
    EXPECT_EQ(image->spec().width, 96) << entry.path();
    EXPECT_EQ(image->spec().height, 72) << entry.path();
  }
  std::sort(want.begin(), want.end());
  std::sort(got.begin(), got.end());
  EXPECT_EQ(got, want);

  // The PSNR line of each run ("from the pack: held-out PSNR ..."): the flat canvas's differs.
  const auto psnr_line = [](const std::string& text) {
    const size_t at = text.find("from the pack: held-out PSNR");
    return at == std::string::npos ? std::string() : text.substr(at, text.find('\n', at) - at);
  };
  Output flat = RunCli(common + " --rti-flat --out " + Path("f.pack.exr"));
  ASSERT_EQ(flat.exit_code, 0) << flat.text;
  ASSERT_FALSE(psnr_line(run.text).empty()) << run.text;
  ASSERT_FALSE(psnr_line(flat.text).empty()) << flat.text;
  EXPECT_NE(psnr_line(run.text), psnr_line(flat.text));
}

}  // namespace
