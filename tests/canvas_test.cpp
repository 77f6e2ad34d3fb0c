// Canvas extraction (ExtractCanvas, FitPlanePca) against analytic scans with a known transform
// and against the synthetic generator's ground truth.
#include "digitize/canvas.h"

#include <gtest/gtest.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "digitize/scan.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/scan_sim.h"

namespace digitize {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Accuracy targets (docs/architecture.md, "Stages of preprocess").
constexpr double kMaxNormalErrorDeg = 0.05;
constexpr double kMinIoU = 0.995;
// A frame wall seen obliquely meets the canvas in a sample whose hit on the wall may lie any
// height above the canvas, down to zero: the lowest of these "wall feet" are indistinguishable
// from canvas samples. None may be kept unless it lies within this distance of the canvas plane
// (a few noise sigmas: the refinement's tight tolerance is 2 sqrt(6) sigma + 0.06 mm).
constexpr double kMaxKeptFootHeightMm = 0.25;

// ---------------------------------------------------------------------------------------------
// An analytic framed painting scanned orthographically: canvas [0, W] x [0, H] at Z = relief(X, Y)
// (smooth Gaussian bumps + ripple), a frame of four boxes around it (vertical inner faces from
// the wall up to the frame top) and a wall plane, all in the canvas frame; rays along scan +Z.

enum Hit : uint8_t { kNone = 0, kCanvasHit = 1, kFrameHit = 2, kWallHit = 3 };

struct SceneOptions {
  double canvas_w = 400, canvas_h = 300;  // mm
  bool frame = true;
  double frame_raise = 25, frame_width = 45, wall_depth = 20;  // mm
  int bumps = 12;
  double bump_height = 2.0, bump_sigma = 6.0;  // mm
  double ripple = 0.05, ripple_period = 8.0;   // mm
  int scan_w = 512, scan_h = 512;
  double field_scale = 1.25;  // field = (canvas + frame) * scale
  double tilt_deg = 8, tilt_axis_deg = 30, roll_deg = 3;
  double off_x = 5, off_y = -3;  // canvas centre in the scan frame (mm)
  double distance = 1000;
  double noise = 0.0;    // Gaussian sigma along the ray (mm)
  double dropout = 0.0;  // share of samples lost at random
  int hole_blobs = 0;
  double hole_radius_px = 6;
  uint32_t seed = 1;
};

struct AnalyticScan {
  Scan scan;
  RigidTransform canvas_from_scan;  // truth: origin at the canvas corner, Z = 0 the base plane
  Grid<uint8_t> hit;
  double pixel_mm = 0;
  SceneOptions o;
  std::vector<Vec3d> bumps;  // x, y, height

