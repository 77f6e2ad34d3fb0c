// `digitize-viewer` as a user runs it (headless screenshots): what it says it wrote is what it
// wrote, a missing screenshot folder is made, and nothing to show is an error that writes nothing.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "test_paths.h"
#include "test_support.h"

namespace {

namespace fs = std::filesystem;

struct Output {
  int exit_code = -1;
  std::string text;  // stdout + stderr
};

class ViewerCliTest : public digitize::test::ScratchDirTest {
 protected:
  ViewerCliTest() : ScratchDirTest("digitize_viewer_cli") {}
  void SetUp() override {
#ifndef DIGITIZE_VIEWER
    GTEST_SKIP() << "digitize-viewer is not built here (GLFW, imgui or stb missing)";
#endif
    ScratchDirTest::SetUp();
  }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  // Runs the viewer in the test's folder, without a display (headless whatever the machine).
  Output RunViewer(const std::string& args) const {
#ifdef DIGITIZE_VIEWER
    const std::string log = Path("viewer.log");
    const std::string command = "cd " + dir_.string() + " && env -u DISPLAY -u WAYLAND_DISPLAY " +
                                DIGITIZE_VIEWER + " " + args + " > " + log + " 2>&1";
    const int status = std::system(command.c_str());
    Output out;
    out.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    std::ifstream in(log);
    std::stringstream ss;
    ss << in.rdbuf();
    out.text = ss.str();
    fs::remove(log);
    return out;
#else
    (void)args;
    return {};
#endif
  }
  // Everything in the folder but the log: what the viewer wrote.
  size_t Entries() const {
    size_t n = 0;
    for (const auto& e : fs::recursive_directory_iterator(dir_))
      n += e.path().filename() != "viewer.log";
    return n;
  }
};

TEST_F(ViewerCliTest, NoPackAndNoSyntheticIsAnErrorWithUsage) {
  const Output out = RunViewer("--screenshot shot.png");
  EXPECT_EQ(out.exit_code, 1) << out.text;
  EXPECT_NE(out.text.find("no pack given"), std::string::npos) << out.text;
  EXPECT_NE(out.text.find("--synthetic"), std::string::npos) << out.text;
  EXPECT_EQ(Entries(), 0u);
  // Without --screenshot (and no display) it would have written gallery.png here.
  EXPECT_EQ(RunViewer("").exit_code, 1);
  EXPECT_EQ(Entries(), 0u);
}

TEST_F(ViewerCliTest, EveryPackFailingWritesNothing) {
  std::ofstream(Path("a.pack.exr")) << "not a pack";
  std::ofstream(Path("b.pack.exr")) << "not one either";
  std::ofstream(Path("shot.png")) << "an older screenshot";
  const Output out = RunViewer("a.pack.exr b.pack.exr missing.pack.exr --screenshot shot.png");
  EXPECT_EQ(out.exit_code, 1) << out.text;
  for (const char* name : {"a.pack.exr", "b.pack.exr", "missing.pack.exr"})
    EXPECT_NE(out.text.find(name), std::string::npos) << name << "\n" << out.text;
  EXPECT_NE(out.text.find("none of the 3 pack(s) could be loaded"), std::string::npos) << out.text;
  EXPECT_EQ(out.text.find("wrote"), std::string::npos) << out.text;
  std::ifstream in(Path("shot.png"));
  std::string content;
  std::getline(in, content);
  EXPECT_EQ(content, "an older screenshot");
}

// A camera path of 3 frames into a folder that does not exist yet: the folder is made, and the
// message names the 3 files written (not the --screenshot name, which is not written).
TEST_F(ViewerCliTest, CameraPathNamesTheFilesItWritesIntoANewFolder) {
  std::ofstream(Path("walk.json")) << R"({"format": "digitize.camera_path", "version": 1,
    "width": 64, "height": 48, "frames": [
      {"eye": [3000, 1500, 1600], "target": [3000, 6000, 1500]},
      {"eye": [3100, 1600, 1600], "target": [3000, 6000, 1500]},
      {"eye": [3200, 1700, 1600], "target": [3000, 6000, 1500]}]})";
  const Output out =
      RunViewer("--synthetic --camera-path walk.json --screenshot walk/day1/shot.png");
  ASSERT_EQ(out.exit_code, 0) << out.text;
  for (const char* f : {"shot_000.png", "shot_001.png", "shot_002.png"})
    EXPECT_TRUE(fs::exists(dir_ / "walk" / "day1" / f)) << f;
  EXPECT_FALSE(fs::exists(dir_ / "walk" / "day1" / "shot.png"));
  EXPECT_NE(out.text.find("walk/day1/shot_000.png"), std::string::npos) << out.text;
  EXPECT_NE(out.text.find("walk/day1/shot_002.png"), std::string::npos) << out.text;
  EXPECT_NE(out.text.find("3 images"), std::string::npos) << out.text;
  EXPECT_EQ(out.text.find("shot.png "), std::string::npos) << out.text;
  // One image: the name given, its folder made too.
  const Output one = RunViewer("--synthetic --size 64x48 --screenshot new/one.png");
  ASSERT_EQ(one.exit_code, 0) << one.text;
  EXPECT_TRUE(fs::exists(dir_ / "new" / "one.png"));
  EXPECT_NE(one.text.find("wrote new/one.png"), std::string::npos) << one.text;
}

