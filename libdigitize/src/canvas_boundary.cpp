// Step 5 of canvas extraction (canvas.cpp's header comment): the grown region's boundary, peeled
// and regrown by a strict height-step test up to the frame step, and the missing samples it
// encloses.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "canvas_steps.h"
#include "mask_ops.h"

namespace digitize::canvas_detail {
namespace {

// Sample spacings are medians over a regular subsample of about this many pairs.
constexpr size_t kSpacingSamples = 50000;
// Boundary refinement. The growth can include the foot of an oblique wall (one pixel): the
// region is peeled by kPeelPx first. The refinement runs until nothing changes (at most
// kMaxRefineSteps) within refine_px of the grown region.
constexpr int kPeelPx = 2;
constexpr int kMaxRefineSteps = 100;
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

}  // namespace

RefinedBoundary RefineBoundary(const Grid<Vec3f>& xyz, const GrownRegion& region,
                               const LocalFrame& frame, double noise_sigma, size_t fit_mask_count,
                               const CanvasOptions& options) {
  const int w = xyz.width, h = xyz.height;
  const cv::Mat& grow = region.grow;
  const cv::Mat& valid = region.valid;
  const cv::Mat& filled = region.filled;
  const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3));
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
  // (Found by a scan, in row order: a dilated copy of the mask was a scan-sized byte mask more.)
  std::vector<int> frontier;  // packed y * w + x
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (in[idx(x, y)]) continue;
      for (int d = 0; d < 4; ++d) {
        const int x1 = x + kDx[d], y1 = y + kDy[d];
        if (inside(x1, y1) && in[idx(x1, y1)]) {
          frontier.push_back(static_cast<int>(idx(x, y)));
          break;
        }
      }
    }
  std::vector<int> accepted;
  // The refinement may reach refine_px beyond the grown region; within that band it runs to
  // convergence (paths around missing samples are longer than the distance).
  const BitMask band = DilatedBits(filled, options.refine_px);
  for (int step = 0; step < kMaxRefineSteps && !frontier.empty(); ++step) {
    accepted.clear();
    for (int q : frontier) {
      const int qx = q % w, qy = q / w;
      if (in[idx(qx, qy)] || !band.Get(qx, qy)) continue;
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
  return RefinedBoundary{mask, spacing_x, spacing_y};
}

// Missing samples the grown region enclosed stay canvas (the truth behind a dropout is the
// surface around it), and so do those between mask pixels (the canvas as the scanner sees it is
// convex). The reach is found by scanning rows and columns for the nearest mask
// pixel each way, into bits: the four dilations it replaces (the same pixels) held four byte
// masks of the scan's size at once, the preprocess's peak on a 12288 x 9216 scan.
void JoinMissingSamples(const cv::Mat& filled, const cv::Mat& valid, cv::Mat& final_mask) {
  const int w = final_mask.cols, h = final_mask.rows, r = kConvexReachPx;
  for (int y = 0; y < h; ++y) {
    uint8_t* m = final_mask.ptr<uint8_t>(y);
    const uint8_t* f = filled.ptr<uint8_t>(y);
    const uint8_t* ok = valid.ptr<uint8_t>(y);
    for (int x = 0; x < w; ++x)
      if (!ok[x] && f[x]) m[x] = 255;
  }
  BitMask between(w, h);  // mask pixels within r both ways along the row or the column
  // Rows: a mask pixel in [x - r, x] and one in [x, x + r].
  tbb::parallel_for(tbb::blocked_range<int>(0, h, 64), [&](const tbb::blocked_range<int>& rows) {
    std::vector<int> left(static_cast<size_t>(w));
    for (int y = rows.begin(); y < rows.end(); ++y) {
      const uint8_t* m = final_mask.ptr<uint8_t>(y);
      int last = -r - 1;
      for (int x = 0; x < w; ++x) left[static_cast<size_t>(x)] = last = m[x] ? x : last;
      int next = w + r;
      for (int x = w - 1; x >= 0; --x) {
        if (m[x]) next = x;
        if (x - left[static_cast<size_t>(x)] <= r && next - x <= r) between.Set(x, y);
      }
    }
  });
  // Columns, in blocks of whole words: a mask pixel in [y - r, y] (marked going down), then one
  // in [y, y + r] (going up).
  BitMask above(w, h);
  const int blocks = (w + 255) / 256;
  tbb::parallel_for(tbb::blocked_range<int>(0, blocks), [&](const tbb::blocked_range<int>& b) {
    const int x0 = b.begin() * 256, x1 = std::min(w, b.end() * 256), n = x1 - x0;
    std::vector<int> last(static_cast<size_t>(n), -r - 1);
    for (int y = 0; y < h; ++y) {
      const uint8_t* m = final_mask.ptr<uint8_t>(y);
      for (int x = x0; x < x1; ++x) {
        int& l = last[static_cast<size_t>(x - x0)];
        if (m[x]) l = y;
        if (y - l <= r) above.Set(x, y);
      }
    }
    std::fill(last.begin(), last.end(), h + r);
    for (int y = h - 1; y >= 0; --y) {
      const uint8_t* m = final_mask.ptr<uint8_t>(y);
      for (int x = x0; x < x1; ++x) {
        int& l = last[static_cast<size_t>(x - x0)];
        if (m[x]) l = y;
        if (l - y <= r && above.Get(x, y)) between.Set(x, y);
      }
    }
  });
  for (int y = 0; y < h; ++y) {
    uint8_t* m = final_mask.ptr<uint8_t>(y);
    const uint8_t* ok = valid.ptr<uint8_t>(y);
    for (int x = 0; x < w; ++x)
      if (!ok[x] && between.Get(x, y)) m[x] = 255;
  }
  FillEnclosedIslands(final_mask);
}

}  // namespace digitize::canvas_detail
