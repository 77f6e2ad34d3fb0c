// Steps 2-3 of canvas extraction (canvas.cpp's header comment): the barrier mask (Sobel height
// gradient and slope) and the region grown from the seed over it, enclosed islands added back.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "canvas_steps.h"
#include "mask_ops.h"

namespace digitize::canvas_detail {
namespace {

// A grown region filling less of its convex hull than this is not a canvas (a frame ring).
constexpr double kMinSolidity = 0.6;

// "(x, y)", appended piecewise (GCC 12 warns falsely about "(" + std::string at -O3).
std::string PointText(int x, int y) {
  std::string text = "(";
  text += std::to_string(x);
  text += ", ";
  text += std::to_string(y);
  text += ")";
  return text;
}
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

}  // namespace

Result<GrownRegion> GrowCanvasRegion(const Grid<Vec3f>& xyz, const PlaneFit& rough,
                                     const CanvasOptions& options, const std::string& src) {
  const int w = xyz.width, h = xyz.height;
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
  cv::Mat filled;
  cv::compare(grow, 2, filled, cv::CMP_EQ);  // 255 / 0: the grown region
  const size_t region_px = static_cast<size_t>(cv::countNonZero(filled));
  FillEnclosedIslands(filled);
  const size_t islands_px = static_cast<size_t>(cv::countNonZero(filled)) - region_px;
  const std::string seed_text = PointText(sx, sy);
  const std::string seed_hint =
      user_seed ? "" : "; the canvas may be off-centre: give a seed on the canvas (--seed X,Y)";
  if (islands_px > static_cast<size_t>(grown))
    return Error{src + ": the region grown from seed " + seed_text + " (" + std::to_string(grown) +
                 " px) encloses a larger area (" + std::to_string(islands_px) +
                 " px): the seed is on the frame or the wall, not on the canvas" + seed_hint};
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
  GrownRegion out;
  out.grow = grow;
  out.valid = valid;
  out.filled = filled;
  out.valid_count = valid_count;
  out.grown = grown;
  out.islands_px = islands_px;
  out.seed_x = sx;
  out.seed_y = sy;
  return out;
}

}  // namespace digitize::canvas_detail
