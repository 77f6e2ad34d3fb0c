// Canvas extraction (canvas.h; SPEC steps 1-2; paper 4.2).
//
// Pipeline inside ExtractCanvas:
//   1. PCA plane of every usable sample (the frame and wall included; only a rough normal).
//   2. Barrier mask: a pixel stops the growth when it is missing, when its Sobel height gradient
//      (mm per pixel) exceeds stop_gradient_mm (depth discontinuities: the frame step on the side
//      the frame occludes), or when its surface slope in the plane's frame exceeds stop_slope
//      (frame walls seen obliquely: vertical in the canvas frame even where the per-pixel step is
//      small, e.g. fine scans). Missing neighbours are replaced by the centre sample, so holes
//      never create gradients.
//   3. Flood fill from the seed over the non-barrier pixels; enclosed islands (impasto walls,
//      holes, outliers) are added back. A region that is not convex (a frame ring) or too small
//      is an error suggesting a seed.
//   4. Robust plane: erode by erode_px, PCA, then trimmed refits (relief above, outliers below).
//   5. Boundary: the region is peeled by kPeelPx pixels (the growth may have climbed onto the foot
//      of a wall) and regrown, up to refine_px beyond it, by a strict test: height step <
//      refine_step_mm, small second differences towards the region, tight ones next to a wall
//      or a missing sample, and not on the line of a wall's samples. This recovers the ring that
//      Sobel's 3x3 support loses without taking wall samples (but those within the noise of the
//      canvas plane, which no test can tell from canvas). Missing samples the region encloses
//      stay in the mask.
//   5b. Outline: the visible canvas as a rectangle in the plane (FitOutline): its sides give the
//      in-plane axes and the extent, the pixels inside it the mask (dropout notches on the
//      border filled, bevel feet left out), frame samples lying over it a hidden-edge warning.
//      Kept out when it disagrees with the grown region (not a rectangle).
//   6. Canvas frame: Z = robust normal, X = the outline's side direction (else the in-plane PCA
//      axis) closest to scan +X, origin at the lower-left corner of the outline (sides on the
//      scan border: of the mask points' bounding rectangle), height 0 on the plane.
#include "digitize/canvas.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "mask_ops.h"

