// Resampling onto the canvas grid (ResampleToCanvasGrid) on analytic surfaces with a known
// transform, and end to end on the synthetic generator with its ground truth.
#include "digitize/resample.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "digitize/canvas.h"
#include "digitize/preprocess.h"
#include "digitize/scan.h"
#include "digitize_synth/ground_truth.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/scan_sim.h"

namespace digitize {
namespace {

constexpr double kPi = 3.14159265358979323846;
using Surface = std::function<double(double, double)>;  // canvas-frame height at (X, Y), mm

// An orthographic scan of the surface Z = f(X, Y) over the canvas [0, W] x [0, H], seen with a
// tilt and a roll; the CanvasResult is the truth (transform, extent, mask of the rays that hit
// the canvas rectangle). Samples are exact (no noise) unless noise_mm > 0.
struct SurfaceScan {
  Scan scan;
  CanvasResult canvas;
  double pixel_mm = 0;
};

SurfaceScan MakeSurfaceScan(const Surface& f, int scan_w = 256, int scan_h = 200,
                            double tilt_deg = 10, double roll_deg = 7, double W = 100,
                            double H = 75, double noise_mm = 0) {
  SurfaceScan s;
  const double deg = kPi / 180;
  const Mat3d base = Vec3d(1, -1, -1).asDiagonal();
  RigidTransform scan_from_canvas;
  scan_from_canvas.rotation =
      Eigen::AngleAxisd(tilt_deg * deg, Vec3d(0.6, 0.8, 0)).toRotationMatrix() *
      Eigen::AngleAxisd(roll_deg * deg, Vec3d::UnitZ()).toRotationMatrix() * base;
  scan_from_canvas.translation =
      Vec3d(0, 0, 600) - scan_from_canvas.rotation * Vec3d(W / 2, H / 2, 0);
  const RigidTransform cfs = scan_from_canvas.Inverse();
  s.pixel_mm = 1.15 * std::max(W / scan_w, H / scan_h) * 1.2;
  s.scan.source = "surface.exr";
  s.scan.xyz_mm = Grid<Vec3f>(scan_w, scan_h, Vec3f::Constant(kMissing));
  s.canvas.mask_scan = Grid<uint8_t>(scan_w, scan_h, 0);
  s.canvas.canvas_from_scan = cfs;
  s.canvas.extent_mm = Eigen::Vector2d(W, H);
  const Vec3d d = cfs.rotation * Vec3d(0, 0, 1);
  uint64_t state = 12345;
  auto gauss = [&state]() {
    auto next = [&state]() {
      state = state * 6364136223846793005ull + 1442695040888963407ull;
      return (static_cast<double>(state >> 11) + 0.5) / 9007199254740992.0;
    };
    return std::sqrt(-2 * std::log(next())) * std::cos(2 * kPi * next());
  };
  for (int y = 0; y < scan_h; ++y)
    for (int x = 0; x < scan_w; ++x) {
      const Vec3d os((x - scan_w / 2.0 + 0.5) * s.pixel_mm, (y - scan_h / 2.0 + 0.5) * s.pixel_mm,
                     0);
      const Vec3d oc = cfs.Apply(os);
      double t = -oc.z() / d.z();
      for (int it = 0; it < 50; ++it) {
        const Vec3d p = oc + t * d;
        t = (f(p.x(), p.y()) - oc.z()) / d.z();
      }
      const Vec3d p = oc + t * d;
      if (p.x() < 0 || p.x() > W || p.y() < 0 || p.y() > H) continue;
      Vec3d ps = os + t * Vec3d(0, 0, 1);
      if (noise_mm > 0) ps.z() += noise_mm * gauss();
      s.scan.xyz_mm(x, y) = ps.cast<float>();
      s.canvas.mask_scan(x, y) = 1;
    }
  return s;
}

void ExpectWellFormed(const HeightField& field, const ResampleStats& stats) {
  ASSERT_EQ(field.height_mm.width, field.state.width);
  ASSERT_EQ(field.height_mm.height, field.state.height);
  EXPECT_GT(field.pitch_mm, 0);
  size_t counts[4] = {0, 0, 0, 0};
  for (size_t i = 0; i < field.height_mm.size(); ++i) {
    ASSERT_TRUE(std::isfinite(field.height_mm.data[i])) << "texel " << i;
    const TexelState st = field.state.data[i];
    ASSERT_LE(static_cast<int>(st), 3);
    ++counts[static_cast<int>(st)];
    if (st == TexelState::kOutside) {
      ASSERT_EQ(field.height_mm.data[i], 0.f);
    }
  }
  EXPECT_EQ(stats.texels, field.height_mm.size());
  EXPECT_EQ(stats.outside, counts[0]);
  EXPECT_EQ(stats.measured, counts[1]);
  EXPECT_EQ(stats.filled, counts[2]);
  EXPECT_EQ(stats.unfilled, counts[3]);
}

// ---------------------------------------------------------------------------------------------
// Options and errors

TEST(ResampleOptions, DefaultsValidateAndAbsurdValuesAreNamed) {
  EXPECT_TRUE(ResampleOptions{}.Validate().ok());
  struct Case {
    void (*set)(ResampleOptions&);
    const char* name;
  };
  const Case cases[] = {
      {[](ResampleOptions& o) { o.pitch_mm = -1; }, "pitch_mm"},
      {[](ResampleOptions& o) { o.pitch_mm = std::numeric_limits<double>::infinity(); },
       "pitch_mm"},
      {[](ResampleOptions& o) { o.max_edge_factor = 0; }, "max_edge_factor"},
      {[](ResampleOptions& o) { o.max_hole_area_mm2 = -4; }, "max_hole_area_mm2"},
      {[](ResampleOptions& o) { o.max_texels_per_side = 0; }, "max_texels_per_side"},
  };
  for (const Case& c : cases) {
    ResampleOptions o;
    c.set(o);
    const Status st = o.Validate();
    EXPECT_FALSE(st.ok()) << c.name;
    EXPECT_NE(st.message().find(c.name), std::string::npos) << st.message();
  }
}

TEST(ResampleToCanvasGrid, BadInputGivesClearErrors) {
  const SurfaceScan s = MakeSurfaceScan([](double, double) { return 0.0; }, 64, 48);
  auto expect_error = [&](const Scan& scan, const CanvasResult& canvas, const ResampleOptions& o,
                          const std::string& needle) {
    const Result<HeightField> r = ResampleToCanvasGrid(scan, canvas, o);
    ASSERT_FALSE(r.ok()) << needle;
    EXPECT_NE(r.error().message.find("surface.exr"), std::string::npos) << r.error().message;
    EXPECT_NE(r.error().message.find(needle), std::string::npos) << r.error().message;
  };
  ResampleOptions bad;
  bad.max_edge_factor = -1;
  expect_error(s.scan, s.canvas, bad, "max_edge_factor");
  CanvasResult wrong_size = s.canvas;
  wrong_size.mask_scan = Grid<uint8_t>(10, 10, 1);
  expect_error(s.scan, wrong_size, {}, "mask");
  CanvasResult skewed = s.canvas;
  skewed.canvas_from_scan.rotation(0, 1) += 0.5;
  expect_error(s.scan, skewed, {}, "rigid");
  CanvasResult no_canvas = s.canvas;
  no_canvas.mask_scan = Grid<uint8_t>(64, 48, 0);
  expect_error(s.scan, no_canvas, {}, "valid samples");
  ResampleOptions tiny_pitch;
  tiny_pitch.pitch_mm = 1e-4;  // a 100 mm canvas would need a million texels per side
  expect_error(s.scan, s.canvas, tiny_pitch, "max_texels_per_side");
  CanvasResult nan_extent = s.canvas;
  nan_extent.extent_mm.x() = std::nan("");
  expect_error(s.scan, nan_extent, {}, "extent");
}

// ---------------------------------------------------------------------------------------------
// Analytic surfaces

TEST(ResampleToCanvasGrid, ReproducesATiltedPlaneExactly) {
  // Linear interpolation is exact on a plane: every measured texel equals the plane at its
  // centre up to float rounding of coordinates near 600 mm (ulp 6e-5 mm): 2e-4 mm.
  const Surface plane = [](double X, double Y) { return 0.5 + 0.01 * X - 0.02 * Y; };
  const SurfaceScan s = MakeSurfaceScan(plane);
  ResampleStats stats;
  const Result<HeightField> r = ResampleToCanvasGrid(s.scan, s.canvas, ResampleOptions{}, &stats);
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectWellFormed(*r, stats);
  EXPECT_EQ(r->width(), static_cast<int>(std::ceil(100 / r->pitch_mm)));
  EXPECT_EQ(r->height(), static_cast<int>(std::ceil(75 / r->pitch_mm)));
  double max_err = 0;
  for (int y = 0; y < r->height(); ++y)
    for (int x = 0; x < r->width(); ++x) {
      if (r->state(x, y) != TexelState::kMeasured) continue;
      const Eigen::Vector2d c = r->TexelCentreMm(x, y);
      max_err = std::max(max_err, std::fabs(r->height_mm(x, y) - plane(c.x(), c.y())));
    }
  EXPECT_LT(max_err, 2e-4);
  // The canvas covers the grid but for a margin of half a sample around the mesh's outline.
  EXPECT_GT(stats.measured, 0.95 * stats.texels);
  EXPECT_EQ(stats.unfilled, 0u);
  EXPECT_EQ(stats.triangles_skipped, 0u);
  EXPECT_GT(stats.triangles_drawn, 0u);
}

TEST(ResampleToCanvasGrid, SmoothReliefWithinTheInterpolationError) {
  // Bumps of 2 mm with a 6 mm sigma sampled every ~0.6 mm: linear interpolation errs by at most
  // |h''| p^2 / 8 = (2 / 36) * 0.36 / 8 = 0.0025 mm; the bound allows 4x.
  const Surface bumps = [](double X, double Y) {
    auto g = [](double dx, double dy) { return std::exp(-(dx * dx + dy * dy) / (2 * 36.0)); };
    return 2.0 * g(X - 30, Y - 40) + 1.5 * g(X - 70, Y - 20) + 0.03 * std::sin(X) * std::cos(Y);
  };
  const SurfaceScan s = MakeSurfaceScan(bumps, 200, 160, 20, -4);
  ResampleStats stats;
  const Result<HeightField> r = ResampleToCanvasGrid(s.scan, s.canvas, ResampleOptions{}, &stats);
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectWellFormed(*r, stats);
  double sum2 = 0;
  size_t n = 0;
  for (int y = 0; y < r->height(); ++y)
    for (int x = 0; x < r->width(); ++x) {
      if (r->state(x, y) != TexelState::kMeasured) continue;
      const Eigen::Vector2d c = r->TexelCentreMm(x, y);
      const double e = r->height_mm(x, y) - bumps(c.x(), c.y());
      sum2 += e * e;
      ++n;
    }
  ASSERT_GT(n, 0u);
  EXPECT_LT(std::sqrt(sum2 / n), 0.01);
}

TEST(ResampleToCanvasGrid, PitchFromTheScanSpacingOrGiven) {
  const SurfaceScan s = MakeSurfaceScan([](double, double) { return 0.0; }, 128, 100, 0, 0);
  const Result<HeightField> automatic = ResampleToCanvasGrid(s.scan, s.canvas, ResampleOptions{});
  ASSERT_TRUE(automatic.ok()) << automatic.error().message;
  // Untilted, unrolled: horizontally adjacent samples are exactly one scan pixel apart.
  EXPECT_NEAR(automatic->pitch_mm, s.pixel_mm, 1e-4);
  ResampleOptions o;
  o.pitch_mm = 0.37;
  const Result<HeightField> given = ResampleToCanvasGrid(s.scan, s.canvas, o);
  ASSERT_TRUE(given.ok()) << given.error().message;
  EXPECT_EQ(given->pitch_mm, 0.37);
  EXPECT_EQ(given->width(), static_cast<int>(std::ceil(100 / 0.37)));
  EXPECT_EQ(given->height(), static_cast<int>(std::ceil(75 / 0.37)));
  // A much finer output pitch still draws every triangle (edges are judged against the scan's
  // own spacing too).
  ResampleOptions fine;
  fine.pitch_mm = s.pixel_mm / 10;
  ResampleStats stats;
  const Result<HeightField> r = ResampleToCanvasGrid(s.scan, s.canvas, fine, &stats);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(stats.triangles_skipped, 0u);
  EXPECT_GT(stats.measured, 0.9 * stats.texels);
}

TEST(ResampleToCanvasGrid, SmallHolesFilledLargeHolesReported) {
  const Surface plane = [](double X, double Y) { return 0.2 + 0.005 * X + 0.003 * Y; };
  SurfaceScan s = MakeSurfaceScan(plane, 256, 200, 5, 3);
  // A 1-sample hole (filled) and a disc of radius 12 samples (hundreds of mm^2: unfilled).
  const int sx = 70, sy = 60, bx = 170, by = 120;
  s.scan.xyz_mm(sx, sy) = Vec3f::Constant(kMissing);
  for (int y = by - 12; y <= by + 12; ++y)
    for (int x = bx - 12; x <= bx + 12; ++x)
      if ((x - bx) * (x - bx) + (y - by) * (y - by) <= 144)
        s.scan.xyz_mm(x, y) = Vec3f::Constant(kMissing);
  ASSERT_TRUE(s.canvas.mask_scan(sx, sy) && s.canvas.mask_scan(bx, by));
  ResampleStats stats;
  const Result<HeightField> r = ResampleToCanvasGrid(s.scan, s.canvas, ResampleOptions{}, &stats);
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectWellFormed(*r, stats);
  EXPECT_EQ(stats.holes_unfilled, 1u);
  EXPECT_GE(stats.holes_filled, 1u);
  // A missing sample's canvas position: the mean of the valid samples `reach` away on its row.
  auto texel_of_missing = [&](int x, int y, int reach) {
    const Vec3f mid = 0.5f * (s.scan.xyz_mm(x - reach, y) + s.scan.xyz_mm(x + reach, y));
    const Vec3d c = s.canvas.canvas_from_scan.Apply(mid.cast<double>());
    const Eigen::Vector2d t = r->TexelFromMm(c.x(), c.y());
    return Eigen::Vector2i(static_cast<int>(std::lround(t.x())),
                           static_cast<int>(std::lround(t.y())));
  };
  const Eigen::Vector2i small = texel_of_missing(sx, sy, 1);
  EXPECT_EQ(r->state(small.x(), small.y()), TexelState::kFilled);
  const Eigen::Vector2i big = texel_of_missing(bx, by, 13);
  EXPECT_EQ(r->state(big.x(), big.y()), TexelState::kUnfilled);
  // The membrane fill of a plane is the plane (harmonic); the relaxation leaves a little, and
  // the large hole gets only a few iterations: 0.01 mm.
  double max_fill_err = 0;
  for (int y = 0; y < r->height(); ++y)
    for (int x = 0; x < r->width(); ++x) {
      const TexelState st = r->state(x, y);
      if (st != TexelState::kFilled && st != TexelState::kUnfilled) continue;
      const Eigen::Vector2d c = r->TexelCentreMm(x, y);
      max_fill_err = std::max(max_fill_err, std::fabs(r->height_mm(x, y) - plane(c.x(), c.y())));
    }
  EXPECT_GT(stats.filled, 0u);
  EXPECT_GT(stats.unfilled, 100u);
  EXPECT_LT(max_fill_err, 0.01);
}

// find_holes = false (the registration's fixed surface): the measured texels as the full
// resample has them, bit for bit, every other texel outside at height 0, no hole filled.
TEST(ResampleToCanvasGrid, WithoutHoleSearchMeasuredTexelsAreUnchanged) {
  const Surface plane = [](double X, double Y) { return 0.2 + 0.005 * X + 0.003 * Y; };
  SurfaceScan s = MakeSurfaceScan(plane, 256, 200, 5, 3);
  for (int y = 100; y < 110; ++y)
    for (int x = 60; x < 75; ++x) s.scan.xyz_mm(x, y) = Vec3f::Constant(kMissing);
  ResampleStats full_stats, bare_stats;
  const Result<HeightField> full =
      ResampleToCanvasGrid(s.scan, s.canvas, ResampleOptions{}, &full_stats);
  ResampleOptions bare_options;
  bare_options.find_holes = false;
  const Result<HeightField> bare =
      ResampleToCanvasGrid(s.scan, s.canvas, bare_options, &bare_stats);
  ASSERT_TRUE(full.ok() && bare.ok());
  ASSERT_EQ(full->width(), bare->width());
  ASSERT_EQ(full->height(), bare->height());
  ASSERT_GT(full_stats.filled, 0u);  // the case has a hole the full resample fills
  size_t measured = 0;
  for (int y = 0; y < full->height(); ++y)
    for (int x = 0; x < full->width(); ++x) {
      if (full->state(x, y) == TexelState::kMeasured) {
        ++measured;
        EXPECT_EQ(bare->state(x, y), TexelState::kMeasured);
        EXPECT_EQ(bare->height_mm(x, y), full->height_mm(x, y));
      } else {
        EXPECT_EQ(bare->state(x, y), TexelState::kOutside);
        EXPECT_EQ(bare->height_mm(x, y), 0.0f);
      }
    }
  EXPECT_EQ(bare_stats.measured, measured);
  EXPECT_EQ(bare_stats.filled + bare_stats.unfilled + bare_stats.holes_filled, 0u);
  EXPECT_EQ(bare_stats.measured + bare_stats.outside, bare_stats.texels);
}

TEST(ResampleToCanvasGrid, OutsideTexelsAreZeroAndRollLeavesCornersOutside) {
  const SurfaceScan s = MakeSurfaceScan([](double, double) { return 1.0; }, 200, 160, 8, 20);
  // The truth extent is the canvas itself; roll does not change it (canvas frame), so to get
  // outside corners, widen the extent beyond the canvas.
  CanvasResult wide = s.canvas;
  wide.extent_mm = Eigen::Vector2d(110, 85);
  ResampleStats stats;
  const Result<HeightField> r = ResampleToCanvasGrid(s.scan, wide, ResampleOptions{}, &stats);
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectWellFormed(*r, stats);
  EXPECT_GT(stats.outside, 0u);
  EXPECT_EQ(r->state(r->width() - 1, 0), TexelState::kOutside);  // beyond X = 100, Y = 75
  EXPECT_EQ(r->height_mm(r->width() - 1, 0), 0.f);
}

TEST(ResampleToCanvasGrid, StepsAreNotBridged) {
  // Two plateaus 10 mm apart: the triangles across the step have edges of 10 mm, far beyond
  // 4 pitches (~2.6 mm), and are skipped; no measured texel lies between the plateaus.
  const Surface step = [](double X, double) { return X < 50 ? 0.0 : 10.0; };
  const SurfaceScan s = MakeSurfaceScan(step, 256, 200, 0, 3);
  ResampleStats stats;
  const Result<HeightField> r = ResampleToCanvasGrid(s.scan, s.canvas, ResampleOptions{}, &stats);
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectWellFormed(*r, stats);
  EXPECT_GT(stats.triangles_skipped, 0u);
  for (int y = 0; y < r->height(); ++y)
    for (int x = 0; x < r->width(); ++x)
      if (r->state(x, y) == TexelState::kMeasured) {
        const float h = r->height_mm(x, y);
        ASSERT_TRUE(std::fabs(h) < 1e-3 || std::fabs(h - 10) < 1e-3) << x << "," << y << ": " << h;
      }
}

TEST(ResampleToCanvasGrid, OverlapsKeepTheHighestSurface) {
  // Scan frame = canvas frame. Three columns fold back: X = 0, 2, 1 at Z = 0, 0, 1. Over
  // X in [1, 2] the fold (height 2 - X) lies above the first quad (height 0).
  Scan scan;
  scan.source = "fold";
  scan.xyz_mm = Grid<Vec3f>(3, 2, Vec3f::Zero());
  const float xs[3] = {0, 2, 1}, zs[3] = {0, 0, 1};
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 3; ++x) scan.xyz_mm(x, y) = Vec3f(xs[x], 1.0f - y, zs[x]);
  CanvasResult canvas;
  canvas.mask_scan = Grid<uint8_t>(3, 2, 1);
  canvas.extent_mm = Eigen::Vector2d(2, 1);
  ResampleOptions o;
  o.pitch_mm = 0.25;
  ResampleStats stats;
  const Result<HeightField> r = ResampleToCanvasGrid(scan, canvas, o, &stats);
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectWellFormed(*r, stats);
  ASSERT_EQ(r->width(), 8);
  ASSERT_EQ(r->height(), 4);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 8; ++x) {
      ASSERT_EQ(r->state(x, y), TexelState::kMeasured) << x << "," << y;
      const double X = r->TexelCentreMm(x, y).x();
      EXPECT_NEAR(r->height_mm(x, y), X < 1 ? 0.0 : 2 - X, 1e-5) << x << "," << y;
    }
}

