// ComputeNormals against analytic surfaces and an independent brute-force reference.
#include "digitize/normals.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <random>
#include <vector>

#include "digitize/height_field.h"
#include "digitize_synth/painting.h"
#include "test_support.h"

namespace digitize {
namespace {

// Float normals of exact data: normalising in double then rounding to float leaves each component
// within one float ulp of 1 (6e-8); a few ulps of slack.
constexpr double kUnitTol = 1e-6;

Vec3d PlaneNormal(double a, double b) { return Vec3d(-a, -b, 1.0).normalized(); }

// Independent reference: the literal definition. 3D vertices at texel centres in the canvas frame
// (TexelCentreMm does the row flip), fan triangles in counter-clockwise order seen from +Z,
// cross products summed in double. Written without the Sobel shortcut on purpose.
Vec3d ReferenceNormal(const HeightField& f, int x, int y, int* triangles = nullptr) {
  auto usable = [&](int u, int v) {
    return f.height_mm.Contains(u, v) && HasHeight(f.state(u, v)) &&
           std::isfinite(f.height_mm(u, v));
  };
  auto vertex = [&](int u, int v) {
    const Eigen::Vector2d c = f.TexelCentreMm(u, v);
    return Vec3d(c.x(), c.y(), f.height_mm(u, v));
  };
  // Neighbours by canvas-frame direction: E, NE, N, NW, W, SW, S, SE (north = previous row).
  const int dx[8] = {1, 1, 0, -1, -1, -1, 0, 1};
  const int dy[8] = {0, -1, -1, -1, 0, 1, 1, 1};
  Vec3d sum = Vec3d::Zero();
  int count = 0;
  if (usable(x, y)) {
    const Vec3d c = vertex(x, y);
    for (int i = 0; i < 8; ++i) {
      const int j = (i + 1) % 8;
      if (!usable(x + dx[i], y + dy[i]) || !usable(x + dx[j], y + dy[j])) continue;
      sum += (vertex(x + dx[i], y + dy[i]) - c).cross(vertex(x + dx[j], y + dy[j]) - c);
      ++count;
    }
  }
  if (triangles) *triangles = count;
  return count == 0 ? Vec3d(0, 0, 1) : sum.normalized();
}

void ExpectAllUnitUp(const Grid<Vec3f>& n) {
  for (int y = 0; y < n.height; ++y)
    for (int x = 0; x < n.width; ++x) {
      const Vec3f& v = n(x, y);
      ASSERT_TRUE(std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z()))
          << "at " << x << "," << y;
      ASSERT_NEAR(v.cast<double>().norm(), 1.0, kUnitTol) << "at " << x << "," << y;
      ASSERT_GT(v.z(), 0.0f) << "at " << x << "," << y;
    }
}

TEST(Normals, EmptyGrid) {
  const HeightField field = test::MakeMmField(0, 0, 0.1);
  EXPECT_TRUE(ComputeNormals(field).empty());
}

TEST(Normals, FlatCanvasIsExactlyUp) {
  const Grid<Vec3f> n = ComputeNormals(test::MakeMmField(31, 17, 0.1));
  for (const Vec3f& v : n.data) EXPECT_EQ(v, Vec3f(0, 0, 1));
}

TEST(Normals, AllOutsideIsUp) {
  HeightField field = test::MakeMmField(9, 7, 0.1, [](double X, double Y) { return X * Y; });
  for (auto& s : field.state.data) s = TexelState::kOutside;
  for (const Vec3f& v : ComputeNormals(field).data) EXPECT_EQ(v, Vec3f(0, 0, 1));
}

// Every fan triangle of a plane lies in the plane, so the normal is exact, borders included.
// Dyadic pitch and slopes make every stored height exact in float: only the final rounding of
// the normal to float remains (kUnitTol).
TEST(Normals, TiltedPlaneDyadicIsExactEverywhere) {
  const double a = 0.25, b = -0.375;
  const HeightField field =
      test::MakeMmField(37, 23, 0.125, [&](double X, double Y) { return a * X + b * Y; });
  const Vec3d expected = PlaneNormal(a, b);
  const Grid<Vec3f> n = ComputeNormals(field);
  for (int y = 0; y < n.height; ++y)
    for (int x = 0; x < n.width; ++x)
      ASSERT_LT((n(x, y).cast<double>() - expected).norm(), kUnitTol) << x << "," << y;
}

// Generic plane: the stored float heights are rounded by at most ulp(h_max)/2. The Sobel weights
// sum to 8 in absolute value and the slope is that sum over 8 pitch, so the slope error is at most
// ulp(h_max) / (2 pitch); a unit normal moves by no more than its slope does.
TEST(Normals, TiltedPlaneGenericWithinFloatRounding) {
  const double a = 0.37, b = 0.81, pitch = 0.07;
  const HeightField field =
      test::MakeMmField(200, 150, pitch, [&](double X, double Y) { return a * X + b * Y; });
  double h_max = 0;
  for (float v : field.height_mm.data) h_max = std::max(h_max, std::abs(double{v}));
  const double ulp = std::nextafter(static_cast<float>(h_max), 1e30f) - static_cast<float>(h_max);
  const double tol = ulp / (2 * pitch) + kUnitTol;  // about 7e-6 here
  const Vec3d expected = PlaneNormal(a, b);
  const Grid<Vec3f> n = ComputeNormals(field);
  double worst = 0;
  for (const Vec3f& v : n.data) worst = std::max(worst, (v.cast<double>() - expected).norm());
  EXPECT_LT(worst, tol);
  EXPECT_LT(tol, 1e-5);
}

// The row flip: row 0 is the top (largest Y). A surface rising towards the top rows has an
// upward slope along +Y, so its normal leans to -Y.
TEST(Normals, RowFlipSign) {
  const HeightField field =
      test::MakeMmField(8, 8, 0.125, [](double, double Y) { return 0.5 * Y; });
  ASSERT_GT(field.height_mm(3, 0), field.height_mm(3, 7));  // row 0 is higher
  const Grid<Vec3f> n = ComputeNormals(field);
  EXPECT_LT(n(3, 3).y(), -0.4f);
  EXPECT_NEAR(n(3, 3).x(), 0.0f, 1e-7);
  const HeightField east = test::MakeMmField(8, 8, 0.125, [](double X, double) { return 0.5 * X; });
  EXPECT_LT(ComputeNormals(east)(3, 3).x(), -0.4f);  // rising to the east leans west
}

// Holes of every kind: triangles touching a texel without height are left out, but whatever
// remains of the fan still lies in the plane, so the normal stays exact; texels with no triangle
// left (or no height themselves) get (0, 0, 1).
TEST(Normals, PlaneWithHolesExactWhereAnyTriangleRemains) {
  const double a = -0.5, b = 0.125;
  HeightField field =
      test::MakeMmField(41, 29, 0.25, [&](double X, double Y) { return a * X + b * Y; });
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> pick(0, 9);
  for (auto& s : field.state.data) {
    const int r = pick(rng);
    if (r < 2)
      s = TexelState::kOutside;
    else if (r == 2)
      s = TexelState::kUnfilled;
    else if (r == 3)
      s = TexelState::kFilled;
  }
  const Vec3d expected = PlaneNormal(a, b);
  const Grid<Vec3f> n = ComputeNormals(field);
  int with = 0, without = 0;
  for (int y = 0; y < n.height; ++y)
    for (int x = 0; x < n.width; ++x) {
      int triangles = 0;
      ReferenceNormal(field, x, y, &triangles);
      if (triangles > 0) {
        ++with;
        ASSERT_LT((n(x, y).cast<double>() - expected).norm(), kUnitTol) << x << "," << y;
      } else {
        ++without;
        ASSERT_EQ(n(x, y), Vec3f(0, 0, 1)) << x << "," << y;
      }
    }
  EXPECT_GT(with, 100);  // both branches exercised
  EXPECT_GT(without, 50);
}

// Fast (Sobel) and general paths against the literal definition on rough random heights with
// holes. Both sides sum in double; they differ by operation order (~1e-15) plus the rounding of
// the result to float.
TEST(Normals, MatchesBruteForceReferenceOnRandomSurface) {
  HeightField field = test::MakeMmField(57, 43, 0.1);
  std::mt19937 rng(11);
  std::normal_distribution<float> height(0.0f, 0.3f);
  std::uniform_int_distribution<int> pick(0, 19);
  for (auto& h : field.height_mm.data) h = height(rng);
  for (auto& s : field.state.data)
    if (pick(rng) == 0) s = TexelState::kOutside;
  const Grid<Vec3f> n = ComputeNormals(field);
  ExpectAllUnitUp(n);
  for (int y = 0; y < n.height; ++y)
    for (int x = 0; x < n.width; ++x)
      ASSERT_LT((n(x, y).cast<double>() - ReferenceNormal(field, x, y)).norm(), kUnitTol)
          << x << "," << y;
}

// The Sobel fan is exact on any quadratic: its central differences are exact there and the
// cross-row smoothing averages a linear term symmetrically.
TEST(Normals, ParaboloidIsExactUpToFloatRounding) {
  const double c = 0.02, pitch = 0.125, cx = 6.0, cy = 4.0;  // paraboloid centred at (cx, cy) mm
  const HeightField field = test::MakeMmField(96, 64, pitch, [&](double X, double Y) {
    return 0.5 * c * ((X - cx) * (X - cx) + (Y - cy) * (Y - cy)) + 0.01 * (X - cx) * (Y - cy);
  });
  const Grid<Vec3f> n = ComputeNormals(field);
  double h_max = 0;
  for (float v : field.height_mm.data) h_max = std::max(h_max, std::abs(double{v}));
  // Same float-rounding bound as for the generic plane.
  const double tol = std::ldexp(1.0, std::ilogb(h_max) - 23) / (2 * pitch) + kUnitTol;
  double worst = 0;
  for (int y = 1; y < n.height - 1; ++y)  // the border fans are one-sided: first order only
    for (int x = 1; x < n.width - 1; ++x) {
      const Eigen::Vector2d p = field.TexelCentreMm(x, y);
      const double hx = c * (p.x() - cx) + 0.01 * (p.y() - cy);
      const double hy = c * (p.y() - cy) + 0.01 * (p.x() - cx);
      worst = std::max(worst, (n(x, y).cast<double>() - PlaneNormal(hx, hy)).norm());
    }
  EXPECT_LT(worst, tol);
}

// Sphere cap (R = 10 mm) where r <= 6 mm. The Sobel slope is second-order accurate:
// error ~ p^2 (|h_xxx| / 6 + |h_xyy| / 4); for this sphere that bracket is largest at the edge
// of the region (r = 6, h = 8): 3 R^2 r / h^5 / 6 + r / h^3 / 4 = 0.0121 per mm^2. The normal's
// angle moves by no more than its slope, so the bound is 0.0121 p^2 rad; we allow 2x that.
// Halving the pitch must divide the error by ~4 (second order).
double SphereCapMaxErrorRad(double pitch) {
  const double R = 10.0, extent = 16.0, cx = 8.0, cy = 8.0;
  const int size = static_cast<int>(std::lround(extent / pitch));
  const HeightField field = test::MakeMmField(size, size, pitch, [&](double X, double Y) {
    const double r2 = (X - cx) * (X - cx) + (Y - cy) * (Y - cy);
    return std::sqrt(std::max(R * R - r2, 0.0)) - 6.0;  // heights in [-6, 4]: small float ulp
  });
  const Grid<Vec3f> n = ComputeNormals(field);
  double worst = 0;
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) {
      const Eigen::Vector2d p = field.TexelCentreMm(x, y);
      const Vec3d q(p.x() - cx, p.y() - cy, 0.0);
      if (q.norm() > 6.0) continue;
      const Vec3d truth = Vec3d(q.x(), q.y(), std::sqrt(R * R - q.squaredNorm())).normalized();
      worst = std::max(worst, AngleDeg(n(x, y).cast<double>(), truth) * M_PI / 180.0);
    }
  return worst;
}

