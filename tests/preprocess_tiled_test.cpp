// The tiled preprocess (preprocess_tiled.h) against the whole one on scans that fit in memory,
// against the generator's truth where its canvas pass reads a stride, and its errors.
#include "digitize/preprocess_tiled.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>

#include "digitize/image_io.h"
#include "digitize/pipeline.h"
#include "digitize/scan_io.h"
#include "digitize_synth/ground_truth.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/scan_sim.h"
#include "test_support.h"

namespace digitize {
namespace {

namespace fs = std::filesystem;

class PreprocessTiled : public test::ScratchDirTest {
 protected:
  PreprocessTiled() : ScratchDirTest("preprocess_tiled") {}

  // A framed painting's scan, written as the XYZ EXR a user would give, and its truth.
  synth::SyntheticScan MakeScan(const synth::ScanSimOptions& scan_options) {
    synth::PaintingOptions p;
    p.resolution_px = synth::MatchedResolution(p, synth::FrameOptions{}, scan_options);
    const synth::Painting painting = synth::MakePainting(p);
    const synth::Scene scene(painting, synth::FrameOptions{});
    synth::SyntheticScan scan = synth::SimulateScan(scene, scan_options);
    EXPECT_TRUE(WriteScanExr(Path("scan.exr"), scan.exposures.front()).ok());
    return scan;
  }
};

// Tolerances, tiled (canvas pass on every sample) against whole, and why:
// - measured heights: 1e-4 mm. The triangles are the same ones (edge lengths from the scan's
//   samples); a tile's texel transform is the whole's moved to the tile, evaluated in float
//   about another reference sample: ~1e-5 relative of the ~300 mm from it (measured 6.4e-5).
// - states: only within kBorderTexels of the grid's border, only outside <-> a hole, at most a
//   border's worth of texels. Where samples on the canvas outline are missing (border holes),
//   the outline is predicted from a quadratic scan pixel -> texel map, fitted to the tile's
//   samples instead of the whole scan's (measured: 11 and 45 texels, 5 from the border at most).
// - filled heights and normals beyond that band: 1e-3 mm and 0.1 deg. The membrane relaxation
//   stops at 1e-5 mm per sweep, so inputs that differ by float rounding may stop after other
//   sweep counts (measured 1.7e-4 mm, 0.03 deg); the scan's noise is 0.02 mm. In the band, next
//   to the outline that differs, a filled hole's edge moves (1.3e-2 mm): not compared.
constexpr double kMeasuredTolMm = 1e-4;
constexpr double kFilledTolMm = 1e-3;
constexpr double kNormalTolDeg = 0.1;
constexpr int kBorderTexels = 8;

struct TiledCase {
  const char* name;
  synth::ScannerModel model;
  int hole_blobs, border_hole_blobs;
  double roll_deg;
  int tile_texels;
};

void PrintTo(const TiledCase& c, std::ostream* os) { *os << c.name; }

class PreprocessTiledEqualsWhole : public PreprocessTiled,
                                   public ::testing::WithParamInterface<TiledCase> {};

TEST_P(PreprocessTiledEqualsWhole, WithEverySampleInTheCanvasPass) {
  const TiledCase& param = GetParam();
  synth::ScanSimOptions scan_options;
  scan_options.model = param.model;
  scan_options.hole_blobs = param.hole_blobs;
  scan_options.border_hole_blobs = param.border_hole_blobs;
  scan_options.roll_deg = param.roll_deg;
  const synth::SyntheticScan scan = MakeScan(scan_options);
  PreprocessOptions options;
  options.resample.pitch_mm = 0.5;
  auto whole = Preprocess(scan.exposures, options);
  ASSERT_TRUE(whole.ok()) << whole.error().message;
  TiledPreprocessOptions tiled;
  tiled.tile_texels = param.tile_texels;
  tiled.canvas_stride = 1;
  const fs::path out = Path("tiled");
  fs::create_directories(out);
  auto result = PreprocessScanTiled(Path("scan.exr"), options, tiled, out, {"scan.exr"});
  ASSERT_TRUE(result.ok()) << result.error().message;
  auto read = ReadPreprocessOutputs(out);
  ASSERT_TRUE(read.ok()) << read.error().message;
  const int w = whole->field.width(), h = whole->field.height();
  ASSERT_EQ(read->field.width(), w);
  ASSERT_EQ(read->field.height(), h);
  EXPECT_GT(w, 3 * param.tile_texels) << "the canvas must be cut into several tiles each way";

  size_t state_differs = 0, far_from_border = 0, not_outline = 0;
  double max_measured = 0, max_filled = 0, max_normal = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const TexelState a = whole->field.state(x, y), b = read->field.state(x, y);
      const bool in_band = std::min({x, y, w - 1 - x, h - 1 - y}) < kBorderTexels;
      if (a != b) {
        ++state_differs;
        far_from_border += !in_band;
        not_outline += (a != TexelState::kOutside && b != TexelState::kOutside) ||
                       a == TexelState::kMeasured || b == TexelState::kMeasured;
        continue;
      }
      const double dh = std::abs(whole->field.height_mm(x, y) - read->field.height_mm(x, y));
      if (in_band && a != TexelState::kMeasured) continue;
      (a == TexelState::kMeasured ? max_measured : max_filled) =
          std::max(a == TexelState::kMeasured ? max_measured : max_filled, dh);
      if (in_band) continue;
      const double cosine =
          std::clamp(static_cast<double>(whole->normals(x, y).dot(read->normals(x, y))), -1.0, 1.0);
      max_normal = std::max(max_normal, std::acos(cosine) * 180.0 / kPi);
    }
  std::printf(
      "%s: %dx%d texels in tiles of %d: %zu states differ; max |dh| measured %.2g, filled "
      "%.2g mm; normals %.3f deg\n",
      param.name, w, h, param.tile_texels, state_differs, max_measured, max_filled, max_normal);
  EXPECT_EQ(far_from_border, 0u);
  EXPECT_EQ(not_outline, 0u);
  EXPECT_LE(state_differs, static_cast<size_t>(w + h)) << "a border texel's worth, at most";
  EXPECT_LE(max_measured, kMeasuredTolMm);
  EXPECT_LE(max_filled, kFilledTolMm);
  EXPECT_LE(max_normal, kNormalTolDeg);