TEST(ResampleToCanvasGrid, GarbageInsideTheMaskNeverReachesTheOutput) {
  SurfaceScan s = MakeSurfaceScan([](double X, double) { return 0.01 * X; }, 128, 100);
  const float inf = std::numeric_limits<float>::infinity();
  int k = 0;
  for (int y = 10; y < 90; y += 7)
    for (int x = 10; x < 118; x += 11, ++k) {
      if (!s.canvas.mask_scan(x, y)) continue;
      s.scan.xyz_mm(x, y) = k % 3 == 0   ? Vec3f(inf, 0, 0)
                            : k % 3 == 1 ? Vec3f(1e30f, 1e30f, 1e30f)
                                         : Vec3f(kMissing, 0, 600);
    }
  ResampleStats stats;
  const Result<HeightField> r = ResampleToCanvasGrid(s.scan, s.canvas, ResampleOptions{}, &stats);
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectWellFormed(*r, stats);
  EXPECT_GT(stats.filled, 0u);
}

TEST(ResampleToCanvasGrid, TinyScans) {
  // 8 x 8 samples: a small grid, no crash, no NaN.
  const SurfaceScan s = MakeSurfaceScan([](double, double) { return 0.0; }, 8, 8, 0, 0, 10, 10);
  ResampleStats stats;
  const Result<HeightField> r = ResampleToCanvasGrid(s.scan, s.canvas, ResampleOptions{}, &stats);
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectWellFormed(*r, stats);
  EXPECT_GT(stats.measured, 0u);
  // One row: no quad, no triangle: a clear error.
  Scan line;
  line.source = "line.exr";
  line.xyz_mm = Grid<Vec3f>(50, 1, Vec3f::Zero());
  for (int x = 0; x < 50; ++x) line.xyz_mm(x, 0) = Vec3f(0.5f * x, 0, 500);
  CanvasResult canvas;
  canvas.mask_scan = Grid<uint8_t>(50, 1, 1);
  canvas.extent_mm = Eigen::Vector2d(24.5, 0);
  canvas.canvas_from_scan.rotation = Vec3d(1, -1, -1).asDiagonal();
  canvas.canvas_from_scan.translation = Vec3d(0, 0, 500);
  const Result<HeightField> l = ResampleToCanvasGrid(line, canvas, ResampleOptions{});
  ASSERT_FALSE(l.ok());
  EXPECT_NE(l.error().message.find("line.exr"), std::string::npos) << l.error().message;
}