namespace digitize {
namespace {

// Coordinates beyond this are sensor garbage even when the scan was not sanitised (1e30).
constexpr float kMaxAbsCoordinateMm = 1e6f;
// Fewer usable samples than this cannot define a canvas.
constexpr size_t kMinValidSamples = 100;
// A grown region filling less of its convex hull than this is not a canvas (a frame ring).
constexpr double kMinSolidity = 0.6;

// Plane fits use a regular subsample of about this many samples (the rough one of the whole
// scan, the robust ones of the canvas): their error stays far below the noise's.
constexpr size_t kRoughSamples = 1000000;
constexpr size_t kFitSamples = 1000000;
// Robust refit: iterations, and the lower trim (outliers below the canvas) in multiples of the
// upper one (relief above).
constexpr int kTrimIterations = 3;
constexpr double kLowerTrimFactor = 2.0;
// Regular subsamples for medians: residuals (MAD), noise (a MAD to better than 1 %), spacing.
constexpr size_t kStatSamples = 250000;
constexpr size_t kNoiseSamples = 100000;
constexpr size_t kSpacingSamples = 50000;
// MAD -> sigma for a Gaussian.
constexpr double kMadToSigma = 1.4826;

// Boundary refinement. The growth can include the foot of an oblique wall (one pixel): the
// region is peeled by kPeelPx first. The refinement runs until nothing changes (at most
// kMaxRefineSteps) within refine_px of the grown region.
constexpr int kPeelPx = 2;
constexpr int kMaxRefineSteps = 100;
// Missing samples with mask pixels on both sides within this many pixels join the mask.
constexpr int kConvexReachPx = 3;
// A candidate next to a wall (a barrier neighbour higher or lower by more than kWallRise sample
// spacings, or a missing neighbour) may be the wall's foot: its second difference along every
// region direction must then stay within kTightSigmas second-difference sigmas (sqrt(6) sigma)
// plus kTightFloorMm of relief curvature. Elsewhere the bound is the larger of
// kRefineCurvatureShare * refine_step_mm and kRefineNoiseSigmas noise sigmas.
constexpr double kWallRise = 0.5;
constexpr double kTightSigmas = 2.0;
constexpr double kTightFloorMm = 0.06;
constexpr double kRefineCurvatureShare = 0.25;
constexpr double kRefineNoiseSigmas = 10.0;
// Foot test: evenly spaced parallel rays hit a plane in evenly spaced collinear points, so a
// candidate within kLineSigmas second-difference sigmas (plus kLineFloorShare of a spacing) of
// the line through the next two barrier samples is on that wall; only where the run is steep
// (slope above kLineSlope) and climbs by more than kLineRiseSigmas height-difference sigmas: a
// barrier run along a frame step on flat canvas is collinear too, but flat. Over a missing
// sample the extrapolation 3 p(q+2d) - 2 p(q+3d) has sqrt(14 / 6) times the noise.
constexpr double kLineSigmas = 4.0;
constexpr double kLineFloorShare = 0.02;
constexpr double kLineRiseSigmas = 3.0;
constexpr double kLineSlope = 0.3;
constexpr double kFarLineFactor = 1.53;

// Canvas frame: in-plane eigenvalues closer than this (relative) leave the axes undefined (use
// scan +X); points farther than kBoundHeightMm from the plane are not canvas (frames rise 15+
// mm) and do not stretch the bounding rectangle (outliers that survived in the mask).
constexpr double kIsotropicEigen = 0.05;
constexpr double kBoundHeightMm = 15.0;
constexpr double kPi = 3.14159265358979323846;

inline bool Usable(const Vec3f& p) {
  return std::fabs(p.x()) <= kMaxAbsCoordinateMm && std::fabs(p.y()) <= kMaxAbsCoordinateMm &&
         std::fabs(p.z()) <= kMaxAbsCoordinateMm;  // false for NaN and Inf too
}

std::string SourceName(const Scan& scan) { return scan.source.empty() ? "scan" : scan.source; }

// "(x, y)", appended piecewise (GCC 12 warns falsely about "(" + std::string at -O3).
std::string PointText(int x, int y) {
  std::string text = "(";
  text += std::to_string(x);
  text += ", ";
  text += std::to_string(y);
  text += ")";
  return text;
}

// First and second moments about a fixed shift (keeps the covariance well conditioned).
struct Moments {
  double n = 0;
  double sx = 0, sy = 0, sz = 0;
  double sxx = 0, sxy = 0, sxz = 0, syy = 0, syz = 0, szz = 0;
  void Add(double x, double y, double z) {
    n += 1;
    sx += x, sy += y, sz += z;
    sxx += x * x, sxy += x * y, sxz += x * z;
    syy += y * y, syz += y * z, szz += z * z;
  }
  void Merge(const Moments& o) {
    n += o.n;
    sx += o.sx, sy += o.sy, sz += o.sz;
    sxx += o.sxx, sxy += o.sxy, sxz += o.sxz;
    syy += o.syy, syz += o.syz, szz += o.szz;
  }
  Vec3d Sum() const { return {sx, sy, sz}; }
  Mat3d SecondMoments() const {
    Mat3d m;
    m << sxx, sxy, sxz, sxy, syy, syz, sxz, syz, szz;
    return m;
  }
};

PlaneFit PlaneFromMoments(const Moments& m, const Vec3d& shift) {
  PlaneFit fit;
  fit.count = static_cast<size_t>(m.n);
  if (m.n < 1) return fit;
  const Vec3d mean = m.Sum() / m.n;
  fit.centroid = shift + mean;
  Mat3d cov = m.SecondMoments() / m.n - mean * mean.transpose();
  cov = 0.5 * (cov + cov.transpose());
  Eigen::SelfAdjointEigenSolver<Mat3d> solver(cov);
  if (solver.info() != Eigen::Success) return fit;
  const Vec3d ev = solver.eigenvalues();  // ascending
  const Mat3d vec = solver.eigenvectors();
  Vec3d major = vec.col(2), minor = vec.col(1), normal = vec.col(0);
  if (normal.z() > 0) normal = -normal;  // towards a scanner looking along +Z
  if (major.cross(minor).dot(normal) < 0) minor = -minor;
  fit.axes.col(0) = major;
  fit.axes.col(1) = minor;
  fit.axes.col(2) = normal;
  fit.eigenvalues = Vec3d(std::max(ev(2), 0.0), std::max(ev(1), 0.0), std::max(ev(0), 0.0));
  return fit;
}

// PCA of the usable scan samples for which pred(x, y, p) holds; rows in parallel.
// PCA of the usable scan samples on every `stride`-th row and column for which pred(x, y, p)
// holds; rows in parallel, moments in double about `shift`.
template <class Pred>
PlaneFit FitGrid(const Grid<Vec3f>& xyz, const Vec3d& shift, int stride, const Pred& pred) {
  const int rows_sampled = (xyz.height + stride - 1) / stride;
  // Deterministic reduction (fixed split): the same scan gives the same plane, bit for bit.
  const Moments m = tbb::parallel_deterministic_reduce(
      tbb::blocked_range<int>(0, rows_sampled, 16), Moments{},
      [&](const tbb::blocked_range<int>& rows, Moments acc) {
        for (int r = rows.begin(); r < rows.end(); ++r) {
          const int y = r * stride;
          const Vec3f* row = xyz.Row(y);
          Moments line;
          for (int x = 0; x < xyz.width; x += stride) {
            const Vec3f& p = row[x];
            if (!Usable(p) || !pred(x, y, p)) continue;
            line.Add(p.x() - shift.x(), p.y() - shift.y(), p.z() - shift.z());
          }
          acc.Merge(line);
        }
        return acc;
      },
      [](Moments a, const Moments& b) {
        a.Merge(b);
        return a;
      });
  return PlaneFromMoments(m, shift);
}

// PCA of the points for which pred(p) holds; in parallel, moments in double about `shift`.
template <class Pred>
PlaneFit FitPoints(const std::vector<Vec3f>& points, const Vec3d& shift, const Pred& pred) {
  const Eigen::Vector3f shift_f = shift.cast<float>();
  const Vec3d shift_used = shift_f.cast<double>();
  const Moments m = tbb::parallel_deterministic_reduce(
      tbb::blocked_range<size_t>(0, points.size(), 1 << 14), Moments{},
      [&](const tbb::blocked_range<size_t>& r, Moments acc) {
        for (size_t i = r.begin(); i < r.end(); ++i) {
          const Vec3f& p = points[i];
          if (!pred(p)) continue;
          // Float subtraction of nearby values is exact to the data's own precision.
          const Eigen::Vector3f d = p - shift_f;
          acc.Add(d.x(), d.y(), d.z());
        }
        return acc;
      },
      [](Moments a, const Moments& b) {
        a.Merge(b);
        return a;
      });
  return PlaneFromMoments(m, shift_used);
}

// Stride giving about `target` samples out of `count`.
int SampleStride(size_t count, size_t target) {
  return std::max(1, static_cast<int>(std::sqrt(static_cast<double>(count) / target)));
}

double Median(std::vector<double>& v) {
  if (v.empty()) return 0;
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  return v[mid];
}

// Median absolute deviation about `center`.
double Mad(const std::vector<double>& v, double center) {
  std::vector<double> d(v.size());
  for (size_t i = 0; i < v.size(); ++i) d[i] = std::fabs(v[i] - center);
  return Median(d);
}

// Heights and in-plane coordinates of a plane frame (float: used per pixel in hot loops).
struct LocalFrame {
  Eigen::Vector3f c, n, a, b;
  explicit LocalFrame(const PlaneFit& f)
      : c(f.centroid.cast<float>()),
        n(f.axes.col(2).cast<float>()),
        a(f.axes.col(0).cast<float>()),
        b(f.axes.col(1).cast<float>()) {}
  float H(const Vec3f& p) const { return n.dot(p - c); }
  Eigen::Vector2f UV(const Vec3f& p) const {
    const Eigen::Vector3f d = p - c;
    return {a.dot(d), b.dot(d)};
  }
};

// Heights h, in-plane coordinates u, v and validity m (1 / 0; h = u = v = 0 where missing) of
// one scan row (interleaved x, y, z). Free function with restrict pointers: vectorised.
void ProjectRow(const float* __restrict xyz, int width, const LocalFrame& frame,
                float* __restrict hh, float* __restrict uu, float* __restrict vv,
                float* __restrict mm) {
  const float cx = frame.c.x(), cy = frame.c.y(), cz = frame.c.z();
  const float nx = frame.n.x(), ny = frame.n.y(), nz = frame.n.z();
  const float ax = frame.a.x(), ay = frame.a.y(), az = frame.a.z();
  const float bx = frame.b.x(), by = frame.b.y(), bz = frame.b.z();
  const uint32_t lim = std::bit_cast<uint32_t>(kMaxAbsCoordinateMm);
  for (int x = 0; x < width; ++x) {
    const float px = xyz[3 * x], py = xyz[3 * x + 1], pz = xyz[3 * x + 2];
    // |p| <= limit on the bit patterns (NaN and Inf fail); integer masks instead of branches so
    // the loop vectorises under strict floating-point semantics.
    const uint32_t ax_bits = std::bit_cast<uint32_t>(px) & 0x7fffffffu;
    const uint32_t ay_bits = std::bit_cast<uint32_t>(py) & 0x7fffffffu;
    const uint32_t az_bits = std::bit_cast<uint32_t>(pz) & 0x7fffffffu;
    const uint32_t mask =
        0u - static_cast<uint32_t>((ax_bits <= lim) & (ay_bits <= lim) & (az_bits <= lim));
    const float dx = std::bit_cast<float>(std::bit_cast<uint32_t>(px - cx) & mask);
    const float dy = std::bit_cast<float>(std::bit_cast<uint32_t>(py - cy) & mask);
    const float dz = std::bit_cast<float>(std::bit_cast<uint32_t>(pz - cz) & mask);
    hh[x] = nx * dx + ny * dy + nz * dz;
    uu[x] = ax * dx + ay * dy + az * dz;
    vv[x] = bx * dx + by * dy + bz * dz;
    mm[x] = std::bit_cast<float>(std::bit_cast<uint32_t>(1.f) & mask);
  }
}

// One row of the barrier test from the vertical Sobel passes (smooth s, difference d) of the
// channels h, u, v, validity (each `stride` apart) and the centre row's values. A free function
// with restrict pointers so the compiler vectorises it.
void BarrierRow(const float* const centre[4], const float* __restrict s, const float* __restrict d,
                size_t stride, int width, float grad_limit2, float slope2,
                uint8_t* __restrict grow_row, uint8_t* __restrict valid_row) {
  const float* __restrict ch = centre[0];
  const float* __restrict cu = centre[1];
  const float* __restrict cv = centre[2];
  const float* __restrict cm = centre[3];
  const float* __restrict sh = s;
  const float* __restrict su = s + stride;
  const float* __restrict sv = s + 2 * stride;
  const float* __restrict sm = s + 3 * stride;
  const float* __restrict dh = d;
  const float* __restrict du = d + stride;
  const float* __restrict dv = d + 2 * stride;
  const float* __restrict dm = d + 3 * stride;
  for (int x = 0; x < width; ++x) {
    const float mx = sm[x + 1] - sm[x - 1], my = dm[x - 1] + 2.f * dm[x] + dm[x + 1];
    const float hc = ch[x], uc = cu[x], vc = cv[x];
    const float hx = (sh[x + 1] - sh[x - 1]) - hc * mx;
    const float hy = (dh[x - 1] + 2.f * dh[x] + dh[x + 1]) - hc * my;
    const float ux = (su[x + 1] - su[x - 1]) - uc * mx;
    const float uy = (du[x - 1] + 2.f * du[x] + du[x + 1]) - uc * my;
    const float vx = (sv[x + 1] - sv[x - 1]) - vc * mx;
    const float vy = (dv[x - 1] + 2.f * dv[x] + dv[x + 1]) - vc * my;
    // Height gradient per pixel: |Sobel| / 8.
    const bool step = hx * hx + hy * hy > grad_limit2;
    // Slope in the plane frame: grad_uv h = J^-T grad_xy h, J = d(u, v) / d(x, y); compared
    // without dividing by det J so vertical and folded geometry (det ~ 0) is a barrier.
    const float det = ux * vy - uy * vx;
    const float gu = vy * hx - vx * hy, gv = ux * hy - uy * hx;
    const bool steep = gu * gu + gv * gv > slope2 * det * det;
    const bool ok = cm[x] > 0.5f;
    grow_row[x] = static_cast<uint8_t>(ok & !step & !steep);
    valid_row[x] = static_cast<uint8_t>(ok);
  }
}

// Barrier test (step 2) for every pixel: growable(x, y) = 1 where growth may pass, valid(x, y) =
// 1 where the sample is usable.
//
// Sobel with missing neighbours replaced by the centre value c is linear: for a channel with
// values n (0 where missing) and validity m, sum_k w_k (m_k n_k + (1 - m_k) c) = S(n) - c S(m)
// because the Sobel weights sum to zero. So each channel (h, u, v) and the validity mask get a
// plain separable Sobel on three sliding rows, and the combination per pixel is branch-free.
void GrowableMask(const Grid<Vec3f>& xyz, const LocalFrame& frame, double stop_gradient_mm,
                  double stop_slope, cv::Mat& growable, cv::Mat& valid) {
  const int w = xyz.width, h = xyz.height;
  growable.create(h, w, CV_8U);
  valid.create(h, w, CV_8U);
  const float grad_limit2 = static_cast<float>(64.0 * stop_gradient_mm * stop_gradient_mm);
  const float slope2 = static_cast<float>(stop_slope * stop_slope);
  constexpr int kChannels = 4;  // h, u, v, validity
  tbb::parallel_for(tbb::blocked_range<int>(0, h, 16), [&](const tbb::blocked_range<int>& rows) {
    const size_t stride = static_cast<size_t>(w) + 2;  // one zero (missing) pad on each side
    std::vector<float> buf(3 * kChannels * stride, 0.f);
    std::vector<float> vs(kChannels * stride), vd(kChannels * stride);  // vertical smooth / diff
    auto row_ptr = [&](int slot, int c) { return buf.data() + (slot * kChannels + c) * stride; };
    auto fill_row = [&](int y, int slot) {
      float* hh = row_ptr(slot, 0) + 1;
      float* uu = row_ptr(slot, 1) + 1;
      float* vv = row_ptr(slot, 2) + 1;
      float* mm = row_ptr(slot, 3) + 1;
      if (y < 0 || y >= h) {
        std::fill(hh, hh + w, 0.f);
        std::fill(uu, uu + w, 0.f);
        std::fill(vv, vv + w, 0.f);
        std::fill(mm, mm + w, 0.f);
        return;
      }
      ProjectRow(xyz.Row(y)->data(), w, frame, hh, uu, vv, mm);
    };
    int slot_of[3] = {0, 1, 2};  // slots of rows y-1, y, y+1
    fill_row(rows.begin() - 1, 0);
    fill_row(rows.begin(), 1);
    for (int y = rows.begin(); y < rows.end(); ++y) {
      fill_row(y + 1, slot_of[2]);
      for (int c = 0; c < kChannels; ++c) {
        const float* __restrict r0 = row_ptr(slot_of[0], c);
        const float* __restrict r1 = row_ptr(slot_of[1], c);
        const float* __restrict r2 = row_ptr(slot_of[2], c);
        float* __restrict s_out = vs.data() + c * stride;
        float* __restrict d_out = vd.data() + c * stride;
        for (size_t x = 0; x < stride; ++x) {
          s_out[x] = r0[x] + 2.f * r1[x] + r2[x];
          d_out[x] = r2[x] - r0[x];
        }
      }
      const float* centre[4] = {row_ptr(slot_of[1], 0) + 1, row_ptr(slot_of[1], 1) + 1,
                                row_ptr(slot_of[1], 2) + 1, row_ptr(slot_of[1], 3) + 1};
      BarrierRow(centre, vs.data() + 1, vd.data() + 1, stride, w, grad_limit2, slope2,
                 growable.ptr<uint8_t>(y), valid.ptr<uint8_t>(y));
      const int old = slot_of[0];
      slot_of[0] = slot_of[1];
      slot_of[1] = slot_of[2];
      slot_of[2] = old;
    }
  });
}

// Pixel count of a region over the area of its convex hull (the hull of each row's extreme
// pixels, rows scanned in parallel).
double Solidity(const cv::Mat& region, size_t count) {
  const int w = region.cols, h = region.rows;
  std::vector<int> first(static_cast<size_t>(h), -1), last(static_cast<size_t>(h), -1);
  tbb::parallel_for(tbb::blocked_range<int>(0, h, 64), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) {
      const uint8_t* row = region.ptr<uint8_t>(y);
      int a = 0, b = w - 1;
      while (a < w && !row[a]) ++a;
      if (a == w) continue;
      while (!row[b]) --b;
      first[static_cast<size_t>(y)] = a;
      last[static_cast<size_t>(y)] = b;
    }
  });
  std::vector<cv::Point2f> extremes;
  for (int y = 0; y < h; ++y) {
    if (first[static_cast<size_t>(y)] < 0) continue;
    // Pixel squares, not centres: a one-pixel-wide region has a hull of its own area.
    const float a = first[static_cast<size_t>(y)] - 0.5f, b = last[static_cast<size_t>(y)] + 0.5f;
    extremes.insert(extremes.end(), {{a, y - 0.5f}, {a, y + 0.5f}, {b, y - 0.5f}, {b, y + 0.5f}});
  }
  if (extremes.size() < 3) return 1;
  std::vector<cv::Point2f> hull;
  cv::convexHull(extremes, hull);
  const double area = cv::contourArea(hull);
  return area > 0 ? static_cast<double>(count) / area : 1;
}