  // The relief: the canvas's H and delta0, and the same boxes (cells, peaks).
  EXPECT_NEAR(read->delta0_mm, whole->relief.delta0_mm, kMeasuredTolMm);
  EXPECT_NEAR(read->max_height_mm, whole->relief.max_height_mm, kMeasuredTolMm);
  ASSERT_EQ(read->boxes.size(), whole->relief.boxes.size());
  EXPECT_FALSE(read->boxes.empty()) << "the default painting has impasto";
  size_t peaks_moved = 0;
  for (size_t i = 0; i < read->boxes.size(); ++i) {
    const ReliefBox &a = whole->relief.boxes[i], &b = read->boxes[i];
    ASSERT_EQ(a.x0, b.x0);
    ASSERT_EQ(a.y0, b.y0);
    ASSERT_EQ(a.width, b.width);
    ASSERT_EQ(a.height, b.height);
    EXPECT_NEAR(a.h_max_mm, b.h_max_mm, kMeasuredTolMm);
    peaks_moved += a.u_max != b.u_max || a.v_max != b.v_max;  // two texels within rounding
  }
  EXPECT_LE(peaks_moved, read->boxes.size() / 100 + 1);
  EXPECT_EQ(read->canvas_from_scan.rotation, whole->canvas.canvas_from_scan.rotation);
  EXPECT_EQ(result->resample.measured + result->resample.filled + result->resample.unfilled +
                result->resample.outside,
            static_cast<size_t>(w) * h);
}

INSTANTIATE_TEST_SUITE_P(
    Scans, PreprocessTiledEqualsWhole,
    ::testing::Values(TiledCase{"ortho_border_holes", synth::ScannerModel::kOrthographic, 10, 3, 3,
                                128},
                      TiledCase{"pinhole_rolled", synth::ScannerModel::kPinhole, 6, 2, 35, 96}),
    [](const ::testing::TestParamInfo<TiledCase>& info) { return std::string(info.param.name); });

// A canvas pass on every 4th sample: the frame is the strided scan's, so the texels are not the
// whole preprocess's; the result is held to the whole preprocess's accuracy targets against the
// generator's truth (preprocess_test.cpp: tilt 0.05 deg, mask IoU 0.995, height RMSE 2 sigma,
// every true relief texel in a box).
TEST_F(PreprocessTiled, StridedCanvasPassMeetsTheWholeAccuracyTargets) {
  synth::ScanSimOptions scan_options;
  scan_options.border_hole_blobs = 2;
  const synth::SyntheticScan scan = MakeScan(scan_options);
  synth::PaintingOptions p;
  p.resolution_px = synth::MatchedResolution(p, synth::FrameOptions{}, scan_options);
  const synth::Painting painting = synth::MakePainting(p);
  TiledPreprocessOptions tiled;
  tiled.tile_texels = 256;
  tiled.canvas_stride = 4;
  const fs::path out = Path("tiled");
  fs::create_directories(out);
  const PreprocessOptions options;
  auto result = PreprocessScanTiled(Path("scan.exr"), options, tiled, out, {"scan.exr"});
  ASSERT_TRUE(result.ok()) << result.error().message;
  auto read = ReadPreprocessOutputs(out);
  ASSERT_TRUE(read.ok()) << read.error().message;
  // What MeasureAccuracy reads, from the folder. The scan mask is not compared (the tiles
  // refine the strided one near the outline, sample by sample); the texels with height are.
  PreprocessResult measured = *result;
  measured.field = read->field;
  measured.normals = read->normals;
  measured.relief.boxes = read->boxes;
  measured.canvas.mask_scan = scan.canvas_mask_scan;
  const synth::PreprocessAccuracy a = synth::MeasureAccuracy(measured, painting, scan);
  auto whole = Preprocess(scan.exposures, options);
  ASSERT_TRUE(whole.ok()) << whole.error().message;
  const synth::PreprocessAccuracy b = synth::MeasureAccuracy(*whole, painting, scan);
  ASSERT_EQ(read->field.width(), whole->field.width());
  ASSERT_EQ(read->field.height(), whole->field.height());
  size_t with_height_differs = 0;
  for (size_t i = 0; i < read->field.state.size(); ++i)
    with_height_differs +=
        HasHeight(read->field.state.data[i]) != HasHeight(whole->field.state.data[i]);
  const double differs = static_cast<double>(with_height_differs) / read->field.state.size();
  std::printf(
      "stride 4: tilt %.4f deg, RMSE %.4f mm, normals median %.3f deg, relief uncovered "
      "%zu of %zu, texels with height in one only %.3f %%; whole: %.4f deg, %.4f mm, "
      "%.3f deg, %zu\n",
      a.normal_error_deg, a.height_rmse_mm, a.normals_median_deg, a.relief_texels_uncovered,
      a.relief_texels_true, 100 * differs, b.normal_error_deg, b.height_rmse_mm,
      b.normals_median_deg, b.relief_texels_uncovered);
  EXPECT_LE(a.normal_error_deg, 0.05);
  EXPECT_LE(a.height_rmse_mm, 2.0 * scan_options.noise_mm);
  EXPECT_LE(a.normals_median_deg, b.normals_median_deg * 1.05);
  EXPECT_GT(a.relief_texels_true, 0u);
  EXPECT_EQ(a.relief_texels_uncovered, 0u);
  // The outline band: a texel of a 0.6 mm grid along the border, at most (0.3 % here).
  EXPECT_LE(differs, 0.003);
}

// Bad input: a scan a tile cannot be read from alone (depth, one channel) is refused, naming
// the file, and the output folder is not made.
TEST_F(PreprocessTiled, RefusesADepthScanAndWritesNothing) {
  Grid<float> z(64, 48, 1000.f);
  ASSERT_TRUE(WriteFloatExr(Path("depth.exr"), z, "Z").ok());
  PreprocessFolderOptions o;
  o.scans = {Path("depth.exr").string()};
  o.read.pixel_pitch_mm = 0.5;
  o.tiled = TiledPreprocessOptions{};
  o.out = Path("canvas").string();
  auto r = PreprocessToFolder(o);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("depth.exr"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("3-channel"), std::string::npos) << r.error().message;
  EXPECT_FALSE(fs::exists(Path("canvas")));
  // Two scans (exposures) or a mask: refused before anything is read.
  o.scans.push_back(o.scans.front());
  r = PreprocessToFolder(o);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("one XYZ scan"), std::string::npos) << r.error().message;
  EXPECT_FALSE(fs::exists(Path("canvas")));
  TiledPreprocessOptions bad;
  bad.tile_texels = 8;
  EXPECT_FALSE(bad.Validate().ok());
}

}  // namespace
}  // namespace digitize
