// End-to-end acceptance of "preprocess scanned height maps" (docs/architecture.md), measured
// against the synthetic generator's ground truth, plus the stress cases: each gets a correct result
// or a clear error, never a crash and never a NaN in an output.
#include "digitize/preprocess.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "digitize_synth/ground_truth.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/scan_sim.h"
#include "test_support.h"

namespace digitize {
namespace {

// Tolerances of the issue, and why they are reachable:
constexpr double kMaxTiltErrorDeg = 0.05;  // issue target; the robust plane fits ~10^5 points
constexpr double kMinMaskIou = 0.995;      // issue target; boundary refinement reaches the step
constexpr double kRmseNoiseFactor = 2.0;   // issue target: RMSE <= 2 sigma (interpolating noisy
                                           // samples averages noise down, resampling adds a little)
constexpr double kMaxNormalsMedianDeg = 0.5;  // issue target on a noise-free scan
constexpr double kWallFootMm = 0.1;  // 5 sigma of the default noise: a frame sample this close to
                                     // the canvas plane is the wall's foot, not frame geometry

struct PipelineRun {
  synth::Painting painting;
  synth::SyntheticScan scan;
  Result<PreprocessResult> result = Error{"not run"};
  synth::PreprocessAccuracy accuracy;
};

// Painting resolution matched to the scan's sampling of the canvas, so the truth surface holds no
// detail the scanner cannot resolve (the generator band-limits features to >= 8 texels).
int MatchedResolution(const synth::ScanSimOptions& scan, const synth::FrameOptions& frame = {}) {
  return synth::MatchedResolution(synth::PaintingOptions{}, frame, scan);
}

PipelineRun RunPipeline(synth::PaintingOptions painting_options, const synth::FrameOptions& frame,
                        const synth::ScanSimOptions& scan_options,
                        const PreprocessOptions& options = PreprocessOptions{}) {
  PipelineRun run;
  if (painting_options.resolution_px == 0)
    painting_options.resolution_px = MatchedResolution(scan_options, frame);
  run.painting = synth::MakePainting(painting_options);
  const synth::Scene scene(run.painting, frame);
  run.scan = synth::SimulateScan(scene, scan_options);
  run.result = Preprocess(run.scan.exposures, options);
  if (run.result.ok()) run.accuracy = synth::MeasureAccuracy(*run.result, run.painting, run.scan);
  return run;
}

void ExpectAllFinite(const PreprocessResult& r) {
  for (float h : r.field.height_mm.data) ASSERT_TRUE(std::isfinite(h));
  for (const Vec3f& n : r.normals.data) {
    ASSERT_TRUE(n.allFinite());
    ASSERT_NEAR(n.norm(), 1.0f, 1e-4f);
  }
  EXPECT_TRUE(std::isfinite(r.relief.delta0_mm));
  EXPECT_TRUE(std::isfinite(r.relief.max_height_mm));
  for (const ReliefBox& b : r.relief.boxes) EXPECT_TRUE(std::isfinite(b.h_max_mm));
}

synth::PaintingOptions DefaultPainting() {
  synth::PaintingOptions p;
  p.resolution_px = 0;  // matched to the scan
  return p;
}

TEST(Preprocess, DefaultSyntheticScanMeetsAccuracyTargets) {
  synth::ScanSimOptions
      scan;  // defaults: 512^2, noise, dropouts, blob holes, outliers, tilt, roll, offset
  const PipelineRun run = RunPipeline(DefaultPainting(), synth::FrameOptions{}, scan);
  ASSERT_TRUE(run.result.ok()) << run.result.error().message;
  ExpectAllFinite(*run.result);
  const auto& a = run.accuracy;
  EXPECT_LE(a.normal_error_deg, kMaxTiltErrorDeg);
  EXPECT_GE(a.mask_iou, kMinMaskIou);
  EXPECT_EQ(a.frame_pixels_kept, 0u);
  EXPECT_LE(a.height_rmse_mm, kRmseNoiseFactor * scan.noise_mm);
  EXPECT_GT(a.relief_texels_true, 0u) << "the default painting has impasto above delta0";
  EXPECT_EQ(a.relief_texels_uncovered, 0u);
  EXPECT_FALSE(run.result->relief.boxes.empty());
  // Reported, not asserted: the normals' median error at the default noise.
  RecordProperty("normals_median_deg_default_noise", std::to_string(a.normals_median_deg));
  std::printf(
      "default noise %.3f mm: tilt err %.4f deg, IoU %.5f, RMSE %.4f mm, normals median %.3f deg\n",
      scan.noise_mm, a.normal_error_deg, a.mask_iou, a.height_rmse_mm, a.normals_median_deg);
}

// The frame's boxes go from the scan into the height field and through the canvas folder
// (transform.json, "frame") unchanged; a frame entry that is no frame is an error naming the file.
// Accuracy of the boxes themselves: canvas_test (FrameBoxesMatchTheFrame).
TEST(Preprocess, FrameBoxesRoundTripThroughTheCanvasFolder) {
  synth::ScanSimOptions scan;
  scan.width_px = scan.height_px = 256;
  const PipelineRun run = RunPipeline(DefaultPainting(), synth::FrameOptions{}, scan);
  ASSERT_TRUE(run.result.ok()) << run.result.error().message;
  const FrameBoxes& frame = run.result->field.frame;
  ASSERT_TRUE(frame.any());
  EXPECT_EQ(frame.raise_mm, run.result->canvas.frame.raise_mm);
  const std::filesystem::path dir = test::FreshScratchDir("preprocess_frame", "", false);
  ASSERT_TRUE(WritePreprocessOutputs(dir, *run.result, PreprocessOptions{}, {"scan"}).ok());
  const Result<PreprocessedCanvas> read = ReadPreprocessOutputs(dir);
  ASSERT_TRUE(read.ok()) << read.error().message;
  for (int side = 0; side < 4; ++side) {
    EXPECT_FLOAT_EQ(read->field.frame.raise_mm[side], frame.raise_mm[side]);
    EXPECT_FLOAT_EQ(read->field.frame.width_mm[side], frame.width_mm[side]);
  }
  std::string text = test::ReadFileBytes(dir / "transform.json");
  const size_t at = text.find("\"width_mm\"");
  ASSERT_NE(at, std::string::npos);
  text.insert(text.find_first_of("0123456789", at), "-");  // a negative width
  test::WriteFileBytes(dir / "transform.json", text);
  const Result<PreprocessedCanvas> bad = ReadPreprocessOutputs(dir);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("transform.json"), std::string::npos) << bad.error().message;
  EXPECT_NE(bad.error().message.find("width_mm"), std::string::npos) << bad.error().message;
  std::filesystem::remove_all(dir);
}

TEST(Preprocess, NoiseFreeScanGivesAccurateNormals) {
  synth::ScanSimOptions scan;
  scan.width_px = scan.height_px = 768;
  scan.noise_mm = 0;
  scan.outliers = 0;
  scan.dropout = 0;
  scan.hole_blobs = 0;
  const PipelineRun run = RunPipeline(DefaultPainting(), synth::FrameOptions{}, scan);
  ASSERT_TRUE(run.result.ok()) << run.result.error().message;
  ExpectAllFinite(*run.result);
  EXPECT_LT(run.accuracy.normals_median_deg, kMaxNormalsMedianDeg);
  EXPECT_LE(run.accuracy.normal_error_deg, kMaxTiltErrorDeg);
  EXPECT_GE(run.accuracy.mask_iou, kMinMaskIou);
}

TEST(Preprocess, PinholeScannerAndSeveralExposures) {
  synth::ScanSimOptions scan;
  scan.model = synth::ScannerModel::kPinhole;
  scan.exposures = 3;
  const PipelineRun run = RunPipeline(DefaultPainting(), synth::FrameOptions{}, scan);
  ASSERT_TRUE(run.result.ok()) << run.result.error().message;
  ExpectAllFinite(*run.result);
  EXPECT_EQ(run.result->merge.exposures, 3);
  EXPECT_GT(run.result->merge.filled_from_others, 0u) << "dropouts differ between exposures";
  EXPECT_LE(run.accuracy.normal_error_deg, kMaxTiltErrorDeg);
  EXPECT_GE(run.accuracy.mask_iou, kMinMaskIou);
  // Three exposures average the noise down: sigma/sqrt(3) for the merged median ~ sigma*0.7.
  EXPECT_LE(run.accuracy.height_rmse_mm, kRmseNoiseFactor * scan.noise_mm);
}

TEST(PreprocessStress, FlatCanvasHasNoBoxesAndNoError) {
  synth::PaintingOptions p = DefaultPainting();
  p.weave = p.strokes = p.impasto = p.craquelure = false;
  synth::ScanSimOptions scan;
  scan.noise_mm = 0;
  scan.outliers = 0;
  const PipelineRun run = RunPipeline(p, synth::FrameOptions{}, scan);
  ASSERT_TRUE(run.result.ok()) << run.result.error().message;
  ExpectAllFinite(*run.result);
  EXPECT_TRUE(run.result->relief.boxes.empty());
  EXPECT_LE(run.accuracy.normal_error_deg, kMaxTiltErrorDeg);
}

TEST(PreprocessStress, NoFrameCanvasFillsTheScan) {
  synth::FrameOptions frame;
  frame.enabled = false;
  synth::ScanSimOptions scan;
  scan.field_margin = -0.1;  // the field of view lies inside the canvas
  const PipelineRun run = RunPipeline(DefaultPainting(), frame, scan);
  ASSERT_TRUE(run.result.ok()) << run.result.error().message;
  ExpectAllFinite(*run.result);
  EXPECT_GE(run.accuracy.mask_iou, kMinMaskIou);
  EXPECT_LE(run.accuracy.normal_error_deg, kMaxTiltErrorDeg);
}

TEST(PreprocessStress, FortyFiveDegreeTilt) {
  synth::ScanSimOptions scan;
  scan.tilt_deg = 45;
  scan.width_px = scan.height_px = 768;
  const PipelineRun run = RunPipeline(DefaultPainting(), synth::FrameOptions{}, scan);
  ASSERT_TRUE(run.result.ok()) << run.result.error().message;
  ExpectAllFinite(*run.result);
  EXPECT_LE(run.accuracy.normal_error_deg, kMaxTiltErrorDeg);
  EXPECT_EQ(run.accuracy.frame_pixels_kept, 0u);
  // At 45 deg the frame hides a strip of canvas and the samples stretch by 1/cos: the mask is
  // judged against what the scanner saw, so the same IoU target holds.
  EXPECT_GE(run.accuracy.mask_iou, kMinMaskIou);
}

TEST(PreprocessStress, ThirtyPercentHoles) {
  synth::ScanSimOptions scan;
  scan.dropout = 0.30;
  const PipelineRun run = RunPipeline(DefaultPainting(), synth::FrameOptions{}, scan);
  ASSERT_TRUE(run.result.ok()) << run.result.error().message;
  ExpectAllFinite(*run.result);
  EXPECT_LE(run.accuracy.normal_error_deg, kMaxTiltErrorDeg);
  EXPECT_GE(run.accuracy.mask_iou, 0.99) << "holes at the boundary blur it by up to a pixel";
  // With 30 % of the samples gone, the neighbours that tell a frame wall's foot from the canvas
  // edge are often missing: a few wall-foot samples may stay, but only ones lying within the
  // noise band of the canvas plane (they carry no frame geometry into the height field).
  EXPECT_LE(run.accuracy.frame_pixels_kept, 10u);
  EXPECT_LE(run.accuracy.frame_pixels_max_height_mm, kWallFootMm);
}

TEST(PreprocessStress, HeavyNoise) {
  synth::ScanSimOptions scan;
  scan.noise_mm = 0.2;  // 10x the default: as large as the brush strokes
  const PipelineRun run = RunPipeline(DefaultPainting(), synth::FrameOptions{}, scan);
  ASSERT_TRUE(run.result.ok()) << run.result.error().message;
  ExpectAllFinite(*run.result);
  EXPECT_LE(run.accuracy.normal_error_deg, 0.1) << "10x noise: a looser plane tolerance";
  EXPECT_GE(run.accuracy.mask_iou, 0.99);
  EXPECT_LE(run.accuracy.height_rmse_mm, kRmseNoiseFactor * scan.noise_mm);
}

TEST(PreprocessStress, OffCentreCanvasGivesClearErrorOrCanvas) {
  synth::ScanSimOptions scan;
  scan.offset_mm = Vec3d(180, 0, 0);  // the scan centre lands on the frame or beyond
  const PipelineRun run = RunPipeline(DefaultPainting(), synth::FrameOptions{}, scan);
  if (run.result.ok()) {
    ExpectAllFinite(*run.result);
    EXPECT_GE(run.accuracy.mask_iou, kMinMaskIou) << "if it finds a canvas, it is the canvas";
  } else {
    EXPECT_NE(run.result.error().message.find("seed"), std::string::npos)
        << "the error tells the user how to fix it: " << run.result.error().message;
  }
}

TEST(PreprocessStress, OffCentreCanvasWithSeedWorks) {
  synth::ScanSimOptions scan;
  scan.offset_mm = Vec3d(180, 0, 0);
  synth::PaintingOptions painting = DefaultPainting();
  painting.resolution_px = MatchedResolution(scan);
  const synth::Painting p = synth::MakePainting(painting);
  const synth::Scene scene(p, synth::FrameOptions{});
  const synth::SyntheticScan s = synth::SimulateScan(scene, scan);
  // Seed at the centre of the true canvas mask.
  double sx = 0, sy = 0, n = 0;
  for (int y = 0; y < s.canvas_mask_scan.height; ++y)
    for (int x = 0; x < s.canvas_mask_scan.width; ++x)
      if (s.canvas_mask_scan(x, y)) sx += x, sy += y, ++n;
  ASSERT_GT(n, 0);
  PreprocessOptions options;
  options.canvas.seed_x = static_cast<int>(sx / n);
  options.canvas.seed_y = static_cast<int>(sy / n);
  Result<PreprocessResult> r = Preprocess(s.exposures, options);
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectAllFinite(*r);
  EXPECT_GE(synth::MeasureAccuracy(*r, p, s).mask_iou, kMinMaskIou);
}

Scan GridScan(int w, int h, float value) {
  Scan scan;
  scan.source = "hostile.exr";
  scan.xyz_mm = Grid<Vec3f>(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) scan.xyz_mm(x, y) = Vec3f(x * 0.5f, y * 0.5f, value);
  return scan;
}

TEST(PreprocessStress, TinyScansGiveResultOrClearError) {
  for (auto [w, h] :
       {std::pair{8, 8}, std::pair{1, 64}, std::pair{64, 1}, std::pair{1, 1}, std::pair{0, 0}}) {
    Result<PreprocessResult> r = Preprocess({GridScan(w, h, 100.0f)}, PreprocessOptions{});
    if (r.ok()) {
      ExpectAllFinite(*r);
    } else {
      EXPECT_NE(r.error().message.find("hostile.exr"), std::string::npos) << r.error().message;
    }
  }
}

TEST(PreprocessStress, AllNanInfAndHugeValuesAreErrorsNamingTheScan) {
  for (float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                    -std::numeric_limits<float>::infinity(), 1e30f}) {
    Scan scan = GridScan(64, 64, 0);
    for (Vec3f& p : scan.xyz_mm.data) p = Vec3f(bad, bad, bad);
    Result<PreprocessResult> r = Preprocess({scan}, PreprocessOptions{});
    ASSERT_FALSE(r.ok()) << "value " << bad;
    EXPECT_NE(r.error().message.find("hostile.exr"), std::string::npos) << r.error().message;
  }
}