// ---------------------------------------------------------------------------------------------
// End to end on the synthetic generator: sanitise, extract the canvas, resample, compare with
// the true surface (synth::MeasureAccuracy: RMS along the true normal, constant offset removed).

struct SynthOutcome {
  synth::PreprocessAccuracy accuracy;
  double canvas_s = 0, resample_s = 0;
  ResampleStats stats;
};

SynthOutcome RunSynthetic(const synth::PaintingOptions& po, const synth::ScanSimOptions& so) {
  const synth::Painting painting = synth::MakePainting(po);
  const synth::Scene scene(painting, synth::FrameOptions{});
  const synth::SyntheticScan truth = synth::SimulateScan(scene, so);
  Scan scan = truth.exposures.at(0);
  SanitizeScan(scan, SanitizeOptions{});
  SynthOutcome out;
  const auto t0 = std::chrono::steady_clock::now();
  Result<CanvasResult> canvas = ExtractCanvas(scan, CanvasOptions{});
  const auto t1 = std::chrono::steady_clock::now();
  EXPECT_TRUE(canvas.ok()) << canvas.error().message;
  if (!canvas.ok()) return out;
  Result<HeightField> field = ResampleToCanvasGrid(scan, *canvas, ResampleOptions{}, &out.stats);
  const auto t2 = std::chrono::steady_clock::now();
  EXPECT_TRUE(field.ok()) << field.error().message;
  if (!field.ok()) return out;
  ExpectWellFormed(*field, out.stats);
  PreprocessResult result;
  result.canvas = std::move(canvas).value();
  result.field = std::move(field).value();
  out.accuracy = synth::MeasureAccuracy(result, painting, truth);
  out.canvas_s = std::chrono::duration<double>(t1 - t0).count();
  out.resample_s = std::chrono::duration<double>(t2 - t1).count();
  std::printf(
      "synthetic %dx%d scan of a %d px painting, noise %.3f mm: normal %.4f deg, IoU %.5f, "
      "frame px kept %zu, height RMSE %.4f mm over %zu texels (%zu filled, %zu unfilled); "
      "canvas %.3f s, resample %.3f s\n",
      so.width_px, so.height_px, po.resolution_px, so.noise_mm, out.accuracy.normal_error_deg,
      out.accuracy.mask_iou, out.accuracy.frame_pixels_kept, out.accuracy.height_rmse_mm,
      out.accuracy.texels_compared, out.stats.filled, out.stats.unfilled, out.canvas_s,
      out.resample_s);
  return out;
}