TEST(Normals, SphereCapSecondOrderAccurate) {
  const double coarse = SphereCapMaxErrorRad(0.1), fine = SphereCapMaxErrorRad(0.05);
  EXPECT_LT(coarse, 2 * 0.0121 * 0.1 * 0.1);
  EXPECT_LT(fine, 2 * 0.0121 * 0.05 * 0.05);
  EXPECT_GT(coarse / fine, 3.5) << "coarse " << coarse << " fine " << fine;
}

// Degenerate shapes: a single row or column forms no triangle (every fan triangle needs a
// neighbour off the line), so every normal is up; a 2x2 grid has two triangles per texel.
TEST(Normals, OneByNAndNByOne) {
  const auto f = [](double X, double Y) { return 0.3 * X - 0.2 * Y; };
  for (const auto& [w, h] : {std::pair{1, 1}, std::pair{1, 50}, std::pair{50, 1}}) {
    const Grid<Vec3f> n = ComputeNormals(test::MakeMmField(w, h, 0.1, f));
    ASSERT_EQ(n.width, w);
    ASSERT_EQ(n.height, h);
    for (const Vec3f& v : n.data) EXPECT_EQ(v, Vec3f(0, 0, 1));
  }
  const HeightField two =
      test::MakeMmField(2, 2, 0.125, [](double X, double Y) { return 0.25 * X + 0.5 * Y; });
  for (const Vec3f& v : ComputeNormals(two).data)
    EXPECT_LT((v.cast<double>() - PlaneNormal(0.25, 0.5)).norm(), kUnitTol);
  const HeightField strip =
      test::MakeMmField(2, 40, 0.125, [](double X, double Y) { return 0.25 * X - Y; });
  for (const Vec3f& v : ComputeNormals(strip).data)
    EXPECT_LT((v.cast<double>() - PlaneNormal(0.25, -1.0)).norm(), kUnitTol);
}