// Packed indices y * width + x of the nonzero pixels of a continuous 8-bit image, in raster
// order; rows scanned in parallel, eight bytes at a time.
std::vector<int> NonZeroIndices(const cv::Mat& image) {
  const int w = image.cols, h = image.rows;
  std::vector<std::vector<int>> per_row(static_cast<size_t>(h));
  tbb::parallel_for(tbb::blocked_range<int>(0, h, 64), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) {
      const uint8_t* row = image.ptr<uint8_t>(y);
      int x = 0;
      for (; x + 8 <= w; x += 8) {
        uint64_t word;
        std::memcpy(&word, row + x, 8);
        if (!word) continue;
        for (int k = 0; k < 8; ++k)
          if (row[x + k]) per_row[static_cast<size_t>(y)].push_back(y * w + x + k);
      }
      for (; x < w; ++x)
        if (row[x]) per_row[static_cast<size_t>(y)].push_back(y * w + x);
    }
  });
  std::vector<int> out;
  for (const auto& v : per_row) out.insert(out.end(), v.begin(), v.end());
  return out;
}

// Nearest pixel to (cx, cy) with growable != 0, searched in square rings.
bool FindSeed(const cv::Mat& growable, int cx, int cy, int* sx, int* sy) {
  const int w = growable.cols, h = growable.rows;
  const int max_r = std::max(w, h);
  for (int r = 0; r <= max_r; ++r) {
    long best = std::numeric_limits<long>::max();
    for (int y = cy - r; y <= cy + r; ++y) {
      if (y < 0 || y >= h) continue;
      const bool edge_row = (y == cy - r || y == cy + r);
      const uint8_t* row = growable.ptr<uint8_t>(y);
      for (int x = cx - r; x <= cx + r; x += edge_row ? 1 : 2 * r) {
        if (x >= 0 && x < w && row[x]) {
          const long d =
              static_cast<long>(x - cx) * (x - cx) + static_cast<long>(y - cy) * (y - cy);
          if (d < best) {
            best = d;
            *sx = x;
            *sy = y;
          }
        }
        if (r == 0) break;
      }
    }
    if (best != std::numeric_limits<long>::max()) return true;
  }
  return false;
}

// Median in-plane spacing between 4-neighbours (dx, dy) that are both usable and in `mask`.
double MedianSpacing(const Grid<Vec3f>& xyz, const cv::Mat& mask, const LocalFrame& frame, int dx,
                     int dy, size_t mask_count) {
  const int stride = SampleStride(mask_count, kSpacingSamples);
  std::vector<double> d;
  for (int y = 0; y + dy < xyz.height; y += stride) {
    const uint8_t* m0 = mask.ptr<uint8_t>(y);
    const uint8_t* m1 = mask.ptr<uint8_t>(y + dy);
    for (int x = 0; x + dx < xyz.width; x += stride) {
      if (!m0[x] || !m1[x + dx]) continue;
      const Vec3f& p = xyz(x, y);
      const Vec3f& q = xyz(x + dx, y + dy);
      if (!Usable(p) || !Usable(q)) continue;
      d.push_back((frame.UV(q) - frame.UV(p)).norm());
    }
  }
  return Median(d);
}

// ---- Outline (step 5b): the visible canvas as a rectangle in the plane.
//
// A canvas is a rectangle and what hides it (the frame's edges) runs parallel to its sides, so
// the visible canvas is a rectangle in the canvas plane. Each scan pixel is placed in the plane
// where its ray meets it, by a homography fitted to the canvas samples (exact for a pinhole or
// orthographic scanner looking at a plane): no noise, no relief, and a place for missing
// samples too. The rectangle's sides are fitted there: angle from line fits of the outermost
// canvas-like samples per bin along each side, position by the threshold that best separates
// canvas-like samples (mask, within the noise of the local canvas height) from the rest. The
// mask is then every pixel the rectangle holds, so dropouts at the border do not notch it and
// samples climbing a bevel or a wall's foot above the canvas height are left out.
constexpr double kOutlineBandMm = 6;          // side band: this far either side of the first guess
constexpr double kOutlineBandSpacings = 20;   // ... or this many sample spacings, the larger
constexpr double kOutlineCornerShare = 0.04;  // side ends left out (corners are rounded by noise)
constexpr double kOutlineCornerMm = 5;
constexpr double kOutlineHeightSigmas = 4;     // canvas-like: within this many noise sigmas
constexpr double kOutlineHeightFloorMm = 0.1;  // ... or this, of the side's local canvas height
constexpr int kOutlineMinBins = 20;            // a side needs this many bins with a sample
constexpr double kOutlineMinSpanShare = 0.3;   // ... spanning this share of its length
constexpr double kOutlineMaxSideDisagreeDeg = 0.5;  // sides' angles agree within this, else no
                                                    // rectangle
constexpr double kOutlineMaxDisagreement = 0.05;    // rectangle vs mask (valid pixels): share
// Overhang: frame samples (higher than the canvas by kOverhangRiseMm) lying over the visible
// canvas by more than max(kOverhangMm, kOverhangSpacings spacings), along kOverhangShare of a
// side, mean the frame hides the canvas's edge there (a lip).
constexpr double kOverhangRiseMm = 1.0;
constexpr double kOverhangMm = 1.0;
constexpr double kOverhangSpacings = 2.0;
constexpr double kOverhangShare = 0.2;

struct Outline {
  bool ok = false;   // rectangle fitted and used for the mask
  double angle = 0;  // rectangle's first axis in the plane's (u, v), radians
  Eigen::Vector2d centre{0, 0};
  std::array<double, 4> edge{};  // outward offsets from the centre: +x', -x', +y', -y'
  std::array<bool, 4> closed{};
  std::array<bool, 4> overhang{};
  cv::Mat mask;      // 255 inside
  std::string note;  // why it was not used
};

// Outward normal of side s in (u, v) for a rectangle at `angle`.
Eigen::Vector2d SideNormal(int s, double angle) {
  const Eigen::Vector2d e0(std::cos(angle), std::sin(angle)), e1(-std::sin(angle), std::cos(angle));
  return s == 0 ? e0 : s == 1 ? Eigen::Vector2d(-e0) : s == 2 ? e1 : Eigen::Vector2d(-e1);
}

