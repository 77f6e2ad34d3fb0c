// Preprocessing on scans unlike the generator's defaults (docs/refusals.md, "Scans"): a perspective
// scan from 1 m of an off-centre, rotated canvas tilted about a diagonal, bowed, in an asymmetric
// bevelled frame, with dropouts; variants with border holes and with a frame lip. Each is built
// in memory and measured against the generator's ground truth.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "digitize/preprocess.h"
#include "digitize_synth/ground_truth.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/scan_sim.h"
#include "test_paths.h"
#include "test_support.h"

namespace digitize {
namespace {

// Targets of the issue.
constexpr double kMaxAxisErrorDeg = 0.05;
constexpr double kMinMaskIou = 0.995;
// The extent is the visible canvas's bounding box: its sides sit within about half a sample
// spacing (0.4 mm here) of the outline, so 1 mm holds with margin.
constexpr double kMaxExtentErrorMm = 1.0;
// A bowed canvas has no plane; the robust fit is held to the bare canvas's least-squares plane
// within the tilt target of a flat one.
constexpr double kMaxBarePlaneTiltDeg = 0.05;

struct Case {
  std::string name;
  synth::PaintingOptions painting;
  synth::FrameOptions frame;
  synth::ScanSimOptions scan;
};

// The independent scan of the issue: 500 x 350 mm canvas, 1200 x 1000 pinhole scan from 1 m,
// 12 deg tilt about a diagonal, 7 deg roll, off-centre, bowed 0.5 mm, frame 35/50/42/60 mm with
// a 3 mm bevel, sigma 0.03 mm, 3.4 % dropouts.
Case IndependentLike() {
  Case c;
  c.name = "independent-like";
  c.painting.width_mm = 500, c.painting.height_mm = 350;
  c.painting.bow_mm = -0.5;
  c.painting.seed = 7;
  c.frame.left_mm = 35, c.frame.right_mm = 50, c.frame.top_mm = 42, c.frame.bottom_mm = 60;
  c.frame.bevel_width_mm = 3, c.frame.bevel_height_mm = 3;
  c.scan.model = synth::ScannerModel::kPinhole;
  c.scan.width_px = 1200, c.scan.height_px = 1000;
  c.scan.distance_mm = 1000;
  c.scan.tilt_deg = 12, c.scan.tilt_axis_deg = 45;
  c.scan.roll_deg = 7;
  c.scan.offset_mm = Vec3d(40, -25, 0);
  c.scan.field_margin = 0.12;
  c.scan.noise_mm = 0.03;
  c.scan.dropout = 0.034;
  c.scan.seed = 11;
  c.painting.resolution_px = synth::MatchedResolution(c.painting, c.frame, c.scan);
  return c;
}

struct ScanRun {
  synth::Painting painting;
  synth::SyntheticScan scan;
  Result<PreprocessResult> result = Error{"not run"};
  synth::PreprocessAccuracy accuracy;
};

ScanRun RunCase(const Case& c) {
  ScanRun run;
  run.painting = synth::MakePainting(c.painting);
  const synth::Scene scene(run.painting, c.frame);
  run.scan = synth::SimulateScan(scene, c.scan);
  run.result = Preprocess(run.scan.exposures, PreprocessOptions{});
  if (run.result.ok()) run.accuracy = synth::MeasureAccuracy(*run.result, run.painting, run.scan);
  const auto& a = run.accuracy;
  const Eigen::Vector2d visible = run.scan.visible_max_mm - run.scan.visible_min_mm;
  if (run.result.ok())
    std::printf(
        "%s: axis %.4f deg, IoU %.5f, extent %.2f x %.2f mm (visible %.2f x %.2f, canvas %.0f x "
        "%.0f), tilt %.4f deg (bare plane %.4f deg), RMSE %.4f mm, %zu frame px kept\n",
        c.name.c_str(), a.axis_error_deg, a.mask_iou, run.result->canvas.extent_mm.x(),
        run.result->canvas.extent_mm.y(), visible.x(), visible.y(), run.painting.width_mm,
        run.painting.height_mm, a.normal_error_deg, a.bare_plane_tilt_deg, a.height_rmse_mm,
        a.frame_pixels_kept);
  return run;
}

TEST(UnlikeScans, IndependentLikeScan) {
  // Three paintings (the impasto that pulled the principal axes differs with the seed).
  for (uint64_t seed : {7, 8, 9}) {
    Case c = IndependentLike();
    c.painting.seed = seed, c.scan.seed = seed + 4;
    c.name = "independent-like, seed " + std::to_string(seed);
    const ScanRun run = RunCase(c);
    ASSERT_TRUE(run.result.ok()) << run.result.error().message;
    SCOPED_TRACE(c.name);
    const auto& a = run.accuracy;
    EXPECT_TRUE(run.result->canvas.outline_fitted) << run.result->canvas.outline_note;
    EXPECT_LE(a.axis_error_deg, kMaxAxisErrorDeg);
    EXPECT_GE(a.mask_iou, kMinMaskIou);
    EXPECT_LE(a.extent_error_mm, kMaxExtentErrorMm);
    EXPECT_LE(a.bare_plane_tilt_deg, kMaxBarePlaneTiltDeg);
    EXPECT_TRUE(run.result->canvas.warnings.empty()) << run.result->canvas.warnings.front();
    // The grid holds no empty wedges (4.4 % of the texels with the PCA axes): what is outside
    // is the ring of texels on the outline whose centres the scan quads do not reach, about
    // one texel along the perimeter (0.4 % here).
    const ResampleStats& rs = run.result->resample;
    EXPECT_LT(static_cast<double>(rs.outside) / static_cast<double>(rs.texels), 0.01);
    RecordProperty("bare_plane_tilt_deg_seed_" + std::to_string(seed),
                   std::to_string(a.bare_plane_tilt_deg));
  }
}

TEST(UnlikeScans, StraightOnPerspectiveScanHasNoWarning) {
  // Rays lean outwards on every side: every inner face of the frame is seen, none overhangs.
  // The hardest case for the IoU: with no roll the pixel grid is parallel to the edges, so a
  // whole row of pixels can land on the bevel's foot a few hundredths of a mm outside the canvas,
  // as high above it as the noise: no test can tell those from canvas (0.4 % of the IoU here).
  Case c = IndependentLike();
  c.name = "straight on";
  c.scan.tilt_deg = 0, c.scan.roll_deg = 0, c.scan.offset_mm = Vec3d::Zero();
  const ScanRun run = RunCase(c);
  ASSERT_TRUE(run.result.ok()) << run.result.error().message;
  EXPECT_TRUE(run.result->canvas.warnings.empty()) << run.result->canvas.warnings.front();
  EXPECT_LE(run.accuracy.axis_error_deg, kMaxAxisErrorDeg);
  EXPECT_GE(run.accuracy.mask_iou, kMinMaskIou);
  EXPECT_LE(run.accuracy.extent_error_mm, kMaxExtentErrorMm);
}

TEST(UnlikeScans, DefaultGeneratorScanHasNoWarning) {
  Case c;
  c.name = "default generator";
  c.painting.resolution_px = synth::MatchedResolution(c.painting, c.frame, c.scan);
  const ScanRun run = RunCase(c);
  ASSERT_TRUE(run.result.ok()) << run.result.error().message;
  EXPECT_TRUE(run.result->canvas.outline_fitted) << run.result->canvas.outline_note;
  EXPECT_TRUE(run.result->canvas.warnings.empty());
  EXPECT_LE(run.accuracy.axis_error_deg, kMaxAxisErrorDeg);
  EXPECT_GE(run.accuracy.mask_iou, kMinMaskIou);
}

TEST(UnlikeScans, BorderHolesDoNotNotchTheMask) {
  Case c = IndependentLike();
  c.name = "border holes";
  c.scan.border_hole_blobs = 40;
  c.scan.seed = 12;
  const ScanRun run = RunCase(c);
  ASSERT_TRUE(run.result.ok()) << run.result.error().message;
  EXPECT_LE(run.accuracy.axis_error_deg, kMaxAxisErrorDeg);
  EXPECT_GE(run.accuracy.mask_iou, kMinMaskIou);
  EXPECT_LE(run.accuracy.extent_error_mm, kMaxExtentErrorMm);
  EXPECT_TRUE(run.result->canvas.warnings.empty());
}

TEST(UnlikeScans, OrthographicTiltedAndRotated) {
  Case c = IndependentLike();
  c.name = "orthographic";
  c.scan.model = synth::ScannerModel::kOrthographic;
  c.scan.tilt_deg = 10, c.scan.tilt_axis_deg = -35, c.scan.roll_deg = -12;
  c.painting.bow_mm = 0.5;
  const ScanRun run = RunCase(c);
  ASSERT_TRUE(run.result.ok()) << run.result.error().message;
  EXPECT_LE(run.accuracy.axis_error_deg, kMaxAxisErrorDeg);
  EXPECT_GE(run.accuracy.mask_iou, kMinMaskIou);
  EXPECT_LE(run.accuracy.extent_error_mm, kMaxExtentErrorMm);
  EXPECT_LE(run.accuracy.bare_plane_tilt_deg, kMaxBarePlaneTiltDeg);
  EXPECT_TRUE(run.result->canvas.warnings.empty());
}

TEST(UnlikeScans, FrameLipIsWarnedAbout) {
  Case c = IndependentLike();
  c.name = "lip";
  c.frame.lip_mm = 6;
  const ScanRun run = RunCase(c);
  ASSERT_TRUE(run.result.ok()) << run.result.error().message;
  const Eigen::Vector2d visible = run.scan.visible_max_mm - run.scan.visible_min_mm;
  EXPECT_LT(visible.x(), run.painting.width_mm - 5) << "the lip hides a strip of the canvas";
  EXPECT_LE(run.accuracy.axis_error_deg, kMaxAxisErrorDeg);
  EXPECT_GE(run.accuracy.mask_iou, kMinMaskIou);
  EXPECT_LE(run.accuracy.extent_error_mm, kMaxExtentErrorMm);
  ASSERT_EQ(run.result->canvas.warnings.size(), 1u);
  EXPECT_NE(run.result->canvas.warnings[0].find("overhangs"), std::string::npos);
  for (const auto& w : run.result->canvas.warnings) std::printf("warning: %s\n", w.c_str());
  // The warning reaches the canvas step's line and report.json.
  bool in_line = false;
  for (const StepReport& step : run.result->steps)
    in_line = in_line || (step.name == "canvas" &&
                          step.line.find("WARNING: the frame overhangs") != std::string::npos);
  EXPECT_TRUE(in_line);
  const nlohmann::json report =
      nlohmann::json::parse(PreprocessReportJson(*run.result, PreprocessOptions{}, {"scan.exr"}));
  ASSERT_EQ(report.at("warnings").size(), 1u);
  EXPECT_FALSE(report.at("canvas").at("hidden_edges").empty());
  EXPECT_TRUE(report.at("canvas").at("outline_fitted").get<bool>());
}

TEST(UnlikeScans, CanvasCutByTheScanBorderKeepsThatSideOpen) {
  Case c = IndependentLike();
  c.name = "cut by the scan border";
  c.scan.offset_mm = Vec3d(-40, 20, 0);
  c.scan.field_margin = -0.15;  // the view ends inside the canvas on both sides
  const ScanRun run = RunCase(c);
  ASSERT_TRUE(run.result.ok()) << run.result.error().message;
  EXPECT_LE(run.accuracy.axis_error_deg, kMaxAxisErrorDeg);
  EXPECT_GE(run.accuracy.mask_iou, kMinMaskIou);
  EXPECT_TRUE(run.result->canvas.warnings.empty());
}

TEST(UnlikeScans, OvalCanvasKeepsTheGrownRegion) {
  // A canvas the scan sees as an ellipse (samples outside it moved down to the wall): no
  // rectangle fits, so the grown region and the PCA axes stay, and the report says why.
  Case c = IndependentLike();
  c.frame.enabled = false;
  c.painting.bow_mm = 0;
  synth::Painting painting = synth::MakePainting(c.painting);
  const synth::Scene scene(painting, c.frame);
  synth::SyntheticScan s = synth::SimulateScan(scene, c.scan);
  Scan& scan = s.exposures[0];
  const RigidTransform scan_from_canvas = s.canvas_from_scan.Inverse();
  Grid<uint8_t> oval(scan.xyz_mm.width, scan.xyz_mm.height, 0);
  for (size_t i = 0; i < scan.xyz_mm.size(); ++i) {
    if (!s.canvas_mask_scan.data[i]) continue;
    Vec3f& p = scan.xyz_mm.data[i];
    if (!IsValid(p)) {
      oval.data[i] = 1;  // a dropout inside: measured against the painting's own outline below
      continue;
    }
    Vec3d q = s.canvas_from_scan.Apply(p.cast<double>());
    const double u = 2 * q.x() / painting.width_mm - 1, v = 2 * q.y() / painting.height_mm - 1;
    if (u * u + v * v <= 1) {
      oval.data[i] = 1;
      continue;
    }
    q.z() = -c.frame.wall_depth_mm;
    p = scan_from_canvas.Apply(q).cast<float>();
  }
  SanitizeScan(scan, SanitizeOptions{});
  const Result<CanvasResult> r = ExtractCanvas(scan, CanvasOptions{});
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_FALSE(r->outline_fitted);
  EXPECT_NE(r->outline_note.find("not a rectangle"), std::string::npos) << r->outline_note;
  size_t inter = 0, uni = 0;
  for (size_t i = 0; i < oval.size(); ++i) {
    const bool e = r->mask_scan.data[i] != 0, t = oval.data[i] != 0;
    inter += e && t, uni += e || t;
  }
  std::printf("oval: IoU %.5f, outline note: %s\n", double(inter) / double(uni),
              r->outline_note.c_str());
  EXPECT_GE(static_cast<double>(inter) / static_cast<double>(uni), 0.99);
}

// The command line: synth's flags for these cases, and the warning in preprocess's output.
std::string RunCli(const std::string& args, int* rc) {
  const std::string command = std::string(DIGITIZE_CLI) + " " + args + " 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  std::string out;
  char buffer[4096];
  while (pipe && fgets(buffer, sizeof(buffer), pipe)) out += buffer;
  *rc = pipe ? WEXITSTATUS(pclose(pipe)) : -1;
  return out;
}

TEST(UnlikeScansCli, SynthFlagsAndThePreprocessWarning) {
  const std::filesystem::path dir = test::FreshScratchDir("unlike_scans_cli");
  const std::string scene =
      " --width-mm 300 --height-mm 220 --model pinhole --scan-size 700 560 --distance-mm 700"
      " --tilt-deg 6 --tilt-axis-deg 45 --roll-deg 5 --offset-mm 20 -10"
      " --frame-sides-mm 30 40 35 45 --bevel-mm 2 2 --bow-mm -0.3 --border-holes 10";
  for (const bool lip : {false, true}) {
    const std::string name = lip ? "lip" : "plain";
    int rc = 0;
    std::string out = RunCli(
        "synth --out " + (dir / ("s_" + name)).string() + scene + (lip ? " --lip-mm 5" : ""), &rc);
    ASSERT_EQ(rc, 0) << out;
    const nlohmann::json truth =
        nlohmann::json::parse(std::ifstream(dir / ("s_" + name) / "truth.json"), nullptr, false);
    ASSERT_FALSE(truth.is_discarded());
    EXPECT_DOUBLE_EQ(truth.at("frame_options").at("side_widths_mm").at("bottom").get<double>(), 45);
    EXPECT_DOUBLE_EQ(truth.at("frame_options").at("lip_mm").get<double>(), lip ? 5 : 0);
    out = RunCli("preprocess " + (dir / ("s_" + name) / "scan.exr").string() + " --out " +
                     (dir / ("c_" + name)).string(),
                 &rc);
    ASSERT_EQ(rc, 0) << out;
    EXPECT_NE(out.find("axes and mask from the canvas outline"), std::string::npos) << out;
    EXPECT_EQ(out.find("WARNING: the frame overhangs") != std::string::npos, lip) << out;
    const nlohmann::json report =
        nlohmann::json::parse(std::ifstream(dir / ("c_" + name) / "report.json"), nullptr, false);
    ASSERT_FALSE(report.is_discarded());
    EXPECT_EQ(report.at("warnings").size(), lip ? 1u : 0u);
  }
  // A bad shape is refused, naming the option, before anything is written.
  int rc = 0;
  const std::string out = RunCli("synth --out " + (dir / "bad").string() + " --bevel-mm 50 2", &rc);
  EXPECT_EQ(rc, 1) << out;
  EXPECT_NE(out.find("bevel_width_mm"), std::string::npos) << out;
  EXPECT_FALSE(std::filesystem::exists(dir / "bad"));
  const std::string lip_out =
      RunCli("synth --out " + (dir / "bad").string() + " --width-mm 300 --lip-mm 200", &rc);
  EXPECT_EQ(rc, 1) << lip_out;
  EXPECT_NE(lip_out.find("lip_mm 200 hides the whole"), std::string::npos) << lip_out;
  EXPECT_FALSE(std::filesystem::exists(dir / "bad"));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace digitize