// Hostile magnitudes: heights up to 1e6 mm (and FLT_MAX) at a 1e-6 mm pitch give slopes near
// 1e12 or more; squares overflow float, so the normal must still be finite, unit, and up.
TEST(Normals, HugeHeightsAndTinyPitchStayFinite) {
  HeightField field = test::MakeMmField(33, 21, 1e-6);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1e6f, 1e6f);
  for (auto& h : field.height_mm.data) h = u(rng);
  field.height_mm(5, 5) = std::numeric_limits<float>::max();
  field.height_mm(6, 5) = -std::numeric_limits<float>::max();
  field.height_mm(20, 10) = std::numeric_limits<float>::max();
  ExpectAllUnitUp(ComputeNormals(field));

  // A very steep plane still has the right direction.
  const HeightField steep =
      test::MakeMmField(16, 16, 1e-6, [](double X, double) { return 1e6 * X; });
  for (const Vec3f& v : ComputeNormals(steep).data) {
    EXPECT_NEAR(v.x(), -1.0f, 1e-6f);
    EXPECT_GT(v.z(), 0.0f);
  }
}

// A non-finite height breaks the HeightField contract; it is treated as missing, not spread.
TEST(Normals, NonFiniteHeightIsLeftOut) {
  HeightField field = test::MakeMmField(12, 12, 0.125, [](double X, double) { return 0.25 * X; });
  field.height_mm(5, 5) = std::numeric_limits<float>::quiet_NaN();
  field.height_mm(8, 2) = std::numeric_limits<float>::infinity();
  const Grid<Vec3f> n = ComputeNormals(field);
  ExpectAllUnitUp(n);
  EXPECT_EQ(n(5, 5), Vec3f(0, 0, 1));
  EXPECT_LT((n(4, 4).cast<double>() - PlaneNormal(0.25, 0)).norm(), kUnitTol);
}