TEST(PreprocessStress, SomeInfAndHugeValuesAreCleanedNotPropagated) {
  synth::ScanSimOptions scan_options;
  scan_options.width_px = scan_options.height_px = 256;
  synth::PaintingOptions po = DefaultPainting();
  po.resolution_px = MatchedResolution(scan_options);
  const synth::Painting p = synth::MakePainting(po);
  const synth::Scene scene(p, synth::FrameOptions{});
  synth::SyntheticScan s = synth::SimulateScan(scene, scan_options);
  Scan& scan = s.exposures.front();
  for (size_t i = 0; i < scan.xyz_mm.size(); i += 97)
    scan.xyz_mm.data[i].z() = std::numeric_limits<float>::infinity();
  for (size_t i = 13; i < scan.xyz_mm.size(); i += 101)
    scan.xyz_mm.data[i] = Vec3f(1e30f, -1e30f, 1e30f);
  Result<PreprocessResult> r = Preprocess(s.exposures, PreprocessOptions{});
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectAllFinite(*r);
  EXPECT_GT(r->sanitize.non_finite, 0u);
  EXPECT_LE(synth::MeasureAccuracy(*r, p, s).normal_error_deg, kMaxTiltErrorDeg);
}

TEST(PreprocessStress, MismatchedExposuresAreAnErrorNamingTheScan) {
  Scan a = GridScan(64, 64, 100), b = GridScan(64, 32, 100);
  b.source = "second.exr";
  Result<PreprocessResult> r = Preprocess({a, b}, PreprocessOptions{});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("second.exr"), std::string::npos) << r.error().message;
}

TEST(PreprocessStress, InvalidOptionsNameTheOption) {
  PreprocessOptions options;
  options.relief.cell_px = 0;
  Result<PreprocessResult> r = Preprocess({GridScan(64, 64, 100)}, options);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("cell_px"), std::string::npos) << r.error().message;
  options = PreprocessOptions{};
  options.relief.delta0_fraction = 1.5;
  r = Preprocess({GridScan(64, 64, 100)}, options);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("delta0"), std::string::npos) << r.error().message;
}

TEST(PreprocessStress, NoScanIsAnError) {
  Result<PreprocessResult> r = Preprocess({}, PreprocessOptions{});
  EXPECT_FALSE(r.ok());
}

}  // namespace
}  // namespace digitize