// Headless without --screenshot used to write gallery.png into the current folder, over a file of
// that name; every usage error exits 1 (CLI11's codes were 105, 109, ...; --technique and --size
// 2).
TEST_F(ViewerCliTest, HeadlessNeedsAScreenshotNameAndUsageErrorsExitOne) {
  std::ofstream(Path("gallery.png")) << "the user's own picture";
  const Output out = RunViewer("--synthetic");
  EXPECT_EQ(out.exit_code, 1) << out.text;
  EXPECT_NE(out.text.find("no display"), std::string::npos) << out.text;
  EXPECT_NE(out.text.find("--screenshot"), std::string::npos) << out.text;
  std::ifstream in(Path("gallery.png"));
  std::string kept;
  std::getline(in, kept);
  EXPECT_EQ(kept, "the user's own picture");
  for (const char* args :
       {"--synthetic --bogus", "--synthetic --technique nope --screenshot s.png",
        "--synthetic --size 12 --screenshot s.png", "--synthetic --window-frames x"}) {
    const Output bad = RunViewer(args);
    EXPECT_EQ(bad.exit_code, 1) << args << "\n" << bad.text;
    EXPECT_FALSE(fs::exists(Path("s.png"))) << args;
  }
  EXPECT_EQ(RunViewer("--help").exit_code, 0);
}

// --mode: every view mode writes its screenshot, each a different image of the same gallery; an
// unknown mode or a light below the canvas is a usage error naming what is wrong, writing nothing.
TEST_F(ViewerCliTest, EveryViewModeWritesItsScreenshot) {
  std::string previous;
  for (const char* mode : {"relit", "light", "specular", "normals", "raking"}) {
    const std::string shot = std::string(mode) + ".png";
    const Output out = RunViewer(std::string("--synthetic --size 96x64 --mode ") + mode +
                                 " --light-azimuth 0 --light-elevation 30 --screenshot " + shot);
    ASSERT_EQ(out.exit_code, 0) << mode << "\n" << out.text;
    std::ifstream in(Path(shot), std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    EXPECT_GT(ss.str().size(), 100u) << mode;
    EXPECT_NE(ss.str(), previous) << mode << " wrote the same image as the mode before it";
    previous = ss.str();
  }
  const Output bad = RunViewer("--synthetic --mode rti --screenshot bad.png");
  EXPECT_EQ(bad.exit_code, 1) << bad.text;
  EXPECT_NE(bad.text.find("unknown view mode 'rti' (relit, light, specular, normals, raking)"),
            std::string::npos)
      << bad.text;
  const Output low =
      RunViewer("--synthetic --mode raking --raking-elevation 0 --screenshot bad.png");
  EXPECT_EQ(low.exit_code, 1) << low.text;
  EXPECT_NE(low.text.find("raking_elevation_deg must be in (0, 90]"), std::string::npos)
      << low.text;
  EXPECT_FALSE(fs::exists(Path("bad.png")));
}

// --style: every style writes its screenshot (and close-up), each unlike the others; --tour
// writes its frames; usage errors (an unknown style, two camera paths, a video without a path)
// exit 1 and write nothing.
TEST_F(ViewerCliTest, EveryStyleAndTheTourWriteTheirImages) {
  std::string previous;
  for (const char* style :
       {"realistic", "watercolor", "binary", "collage", "hatching", "painterly"}) {
    const std::string shot = std::string(style) + ".png", near = std::string(style) + "_near.png";
    const Output out = RunViewer(std::string("--synthetic --size 160x90 --style ") + style +
                                 " --screenshot " + shot + " --close-up " + near);
    ASSERT_EQ(out.exit_code, 0) << style << "\n" << out.text;
    std::ifstream in(Path(shot), std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    EXPECT_GT(ss.str().size(), 100u) << style;
    EXPECT_NE(ss.str(), previous) << style << " wrote the same image as the style before it";
    EXPECT_TRUE(fs::exists(Path(near))) << style;
    previous = ss.str();
  }
  const Output tour = RunViewer("--synthetic --size 64x36 --tour 5 --screenshot t/tour.png");
  ASSERT_EQ(tour.exit_code, 0) << tour.text;
  for (int i = 0; i < 5; ++i)
    EXPECT_TRUE(fs::exists(Path("t/tour_00" + std::to_string(i) + ".png"))) << i;
  for (const char* args : {"--synthetic --style oil --screenshot bad.png",
                           "--synthetic --tour 5 --camera-path x.json --screenshot bad.png",
                           "--synthetic --video v.mp4 --screenshot bad.png",
                           "--synthetic --tour 1 --screenshot bad.png"}) {
    const Output bad = RunViewer(args);
    EXPECT_EQ(bad.exit_code, 1) << args << "\n" << bad.text;
    EXPECT_FALSE(fs::exists(Path("bad.png"))) << args;
    EXPECT_FALSE(fs::exists(Path("v.mp4"))) << args;
  }
  EXPECT_NE(
      RunViewer("--synthetic --style oil --screenshot bad.png").text.find("unknown style 'oil'"),
      std::string::npos);
}

}  // namespace