// Against the generator's analytic normals (exact gradient of the continuous, band-limited
// surface) on its own truth grid: what is left is the discretisation error of the 8-neighbour fan,
// the floor under any preprocessing result. Features are faded in from 8 texels per wavelength,
// where a central difference already underestimates a sinusoid's slope by 1 - sin(kp)/kp = 10 %;
// steep crests and impasto walls (a few texels wide) give the tail. Measured at 1024 px (pitch
// 0.39 mm) over seeds 1-6: median 0.145-0.194 deg, p90 0.73-0.85 deg, p99 2.1-4.2 deg. Bounds
// leave ~1.5x headroom and keep the median well under the 0.5 deg budget of the whole pipeline.
constexpr double kSynthMedianTolDeg = 0.3;
constexpr double kSynthP90TolDeg = 1.2;

TEST(Normals, SyntheticPaintingMatchesAnalyticNormals) {
  synth::PaintingOptions options;
  options.resolution_px = 1024;
  options.seed = 1;
  const synth::Painting painting = synth::MakePainting(options);
  const Grid<Vec3f> n = ComputeNormals(painting.truth);
  ASSERT_EQ(n.width, painting.normals.width);
  ASSERT_EQ(n.height, painting.normals.height);
  ExpectAllUnitUp(n);
  std::vector<double> error_deg;
  error_deg.reserve(n.size());
  for (size_t i = 0; i < n.size(); ++i)
    error_deg.push_back(
        AngleDeg(n.data[i].cast<double>(), painting.normals.data[i].cast<double>()));
  auto quantile = [&](double q) {
    std::vector<double> v = error_deg;
    const auto k = static_cast<std::ptrdiff_t>(q * static_cast<double>(v.size() - 1));
    std::nth_element(v.begin(), v.begin() + k, v.end());
    return v[static_cast<size_t>(k)];
  };
  const double median = quantile(0.5), p90 = quantile(0.9);
  RecordProperty("median_deg", std::to_string(median));
  RecordProperty("p90_deg", std::to_string(p90));
  EXPECT_LT(median, kSynthMedianTolDeg);
  EXPECT_LT(p90, kSynthP90TolDeg);
}

TEST(Normals, BrokenFieldThrows) {
  HeightField field = test::MakeMmField(4, 4, 0.0);
  EXPECT_THROW(ComputeNormals(field), InvariantError);
  field.pitch_mm = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(ComputeNormals(field), InvariantError);
  field.pitch_mm = 0.1;
  field.state = Grid<TexelState>(3, 4, TexelState::kMeasured);
  EXPECT_THROW(ComputeNormals(field), InvariantError);
}

}  // namespace
}  // namespace digitize