Outline FitOutline(const Grid<Vec3f>& xyz, const cv::Mat& mask, const cv::Mat& valid,
                   const cv::Mat& fit_mask, const LocalFrame& frame, double noise_sigma,
                   double spacing) {
  Outline out;
  const int w = xyz.width, h = xyz.height;
  // Homography pixel -> (u, v), fitted to the (relief-trimmed by reprojection) canvas samples.
  cv::Mat hom;
  cv::Point2f ref_px;  // a canvas sample's pixel: on the plane's side of the horizon
  {
    const size_t count = static_cast<size_t>(cv::countNonZero(fit_mask));
    const int stride = SampleStride(count, 20000);
    std::vector<cv::Point2f> px, uv;
    for (int y = 0; y < h; y += stride) {
      const uint8_t* m = fit_mask.ptr<uint8_t>(y);
      for (int x = 0; x < w; x += stride)
        if (m[x] && Usable(xyz(x, y))) {
          const Eigen::Vector2f q = frame.UV(xyz(x, y));
          px.emplace_back(static_cast<float>(x), static_cast<float>(y));
          uv.emplace_back(q.x(), q.y());
        }
    }
    if (px.size() < 12) {
      out.note = "too few canvas samples for the outline";
      return out;
    }
    ref_px = px[px.size() / 2];
    for (int pass = 0; pass < 2; ++pass) {
      hom = cv::findHomography(px, uv, 0);
      if (hom.empty() || pass == 1) break;
      std::vector<cv::Point2f> proj;
      cv::perspectiveTransform(px, proj, hom);
      std::vector<double> err(px.size());
      for (size_t i = 0; i < px.size(); ++i) err[i] = cv::norm(proj[i] - uv[i]);
      std::vector<double> tmp = err;
      const double limit = 3 * kMadToSigma * std::max(Median(tmp), 1e-6);
      std::vector<cv::Point2f> px2, uv2;
      for (size_t i = 0; i < px.size(); ++i)
        if (err[i] <= limit) px2.push_back(px[i]), uv2.push_back(uv[i]);
      if (px2.size() < 12) break;
      px.swap(px2), uv.swap(uv2);
    }
    if (hom.empty() || !cv::checkRange(hom)) {
      out.note = "no homography from the scan pixels to the canvas plane";
      return out;
    }
  }
  const cv::Matx33d H(hom);
  // Pixels whose rays miss the plane (beyond its horizon in the image: the homography's third
  // coordinate changes sign) have no place on it: NaN, which every test below reads as outside.
  const double z_sign = H(2, 0) * ref_px.x + H(2, 1) * ref_px.y + H(2, 2) >= 0 ? 1.0 : -1.0;
  auto plane_of = [&H, z_sign](int x, int y) -> Eigen::Vector2d {
    const double X = H(0, 0) * x + H(0, 1) * y + H(0, 2), Y = H(1, 0) * x + H(1, 1) * y + H(1, 2),
                 Z = H(2, 0) * x + H(2, 1) * y + H(2, 2);
    if (!(Z * z_sign > 1e-12))
      return Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN());
    return Eigen::Vector2d(X / Z, Y / Z);
  };

  // First guess: minimum-area rectangle of the mask's boundary pixels, placed by the homography.
  // Rows in parallel, gathered in row order (the same result whatever the schedule).
  auto gather_rows = [h](auto&& row_fn, auto& per_row) {
    tbb::parallel_for(tbb::blocked_range<int>(0, h, 16), [&](const tbb::blocked_range<int>& r) {
      for (int y = r.begin(); y < r.end(); ++y) row_fn(y, per_row[static_cast<size_t>(y)]);
    });
  };
  std::vector<cv::Point2f> boundary;
  {
    std::vector<std::vector<cv::Point2f>> per_row(static_cast<size_t>(h));
    gather_rows(
        [&](int y, std::vector<cv::Point2f>& row_out) {
          const uint8_t* m = mask.ptr<uint8_t>(y);
          for (int x = 0; x < w; ++x) {
            if (!m[x]) continue;
            const bool edge = x == 0 || y == 0 || x == w - 1 || y == h - 1 || !m[x - 1] ||
                              !m[x + 1] || !mask.ptr<uint8_t>(y - 1)[x] ||
                              !mask.ptr<uint8_t>(y + 1)[x];
            if (!edge) continue;
            const Eigen::Vector2d q = plane_of(x, y);
            if (q.allFinite())
              row_out.emplace_back(static_cast<float>(q.x()), static_cast<float>(q.y()));
          }
        },
        per_row);
    for (const auto& row : per_row) boundary.insert(boundary.end(), row.begin(), row.end());
  }
  if (boundary.size() < 8) {
    out.note = "mask too small for an outline";
    return out;
  }
  const cv::RotatedRect guess = cv::minAreaRect(boundary);
  cv::Point2f corner[4];
  guess.points(corner);
  const cv::Point2f e0 = corner[1] - corner[0], e1 = corner[2] - corner[1];
  const double angle0 = std::atan2(e0.y, e0.x);
  out.centre = Eigen::Vector2d(guess.center.x, guess.center.y);
  const double half0[2] = {0.5 * cv::norm(e0), 0.5 * cv::norm(e1)};
  const std::array<double, 4> edge0 = {half0[0], half0[0], half0[1], half0[1]};
  const double band = std::max(kOutlineBandMm, kOutlineBandSpacings * spacing);

  // Samples in the band around the guess, each on its nearest side.
  struct Cand {
    int side;
    float t, o;    // along the side, outwards (first-guess frame)
    float u, v;    // where the pixel's ray meets the plane
    float uo, vo;  // the sample projected on the plane (valid only)
    float height;  // above the plane (valid only)
    uint8_t in_mask, usable, scan_border;
  };
  std::array<std::vector<Cand>, 4> side_cands;
  const Eigen::Vector2d n0[4] = {SideNormal(0, angle0), SideNormal(1, angle0),
                                 SideNormal(2, angle0), SideNormal(3, angle0)};
  std::vector<std::array<std::vector<Cand>, 4>> cands_per_row(static_cast<size_t>(h));
  gather_rows(
      [&](int y, std::array<std::vector<Cand>, 4>& row_out) {
        const uint8_t* m = mask.ptr<uint8_t>(y);
        const uint8_t* ok = valid.ptr<uint8_t>(y);
        for (int x = 0; x < w; ++x) {
          const Eigen::Vector2d q = plane_of(x, y), d = q - out.centre;
          int best = -1;
          double best_dist = band;
          for (int s = 0; s < 4; ++s) {
            const double dist = std::fabs(n0[s].dot(d) - edge0[static_cast<size_t>(s)]);
            if (dist < best_dist) best = s, best_dist = dist;
          }
          if (best < 0) continue;
          const double o = n0[best].dot(d);
          // The band's inner half only gives the local canvas height: one sample in four will do.
          if (o < edge0[static_cast<size_t>(best)] - 0.5 * band && ((x | y) & 1)) continue;
          Cand c{};
          c.side = best;
          c.o = static_cast<float>(o);
          c.t = static_cast<float>(n0[best < 2 ? 2 : 0].dot(d));
          c.u = static_cast<float>(q.x()), c.v = static_cast<float>(q.y());
          c.in_mask = m[x] != 0;
          c.usable = ok[x] != 0;
          c.scan_border = x == 0 || y == 0 || x == w - 1 || y == h - 1;
          if (c.usable) {
            const Eigen::Vector2f qo = frame.UV(xyz(x, y));
            c.uo = qo.x(), c.vo = qo.y();
            c.height = frame.H(xyz(x, y));
          }
          row_out[static_cast<size_t>(best)].push_back(c);
        }
      },
      cands_per_row);
  for (const auto& row : cands_per_row)
    for (int s = 0; s < 4; ++s)
      side_cands[static_cast<size_t>(s)].insert(side_cands[static_cast<size_t>(s)].end(),
                                                row[static_cast<size_t>(s)].begin(),
                                                row[static_cast<size_t>(s)].end());

  // Per side: the local canvas height (a line along the side, from the band's inner half),
  // canvas-like samples, open or closed, and the side's angle.
  const double tol = std::max(kOutlineHeightSigmas * noise_sigma, kOutlineHeightFloorMm);
  std::array<std::vector<uint8_t>, 4> canvas_like;
  std::array<Eigen::Vector2d, 4> height_line;  // height = [0] + [1] t
  std::array<double, 4> delta{}, weight{};
  std::array<double, 4> half_len{};
  for (int s = 0; s < 4; ++s) {
    const auto& cands = side_cands[static_cast<size_t>(s)];
    const double e = edge0[static_cast<size_t>(s)];
    half_len[static_cast<size_t>(s)] = s < 2 ? half0[1] : half0[0];
    const double corner_cut =
        half_len[static_cast<size_t>(s)] -
        std::max(kOutlineCornerMm, kOutlineCornerShare * 2 * half_len[static_cast<size_t>(s)]);
    // Height line by trimmed least squares.
    std::vector<const Cand*> inner;
    for (const Cand& c : cands) {
      if (c.in_mask && c.usable && c.o < e - 0.5 * band && std::fabs(c.t) < corner_cut)
        inner.push_back(&c);
    }
    Eigen::Vector2d line(0, 0);
    for (int pass = 0; pass < 3 && inner.size() >= 3; ++pass) {
      Eigen::Matrix2d ata = Eigen::Matrix2d::Zero();
      Eigen::Vector2d atb = Eigen::Vector2d::Zero();
      for (const Cand* c : inner) {
        const Eigen::Vector2d a(1, c->t);
        ata += a * a.transpose();
        atb += a * c->height;
      }
      if (std::fabs(ata.determinant()) < 1e-12) break;
      line = ata.ldlt().solve(atb);
      std::vector<double> r;
      for (const Cand* c : inner) r.push_back(c->height - line.dot(Eigen::Vector2d(1, c->t)));
      std::vector<double> tmp = r;
      const double med = Median(tmp);
      const double lim = 3 * kMadToSigma * std::max(Mad(r, med), 1e-4);
      std::vector<const Cand*> kept;
      for (size_t i = 0; i < inner.size(); ++i)
        if (std::fabs(r[i] - med) <= lim) kept.push_back(inner[i]);
      inner.swap(kept);
    }
    height_line[static_cast<size_t>(s)] = line;
    auto& like = canvas_like[static_cast<size_t>(s)];
    like.resize(cands.size());
    for (size_t i = 0; i < cands.size(); ++i) {
      const Cand& c = cands[i];
      like[i] = c.in_mask && c.usable && c.height <= line.dot(Eigen::Vector2d(1, c.t)) + tol;
    }
    // Bins of one spacing along the side: the outermost canvas-like sample of each, unless it
    // lies on the scan's border (the canvas goes on beyond the view there).
    const int nbins = std::max(1, static_cast<int>(2 * corner_cut / spacing));
    std::vector<int> bin_best(static_cast<size_t>(nbins), -1);
    for (size_t i = 0; i < cands.size(); ++i) {
      const Cand& c = cands[i];
      if (!like[i] || std::fabs(c.t) >= corner_cut) continue;
      const int b = std::clamp(static_cast<int>((c.t + corner_cut) / spacing), 0, nbins - 1);
      int& best = bin_best[static_cast<size_t>(b)];
      if (best < 0 || c.o > cands[static_cast<size_t>(best)].o) best = static_cast<int>(i);
    }
    std::vector<Eigen::Vector2d> pts;  // (t, o)
    for (int b = 0; b < nbins; ++b) {
      const int best = bin_best[static_cast<size_t>(b)];
      if (best >= 0 && !cands[static_cast<size_t>(best)].scan_border)
        pts.emplace_back(-corner_cut + (b + 0.5) * spacing, cands[static_cast<size_t>(best)].o);
    }
    // Open: too little of the side's edge is in view to place it.
    out.closed[static_cast<size_t>(s)] =
        static_cast<int>(pts.size()) >= kOutlineMinBins &&
        pts.back().x() - pts.front().x() >=
            kOutlineMinSpanShare * 2 * half_len[static_cast<size_t>(s)];
    if (!out.closed[static_cast<size_t>(s)]) continue;
    double beta = 0;
    bool fitted = false;
    for (int pass = 0; pass < 4 && pts.size() >= 3; ++pass) {
      Eigen::Matrix2d ata = Eigen::Matrix2d::Zero();
      Eigen::Vector2d atb = Eigen::Vector2d::Zero();
      for (const auto& p : pts) {
        const Eigen::Vector2d a(1, p.x());
        ata += a * a.transpose();
        atb += a * p.y();
      }
      if (std::fabs(ata.determinant()) < 1e-12) break;
      const Eigen::Vector2d ab = ata.ldlt().solve(atb);
      beta = ab(1);
      fitted = true;
      std::vector<double> r;
      for (const auto& p : pts) r.push_back(p.y() - ab(0) - ab(1) * p.x());
      std::vector<double> tmp = r;
      const double med = Median(tmp);
      const double lim = std::max(3 * kMadToSigma * Mad(r, med), 0.5 * spacing);
      std::vector<Eigen::Vector2d> kept;
      for (size_t i = 0; i < pts.size(); ++i)
        if (std::fabs(r[i] - med) <= lim) kept.push_back(pts[i]);
      if (kept.size() == pts.size()) break;
      pts.swap(kept);
    }
    if (!fitted || static_cast<int>(pts.size()) < kOutlineMinBins) continue;
    const double span = pts.back().x() - pts.front().x();
    if (span < kOutlineMinSpanShare * 2 * half_len[static_cast<size_t>(s)]) continue;
    static constexpr double kSign[4] = {-1, 1, 1, -1};
    delta[static_cast<size_t>(s)] = std::atan(kSign[s] * beta);
    weight[static_cast<size_t>(s)] = static_cast<double>(pts.size()) * span * span;
  }
  double wsum = 0, dsum = 0;
  for (int s = 0; s < 4; ++s)
    wsum += weight[static_cast<size_t>(s)],
        dsum += weight[static_cast<size_t>(s)] * delta[static_cast<size_t>(s)];
  if (!(wsum > 0)) {
    out.note = "no side of the canvas outline could be fitted";
    return out;
  }
  const double d = dsum / wsum;
  for (int s = 0; s < 4; ++s)
    if (weight[static_cast<size_t>(s)] > 0 &&
        std::fabs(delta[static_cast<size_t>(s)] - d) > kOutlineMaxSideDisagreeDeg * kPi / 180) {
      out.note = "the outline's sides are not those of a rectangle";
      return out;
    }
  out.angle = angle0 + d;

  // Side positions in the refined frame: the threshold that best separates canvas-like samples
  // (inside) from the others (outside); open sides reach the mask's extent.
  for (int s = 0; s < 4; ++s) {
    const auto& cands = side_cands[static_cast<size_t>(s)];
    const auto& like = canvas_like[static_cast<size_t>(s)];
    const Eigen::Vector2d n = SideNormal(s, out.angle);
    const double corner_cut =
        half_len[static_cast<size_t>(s)] -
        std::max(kOutlineCornerMm, kOutlineCornerShare * 2 * half_len[static_cast<size_t>(s)]);
    std::vector<std::pair<float, int>> samples;  // (offset, +1 inside / -1 outside)
    double mask_extent = -std::numeric_limits<double>::max();
    for (size_t i = 0; i < cands.size(); ++i) {
      const Cand& c = cands[i];
      const double o = n.dot(Eigen::Vector2d(c.u, c.v) - out.centre);
      if (c.in_mask) mask_extent = std::max(mask_extent, o);
      if (!c.usable || std::fabs(c.t) >= corner_cut) continue;
      samples.emplace_back(static_cast<float>(o), like[i] ? 1 : -1);
    }
    if (!out.closed[static_cast<size_t>(s)] || samples.empty()) {
      out.closed[static_cast<size_t>(s)] = false;
      out.edge[static_cast<size_t>(s)] = mask_extent > -std::numeric_limits<double>::max()
                                             ? mask_extent + spacing
                                             : edge0[static_cast<size_t>(s)];
      continue;
    }
    std::sort(samples.begin(), samples.end());
    long cost = 0;
    for (const auto& p : samples) cost += p.second > 0;
    long best = cost;
    size_t best_k = 0;  // edge before samples[best_k]
    for (size_t k = 0; k < samples.size(); ++k) {
      cost += samples[k].second > 0 ? -1 : 1;
      if (cost < best) best = cost, best_k = k + 1;
    }
    // The edge at the outermost canvas-like sample of the best split: pixels beyond it up to
    // the first other sample may be missing samples of a steep wall seen edge-on.
    const double e = best_k == 0 ? samples.front().first : samples[best_k - 1].first;
    out.edge[static_cast<size_t>(s)] = e;
    // Overhang: frame samples over the visible canvas.
    const double reach = std::max(kOverhangMm, kOverhangSpacings * spacing);
    size_t over = 0;
    for (size_t i = 0; i < cands.size(); ++i) {
      const Cand& c = cands[i];
      // A frame sample: outside the grown region, its ray past the edge.
      if (!c.usable || c.in_mask || std::fabs(c.t) >= corner_cut ||
          !(n.dot(Eigen::Vector2d(c.u, c.v) - out.centre) > e))
        continue;
      const double rise =
          c.height - height_line[static_cast<size_t>(s)].dot(Eigen::Vector2d(1, c.t));
      const double o = n.dot(Eigen::Vector2d(c.uo, c.vo) - out.centre);
      if (rise > kOverhangRiseMm && o < e - reach) ++over;
    }
    out.overhang[static_cast<size_t>(s)] = over > kOverhangShare * 2 * corner_cut / spacing;
  }

  // The mask: every pixel whose ray meets the plane inside the rectangle, but for samples the
  // grown region left out: those stay out unless they lie a sample spacing inside it, within
  // the canvas's height band (a frame sample grazed at the very edge is no canvas).
  double band_mm = tol;
  for (int s = 0; s < 4; ++s)
    for (double t : {-half_len[static_cast<size_t>(s)], half_len[static_cast<size_t>(s)]})
      band_mm = std::max(
          band_mm, tol + std::fabs(height_line[static_cast<size_t>(s)].dot(Eigen::Vector2d(1, t))));
  out.mask = cv::Mat::zeros(h, w, CV_8U);
  std::array<Eigen::Vector2d, 4> normals;
  for (int s = 0; s < 4; ++s) normals[static_cast<size_t>(s)] = SideNormal(s, out.angle);
  std::atomic<size_t> differ{0};
  tbb::parallel_for(tbb::blocked_range<int>(0, h, 32), [&](const tbb::blocked_range<int>& r) {
    size_t local = 0;
    for (int y = r.begin(); y < r.end(); ++y) {
      uint8_t* o = out.mask.ptr<uint8_t>(y);
      const uint8_t* m = mask.ptr<uint8_t>(y);
      const uint8_t* ok = valid.ptr<uint8_t>(y);
      for (int x = 0; x < w; ++x) {
        const Eigen::Vector2d dq = plane_of(x, y) - out.centre;
        double inside = std::numeric_limits<double>::max();
        for (int s = 0; s < 4; ++s)
          inside = std::min(
              inside, out.edge[static_cast<size_t>(s)] - normals[static_cast<size_t>(s)].dot(dq));
        bool in = inside >= 0 && std::isfinite(dq.x());
        local += ok[x] && (in != (m[x] != 0));
        if (in && ok[x] && !m[x]) in = inside > spacing && std::fabs(frame.H(xyz(x, y))) <= band_mm;
        o[x] = in ? 255 : 0;
      }
    }
    differ += local;
  });
  const double mask_px = std::max(1.0, static_cast<double>(cv::countNonZero(mask)));
  if (static_cast<double>(differ.load()) > kOutlineMaxDisagreement * mask_px) {
    out.note = "the canvas outline is not a rectangle (it differs from the grown region by " +
               std::to_string(static_cast<int>(100.0 * differ.load() / mask_px)) + " %)";
    out.mask.release();
    return out;
  }
  out.ok = true;
  return out;
}
}  // namespace