TEST(ResampleSynthetic, HeightRmseWithinTwiceTheNoise) {
  // The scan must resolve the painting: features are band-limited to 8 painting texels
  // (3.1 mm at 1024 px over 400 mm) and a 1024^2 scan samples every 0.6 mm, so interpolation
  // adds far less than the noise. Target: RMSE <= 2 sigma.
  synth::PaintingOptions po;
  po.resolution_px = 1024;
  synth::ScanSimOptions so;
  so.width_px = so.height_px = 1024;
  const SynthOutcome out = RunSynthetic(po, so);
  EXPECT_LT(out.accuracy.normal_error_deg, 0.05);
  EXPECT_GE(out.accuracy.mask_iou, 0.995);
  EXPECT_LE(out.accuracy.height_rmse_mm, 2 * so.noise_mm);
  EXPECT_GT(out.accuracy.texels_compared, 100000u);
}

TEST(ResampleSynthetic, HeavyNoiseAndHoles) {
  synth::PaintingOptions po;
  po.resolution_px = 512;
  synth::ScanSimOptions so;
  so.noise_mm = 0.2;
  so.dropout = 0.3;
  so.hole_blobs = 8;
  const SynthOutcome out = RunSynthetic(po, so);
  EXPECT_LT(out.accuracy.normal_error_deg, 0.05);
  // Interpolating noisy samples averages them a little: the RMSE stays below the noise.
  EXPECT_LE(out.accuracy.height_rmse_mm, so.noise_mm);
  EXPECT_GT(out.stats.filled, 0u);
}

}  // namespace
}  // namespace digitize
