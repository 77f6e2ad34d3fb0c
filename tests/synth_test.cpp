// data_synthetic: synthetic paintings, the scene, the simulated scan, ground-truth accuracy and
// the on-disk layout. Every check is against an analytic expectation or the generator's own
// ground truth; tolerances say where their size comes from.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <numeric>
#include <random>
#include <set>
#include <vector>

#include "digitize/image_io.h"
#include "digitize/scan_io.h"
#include "digitize_synth/ground_truth.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/scan_sim.h"
#include "digitize_synth/synth_io.h"
#include "test_support.h"

namespace digitize::synth {
namespace {

namespace fs = std::filesystem;

// Small, fast defaults for tests: a 200 x 150 mm canvas at 512 texels (pitch 0.39 mm).
PaintingOptions SmallPainting(uint64_t seed = 1) {
  PaintingOptions o;
  o.width_mm = 200;
  o.height_mm = 150;
  o.resolution_px = 512;
  o.seed = seed;
  return o;
}

ScanSimOptions SmallScan(uint64_t seed = 1) {
  ScanSimOptions o;
  o.width_px = 384;
  o.height_px = 320;
  o.seed = seed;
  return o;
}

// A perfectly clean scan: no noise, no losses.
ScanSimOptions CleanScan(ScanSimOptions o) {
  o.noise_mm = 0;
  o.dropout = 0;
  o.hole_blobs = 0;
  o.outliers = 0;
  return o;
}

template <class T>
bool SameBytes(const Grid<T>& a, const Grid<T>& b) {
  return a.width == b.width && a.height == b.height &&
         std::memcmp(a.data.data(), b.data.data(), a.data.size() * sizeof(T)) == 0;
}

// Bilinear truth height at canvas-frame (X, Y) (the grid convention of height_field.h).
double TruthHeightAt(const HeightField& f, double X, double Y) {
  Eigen::Vector2d t = f.TexelFromMm(X, Y);
  double tx = std::clamp(t.x(), 0.0, f.width() - 1.0),
         ty = std::clamp(t.y(), 0.0, f.height() - 1.0);
  int x0 = std::min(static_cast<int>(tx), f.width() - 2),
      y0 = std::min(static_cast<int>(ty), f.height() - 2);
  double fx = tx - x0, fy = ty - y0;
  const Grid<float>& h = f.height_mm;
  return (1 - fy) * ((1 - fx) * h(x0, y0) + fx * h(x0 + 1, y0)) +
         fy * ((1 - fx) * h(x0, y0 + 1) + fx * h(x0 + 1, y0 + 1));
}

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return std::nan("");
  size_t k = static_cast<size_t>(q * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

float MaxHeight(const Painting& p) {
  return *std::max_element(p.truth.height_mm.data.begin(), p.truth.height_mm.data.end());
}
float MinHeight(const Painting& p) {
  return *std::min_element(p.truth.height_mm.data.begin(), p.truth.height_mm.data.end());
}

// ---------------------------------------------------------------------------------------------
// Options

TEST(PaintingOptions, DefaultsAreValidAndBadValuesAreNamed) {
  EXPECT_TRUE(PaintingOptions{}.Validate().ok());
  PaintingOptions o;
  o.resolution_px = 32;
  Status s = o.Validate();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("resolution_px"), std::string::npos) << s.message();
  o.resolution_px = 16384;  // the largest: a 16k painting for the tiles bench (~13.5 GB)
  EXPECT_TRUE(o.Validate().ok()) << o.Validate().message();
  o.resolution_px = 16385;
  EXPECT_FALSE(o.Validate().ok());
  o = {};
  o.width_mm = -1;
  EXPECT_NE(o.Validate().message().find("width_mm"), std::string::npos);
  o = {};
  o.stroke_max_mm = 0.01;  // below stroke_min_mm
  EXPECT_NE(o.Validate().message().find("stroke_max_mm"), std::string::npos);
  o = {};
  o.region_count = 0;
  EXPECT_NE(o.Validate().message().find("region_count"), std::string::npos);
  o = {};
  o.crack_width_mm = std::nan("");
  EXPECT_FALSE(o.Validate().ok());
  EXPECT_THROW(MakePainting(o), InvariantError);
}

TEST(ScanSimOptions, DefaultsAreValidAndBadValuesAreNamed) {
  EXPECT_TRUE(ScanSimOptions{}.Validate().ok());
  EXPECT_TRUE(FrameOptions{}.Validate().ok());
  ScanSimOptions o;
  o.dropout = 1.5;
  EXPECT_NE(o.Validate().message().find("dropout"), std::string::npos);
  o = {};
  o.width_px = 0;
  EXPECT_NE(o.Validate().message().find("width_px"), std::string::npos);
  o = {};
  o.exposures = 0;
  EXPECT_NE(o.Validate().message().find("exposures"), std::string::npos);
  o = {};
  o.noise_mm = std::numeric_limits<double>::infinity();
  EXPECT_NE(o.Validate().message().find("noise_mm"), std::string::npos);
  FrameOptions f;
  f.raise_mm = 0;
  EXPECT_NE(f.Validate().message().find("raise_mm"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Painting

TEST(Painting, GridMatchesTheRequestedSizeAndResolution) {
  Painting p = MakePainting(SmallPainting());
  EXPECT_EQ(p.truth.width(), 512);
  EXPECT_EQ(p.truth.height(), 384);
  EXPECT_DOUBLE_EQ(p.truth.pitch_mm, 200.0 / 512);
  EXPECT_DOUBLE_EQ(p.width_mm, p.truth.width() * p.truth.pitch_mm);
  EXPECT_DOUBLE_EQ(p.height_mm, p.truth.height() * p.truth.pitch_mm);
  EXPECT_EQ(p.normals.width, 512);
  EXPECT_EQ(p.region.height, 384);
  for (TexelState s : p.truth.state.data) ASSERT_EQ(s, TexelState::kMeasured);

  PaintingOptions tall = SmallPainting();
  tall.width_mm = 100;
  tall.height_mm = 300;
  tall.resolution_px = 64;  // the smallest allowed
  Painting t = MakePainting(tall);
  EXPECT_EQ(t.truth.height(), 64);
  EXPECT_EQ(t.truth.width(), 21);  // round(100 / (300 / 64))
}

TEST(Painting, SameSeedSameDataOtherSeedOtherData) {
  Painting a = MakePainting(SmallPainting(7));
  Painting b = MakePainting(SmallPainting(7));
  EXPECT_TRUE(SameBytes(a.truth.height_mm, b.truth.height_mm));
  EXPECT_TRUE(SameBytes(a.normals, b.normals));
  EXPECT_TRUE(SameBytes(a.region, b.region));
  Painting c = MakePainting(SmallPainting(8));
  EXPECT_FALSE(SameBytes(a.truth.height_mm, c.truth.height_mm));
  EXPECT_FALSE(SameBytes(a.region, c.region));
}

TEST(Painting, EveryFeatureOffGivesAFlatCanvas) {
  PaintingOptions o = SmallPainting();
  o.weave = o.strokes = o.impasto = o.craquelure = false;
  Painting p = MakePainting(o);
  for (float h : p.truth.height_mm.data) ASSERT_EQ(h, 0.0f);
  for (const Vec3f& n : p.normals.data) ASSERT_EQ(n, Vec3f(0, 0, 1));
}

TEST(Painting, SwitchingOneFeatureOffLeavesTheOthersUnchanged) {
  // Each feature family draws from its own random stream.
  PaintingOptions with = SmallPainting();
  with.weave = with.craquelure = false;
  PaintingOptions without = with;
  without.impasto = false;
  PaintingOptions strokes_only = without;
  Painting a = MakePainting(with), b = MakePainting(strokes_only);
  size_t same = 0;
  for (size_t i = 0; i < a.truth.height_mm.size(); ++i)
    same += a.truth.height_mm.data[i] == b.truth.height_mm.data[i];
  // Impasto covers a minority of the canvas; everywhere else the strokes are bit-identical.
  EXPECT_GT(same, a.truth.height_mm.size() / 2);
  EXPECT_GT(MaxHeight(a), MaxHeight(b));
}

TEST(Painting, FeatureHeightsAreInTheirRanges) {
  PaintingOptions base = SmallPainting();
  base.weave = base.strokes = base.impasto = base.craquelure = false;

  PaintingOptions strokes = base;
  strokes.strokes = true;
  Painting s = MakePainting(strokes);
  // Ridges reach at most stroke_max (x 1.25 for bristle marks on top, x overlap of two strokes).
  EXPECT_GE(MinHeight(s), 0.0f);
  EXPECT_GT(MaxHeight(s), strokes.stroke_min_mm);
  EXPECT_LT(MaxHeight(s), 2 * 1.25 * strokes.stroke_max_mm);

  PaintingOptions impasto = base;
  impasto.impasto = true;
  Painting i = MakePainting(impasto);
  EXPECT_GE(MinHeight(i), 0.0f);
  EXPECT_GT(MaxHeight(i), 0.35 * impasto.impasto_max_mm);     // the lowest blob is 35 % of the max
  EXPECT_LT(MaxHeight(i), 2 * 1.4 * impasto.impasto_max_mm);  // knife pile-up, overlap

  PaintingOptions cracks = base;
  cracks.craquelure = true;
  cracks.width_mm = 100;
  cracks.height_mm = 75;
  cracks.resolution_px = 1024;  // pitch 0.1 mm: the 0.4 mm cracks keep most of their depth
  Painting c = MakePainting(cracks);
  EXPECT_LT(MinHeight(c), -0.5 * cracks.crack_depth_mm);
  EXPECT_GT(MinHeight(c), -1.01 * cracks.crack_depth_mm);
  EXPECT_LT(MaxHeight(c), 0.5 * cracks.crack_depth_mm);  // only the cupping lip is above 0
}

TEST(Painting, WeaveIsKeptWhenResolvedAndFadedWhenNot) {
  PaintingOptions o;
  o.weave = true;
  o.strokes = o.impasto = o.craquelure = false;
  o.width_mm = 40;
  o.height_mm = 30;
  o.resolution_px = 1024;  // pitch 0.039 mm: 25 texels per 1 mm period, above the 16 of the fade
  Painting fine = MakePainting(o);
  // Amplitude varies by +-20 % over the canvas (slow modulation) and the two terms add up.
  EXPECT_GT(MaxHeight(fine), 0.6 * o.weave_amplitude_mm);
  EXPECT_LT(MaxHeight(fine), 1.3 * o.weave_amplitude_mm);
  EXPECT_LT(MinHeight(fine), -0.5 * o.weave_amplitude_mm);

  o.width_mm = 400;
  o.height_mm = 300;
  o.resolution_px = 512;  // pitch 0.78 mm: fewer than 8 texels per period -> faded to zero
  Painting coarse = MakePainting(o);
  EXPECT_EQ(MaxHeight(coarse), 0.0f);
  EXPECT_EQ(MinHeight(coarse), 0.0f);
}

TEST(Painting, NormalsAreUnitUpwardAndMatchFiniteDifferences) {
  PaintingOptions o = SmallPainting();
  o.resolution_px = 1024;
  Painting p = MakePainting(o);
  const HeightField& f = p.truth;
  const double pitch = f.pitch_mm;
  std::vector<double> errors;
  for (int y = 0; y < f.height(); ++y) {
    for (int x = 0; x < f.width(); ++x) {
      const Vec3f& n = p.normals(x, y);
      ASSERT_NEAR(n.norm(), 1.0, 1e-5);
      ASSERT_GT(n.z(), 0.0f);
      if (x < 2 || y < 2 || x >= f.width() - 2 || y >= f.height() - 2) continue;
      // Central differences (rows go down: +Y is -row).
      auto h = [&](int xx, int yy) { return static_cast<double>(f.height_mm(xx, yy)); };
      double gx = (h(x + 1, y) - h(x - 1, y)) / (2 * pitch);
      double gy = (h(x, y - 1) - h(x, y + 1)) / (2 * pitch);
      // "Where smooth": the slope changes little over a texel (not on a band-limited wall).
      double curv = std::abs(h(x + 1, y) - 2 * h(x, y) + h(x - 1, y)) +
                    std::abs(h(x, y + 1) - 2 * h(x, y) + h(x, y - 1));
      if (curv / pitch > 0.02) continue;  // second difference of 0.02 mm/mm: a 1 deg turn/texel
      errors.push_back(AngleDeg(Vec3d(-gx, -gy, 1), n.cast<double>()));
    }
  }
  ASSERT_GT(errors.size(), f.height_mm.size() / 2);
  // Central differences are exact to O(pitch^2 h'''): on the band-limited surface that is a few
  // hundredths of a degree (measured: median 0.03, p99 0.29 deg); the tail is feature edges
  // (walls rise over >= 4 texels, ridges and cracks have sigma >= 2 texels).
  EXPECT_LT(Quantile(errors, 0.5), 0.05);
  EXPECT_LT(Quantile(errors, 0.99), 0.5);
}

TEST(Painting, RegionsAreBetweenZeroAndCountAndSeveralAppear) {
  PaintingOptions o = SmallPainting();
  o.region_count = 5;
  Painting p = MakePainting(o);
  std::set<int> seen;
  for (uint8_t r : p.region.data) {
    ASSERT_LT(r, 5);
    seen.insert(r);
  }
  EXPECT_GE(seen.size(), 3u);
}

// ---------------------------------------------------------------------------------------------
// Scene

TEST(Scene, RaysHitCanvasFrameAndWallWhereExpected) {
  Painting p = MakePainting(SmallPainting());
  FrameOptions frame;
  Scene scene(p, frame);
  const double cx = 0.5 * p.width_mm, cy = 0.5 * p.height_mm;
  std::vector<Vec3d> origins = {
      {cx, cy, 500},                      // canvas centre, straight down
      {-0.05 * frame.width_mm, cy, 500},  // the frame's sight edge (flat, raise_mm)
      {-frame.width_mm - 10, cy, 500},    // beyond the frame: the wall
      {cx, cy, 500},                      // pointing away: nothing
  };
  std::vector<Vec3d> dirs = {{0, 0, -1}, {0, 0, -2}, {0, 0, -1}, {0, 0, 1}};
  std::vector<Scene::RayHit> hits;
  scene.Intersect(origins, dirs, hits);
  ASSERT_EQ(hits.size(), 4u);
  EXPECT_EQ(hits[0].what, Scene::Hit::kCanvas);
  // Float geometry at 500 mm: a few 1e-5 mm of rounding.
  EXPECT_NEAR(hits[0].t, 500 - TruthHeightAt(p.truth, cx, cy), 2e-3);
  EXPECT_GT(hits[0].normal.z(), 0.5);
  EXPECT_EQ(hits[1].what, Scene::Hit::kFrame);
  EXPECT_NEAR(hits[1].t, 500 - frame.raise_mm, 1e-3);  // t is along the unit direction
  EXPECT_NEAR(hits[1].normal.z(), 1.0, 1e-6);
  EXPECT_EQ(hits[2].what, Scene::Hit::kWall);
  EXPECT_NEAR(hits[2].t, 500 + frame.wall_depth_mm, 1e-3);
  EXPECT_EQ(hits[3].what, Scene::Hit::kNone);

  // The sharp step: just inside the outline is canvas, just outside is frame top.
  std::vector<Vec3d> o2 = {{0.02, cy, 500}, {-0.02, cy, 500}};
  scene.Intersect(o2, {{0, 0, -1}, {0, 0, -1}}, hits);
  EXPECT_EQ(hits[0].what, Scene::Hit::kCanvas);
  EXPECT_EQ(hits[1].what, Scene::Hit::kFrame);
  EXPECT_NEAR(hits[1].t, 500 - frame.raise_mm, 1e-3);
}

TEST(Scene, WithoutFrameTheCanvasEdgeDropsToTheWall) {
  Painting p = MakePainting(SmallPainting());
  FrameOptions frame;
  frame.enabled = false;
  Scene scene(p, frame);
  std::vector<Scene::RayHit> hits;
  scene.Intersect({{-1, 10, 500}, {1, 10, 500}}, {{0, 0, -1}, {0, 0, -1}}, hits);
  EXPECT_EQ(hits[0].what, Scene::Hit::kWall);
  EXPECT_EQ(hits[1].what, Scene::Hit::kCanvas);
}

// Scans unlike the defaults (docs/refusals.md, "Scans"): per-side widths, bevel, lip, bow.

TEST(FrameOptions, NewShapeOptionsValidateAndNameTheOption) {
  FrameOptions f;
  EXPECT_TRUE(f.Validate().ok());
  f.left_mm = -1;
  EXPECT_NE(f.Validate().message().find("left_mm"), std::string::npos);
  f = FrameOptions{};
  f.top_mm = 20;
  f.bevel_width_mm = 25;  // wider than the narrowest side
  EXPECT_NE(f.Validate().message().find("bevel_width_mm"), std::string::npos);
  f = FrameOptions{};
  f.bevel_height_mm = f.raise_mm + 1;
  EXPECT_NE(f.Validate().message().find("bevel_height_mm"), std::string::npos);
  f = FrameOptions{};
  f.lip_mm = 5, f.lip_gap_mm = f.raise_mm;
  EXPECT_NE(f.Validate().message().find("lip_gap_mm"), std::string::npos);
  EXPECT_DOUBLE_EQ(FrameOptions{}.Width(2), FrameOptions{}.width_mm);
  PaintingOptions p;
  p.bow_mm = std::nan("");
  EXPECT_NE(p.Validate().message().find("bow_mm"), std::string::npos);
  ScanSimOptions s;
  s.border_hole_blobs = -1;
  EXPECT_NE(s.Validate().message().find("border_hole_blobs"), std::string::npos);
}

TEST(Scene, AsymmetricBevelledFrameAndLipAreWhereAsked) {
  Painting p = MakePainting(SmallPainting());
  const double cy = 0.5 * p.height_mm, W = p.width_mm;
  auto hit_down = [&](const Scene& scene, double x, double y) {
    std::vector<Scene::RayHit> hits;
    scene.Intersect({{x, y, 500}}, {{0, 0, -1}}, hits);
    return hits[0];
  };
  FrameOptions frame;
  frame.left_mm = 35, frame.right_mm = 50, frame.top_mm = 42, frame.bottom_mm = 60;
  frame.bevel_width_mm = 3, frame.bevel_height_mm = 3;
  const Scene scene(p, frame);
  EXPECT_EQ(hit_down(scene, -34, cy).what, Scene::Hit::kFrame);
  EXPECT_EQ(hit_down(scene, -36, cy).what, Scene::Hit::kWall);
  EXPECT_EQ(hit_down(scene, W + 49, cy).what, Scene::Hit::kFrame);
  EXPECT_EQ(hit_down(scene, W + 51, cy).what, Scene::Hit::kWall);
  EXPECT_EQ(hit_down(scene, 20, -59).what, Scene::Hit::kFrame);
  EXPECT_EQ(hit_down(scene, 20, p.height_mm + 43).what, Scene::Hit::kWall);
  // The 45 deg bevel: 1.5 mm out, 1.5 mm up (float geometry at 500 mm: 1e-3).
  const Scene::RayHit bevel = hit_down(scene, -1.5, cy);
  EXPECT_EQ(bevel.what, Scene::Hit::kFrame);
  EXPECT_NEAR(bevel.t, 500 - 1.5, 1e-3);
  EXPECT_NEAR(bevel.normal.z(), std::sqrt(0.5), 1e-4);

  FrameOptions lip;
  lip.lip_mm = 6;
  const Scene lipped(p, lip);
  const Scene::RayHit over = hit_down(lipped, 3, cy);
  EXPECT_EQ(over.what, Scene::Hit::kFrame);
  EXPECT_NEAR(over.t, 500 - lip.raise_mm, 1e-3);
  EXPECT_EQ(hit_down(lipped, 7, cy).what, Scene::Hit::kCanvas);
  // Under the lip the canvas goes on: a grazing ray below the underside reaches it.
  std::vector<Scene::RayHit> hits;
  lipped.Intersect({{8, cy, lip.lip_gap_mm - 1}}, {{-1, 0, -2}}, hits);  // lands at X = 4.5
  EXPECT_EQ(hits[0].what, Scene::Hit::kCanvas);
}

TEST(Painting, BowIsInTheTruthAndItsPlaneIsTheLeastSquaresOne) {
  PaintingOptions o = SmallPainting();
  o.weave = o.strokes = o.impasto = o.craquelure = false;
  o.bow_mm = -0.5;
  const Painting p = MakePainting(o);
  const HeightField& t = p.truth;
  EXPECT_NEAR(t.height_mm(t.width() / 2, t.height() / 2), -0.5, 1e-3);
  EXPECT_NEAR(t.height_mm(0, 0), 0, 0.02);  // half a texel in from the corner
  // The mean of (1 - u^2)(1 - v^2) over the square is (2/3)^2; symmetric: no slope.
  EXPECT_NEAR(p.bare_plane_offset_mm, -0.5 * 4.0 / 9.0, 2e-3);
  EXPECT_NEAR(p.bare_plane_normal.z(), 1.0, 1e-12);
  // Normals carry the bow's slope: at a quarter of the width, d/dX = bow (-2u)(2/W)(1 - v^2).
  const int x = t.width() / 4, y = t.height() / 2;
  const double X = (x + 0.5) * t.pitch_mm, u = 2 * X / p.width_mm - 1;
  const double Y = p.height_mm - (y + 0.5) * t.pitch_mm, v = 2 * Y / p.height_mm - 1;
  const double slope = -0.5 * (-2 * u) * (2 / p.width_mm) * (1 - v * v);
  EXPECT_NEAR(p.normals(x, y).x(), -slope, 1e-5);
}

TEST(Scan, BorderHolesLieOnTheCanvasOutline) {
  Painting p = MakePainting(SmallPainting());
  const Scene scene(p, FrameOptions{});
  ScanSimOptions o = CleanScan(SmallScan());
  o.border_hole_blobs = 12;
  const SyntheticScan s = SimulateScan(scene, o);
  const Grid<Vec3f>& xyz = s.exposures[0].xyz_mm;
  // Distance of every canvas pixel to the outline (pixels with a non-canvas 4-neighbour).
  const int w = xyz.width, h = xyz.height;
  size_t lost = 0, far = 0;
  const double reach = o.hole_blob_radius_px * 1.5 * 1.4 + 1;  // largest blob radius
  std::vector<std::pair<int, int>> outline;
  for (int y = 1; y + 1 < h; ++y)
    for (int x = 1; x + 1 < w; ++x)
      if (s.canvas_mask_scan(x, y) &&
          (!s.canvas_mask_scan(x - 1, y) || !s.canvas_mask_scan(x + 1, y) ||
           !s.canvas_mask_scan(x, y - 1) || !s.canvas_mask_scan(x, y + 1)))
        outline.emplace_back(x, y);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (!s.canvas_mask_scan(x, y) || IsValid(xyz(x, y))) continue;
      ++lost;
      double best = 1e9;
      for (const auto& [ox, oy] : outline) best = std::min(best, std::hypot(x - ox, y - oy));
      far += best > reach;
    }
  EXPECT_GT(lost, 100u);
  EXPECT_EQ(far, 0u);
  // The visible canvas's box: the whole canvas less the strip the tilted frame hides.
  EXPECT_LE(s.visible_max_mm.x() - s.visible_min_mm.x(), p.width_mm);
  EXPECT_GT(s.visible_max_mm.x() - s.visible_min_mm.x(), p.width_mm - 10);
}

// ---------------------------------------------------------------------------------------------
// Scan

TEST(Scan, SameSeedSameScanOtherSeedOtherNoise) {
  Painting p = MakePainting(SmallPainting());
  Scene scene(p, FrameOptions{});
  ScanSimOptions o = SmallScan(3);
  o.exposures = 2;
  SyntheticScan a = SimulateScan(scene, o), b = SimulateScan(scene, o);
  ASSERT_EQ(a.exposures.size(), 2u);
  for (size_t e = 0; e < 2; ++e)
    EXPECT_TRUE(SameBytes(a.exposures[e].xyz_mm, b.exposures[e].xyz_mm));
  EXPECT_TRUE(SameBytes(a.hit_scan, b.hit_scan));
  o.seed = 4;
  SyntheticScan c = SimulateScan(scene, o);
  EXPECT_FALSE(SameBytes(a.exposures[0].xyz_mm, c.exposures[0].xyz_mm));
  EXPECT_TRUE(SameBytes(a.hit_scan, c.hit_scan));  // the pose does not depend on the seed
}

TEST(Scan, UntiltedCanvasIsUprightInTheScanImage) {
  Painting p = MakePainting(SmallPainting());
  Scene scene(p, FrameOptions{});
  ScanSimOptions o = CleanScan(SmallScan());
  o.tilt_deg = o.roll_deg = 0;
  SyntheticScan s = SimulateScan(scene, o);
  Mat3d expected;
  expected << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  EXPECT_LT((s.canvas_from_scan.rotation - expected).norm(), 1e-12);
  // The canvas's top (high Y) is seen in the upper rows, its left (low X) in the left columns.
  double y_top = 0, y_bottom = 0, x_left = 0, x_right = 0;
  int n = 0;
  for (int x = 0; x < o.width_px; ++x) {
    int top = -1, bottom = -1;
    for (int y = 0; y < o.height_px; ++y)
      if (s.canvas_mask_scan(x, y)) {
        if (top < 0) top = y;
        bottom = y;
      }
    if (top < 0) continue;
    y_top += s.canvas_from_scan.Apply(s.exposures[0].xyz_mm(x, top).cast<double>()).y();
    y_bottom += s.canvas_from_scan.Apply(s.exposures[0].xyz_mm(x, bottom).cast<double>()).y();
    ++n;
  }
  ASSERT_GT(n, 0);
  EXPECT_NEAR(y_top / n, p.height_mm, 2 * s.pixel_pitch_mm);
  EXPECT_NEAR(y_bottom / n, 0, 2 * s.pixel_pitch_mm);
  int row = o.height_px / 2;
  int left = -1, right = -1;
  for (int x = 0; x < o.width_px; ++x)
    if (s.canvas_mask_scan(x, row)) {
      if (left < 0) left = x;
      right = x;
    }
  x_left = s.canvas_from_scan.Apply(s.exposures[0].xyz_mm(left, row).cast<double>()).x();
  x_right = s.canvas_from_scan.Apply(s.exposures[0].xyz_mm(right, row).cast<double>()).x();
  EXPECT_NEAR(x_left, 0, s.pixel_pitch_mm);
  EXPECT_NEAR(x_right, p.width_mm, s.pixel_pitch_mm);
}

TEST(Scan, OrthographicUntiltedCanvasOnlyScanSeesTheTrueHeights) {
  Painting p = MakePainting(SmallPainting());
  FrameOptions frame;
  frame.enabled = false;
  Scene scene(p, frame);
  ScanSimOptions o = CleanScan(SmallScan());
  o.tilt_deg = o.roll_deg = 0;
  o.field_margin = -0.1;  // crop into the canvas: only canvas in view
  o.width_px = 512;
  o.height_px = 384;
  SyntheticScan clean = SimulateScan(scene, o);
  o.noise_mm = 0.02;
  SyntheticScan noisy = SimulateScan(scene, o);
  std::vector<double> clean_err, noisy_err;
  for (int y = 0; y < o.height_px; ++y) {
    for (int x = 0; x < o.width_px; ++x) {
      ASSERT_EQ(clean.hit_scan(x, y), static_cast<uint8_t>(Scene::Hit::kCanvas));
      ASSERT_TRUE(IsValid(clean.exposures[0].xyz_mm(x, y)));
      Vec3d c = clean.canvas_from_scan.Apply(clean.exposures[0].xyz_mm(x, y).cast<double>());
      Vec3d n = noisy.canvas_from_scan.Apply(noisy.exposures[0].xyz_mm(x, y).cast<double>());
      double truth = TruthHeightAt(p.truth, c.x(), c.y());
      clean_err.push_back(c.z() - truth);
      noisy_err.push_back(n.z() - truth);
    }
  }
  // Noise-free: the scan lies on the triangulated grid; bilinear and triangle interpolation of
  // the same texels differ by a fraction of the relief's change over one texel (and float
  // coordinates at 1 m add ~1e-4 mm).
  EXPECT_LT(Quantile(clean_err, 0.5), 1e-3);
  std::vector<double> abs_clean(clean_err.size());
  std::transform(clean_err.begin(), clean_err.end(), abs_clean.begin(),
                 [](double e) { return std::abs(e); });
  EXPECT_LT(Quantile(abs_clean, 0.99), 0.02);
  // With noise: zero mean, sigma as asked (196k samples: 1 % on sigma is > 5 standard errors).
  double mean = std::accumulate(noisy_err.begin(), noisy_err.end(), 0.0) / noisy_err.size();
  double var = 0;
  for (size_t i = 0; i < noisy_err.size(); ++i) {
    double e = noisy_err[i] - clean_err[i];  // the noise alone
    var += e * e;
  }
  EXPECT_NEAR(mean, 0, 1e-3);
  EXPECT_NEAR(std::sqrt(var / noisy_err.size()), 0.02, 0.02 * 0.02);
}

TEST(Scan, MaskFractionsAndLossesArePlausible) {
  Painting p = MakePainting(SmallPainting());
  Scene scene(p, FrameOptions{});
  ScanSimOptions o = SmallScan();
  o.dropout = 0.3;
  o.hole_blobs = 0;
  o.outliers = 0.01;
  SyntheticScan s = SimulateScan(scene, o);
  std::map<int, size_t> hits;
  for (uint8_t h : s.hit_scan.data) ++hits[h];
  const double total = static_cast<double>(s.hit_scan.size());
  // Canvas 200 x 150 inside a 45 mm frame, field 1.25 x the footprint: canvas ~ 0.3 of the view.
  EXPECT_GT(hits[1] / total, 0.2);
  EXPECT_LT(hits[1] / total, 0.5);
  EXPECT_GT(hits[2] / total, 0.1);   // frame
  EXPECT_GT(hits[3] / total, 0.05);  // wall
  EXPECT_EQ(hits[0], 0u);            // the wall fills every view
  size_t mask = 0;
  for (size_t i = 0; i < s.hit_scan.size(); ++i) {
    ASSERT_EQ(s.canvas_mask_scan.data[i], s.hit_scan.data[i] == 1 ? 1 : 0);
    mask += s.canvas_mask_scan.data[i];
  }
  EXPECT_EQ(mask, hits[1]);
  // Dropouts and outliers: binomial on 123k samples, tolerances > 5 standard errors.
  size_t valid = 0, outliers = 0;
  ScanSimOptions clean_o = CleanScan(o);
  SyntheticScan clean = SimulateScan(scene, clean_o);
  for (size_t i = 0; i < s.hit_scan.size(); ++i) {
    const Vec3f& v = s.exposures[0].xyz_mm.data[i];
    if (!IsValid(v)) continue;
    ++valid;
    if ((v - clean.exposures[0].xyz_mm.data[i]).norm() > 1.5) ++outliers;
  }
  EXPECT_NEAR(valid / total, 0.7, 0.01);
  EXPECT_NEAR(outliers / static_cast<double>(valid), 0.01, 0.002);

  // Blob holes remove whole patches.
  ScanSimOptions holes = CleanScan(o);
  holes.hole_blobs = 20;
  holes.hole_blob_radius_px = 10;
  SyntheticScan h = SimulateScan(scene, holes);
  size_t missing = 0;
  for (const Vec3f& v : h.exposures[0].xyz_mm.data) missing += !IsValid(v);
  // 20 discs of radius 6..15 px (area ~ 20 x 350 px, overlaps and image border aside).
  EXPECT_GT(missing, 2000u);
  EXPECT_LT(missing, 20000u);
}

TEST(Scan, ExposuresDifferOnlyInNoiseAndLosses) {
  Painting p = MakePainting(SmallPainting());
  Scene scene(p, FrameOptions{});
  ScanSimOptions o = SmallScan();
  o.exposures = 3;
  o.noise_mm = 0.02;
  o.outliers = 0;
  o.dropout = 0.05;
  SyntheticScan s = SimulateScan(scene, o);
  ASSERT_EQ(s.exposures.size(), 3u);
  for (int a = 0; a < 3; ++a) {
    for (int b = a + 1; b < 3; ++b) {
      const auto& ea = s.exposures[a].xyz_mm.data;
      const auto& eb = s.exposures[b].xyz_mm.data;
      size_t both = 0, differ_valid = 0;
      double sum2 = 0, max_d = 0;
      for (size_t i = 0; i < ea.size(); ++i) {
        bool va = IsValid(ea[i]), vb = IsValid(eb[i]);
        differ_valid += va != vb;
        if (!(va && vb)) continue;
        ++both;
        // Same pose: the two samples lie on the same ray (orthographic: same X, Y).
        ASSERT_NEAR(ea[i].x(), eb[i].x(), 1e-4);
        ASSERT_NEAR(ea[i].y(), eb[i].y(), 1e-4);
        double d = ea[i].z() - eb[i].z();
        sum2 += d * d;
        max_d = std::max(max_d, std::abs(d));
      }
      EXPECT_GT(differ_valid, ea.size() / 20);  // each exposure loses its own samples
      // The difference of two independent N(0, s) is N(0, s sqrt 2); 100k samples.
      EXPECT_NEAR(std::sqrt(sum2 / both), 0.02 * std::sqrt(2.0), 0.002);
      EXPECT_LT(max_d, 0.02 * std::sqrt(2.0) * 6.5);  // no outliers asked for
    }
  }
}

TEST(Scan, PinholeSamplesLieOnTheirRays) {
  Painting p = MakePainting(SmallPainting());
  Scene scene(p, FrameOptions{});
  ScanSimOptions o = SmallScan();
  o.model = ScannerModel::kPinhole;
  o.outliers = 0.001;
  SyntheticScan s = SimulateScan(scene, o);
  ASSERT_GT(s.focal_px, 0);
  EXPECT_EQ(s.pixel_pitch_mm, 0);
  double worst_deg = 0;
  size_t canvas = 0;
  for (int y = 0; y < o.height_px; ++y) {
    for (int x = 0; x < o.width_px; ++x) {
      const Vec3f& v = s.exposures[0].xyz_mm(x, y);
      if (!IsValid(v)) continue;
      Vec3d ray((x + 0.5 - 0.5 * o.width_px) / s.focal_px,
                (y + 0.5 - 0.5 * o.height_px) / s.focal_px, 1);
      worst_deg = std::max(worst_deg, AngleDeg(ray, v.cast<double>()));
      canvas += s.canvas_mask_scan(x, y);
    }
  }
  // Float storage of points ~1 m away: 1e-4 mm / 1000 mm ~ 1e-5 deg.
  EXPECT_LT(worst_deg, 1e-4);
  EXPECT_GT(canvas, s.hit_scan.size() / 5);
}

TEST(Scan, TiltedPoseIsARotationWithTheAskedTilt) {
  Painting p = MakePainting(SmallPainting());
  Scene scene(p, FrameOptions{});
  for (double tilt : {0.0, 8.0, 30.0, 45.0}) {
    ScanSimOptions o = SmallScan();
    o.tilt_deg = tilt;
    o.tilt_axis_deg = 70;
    o.roll_deg = -12;
    SyntheticScan s = SimulateScan(scene, o);
    const Mat3d& r = s.canvas_from_scan.rotation;
    EXPECT_LT((r * r.transpose() - Mat3d::Identity()).norm(), 1e-12);
    EXPECT_NEAR(r.determinant(), 1.0, 1e-12);
    // The canvas normal (canvas +Z, row 2) against the direction back to the scanner (scan -Z).
    EXPECT_NEAR(AngleDeg(r.row(2).transpose(), Vec3d(0, 0, -1)), tilt, 1e-9);
    // The canvas centre is where the offset puts it.
    Vec3d centre =
        s.canvas_from_scan.Inverse().Apply(Vec3d(0.5 * p.width_mm, 0.5 * p.height_mm, 0));
    EXPECT_LT((centre - Vec3d(o.offset_mm.x(), o.offset_mm.y(), o.distance_mm)).norm(), 1e-9);
    size_t canvas = 0;
    for (uint8_t m : s.canvas_mask_scan.data) canvas += m;
    EXPECT_GT(canvas, s.hit_scan.size() / 8) << "tilt " << tilt;
    // The centre pixel sees the canvas.
    EXPECT_EQ(s.canvas_mask_scan(o.width_px / 2, o.height_px / 2), 1);
  }
}

TEST(Scan, NoFrameAndNegativeMarginFillsTheScanWithCanvas) {
  Painting p = MakePainting(SmallPainting());
  FrameOptions frame;
  frame.enabled = false;
  Scene scene(p, frame);
  ScanSimOptions o = SmallScan();
  // 25 % in from the footprint box: enough for the corners the 3 deg roll cuts off the box and
  // the (5, -3) mm offset of the default pose.
  o.field_margin = -0.25;
  SyntheticScan s = SimulateScan(scene, o);
  for (uint8_t m : s.canvas_mask_scan.data) ASSERT_EQ(m, 1);
}

TEST(Scan, TinyScansWork) {
  Painting p = MakePainting(SmallPainting());
  Scene scene(p, FrameOptions{});
  for (auto [w, h] : {std::pair{8, 8}, std::pair{1, 50}, std::pair{50, 1}, std::pair{1, 1}}) {
    ScanSimOptions o = SmallScan();
    o.width_px = w;
    o.height_px = h;
    SyntheticScan s = SimulateScan(scene, o);
    EXPECT_EQ(s.exposures[0].xyz_mm.width, w);
    EXPECT_EQ(s.exposures[0].xyz_mm.height, h);
    EXPECT_EQ(s.canvas_mask_scan.size(), static_cast<size_t>(w * h));
  }
}

// ---------------------------------------------------------------------------------------------
// Ground truth accuracy

// A "perfect" preprocessing result: the truth itself, with boxes over every 16 x 16 cell that
// holds a texel above 30 % of the max height.
PreprocessResult PerfectResult(const Painting& p, const SyntheticScan& s) {
  PreprocessResult r;
  r.canvas.mask_scan = s.canvas_mask_scan;
  r.canvas.canvas_from_scan = s.canvas_from_scan;
  r.field = p.truth;
  r.normals = p.normals;
  r.relief.max_height_mm = MaxHeight(p);
  r.relief.delta0_mm = 0.3 * r.relief.max_height_mm;
  r.relief.cell_px = 16;
  const int w = p.truth.width(), h = p.truth.height();
  for (int y0 = 0; y0 < h; y0 += 16) {
    for (int x0 = 0; x0 < w; x0 += 16) {
      ReliefBox box{x0, y0, std::min(16, w - x0), std::min(16, h - y0), 0.f, 0, 0};
      bool any = false;
      for (int y = y0; y < y0 + box.height; ++y)
        for (int x = x0; x < x0 + box.width; ++x)
          if (p.truth.height_mm(x, y) > r.relief.delta0_mm) any = true;
      if (any) r.relief.boxes.push_back(box);
    }
  }
  return r;
}

TEST(MeasureAccuracy, PerfectEstimateHasNoError) {
  Painting p = MakePainting(SmallPainting());
  Scene scene(p, FrameOptions{});
  SyntheticScan s = SimulateScan(scene, SmallScan());
  PreprocessResult r = PerfectResult(p, s);
  PreprocessAccuracy a = MeasureAccuracy(r, p, s);
  EXPECT_NEAR(a.normal_error_deg, 0, 1e-9);
  EXPECT_DOUBLE_EQ(a.mask_iou, 1.0);
  EXPECT_EQ(a.frame_pixels_kept, 0u);
  EXPECT_EQ(a.texels_compared, p.truth.height_mm.size());
  // Texel centres map onto texel centres: bilinear lookups return the stored values (the
  // rigid round trip adds ~1e-13 mm).
  EXPECT_LT(a.height_rmse_mm, 1e-6);
  EXPECT_LT(std::abs(a.height_offset_mm), 1e-6);
  EXPECT_LT(a.normals_median_deg, 1e-3);
  EXPECT_LT(a.normals_p90_deg, 1e-3);
  EXPECT_GT(a.relief_texels_true, 0u);
  EXPECT_EQ(a.relief_texels_uncovered, 0u);
  EXPECT_EQ(a.relief_texels_outside, 0u);

  // Without boxes all that relief is uncovered.
  r.relief.boxes.clear();
  PreprocessAccuracy none = MeasureAccuracy(r, p, s);
  EXPECT_EQ(none.relief_texels_uncovered, none.relief_texels_true);
}

TEST(MeasureAccuracy, ReportsOffsetsTiltsAndMaskErrors) {
  Painting p = MakePainting(SmallPainting());
  Scene scene(p, FrameOptions{});
  SyntheticScan s = SimulateScan(scene, SmallScan());

  // Heights 0.05 mm too high everywhere: an offset, no RMSE.
  PreprocessResult r = PerfectResult(p, s);
  for (float& h : r.field.height_mm.data) h += 0.05f;
  PreprocessAccuracy a = MeasureAccuracy(r, p, s);
  EXPECT_NEAR(a.height_offset_mm, 0.05, 1e-3);  // times n_z (~1 on most of the canvas)
  EXPECT_LT(a.height_rmse_mm, 2e-3);            // n_z < 1 on slopes scales the offset there

  // The estimated frame turned by 0.2 deg about its X axis.
  r = PerfectResult(p, s);
  RigidTransform turn;
  turn.rotation = Eigen::AngleAxisd(0.2 * M_PI / 180, Vec3d::UnitX()).toRotationMatrix();
  r.canvas.canvas_from_scan = turn * s.canvas_from_scan;
  a = MeasureAccuracy(r, p, s);
  EXPECT_NEAR(a.normal_error_deg, 0.2, 1e-9);
  // Heights are now compared on a plane tilted by 0.2 deg: up to ~0.5 mm over 150 mm.
  EXPECT_GT(a.height_rmse_mm, 0.05);

  // A mask that also takes the frame.
  r = PerfectResult(p, s);
  size_t frame_px = 0, canvas_px = 0;
  for (size_t i = 0; i < s.hit_scan.size(); ++i) {
    if (s.hit_scan.data[i] == static_cast<uint8_t>(Scene::Hit::kFrame)) {
      r.canvas.mask_scan.data[i] = 1;
      ++frame_px;
    }
    canvas_px += s.canvas_mask_scan.data[i];
  }
  a = MeasureAccuracy(r, p, s);
  EXPECT_EQ(a.frame_pixels_kept, frame_px);
  EXPECT_NEAR(a.mask_iou, static_cast<double>(canvas_px) / (canvas_px + frame_px), 1e-12);
}

TEST(MeasureAccuracy, EmptyEstimateGivesNaNNotZero) {
  Painting p = MakePainting(SmallPainting());
  Scene scene(p, FrameOptions{});
  SyntheticScan s = SimulateScan(scene, SmallScan());
  PreprocessResult r;  // nothing estimated
  PreprocessAccuracy a = MeasureAccuracy(r, p, s);
  EXPECT_EQ(a.texels_compared, 0u);
  EXPECT_TRUE(std::isnan(a.height_rmse_mm));
  EXPECT_TRUE(std::isnan(a.normals_median_deg));
  EXPECT_EQ(a.mask_iou, 0.0);
}

// ---------------------------------------------------------------------------------------------
// Files

class SynthIo : public test::ScratchDirTest {
 protected:
  SynthIo() : ScratchDirTest("digitize_synth_test", /*create=*/false) {}
};

TEST_F(SynthIo, WritesScanAndGroundTruthThatReadBack) {
  PaintingOptions po = SmallPainting();
  po.resolution_px = 128;
  Painting p = MakePainting(po);
  Scene scene(p, FrameOptions{});
  ScanSimOptions so = SmallScan();
  so.width_px = 96;
  so.height_px = 80;
  so.exposures = 2;
  SyntheticScan s = SimulateScan(scene, so);
  Status st = WriteSyntheticScan(dir_, p, s);
  ASSERT_TRUE(st.ok()) << st.message();
  for (const char* name :
       {"scan_0.exr", "scan_1.exr", "truth_height.exr", "truth_normals.exr", "truth_regions.png",
        "truth_mask_scan.png", "truth_hit_scan.png", "truth.json"})
    EXPECT_TRUE(fs::exists(dir_ / name)) << name;
  EXPECT_FALSE(fs::exists(dir_ / "scan.exr"));

  std::ifstream in(dir_ / "truth.json");
  nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j["format"], "digitize.synthetic_truth");
  EXPECT_EQ(j["canvas"]["width_px"], p.truth.width());
  EXPECT_DOUBLE_EQ(j["canvas"]["pitch_mm"].get<double>(), p.truth.pitch_mm);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c)
      EXPECT_DOUBLE_EQ(j["canvas_from_scan"]["matrix"][r][c].get<double>(),
                       s.canvas_from_scan.rotation(r, c));
    EXPECT_DOUBLE_EQ(j["canvas_from_scan"]["matrix"][r][3].get<double>(),
                     s.canvas_from_scan.translation(r));
  }
  EXPECT_EQ(j["painting_options"]["seed"], po.seed);
  EXPECT_EQ(j["scan_options"]["exposures"], 2);