Status CanvasOptions::Validate() const {
  auto fail = [](const std::string& what) { return Status(Error{"canvas options: " + what}); };
  if (!(stop_gradient_mm > 0) || !std::isfinite(stop_gradient_mm))
    return fail("stop_gradient_mm must be > 0, got " + std::to_string(stop_gradient_mm));
  if (!(stop_slope > 0) || !std::isfinite(stop_slope))
    return fail("stop_slope must be > 0, got " + std::to_string(stop_slope));
  if (!(refine_step_mm > 0) || !std::isfinite(refine_step_mm))
    return fail("refine_step_mm must be > 0, got " + std::to_string(refine_step_mm));
  if (refine_px < 0 || refine_px > 1000)
    return fail("refine_px must be in [0, 1000], got " + std::to_string(refine_px));
  if (erode_px < 0 || erode_px > 1000)
    return fail("erode_px must be in [0, 1000], got " + std::to_string(erode_px));
  if (!(trim_sigmas > 0) || !std::isfinite(trim_sigmas))
    return fail("trim_sigmas must be > 0, got " + std::to_string(trim_sigmas));
  if ((seed_x < 0) != (seed_y < 0) || seed_x < -1 || seed_y < -1)
    return fail("seed must be both -1 (scan centre) or both >= 0, got (" + std::to_string(seed_x) +
                ", " + std::to_string(seed_y) + ")");
  if (!(min_canvas_fraction >= 0 && min_canvas_fraction <= 1))
    return fail("min_canvas_fraction must be in [0, 1], got " +
                std::to_string(min_canvas_fraction));
  return Status::Ok();
}