  double Relief(double x, double y) const {
    double h = o.ripple * std::sin(2 * kPi * x / o.ripple_period) *
               std::sin(2 * kPi * y / o.ripple_period);
    for (const Vec3d& b : bumps) {
      const double dx = x - b.x(), dy = y - b.y();
      h += b.z() * std::exp(-(dx * dx + dy * dy) / (2 * o.bump_sigma * o.bump_sigma));
    }
    return h;
  }
  // Height of a scan sample above the true canvas base plane.
  double TrueHeight(const Vec3f& p) const { return canvas_from_scan.Apply(p.cast<double>()).z(); }
};

bool RayBox(const Vec3d& o, const Vec3d& d, const Vec3d& lo, const Vec3d& hi, double* t) {
  double t0 = -1e300, t1 = 1e300;
  for (int a = 0; a < 3; ++a) {
    if (std::fabs(d[a]) < 1e-15) {
      if (o[a] < lo[a] || o[a] > hi[a]) return false;
      continue;
    }
    double ta = (lo[a] - o[a]) / d[a], tb = (hi[a] - o[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  if (t0 > t1 || t1 < 0) return false;
  *t = std::max(t0, 0.0);
  return true;
}

// Deterministic per-pixel random numbers, independent of the thread schedule.
double Uniform(uint64_t key) {
  key += 0x9e3779b97f4a7c15ull;
  key = (key ^ (key >> 30)) * 0xbf58476d1ce4e5b9ull;
  key = (key ^ (key >> 27)) * 0x94d049bb133111ebull;
  key ^= key >> 31;
  return (static_cast<double>(key >> 11) + 0.5) / 9007199254740992.0;
}
double Gaussian(uint64_t key) {
  return std::sqrt(-2 * std::log(Uniform(2 * key))) * std::cos(2 * kPi * Uniform(2 * key + 1));
}

AnalyticScan MakeAnalyticScan(const SceneOptions& o) {
  AnalyticScan s;
  s.o = o;
  std::mt19937 rng(o.seed);
  std::uniform_real_distribution<double> u01(0, 1);
  for (int i = 0; i < o.bumps; ++i)
    s.bumps.emplace_back(20 + u01(rng) * (o.canvas_w - 40), 20 + u01(rng) * (o.canvas_h - 40),
                         o.bump_height * (0.3 + 0.7 * u01(rng)));
  const double deg = kPi / 180;
  const Mat3d base = Vec3d(1, -1, -1).asDiagonal();  // canvas top at scan row 0, Z to the scanner
  const Eigen::AngleAxisd roll(o.roll_deg * deg, Vec3d::UnitZ());
  const Vec3d axis(std::cos(o.tilt_axis_deg * deg), std::sin(o.tilt_axis_deg * deg), 0);
  const Eigen::AngleAxisd tilt(o.tilt_deg * deg, axis);
  RigidTransform scan_from_canvas;
  scan_from_canvas.rotation = tilt.toRotationMatrix() * roll.toRotationMatrix() * base;
  scan_from_canvas.translation =
      Vec3d(o.off_x, o.off_y, o.distance) -
      scan_from_canvas.rotation * Vec3d(o.canvas_w / 2, o.canvas_h / 2, 0);
  s.canvas_from_scan = scan_from_canvas.Inverse();
  const double fw = (o.canvas_w + 2 * o.frame_width) * o.field_scale;
  const double fh = (o.canvas_h + 2 * o.frame_width) * o.field_scale;
  s.pixel_mm = std::max(fw / o.scan_w, fh / o.scan_h);
  s.scan.source = "analytic.exr";
  s.scan.xyz_mm = Grid<Vec3f>(o.scan_w, o.scan_h, Vec3f::Constant(kMissing));
  s.hit = Grid<uint8_t>(o.scan_w, o.scan_h, kNone);
  const Vec3d d = s.canvas_from_scan.rotation * Vec3d(0, 0, 1);
  const double F = o.frame_width, W = o.canvas_w, H = o.canvas_h;
  std::vector<std::pair<Vec3d, Vec3d>> boxes;
  if (o.frame) {
    const double z0 = -o.wall_depth, z1 = o.frame_raise;
    boxes.push_back({{-F, -F, z0}, {0, H + F, z1}});
    boxes.push_back({{W, -F, z0}, {W + F, H + F, z1}});
    boxes.push_back({{0, -F, z0}, {W, 0, z1}});
    boxes.push_back({{0, H, z0}, {W, H + F, z1}});
  }
  tbb::parallel_for(tbb::blocked_range<int>(0, o.scan_h), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y)
      for (int x = 0; x < o.scan_w; ++x) {
        const Vec3d os((x - o.scan_w / 2.0 + 0.5) * s.pixel_mm,
                       (y - o.scan_h / 2.0 + 0.5) * s.pixel_mm, 0);
        const Vec3d oc = s.canvas_from_scan.Apply(os);
        double best = 1e300;
        uint8_t what = kNone;
        for (const auto& b : boxes) {
          double t;
          if (RayBox(oc, d, b.first, b.second, &t) && t < best) best = t, what = kFrameHit;
        }
        double t = -oc.z() / d.z();
        for (int it = 0; it < 8; ++it) {
          const Vec3d p = oc + t * d;
          t = (s.Relief(p.x(), p.y()) - oc.z()) / d.z();
        }
        const Vec3d p = oc + t * d;
        const bool on_canvas = !o.frame || (p.x() >= 0 && p.x() <= W && p.y() >= 0 && p.y() <= H);
        if (on_canvas && t > 0 && t < best) best = t, what = kCanvasHit;
        if (o.frame) {
          const double tw = (-o.wall_depth - oc.z()) / d.z();
          if (tw > 0 && tw < best) best = tw, what = kWallHit;
        }
        s.hit(x, y) = what;
        if (what == kNone) continue;
        const uint64_t key =
            (static_cast<uint64_t>(o.seed) << 40) ^ (static_cast<uint64_t>(y) * o.scan_w + x);
        Vec3d ps = os + best * Vec3d(0, 0, 1);
        ps.z() += o.noise * Gaussian(key);
        if (Uniform(key ^ 0x5555555555ull) >= o.dropout) s.scan.xyz_mm(x, y) = ps.cast<float>();
      }
  });
  for (int b = 0; b < o.hole_blobs; ++b) {
    const double cx = u01(rng) * o.scan_w, cy = u01(rng) * o.scan_h, r = o.hole_radius_px;
    for (int y = std::max(0, int(cy - r)); y <= std::min(o.scan_h - 1, int(cy + r)); ++y)
      for (int x = std::max(0, int(cx - r)); x <= std::min(o.scan_w - 1, int(cx + r)); ++x)
        if ((x - cx) * (x - cx) + (y - cy) * (y - cy) <= r * r)
          s.scan.xyz_mm(x, y) = Vec3f::Constant(kMissing);
  }
  return s;
}

struct MaskScore {
  double normal_error_deg = 0;
  double iou = 0;
  size_t frame_kept = 0;          // frame or wall pixels in the mask
  double max_kept_height_mm = 0;  // of those, the largest |height above the canvas plane|
  size_t canvas_px = 0;
};

MaskScore Score(const CanvasResult& c, const RigidTransform& truth, const Grid<uint8_t>& hit,
                const Scan& scan) {
  MaskScore s;
  s.normal_error_deg =
      AngleDeg(c.canvas_from_scan.rotation.row(2).transpose(), truth.rotation.row(2).transpose());
  size_t inter = 0, uni = 0;
  for (size_t i = 0; i < hit.size(); ++i) {
    const bool est = c.mask_scan.data[i] != 0, canvas = hit.data[i] == kCanvasHit;
    inter += est && canvas;
    uni += est || canvas;
    s.canvas_px += canvas;
    if (est && (hit.data[i] == kFrameHit || hit.data[i] == kWallHit)) {
      ++s.frame_kept;
      const Vec3f& p = scan.xyz_mm.data[i];
      if (IsValid(p))
        s.max_kept_height_mm =
            std::max(s.max_kept_height_mm, std::fabs(truth.Apply(p.cast<double>()).z()));
    }
  }
  s.iou = uni ? static_cast<double>(inter) / static_cast<double>(uni) : 0;
  return s;
}

MaskScore Score(const CanvasResult& c, const AnalyticScan& a) {
  return Score(c, a.canvas_from_scan, a.hit, a.scan);
}

void ExpectFrameSane(const CanvasResult& c) {
  const Mat3d& r = c.canvas_from_scan.rotation;
  EXPECT_TRUE((r.transpose() * r).isApprox(Mat3d::Identity(), 1e-9));
  EXPECT_NEAR(r.determinant(), 1.0, 1e-9);
  EXPECT_LT(r(2, 2), 0) << "canvas Z must point towards the scanner (scan -Z)";
  EXPECT_TRUE(c.canvas_from_scan.translation.allFinite());
  EXPECT_TRUE(c.extent_mm.allFinite());
  EXPECT_TRUE(std::isfinite(c.noise_sigma_mm) && c.noise_sigma_mm >= 0);
  EXPECT_TRUE(std::isfinite(c.plane_rms_mm) && c.plane_rms_mm >= 0);
}

// ---------------------------------------------------------------------------------------------
// Options

TEST(CanvasOptions, DefaultsValidate) { EXPECT_TRUE(CanvasOptions{}.Validate().ok()); }

TEST(CanvasOptions, RejectsAbsurdValuesNamingTheOption) {
  struct Case {
    void (*set)(CanvasOptions&);
    const char* name;
  };
  const Case cases[] = {
      {[](CanvasOptions& o) { o.stop_gradient_mm = 0; }, "stop_gradient_mm"},
      {[](CanvasOptions& o) { o.stop_gradient_mm = std::nan(""); }, "stop_gradient_mm"},
      {[](CanvasOptions& o) { o.stop_slope = -1; }, "stop_slope"},
      {[](CanvasOptions& o) { o.refine_step_mm = -3; }, "refine_step_mm"},
      {[](CanvasOptions& o) { o.refine_px = -1; }, "refine_px"},
      {[](CanvasOptions& o) { o.erode_px = -2; }, "erode_px"},
      {[](CanvasOptions& o) { o.trim_sigmas = 0; }, "trim_sigmas"},
      {[](CanvasOptions& o) { o.seed_x = 5; }, "seed"},
      {[](CanvasOptions& o) { o.seed_x = -7, o.seed_y = -7; }, "seed"},
      {[](CanvasOptions& o) { o.min_canvas_fraction = 1.5; }, "min_canvas_fraction"},
      {[](CanvasOptions& o) { o.max_frame_points = 10; }, "max_frame_points"},
  };
  for (const Case& c : cases) {
    CanvasOptions o;
    c.set(o);
    const Status st = o.Validate();
    EXPECT_FALSE(st.ok()) << c.name;
    EXPECT_NE(st.message().find(c.name), std::string::npos) << st.message();
  }
}

TEST(ExtractCanvas, InvalidOptionsAreAnErrorNamingTheScan) {
  const AnalyticScan a = MakeAnalyticScan(SceneOptions{.scan_w = 64, .scan_h = 64});
  CanvasOptions o;
  o.erode_px = -2;
  const Result<CanvasResult> r = ExtractCanvas(a.scan, o);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("analytic.exr"), std::string::npos);
  EXPECT_NE(r.error().message.find("erode_px"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// FitPlanePca

TEST(FitPlanePca, RecoversAKnownPlane) {
  // Points on a 200 x 100 mm patch of the plane with normal n through c, noise 0.01 mm.
  const Vec3d n = Vec3d(0.1, -0.2, -1).normalized();
  const Vec3d c(10, 20, 800);
  const Vec3d a = n.unitOrthogonal(), b = n.cross(a);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  std::normal_distribution<double> g(0, 0.01);
  std::vector<Vec3d> pts;
  for (int i = 0; i < 20000; ++i)
    pts.push_back(c + 100 * u(rng) * a + 50 * u(rng) * b + g(rng) * n);
  const PlaneFit fit = FitPlanePca(pts);
  EXPECT_EQ(fit.count, pts.size());
  // Tolerance: 0.01 mm noise over a 200 mm patch tilts the fit by ~1e-6 rad; 1e-3 deg is loose.
  EXPECT_LT(AngleDeg(fit.axes.col(2), n), 1e-3);
  EXPECT_LT(fit.axes(2, 2), 0) << "normal oriented towards the scanner";
  EXPECT_LT((fit.centroid - c).norm(), 0.5);
  EXPECT_GE(fit.eigenvalues(0), fit.eigenvalues(1));
  EXPECT_GE(fit.eigenvalues(1), fit.eigenvalues(2));
  EXPECT_NEAR(std::sqrt(fit.eigenvalues(2)), 0.01, 1e-3);
  EXPECT_NEAR(fit.axes.determinant(), 1.0, 1e-9) << "right-handed axes";
  EXPECT_GT(std::fabs(fit.axes.col(0).dot(a)), 0.999) << "major axis along the 200 mm side";
}

TEST(FitPlanePca, EmptyAndDegenerateInputs) {
  const PlaneFit empty = FitPlanePca({});
  EXPECT_EQ(empty.count, 0u);
  EXPECT_TRUE(empty.axes.allFinite());
  // Collinear points: a zero second eigenvalue, finite axes, no NaN.
  std::vector<Vec3d> line;
  for (int i = 0; i < 100; ++i) line.emplace_back(i, 2.0 * i, 500);
  const PlaneFit fit = FitPlanePca(line);
  EXPECT_EQ(fit.count, 100u);
  EXPECT_TRUE(fit.axes.allFinite());
  EXPECT_NEAR(fit.eigenvalues(1), 0, 1e-6);
  // Non-finite points are ignored.
  line.push_back(Vec3d(std::nan(""), 0, 0));
  EXPECT_EQ(FitPlanePca(line).count, 100u);
}

// ---------------------------------------------------------------------------------------------
// Analytic scans

TEST(ExtractCanvas, NoiseFreeFramedScanKeepsNoFramePixel) {
  const AnalyticScan a = MakeAnalyticScan(SceneOptions{});
  const Result<CanvasResult> r = ExtractCanvas(a.scan, CanvasOptions{});
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectFrameSane(*r);
  const MaskScore s = Score(*r, a);
  EXPECT_LT(s.normal_error_deg, 0.01);
  EXPECT_GE(s.iou, 0.998);
  EXPECT_EQ(s.frame_kept, 0u);
  // The canvas frame: X along the canvas edges (from the outline rectangle), origin at the
  // visible canvas's corner. The extent is the visible canvas's (the frame hides a strip along
  // two sides: what the canvas-hit samples span in the true frame) within two scan pixels.
  const RigidTransform est_from_truth = r->canvas_from_scan * a.canvas_from_scan.Inverse();
  EXPECT_LT(AngleDeg(est_from_truth.rotation.col(0), Vec3d::UnitX()), 0.05);
  Eigen::AlignedBox2d visible;
  for (size_t i = 0; i < a.hit.size(); ++i)
    if (a.hit.data[i] == kCanvasHit)
      visible.extend(a.canvas_from_scan.Apply(a.scan.xyz_mm.data[i].cast<double>()).head<2>());
  EXPECT_NEAR(r->extent_mm.x(), visible.sizes().x(), 2 * a.pixel_mm);
  EXPECT_NEAR(r->extent_mm.y(), visible.sizes().y(), 2 * a.pixel_mm);
  EXPECT_LT(est_from_truth.translation.head<2>().norm(), 4.4 + 2 * a.pixel_mm);
  // Height 0 is the robust canvas plane: the truth's base plane plus the mean ripple, ~0.
  EXPECT_NEAR(est_from_truth.translation.z(), 0, 0.05);
  EXPECT_LT(r->noise_sigma_mm, 0.01);
  EXPECT_GT(r->grown_px, 0u);
  EXPECT_GT(r->plane_points, 1000u);
}

TEST(ExtractCanvas, DefaultNoiseHolesAndTiltMeetTheTargets) {
  SceneOptions o;
  o.noise = 0.02, o.dropout = 0.01, o.hole_blobs = 6;
  const AnalyticScan a = MakeAnalyticScan(o);
  const Result<CanvasResult> r = ExtractCanvas(a.scan, CanvasOptions{});
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectFrameSane(*r);
  const MaskScore s = Score(*r, a);
  EXPECT_LT(s.normal_error_deg, kMaxNormalErrorDeg);
  EXPECT_GE(s.iou, kMinIoU);
  EXPECT_LE(s.max_kept_height_mm, kMaxKeptFootHeightMm) << s.frame_kept << " frame pixels kept";
  EXPECT_LE(s.frame_kept, 10u);
  // The noise estimate: within 20 % (the relief's curvature adds a little).
  EXPECT_NEAR(r->noise_sigma_mm, 0.02, 0.004);
  EXPECT_GT(r->islands_filled_px, 0u) << "dropouts inside the canvas are enclosed islands";
}

TEST(ExtractCanvas, SteepTiltsAndOtherAxes) {
  struct Case {
    double tilt, axis, roll;
  };
  for (const Case c : {Case{30, 120, -5}, Case{45, 30, 3}, Case{20, 75, 10}, Case{2, 0, 0}}) {
    SceneOptions o;
    o.noise = 0.02, o.dropout = 0.01, o.tilt_deg = c.tilt, o.tilt_axis_deg = c.axis;
    o.roll_deg = c.roll, o.seed = 7;
    const AnalyticScan a = MakeAnalyticScan(o);
    const Result<CanvasResult> r = ExtractCanvas(a.scan, CanvasOptions{});
    ASSERT_TRUE(r.ok()) << r.error().message;
    ExpectFrameSane(*r);
    const MaskScore s = Score(*r, a);
    SCOPED_TRACE("tilt " + std::to_string(c.tilt) + " axis " + std::to_string(c.axis));
    EXPECT_LT(s.normal_error_deg, kMaxNormalErrorDeg);
    EXPECT_GE(s.iou, kMinIoU);
    EXPECT_LE(s.max_kept_height_mm, kMaxKeptFootHeightMm);
  }
}

TEST(ExtractCanvas, HeavyNoise) {
  SceneOptions o;
  o.noise = 0.2, o.dropout = 0.01;
  const AnalyticScan a = MakeAnalyticScan(o);
  const Result<CanvasResult> r = ExtractCanvas(a.scan, CanvasOptions{});
  ASSERT_TRUE(r.ok()) << r.error().message;
  const MaskScore s = Score(*r, a);
  EXPECT_LT(s.normal_error_deg, kMaxNormalErrorDeg);
  // Ten times the noise: the boundary test tolerates ten times more, so the target IoU is looser
  // and kept wall feet may reach a few noise sigmas.
  EXPECT_GE(s.iou, 0.99);
  EXPECT_LE(s.max_kept_height_mm, 1.5);
  EXPECT_NEAR(r->noise_sigma_mm, 0.2, 0.03);
}

TEST(ExtractCanvas, ThirtyPercentHoles) {
  SceneOptions o;
  o.noise = 0.02, o.dropout = 0.30, o.hole_blobs = 6;
  const AnalyticScan a = MakeAnalyticScan(o);
  const Result<CanvasResult> r = ExtractCanvas(a.scan, CanvasOptions{});
  ASSERT_TRUE(r.ok()) << r.error().message;
  const MaskScore s = Score(*r, a);
  EXPECT_LT(s.normal_error_deg, kMaxNormalErrorDeg);
  // Missing samples on the outline cannot be told from frame: a few percent of the ring is lost.
  EXPECT_GE(s.iou, 0.99);
  EXPECT_LE(s.max_kept_height_mm, kMaxKeptFootHeightMm);
}

TEST(ExtractCanvas, CanvasFillingTheScanIsNotAnError) {
  SceneOptions o;
  o.frame = false, o.field_scale = 0.5, o.noise = 0.02, o.dropout = 0.01, o.hole_blobs = 3;
  const AnalyticScan a = MakeAnalyticScan(o);
  const Result<CanvasResult> r = ExtractCanvas(a.scan, CanvasOptions{});
  ASSERT_TRUE(r.ok()) << r.error().message;
  const MaskScore s = Score(*r, a);
  EXPECT_LT(s.normal_error_deg, kMaxNormalErrorDeg);
  // Every pixel is canvas; only holes touching the scan border stay outside the mask.
  EXPECT_GE(s.iou, 0.99);
}

TEST(ExtractCanvas, OffCentreCanvasNeedsASeed) {
  SceneOptions o;
  o.off_x = 240, o.noise = 0.02;  // the scan centre now looks at the left frame moulding
  const AnalyticScan a = MakeAnalyticScan(o);
  const int cx = o.scan_w / 2, cy = o.scan_h / 2;
  ASSERT_EQ(a.hit(cx, cy), kFrameHit) << "test setup: the centre must land on the frame";
  const Result<CanvasResult> r = ExtractCanvas(a.scan, CanvasOptions{});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("analytic.exr"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("--seed"), std::string::npos) << r.error().message;
  // A seed on the canvas works.
  CanvasOptions seeded;
  for (int x = 0; x < o.scan_w && seeded.seed_x < 0; ++x)
    if (a.hit(x, cy) == kCanvasHit && a.hit(x + 20, cy) == kCanvasHit) seeded.seed_x = x + 20;
  seeded.seed_y = cy;
  const Result<CanvasResult> ok = ExtractCanvas(a.scan, seeded);
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_GE(Score(*ok, a).iou, kMinIoU);
  EXPECT_EQ(ok->seed_x, seeded.seed_x);
}

TEST(ExtractCanvas, SeedOutsideTheScanIsAnError) {
  const AnalyticScan a = MakeAnalyticScan(SceneOptions{.scan_w = 64, .scan_h = 64});
  CanvasOptions o;
  o.seed_x = 64, o.seed_y = 3;
  const Result<CanvasResult> r = ExtractCanvas(a.scan, o);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("outside"), std::string::npos) << r.error().message;
}

TEST(ExtractCanvas, DegenerateScansGiveClearErrors) {
  auto expect_error = [](const Scan& scan, const std::string& what) {
    const Result<CanvasResult> r = ExtractCanvas(scan, CanvasOptions{});
    ASSERT_FALSE(r.ok()) << what;
    EXPECT_NE(r.error().message.find(scan.source), std::string::npos) << r.error().message;
  };
  Scan empty;
  empty.source = "empty.exr";
  expect_error(empty, "empty");
  Scan tiny;
  tiny.source = "tiny.exr";
  tiny.xyz_mm = Grid<Vec3f>(8, 8, Vec3f::Zero());
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x) tiny.xyz_mm(x, y) = Vec3f(x, y, 500);
  expect_error(tiny, "8x8");
  Scan line;
  line.source = "line.exr";
  line.xyz_mm = Grid<Vec3f>(1000, 1, Vec3f::Zero());
  for (int x = 0; x < 1000; ++x) line.xyz_mm(x, 0) = Vec3f(0.2f * x, 0, 500 + 0.01f * x);
  expect_error(line, "1xN");
  Scan nan;
  nan.source = "nan.exr";
  nan.xyz_mm = Grid<Vec3f>(256, 256, Vec3f::Constant(kMissing));
  expect_error(nan, "all NaN");
  Scan garbage = nan;
  garbage.source = "garbage.exr";
  for (size_t i = 0; i < garbage.xyz_mm.size(); ++i)
    garbage.xyz_mm.data[i] = Vec3f(i % 2 ? 1e30f : std::numeric_limits<float>::infinity(), 0, 1);
  expect_error(garbage, "Inf and 1e30");
}

TEST(ExtractCanvas, UnsanitisedGarbageIsTreatedAsMissing) {
  SceneOptions o;
  o.noise = 0.02;
  AnalyticScan a = MakeAnalyticScan(o);
  std::mt19937 rng(5);
  std::uniform_int_distribution<size_t> pick(0, a.scan.xyz_mm.size() - 1);
  for (int i = 0; i < 500; ++i) {
    Vec3f& p = a.scan.xyz_mm.data[pick(rng)];
    p = i % 3 == 0   ? Vec3f(1e30f, 0, 0)
        : i % 3 == 1 ? Vec3f(0, std::numeric_limits<float>::infinity(), 1)
                     : Vec3f(p.x(), p.y(), -std::numeric_limits<float>::infinity());
  }
  const Result<CanvasResult> r = ExtractCanvas(a.scan, CanvasOptions{});
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectFrameSane(*r);
  const MaskScore s = Score(*r, a);
  EXPECT_LT(s.normal_error_deg, kMaxNormalErrorDeg);
  EXPECT_GE(s.iou, kMinIoU);
}

TEST(ExtractCanvas, IsDeterministic) {
  SceneOptions o;
  o.noise = 0.02, o.dropout = 0.01, o.hole_blobs = 2;
  const AnalyticScan a = MakeAnalyticScan(o);
  const Result<CanvasResult> r1 = ExtractCanvas(a.scan, CanvasOptions{});
  const Result<CanvasResult> r2 = ExtractCanvas(a.scan, CanvasOptions{});
  ASSERT_TRUE(r1.ok() && r2.ok());
  EXPECT_EQ(r1->mask_scan.data, r2->mask_scan.data);
  EXPECT_EQ(r1->canvas_from_scan.rotation, r2->canvas_from_scan.rotation);
  EXPECT_EQ(r1->canvas_from_scan.translation, r2->canvas_from_scan.translation);
}

// ---------------------------------------------------------------------------------------------
// The synthetic generator (data_synthetic): framed painting, Embree-traced scan.

struct SynthCase {
  synth::PaintingOptions painting;
  synth::FrameOptions frame;
  synth::ScanSimOptions scan;
};

struct SynthRun {
  synth::Painting painting;
  synth::SyntheticScan truth;
  Scan scan;
};

SynthRun RunSynth(const SynthCase& c) {
  SynthRun run;
  run.painting = synth::MakePainting(c.painting);
  const synth::Scene scene(run.painting, c.frame);
  run.truth = synth::SimulateScan(scene, c.scan);
  run.scan = run.truth.exposures.at(0);
  SanitizeScan(run.scan, SanitizeOptions{});
  return run;
}

MaskScore Score(const CanvasResult& c, const SynthRun& run) {
  // Scene::Hit and the analytic Hit share their values (none, canvas, frame, wall).
  return Score(c, run.truth.canvas_from_scan, run.truth.hit_scan, run.truth.exposures.at(0));
}

TEST(ExtractCanvasSynthetic, DefaultScanMeetsTheTargets) {
  SynthCase c;
  c.painting.resolution_px = 512;
  const SynthRun run = RunSynth(c);
  const auto t0 = std::chrono::steady_clock::now();
  const Result<CanvasResult> r = ExtractCanvas(run.scan, CanvasOptions{});
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(r.ok()) << r.error().message;
  ExpectFrameSane(*r);
  const MaskScore s = Score(*r, run);
  std::printf(
      "default synthetic %dx%d scan: normal %.4f deg, IoU %.5f, %zu frame px kept "
      "(max %.3f mm above the plane), noise %.4f mm, %.3f s\n",
      c.scan.width_px, c.scan.height_px, s.normal_error_deg, s.iou, s.frame_kept,
      s.max_kept_height_mm, r->noise_sigma_mm, seconds);
  EXPECT_LT(s.normal_error_deg, kMaxNormalErrorDeg);
  EXPECT_GE(s.iou, kMinIoU);
  EXPECT_LE(s.max_kept_height_mm, kMaxKeptFootHeightMm);
}

TEST(ExtractCanvasSynthetic, PinholeNoFrameAndFlatCanvas) {
  {
    SynthCase c;
    c.painting.resolution_px = 512;
    c.scan.model = synth::ScannerModel::kPinhole;
    const SynthRun run = RunSynth(c);
    const Result<CanvasResult> r = ExtractCanvas(run.scan, CanvasOptions{});
    ASSERT_TRUE(r.ok()) << r.error().message;
    const MaskScore s = Score(*r, run);
    EXPECT_LT(s.normal_error_deg, kMaxNormalErrorDeg) << "pinhole";
    EXPECT_GE(s.iou, kMinIoU) << "pinhole";
    EXPECT_LE(s.max_kept_height_mm, kMaxKeptFootHeightMm) << "pinhole";
  }
  {
    SynthCase c;
    c.painting.resolution_px = 512;
    c.frame.enabled = false;
    c.scan.field_margin = -0.3;  // crop into the canvas: it fills the scan
    const SynthRun run = RunSynth(c);
    const Result<CanvasResult> r = ExtractCanvas(run.scan, CanvasOptions{});
    ASSERT_TRUE(r.ok()) << r.error().message;
    const MaskScore s = Score(*r, run);
    EXPECT_LT(s.normal_error_deg, kMaxNormalErrorDeg) << "no frame";
    EXPECT_GE(s.iou, 0.99) << "no frame";
  }
  {
    SynthCase c;
    c.painting.resolution_px = 512;
    c.painting.weave = c.painting.strokes = c.painting.impasto = c.painting.craquelure = false;
    const SynthRun run = RunSynth(c);
    const Result<CanvasResult> r = ExtractCanvas(run.scan, CanvasOptions{});
    ASSERT_TRUE(r.ok()) << r.error().message;
    const MaskScore s = Score(*r, run);
    EXPECT_LT(s.normal_error_deg, kMaxNormalErrorDeg) << "flat";
    EXPECT_GE(s.iou, kMinIoU) << "flat";
    EXPECT_NEAR(r->noise_sigma_mm, c.scan.noise_mm, 0.2 * c.scan.noise_mm) << "flat";
  }
}

// The frame's boxes (step 7) against the generator's frame: raise = the moulding's top (its
// profile peaks at raise_mm at the sight edge), width = the top's extent, gap = how far outside
// the measured outline the frame starts (truth: the visible outline mapped into the true canvas
// frame; > 0 where the frame hides a strip of canvas from the scanner). Tolerances: the raise is
// a 98 % quantile of a profile whose upper 10 % lies at the top, plus the scan noise (0.3 mm);
// straight on, width and gap come from the top's 10 % and 90 % quantiles of evenly sampled
// points (1 mm); at 45 degrees the top is sampled unevenly (its slopes face the scanner or not),
// so 5 mm, which moves a shadow's edge by less than 2 texels here. Without a frame the sides drop
// to the wall: no box. The same bounds hold with the frame's points thinned to 2000 a side
// (CanvasOptions::max_frame_points; here ~10-40k a side): the points kept must spread over the
// whole band, not be the first rows of it.
TEST(ExtractCanvasSynthetic, FrameBoxesMatchTheFrame) {
  for (double tilt : {0.0, 45.0}) {
    SynthCase c;
    c.painting.resolution_px = 512;
    c.frame.left_mm = 35;
    c.frame.raise_mm = 30;
    c.scan.tilt_deg = tilt;
    const SynthRun run = RunSynth(c);
    for (size_t max_points : {size_t{1} << 19, size_t{2000}}) {
      CanvasOptions options;
      options.max_frame_points = max_points;
      const Result<CanvasResult> r = ExtractCanvas(run.scan, options);
      ASSERT_TRUE(r.ok()) << r.error().message;
      const FrameBoxes truth = c.frame.Boxes();
      // The measured outline's sides in the true canvas frame.
      const RigidTransform truth_from_measured =
          run.truth.canvas_from_scan * r->canvas_from_scan.Inverse();
      const double W = r->extent_mm.x(), H = r->extent_mm.y();
      const auto to_truth = [&](double X, double Y) {
        return truth_from_measured.Apply(Vec3d(X, Y, 0));
      };
      const double true_gap[4] = {
          to_truth(0, H / 2).x(), c.painting.width_mm - to_truth(W, H / 2).x(),
          to_truth(W / 2, 0).y(), c.painting.height_mm - to_truth(W / 2, H).y()};
      const double tol = tilt == 0 ? 1.0 : 5.0;
      for (int side = 0; side < 4; ++side) {
        std::printf(
            "tilt %.0f, %zu points: %s: raise %.2f mm (truth %.1f), width %.2f mm (truth %.1f), "
            "gap %.2f mm (truth %.2f)\n",
            tilt, max_points, kFrameSideNames[side], r->frame.raise_mm[side], truth.raise_mm[side],
            r->frame.width_mm[side], truth.width_mm[side], r->frame.gap_mm[side], true_gap[side]);
        EXPECT_NEAR(r->frame.raise_mm[side], truth.raise_mm[side], 0.3)
            << kFrameSideNames[side] << ", tilt " << tilt << ", " << max_points << " points";
        EXPECT_NEAR(r->frame.width_mm[side], truth.width_mm[side], tol)
            << kFrameSideNames[side] << ", tilt " << tilt << ", " << max_points << " points";
        EXPECT_NEAR(r->frame.gap_mm[side], std::max(0.0, true_gap[side]), tol)
            << kFrameSideNames[side] << ", tilt " << tilt << ", " << max_points << " points";
      }
    }
  }
  SynthCase c;
  c.painting.resolution_px = 256;
  c.frame.enabled = false;
  const SynthRun run = RunSynth(c);
  const Result<CanvasResult> r = ExtractCanvas(run.scan, CanvasOptions{});
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_FALSE(r->frame.any()) << "raise " << r->frame.max_raise_mm() << " mm without a frame";
}

TEST(ExtractCanvasSynthetic, FortyFiveDegreesAndHeavyNoise) {
  {
    SynthCase c;
    c.painting.resolution_px = 512;
    c.scan.tilt_deg = 45;
    const SynthRun run = RunSynth(c);
    const Result<CanvasResult> r = ExtractCanvas(run.scan, CanvasOptions{});
    ASSERT_TRUE(r.ok()) << r.error().message;
    const MaskScore s = Score(*r, run);
    EXPECT_LT(s.normal_error_deg, kMaxNormalErrorDeg) << "45 deg";
    EXPECT_GE(s.iou, kMinIoU) << "45 deg";
    EXPECT_LE(s.max_kept_height_mm, kMaxKeptFootHeightMm) << "45 deg";
  }
  {
    SynthCase c;
    c.painting.resolution_px = 512;
    c.scan.noise_mm = 0.2;
    const SynthRun run = RunSynth(c);
    const Result<CanvasResult> r = ExtractCanvas(run.scan, CanvasOptions{});
    ASSERT_TRUE(r.ok()) << r.error().message;
    const MaskScore s = Score(*r, run);
    EXPECT_LT(s.normal_error_deg, kMaxNormalErrorDeg) << "heavy noise";
    EXPECT_GE(s.iou, 0.99) << "heavy noise";
  }
}

}  // namespace
}  // namespace digitize