  Result<FloatImage> height = ReadImage(dir_ / "truth_height.exr");
  ASSERT_TRUE(height.ok()) << height.error().message;
  ASSERT_EQ(height->width, p.truth.width());
  ASSERT_EQ(height->channels, 1);
  for (size_t i = 0; i < p.truth.height_mm.size(); ++i)
    ASSERT_EQ(height->pixels[i], p.truth.height_mm.data[i]);

  Result<Scan> scan = ReadScan(dir_ / "scan_1.exr", ScanReadOptions{});
  ASSERT_TRUE(scan.ok()) << scan.error().message;
  for (size_t i = 0; i < s.exposures[1].xyz_mm.size(); ++i) {
    const Vec3f& a = s.exposures[1].xyz_mm.data[i];
    const Vec3f& b = scan->xyz_mm.data[i];
    ASSERT_EQ(IsValid(a), IsValid(b));
    if (IsValid(a)) {
      ASSERT_EQ(a, b);
    }
  }

  Result<FloatImage> mask = ReadImage(dir_ / "truth_mask_scan.png");
  ASSERT_TRUE(mask.ok()) << mask.error().message;
  for (size_t i = 0; i < s.canvas_mask_scan.size(); ++i)
    ASSERT_EQ(mask->pixels[i] > 0.5f, s.canvas_mask_scan.data[i] != 0);
}

TEST_F(SynthIo, OneExposureIsScanExrAndAnUnwritableDirIsAnError) {
  PaintingOptions po = SmallPainting();
  po.resolution_px = 64;
  Painting p = MakePainting(po);
  Scene scene(p, FrameOptions{});
  ScanSimOptions so = SmallScan();
  so.width_px = so.height_px = 16;
  SyntheticScan s = SimulateScan(scene, so);
  ASSERT_TRUE(WriteSyntheticScan(dir_, p, s).ok());
  EXPECT_TRUE(fs::exists(dir_ / "scan.exr"));

  // A regular file where the directory should be.
  fs::path blocker = dir_ / "blocker";
  std::ofstream(blocker) << "x";
  Status st = WriteSyntheticScan(blocker / "out", p, s);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("blocker"), std::string::npos) << st.message();
}

}  // namespace
}  // namespace digitize::synth