PlaneFit FitPlanePca(const std::vector<Vec3d>& points) {
  // Shift by the first finite point so the second moments stay small.
  Vec3d shift = Vec3d::Zero();
  for (const Vec3d& p : points)
    if (p.allFinite()) {
      shift = p;
      break;
    }
  const Moments m = tbb::parallel_deterministic_reduce(
      tbb::blocked_range<size_t>(0, points.size(), 4096), Moments{},
      [&](const tbb::blocked_range<size_t>& r, Moments acc) {
        for (size_t i = r.begin(); i < r.end(); ++i)
          if (points[i].allFinite()) {
            const Vec3d d = points[i] - shift;
            acc.Add(d.x(), d.y(), d.z());
          }
        return acc;
      },
      [](Moments a, const Moments& b) {
        a.Merge(b);
        return a;
      });
  return PlaneFromMoments(m, shift);
}

Result<CanvasResult> ExtractCanvas(const Scan& scan, const CanvasOptions& options) {
  const std::string src = SourceName(scan);
  if (Status st = options.Validate(); !st.ok()) return Error{src + ": " + st.message()};
  const Grid<Vec3f>& xyz = scan.xyz_mm;
  const int w = xyz.width, h = xyz.height;
  if (xyz.empty() || xyz.data.size() != static_cast<size_t>(w) * static_cast<size_t>(h))
    return Error{src + ": empty scan (" + std::to_string(w) + "x" + std::to_string(h) + ")"};

  // ---- 1. Rough plane of every usable sample.
  // Moments about the first usable sample at or after the centre keep the covariance well
  // conditioned; the rough plane needs only a regular subsample.
  Vec3d shift = Vec3d::Zero();
  {
    const size_t total = xyz.size(), start = total / 2;
    for (size_t k = 0; k < total; ++k) {
      const Vec3f& p = xyz.data[(start + k) % total];
      if (Usable(p)) {
        shift = p.cast<double>();
        break;
      }
    }
  }
  const auto all = [](int, int, const Vec3f&) { return true; };
  const int rough_stride = SampleStride(xyz.size(), kRoughSamples);
  PlaneFit rough = FitGrid(xyz, shift, rough_stride, all);
  if (rough_stride > 1 && rough.count < kRoughSamples / 100) rough = FitGrid(xyz, shift, 1, all);
  if (rough.count < kMinValidSamples)
    return Error{src + ": only " + std::to_string(rough.count) + " valid samples in a " +
                 std::to_string(w) + "x" + std::to_string(h) + " scan (at least " +
                 std::to_string(kMinValidSamples) + " needed to find a canvas)"};
  if (!(rough.eigenvalues(1) > 1e-9 * rough.eigenvalues(0)) || !(rough.eigenvalues(0) > 0))
    return Error{src + ": the valid samples are (nearly) collinear; a " + std::to_string(w) + "x" +
                 std::to_string(h) + " scan does not span a canvas plane"};

  // ---- 2. Barrier mask.
  cv::Mat grow, valid;
  GrowableMask(xyz, LocalFrame(rough), options.stop_gradient_mm, options.stop_slope, grow, valid);
  const size_t valid_count = static_cast<size_t>(cv::countNonZero(valid));

  // ---- 3. Region growing from the seed, enclosed islands added back.
  const bool user_seed = options.seed_x >= 0;
  int cx = user_seed ? options.seed_x : w / 2, cy = user_seed ? options.seed_y : h / 2;
  if (user_seed && (cx >= w || cy >= h))
    return Error{src + ": seed " + PointText(cx, cy) + " lies outside the " + std::to_string(w) +
                 "x" + std::to_string(h) + " scan"};
  int sx = -1, sy = -1;
  if (!FindSeed(grow, cx, cy, &sx, &sy))
    return Error{src + ": no valid sample with a low gradient near the seed " + PointText(cx, cy) +
                 "; nothing to grow the canvas from"};
  const int grown = cv::floodFill(grow, cv::Point(sx, sy), cv::Scalar(2), nullptr, cv::Scalar(0),
                                  cv::Scalar(0), 8);
  cv::Mat region;
  cv::compare(grow, 2, region, cv::CMP_EQ);  // 255 / 0
  const cv::Mat islands = EnclosedIslands(region);
  const size_t islands_px = static_cast<size_t>(cv::countNonZero(islands));
  const std::string seed_text = PointText(sx, sy);
  const std::string seed_hint =
      user_seed ? "" : "; the canvas may be off-centre: give a seed on the canvas (--seed X,Y)";
  if (islands_px > static_cast<size_t>(grown))
    return Error{src + ": the region grown from seed " + seed_text + " (" + std::to_string(grown) +
                 " px) encloses a larger area (" + std::to_string(islands_px) +
                 " px): the seed is on the frame or the wall, not on the canvas" + seed_hint};
  cv::Mat filled;
  cv::bitwise_or(region, islands, filled);
  region.release();
  const size_t filled_px = static_cast<size_t>(grown) + islands_px;
  if (static_cast<double>(filled_px) <
      options.min_canvas_fraction * static_cast<double>(valid_count))
    return Error{
        src + ": the region grown from seed " + seed_text + " covers " + std::to_string(filled_px) +
        " px, less than " + std::to_string(options.min_canvas_fraction * 100) + " % of the " +
        std::to_string(valid_count) + " valid samples (seed on the frame or a speck?)" + seed_hint};
  // A canvas seen by a scanner is convex (a rectangle, an oval; occlusion by the frame cuts it
  // along straight lines). A region grown on the frame is a ring or a part of one: it fills a
  // small share of its convex hull.
  if (const double solidity = Solidity(filled, filled_px); solidity < kMinSolidity)
    return Error{src + ": the region grown from seed " + seed_text + " is not convex (it fills " +
                 std::to_string(static_cast<int>(solidity * 100)) +
                 " % of its convex hull): the seed is on the frame or the wall, not on the canvas" +
                 seed_hint};

  // ---- 4. Robust plane on the eroded region.
  const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3));
  cv::Mat fit_mask;
  if (options.erode_px > 0)
    cv::erode(filled, fit_mask, kernel, cv::Point(-1, -1), options.erode_px);
  else
    fit_mask = filled.clone();
  cv::bitwise_and(fit_mask, valid, fit_mask);  // valid is 0/1: nonzero where valid
  if (static_cast<size_t>(cv::countNonZero(fit_mask)) < kMinValidSamples)
    cv::bitwise_and(filled, valid, fit_mask);  // tiny canvas: fit on all of it
  const size_t fit_mask_count = static_cast<size_t>(cv::countNonZero(fit_mask));
  // The fit samples, gathered once (a regular subsample of the eroded canvas).
  std::vector<Vec3f> fit_points;
  {
    const int stride = SampleStride(fit_mask_count, kFitSamples);
    const int rows_sampled = (h + stride - 1) / stride;
    std::vector<std::vector<Vec3f>> per_row(static_cast<size_t>(rows_sampled));
    tbb::parallel_for(tbb::blocked_range<int>(0, rows_sampled),
                      [&](const tbb::blocked_range<int>& r) {
                        for (int i = r.begin(); i < r.end(); ++i) {
                          const int y = i * stride;
                          const uint8_t* m = fit_mask.ptr<uint8_t>(y);
                          const Vec3f* row = xyz.Row(y);
                          for (int x = 0; x < w; x += stride)
                            if (m[x] && Usable(row[x]))
                              per_row[static_cast<size_t>(i)].push_back(row[x]);
                        }
                      });
    size_t total = 0;
    for (const auto& v : per_row) total += v.size();
    fit_points.reserve(total);
    for (const auto& v : per_row) fit_points.insert(fit_points.end(), v.begin(), v.end());
  }
  PlaneFit plane = FitPoints(fit_points, rough.centroid, [](const Vec3f&) { return true; });
  if (plane.count < 3)
    return Error{src + ": too few canvas samples (" + std::to_string(plane.count) +
                 ") to fit the canvas plane"};
  const size_t residual_step = std::max<size_t>(1, fit_points.size() / kStatSamples);
  for (int it = 0; it < kTrimIterations; ++it) {
    const Eigen::Vector3f c = plane.centroid.cast<float>(), n = plane.axes.col(2).cast<float>();
    std::vector<double> r;
    r.reserve(fit_points.size() / residual_step + 1);
    for (size_t i = 0; i < fit_points.size(); i += residual_step)
      r.push_back(n.dot(fit_points[i] - c));
    if (r.size() < 3) break;
    std::vector<double> tmp = r;
    const double med = Median(tmp);
    const double sigma = std::max(kMadToSigma * Mad(r, med), 1e-6);
    const float hi = static_cast<float>(med + options.trim_sigmas * sigma);
    const float lo = static_cast<float>(med - kLowerTrimFactor * options.trim_sigmas * sigma);
    PlaneFit next = FitPoints(fit_points, plane.centroid, [&](const Vec3f& p) {
      const float d = n.dot(p - c);
      return d >= lo && d <= hi;
    });
    if (next.count < 3 || !(next.eigenvalues(1) > 0)) break;
    plane = next;
  }
  const LocalFrame frame(plane);

  // Noise: Immerkaer's mask [1 -2 1; -2 4 -2; 1 -2 1] (a product of second differences, blind to
  // planes and to curvature along x or y) has a response of 6 sigma on white noise.
  double noise_sigma = 0;
  {
    std::vector<double> resp;
    const int noise_stride = SampleStride(fit_mask_count, kNoiseSamples);
    for (int y = 1; y + 1 < h; y += noise_stride) {
      const uint8_t* m = fit_mask.ptr<uint8_t>(y);
      for (int x = 1; x + 1 < w; x += noise_stride) {
        if (!m[x]) continue;
        static constexpr float k[3][3] = {{1, -2, 1}, {-2, 4, -2}, {1, -2, 1}};
        double acc = 0;
        bool ok = true;
        for (int j = -1; j <= 1 && ok; ++j)
          for (int i = -1; i <= 1; ++i) {
            const Vec3f& p = xyz(x + i, y + j);
            if (!Usable(p)) {
              ok = false;
              break;
            }
            acc += k[j + 1][i + 1] * frame.H(p);
          }
        if (ok) resp.push_back(acc);
      }
    }
    if (!resp.empty()) {
      std::vector<double> tmp = resp;
      const double med = Median(tmp);
      noise_sigma = kMadToSigma * Mad(resp, med) / 6.0;
    }
  }

  // ---- 5. Boundary: peel, then regrow with the strict test.
  cv::Mat core;
  cv::erode(filled, core, kernel, cv::Point(-1, -1), kPeelPx);
  if (cv::countNonZero(core) == 0) core = filled.clone();
  const double spacing_x = MedianSpacing(xyz, core, frame, 1, 0, fit_mask_count);
  const double spacing_y = MedianSpacing(xyz, core, frame, 0, 1, fit_mask_count);
  const double tol_loose =
      std::max(kRefineCurvatureShare * options.refine_step_mm, kRefineNoiseSigmas * noise_sigma);
  const double tol_tight = kTightSigmas * std::sqrt(6.0) * noise_sigma + kTightFloorMm;
  const float tol_line = static_cast<float>(kLineSigmas * std::sqrt(6.0) * noise_sigma +
                                            kLineFloorShare * std::min(spacing_x, spacing_y));
  const float rise_line = static_cast<float>(kLineRiseSigmas * std::sqrt(2.0) * noise_sigma +
                                             kLineFloorShare * std::min(spacing_x, spacing_y));
  const float step_mm = static_cast<float>(options.refine_step_mm);
  // The mask being refined: 255 = in. Continuous, so it is indexed directly.
  cv::Mat mask = core.isContinuous() ? core : core.clone();
  core.release();
  uint8_t* in = mask.data;
  auto idx = [w](int x, int y) { return static_cast<size_t>(y) * w + x; };
  auto usable_at = [&](int x, int y) { return valid.ptr<uint8_t>(y)[x] != 0; };
  static constexpr int kDx[4] = {1, -1, 0, 0};
  static constexpr int kDy[4] = {0, 0, 1, -1};
  auto inside = [&](int x, int y) { return x >= 0 && y >= 0 && x < w && y < h; };
  auto accept = [&](int qx, int qy) {
    const Vec3f& pq = xyz(qx, qy);
    const float hq = frame.H(pq);
    // A barrier next to q (steep or a step: a frame wall) clearly higher or lower, or a missing
    // sample: q may be a wall's foot, so q must then continue the canvas within the noise.
    bool wall_next = false;
    for (int d = 0; d < 4; ++d) {
      const int x1 = qx + kDx[d], y1 = qy + kDy[d];
      if (!inside(x1, y1)) continue;
      const double spacing = kDx[d] != 0 ? spacing_x : spacing_y;
      if (!usable_at(x1, y1)) {
        // A missing neighbour outside the region may be a wall the scanner saw too obliquely to
        // measure (structured light drops grazing surfaces): q may be its foot.
        wall_next = wall_next || !in[idx(x1, y1)];
        // The same foot test one step further (q = 3 p(q+2d) - 2 p(q+3d)).
        const int x2 = x1 + kDx[d], y2 = y1 + kDy[d], x3 = x2 + kDx[d], y3 = y2 + kDy[d];
        if (!inside(x3, y3) || !usable_at(x2, y2) || !usable_at(x3, y3) || in[idx(x2, y2)] ||
            in[idx(x3, y3)])
          continue;
        const Vec3f& p2 = xyz(x2, y2);
        const Vec3f& p3 = xyz(x3, y3);
        const float h2 = frame.H(p2);
        const float rise = std::fabs(frame.H(p3) - h2);
        if (!(rise > rise_line && rise > kLineSlope * (frame.UV(p3) - frame.UV(p2)).norm()))
          continue;
        wall_next = wall_next || std::fabs(h2 - hq) > 2 * kWallRise * spacing;
        if ((pq - 3.0f * p2 + 2.0f * p3).norm() < kFarLineFactor * tol_line) return false;
        continue;
      }
      if (in[idx(x1, y1)]) continue;
      const int x2 = x1, y2 = y1;
      const Vec3f& p2 = xyz(x2, y2);
      const float h2 = frame.H(p2);
      const bool barrier = grow.ptr<uint8_t>(y2)[x2] == 0;
      wall_next = wall_next || (barrier && std::fabs(h2 - hq) > kWallRise * spacing);
      // Foot test: samples of parallel, evenly spaced rays on a plane are evenly spaced on a
      // line, so q is on the wall when it continues the steep run q + 2d, q + d outside the
      // region (a wall's lowest samples need not be barriers when the rest is missing). A canvas
      // sample before the wall misses that point by (its distance to the wall) / sin(view angle).
      const int x3 = x2 + kDx[d], y3 = y2 + kDy[d];
      if (!inside(x3, y3) || !usable_at(x3, y3) || in[idx(x3, y3)]) continue;
      const Vec3f& p3 = xyz(x3, y3);
      const float rise = std::fabs(frame.H(p3) - h2);
      if (!(rise > rise_line && rise > kLineSlope * (frame.UV(p3) - frame.UV(p2)).norm())) continue;
      if ((pq - 2.0f * p2 + p3).norm() < tol_line) return false;
    }
    const double tol = wall_next ? tol_tight : tol_loose;
    // Every region neighbour must agree: small step, and q on the linear extrapolation of the
    // region through that neighbour.
    int agree = 0;
    for (int d = 0; d < 4; ++d) {
      const int rx = qx - kDx[d], ry = qy - kDy[d];
      if (!inside(rx, ry) || !in[idx(rx, ry)] || !usable_at(rx, ry)) continue;
      const float hr = frame.H(xyz(rx, ry));
      if (!(std::fabs(hq - hr) < step_mm)) return false;
      const int r2x = rx - kDx[d], r2y = ry - kDy[d];
      double second = hq - hr;
      if (inside(r2x, r2y) && in[idx(r2x, r2y)] != 0 && usable_at(r2x, r2y))
        second = hq - 2.0 * hr + frame.H(xyz(r2x, r2y));
      if (!(std::fabs(second) < tol)) return false;
      ++agree;
    }
    return agree > 0;
  };
  // Initial frontier: pixels outside the core with a 4-neighbour inside.
  std::vector<int> frontier;  // packed y * w + x
  {
    cv::Mat ring;
    cv::dilate(mask, ring, cv::getStructuringElement(cv::MORPH_CROSS, cv::Size(3, 3)));
    cv::bitwise_xor(ring, mask, ring);
    frontier = NonZeroIndices(ring);
  }
  std::vector<int> accepted;
  // The refinement may reach refine_px beyond the grown region; within that band it runs to
  // convergence (paths around missing samples are longer than the distance).
  cv::Mat band;
  cv::dilate(filled, band, kernel, cv::Point(-1, -1), options.refine_px);
  const uint8_t* in_band = band.data;
  for (int step = 0; step < kMaxRefineSteps && !frontier.empty(); ++step) {
    accepted.clear();
    for (int q : frontier) {
      const int qx = q % w, qy = q / w;
      if (in[idx(qx, qy)] || !in_band[q]) continue;
      if (!usable_at(qx, qy)) continue;
      if (accept(qx, qy)) accepted.push_back(q);
    }
    for (int q : accepted) in[static_cast<size_t>(q)] = 255;
    frontier.clear();
    for (int q : accepted) {
      const int qx = q % w, qy = q / w;
      for (int d = 0; d < 4; ++d) {
        const int nx = qx + kDx[d], ny = qy + kDy[d];
        if (inside(nx, ny) && !in[idx(nx, ny)]) frontier.push_back(ny * w + nx);
      }
    }
  }
  // Missing samples: those the grown region enclosed stay canvas (the truth behind a dropout is
  // the surface around it), and so do those with mask pixels on both sides along a row or a
  // column within kConvexReachPx (the canvas as the scanner sees it is convex); then everything
  // the final mask encloses.
  cv::Mat final_mask = mask;
  {
    cv::Mat missing;
    cv::compare(valid, 0, missing, cv::CMP_EQ);
    cv::Mat add;
    cv::bitwise_and(filled, missing, add);
    final_mask.setTo(255, add);
    auto reach = [&](int kw, int kh, cv::Point anchor) {
      cv::Mat out;
      cv::dilate(final_mask, out, cv::Mat::ones(kh, kw, CV_8U), anchor, 1, cv::BORDER_CONSTANT,
                 cv::Scalar(0));
      return out;
    };
    const int r = kConvexReachPx;
    cv::Mat left = reach(r + 1, 1, cv::Point(r, 0)), right = reach(r + 1, 1, cv::Point(0, 0));
    cv::Mat up = reach(1, r + 1, cv::Point(0, r)), down = reach(1, r + 1, cv::Point(0, 0));
    cv::bitwise_and(left, right, left);
    cv::bitwise_and(up, down, up);
    cv::bitwise_or(left, up, add);
    cv::bitwise_and(add, missing, add);
    final_mask.setTo(255, add);
    const cv::Mat holes = EnclosedIslands(final_mask);
    cv::bitwise_or(final_mask, holes, final_mask);
  }

  // ---- 5b. Outline: the visible canvas as a rectangle in the plane (axes, mask, hidden edges).
  const Outline outline = FitOutline(xyz, final_mask, valid, fit_mask, frame, noise_sigma,
                                     std::min(spacing_x, spacing_y));
  if (outline.ok) final_mask = outline.mask;

  // ---- 6. Canvas frame.
  const Vec3d n = plane.axes.col(2);
  Vec3d x_axis;
  {
    Vec3d scan_x = Vec3d::UnitX() - n.x() * n;  // scan +X projected on the plane
    if (scan_x.norm() < 1e-6) scan_x = plane.axes.col(0);
    scan_x.normalize();
    const double l1 = plane.eigenvalues(0), l2 = plane.eigenvalues(1);
    const Vec3d a = plane.axes.col(0), b = plane.axes.col(1);
    if (outline.ok) {
      // The canvas edges give the axes; the PCA axes of the relief-trimmed points are pulled by
      // the impasto (about a degree).
      const Vec3d e0 = std::cos(outline.angle) * a + std::sin(outline.angle) * b;
      const Vec3d e1 = n.cross(e0);
      x_axis = std::fabs(e0.dot(scan_x)) >= std::fabs(e1.dot(scan_x)) ? e0 : e1;
      if (x_axis.dot(scan_x) < 0) x_axis = -x_axis;
    } else if (l1 - l2 <= kIsotropicEigen * l1) {
      x_axis = scan_x;
    } else {
      x_axis = std::fabs(a.dot(scan_x)) >= std::fabs(b.dot(scan_x)) ? a : b;
      if (x_axis.dot(scan_x) < 0) x_axis = -x_axis;
    }
  }
  const Vec3d y_axis = n.cross(x_axis).normalized();
  x_axis = y_axis.cross(n).normalized();
  Mat3d rot;
  rot.row(0) = x_axis.transpose();
  rot.row(1) = y_axis.transpose();
  rot.row(2) = n.transpose();
  const Vec3d c0 = plane.centroid;
  struct Box {
    double x0 = std::numeric_limits<double>::max(), y0 = std::numeric_limits<double>::max();
    double x1 = std::numeric_limits<double>::lowest(), y1 = std::numeric_limits<double>::lowest();
    size_t count = 0;                 // points in the rectangle
    size_t mask_px = 0, kept_px = 0;  // mask pixels; of those, in the grown + filled region
  };
  // Bounding rectangle of the mask points, the output mask and its counts in one parallel pass.
  CanvasResult result;
  result.mask_scan = Grid<uint8_t>(w, h, 0);
  auto box_of = [&](bool bound_height) {
    return tbb::parallel_reduce(
        tbb::blocked_range<int>(0, h), Box{},
        [&](const tbb::blocked_range<int>& rows, Box b) {
          for (int y = rows.begin(); y < rows.end(); ++y) {
            const uint8_t* m = final_mask.ptr<uint8_t>(y);
            const uint8_t* f = filled.ptr<uint8_t>(y);
            const Vec3f* row = xyz.Row(y);
            uint8_t* out = result.mask_scan.Row(y);
            for (int x = 0; x < w; ++x) {
              if (!m[x]) continue;
              out[x] = 1;
              ++b.mask_px;
              b.kept_px += f[x] != 0;
              if (!Usable(row[x])) continue;
              const Vec3d q = rot * (row[x].cast<double>() - c0);
              if (bound_height && std::fabs(q.z()) > kBoundHeightMm) continue;
              b.x0 = std::min(b.x0, q.x());
              b.x1 = std::max(b.x1, q.x());
              b.y0 = std::min(b.y0, q.y());
              b.y1 = std::max(b.y1, q.y());
              ++b.count;
            }
          }
          return b;
        },
        [](Box a, const Box& b) {
          a.x0 = std::min(a.x0, b.x0);
          a.y0 = std::min(a.y0, b.y0);
          a.x1 = std::max(a.x1, b.x1);
          a.y1 = std::max(a.y1, b.y1);
          a.count += b.count;
          a.mask_px += b.mask_px;
          a.kept_px += b.kept_px;
          return a;
        });
  };
  Box box = box_of(true);
  if (box.count == 0) box = box_of(false);
  if (box.count == 0) return Error{src + ": the canvas mask holds no valid sample"};
  // Closed sides of the outline bound the canvas where its edge is (the samples' box stops up
  // to a sample spacing short of it); each side also names the canvas edge it is.
  std::vector<std::string> hidden;
  if (outline.ok) {
    const Eigen::Vector2d xu(x_axis.dot(plane.axes.col(0)), x_axis.dot(plane.axes.col(1)));
    const Eigen::Vector2d yu(y_axis.dot(plane.axes.col(0)), y_axis.dot(plane.axes.col(1)));
    for (int s = 0; s < 4; ++s) {
      const Eigen::Vector2d ns = SideNormal(s, outline.angle);
      const double at = outline.edge[static_cast<size_t>(s)] + ns.dot(outline.centre);
      const char* name = nullptr;
      if (ns.dot(xu) > 0.5)
        name = "right", box.x1 = outline.closed[static_cast<size_t>(s)] ? at : box.x1;
      if (ns.dot(xu) < -0.5)
        name = "left", box.x0 = outline.closed[static_cast<size_t>(s)] ? -at : box.x0;
      if (ns.dot(yu) > 0.5)
        name = "top", box.y1 = outline.closed[static_cast<size_t>(s)] ? at : box.y1;
      if (ns.dot(yu) < -0.5)
        name = "bottom", box.y0 = outline.closed[static_cast<size_t>(s)] ? -at : box.y0;
      if (outline.overhang[static_cast<size_t>(s)] && name) hidden.push_back(name);
    }
  }

  result.canvas_from_scan.rotation = rot;
  result.canvas_from_scan.translation = -(rot * c0) - Vec3d(box.x0, box.y0, 0);
  result.extent_mm = Eigen::Vector2d(box.x1 - box.x0, box.y1 - box.y0);
  result.plane_rms_mm = std::sqrt(plane.eigenvalues(2));
  result.noise_sigma_mm = noise_sigma;
  result.grown_px = static_cast<size_t>(grown);
  result.islands_filled_px = islands_px;
  result.refined_px = box.mask_px - box.kept_px;
  result.plane_points = plane.count;
  result.outline_fitted = outline.ok;
  result.outline_note = outline.ok ? "" : outline.note;
  if (!hidden.empty()) {
    std::string sides;
    for (size_t k = 0; k < hidden.size(); ++k)
      sides += (k == 0 ? "" : k + 1 == hidden.size() ? " and " : ", ") + hidden[k];
    result.hidden_edges = hidden;
    result.warnings.push_back("the frame overhangs the canvas along its " + sides +
                              (hidden.size() > 1 ? " edges" : " edge") +
                              ": the canvas goes on under it, so it is larger than the " +
                              std::to_string(static_cast<int>(std::lround(result.extent_mm.x()))) +
                              " x " +
                              std::to_string(static_cast<int>(std::lround(result.extent_mm.y()))) +
                              " mm seen (scan it out of the frame for the whole canvas)");
  }
  result.seed_x = sx;
  result.seed_y = sy;
  return result;
}

}  // namespace digitize
