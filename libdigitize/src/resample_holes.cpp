// Holes of the resampled canvas grid (resample.cpp's header comment, step 4): found inside the
// outline, split into small and large, filled by push-pull interpolation relaxed towards a
// membrane; then the texel states (step 5).
#include "resample_holes.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "mask_ops.h"

namespace digitize::resample_detail {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr int kMaxRelaxIterations = 200;      // membrane relaxation of a filled hole
constexpr int kUnfilledRelaxIterations = 20;  // large holes: continuity only
constexpr float kRelaxToleranceMm = 1e-5f;    // relaxation stops below this change per sweep

// Scratch space of the hole filler, one per thread (no per-hole allocation in steady state).
struct FillScratch {
  std::vector<float> val, wt;  // pyramid levels, concatenated
  std::vector<int> level_offset, level_w, level_h;
  std::vector<uint8_t> role;      // level-0 role: 0 ignore, 1 known, 2 unknown
  std::vector<uint32_t> unknown;  // level-0 unknown texels with a neighbour
};

// Fills the texels labelled `label` inside rect (which has a one-texel margin) from the covered
// texels around them: push-pull initial values, then Gauss-Seidel relaxation of the membrane
// equation. Writes only texels of this label; reads covered texels and its own.
void FillHole(const cv::Rect& rect, int label, const cv::Mat& labels, const cv::Mat& covered,
              float* height, int grid_w, int iterations, FillScratch& s) {
  const int bw = rect.width, bh = rect.height;
  s.level_offset.clear();
  s.level_w.clear();
  s.level_h.clear();
  size_t total = 0;
  for (int lw = bw, lh = bh;;) {
    s.level_offset.push_back(static_cast<int>(total));
    s.level_w.push_back(lw);
    s.level_h.push_back(lh);
    total += static_cast<size_t>(lw) * lh;
    if (lw == 1 && lh == 1) break;
    lw = (lw + 1) / 2;
    lh = (lh + 1) / 2;
  }
  s.val.assign(total, 0.f);
  s.wt.assign(total, 0.f);
  s.role.assign(static_cast<size_t>(bw) * bh, 0);
  bool any_known = false;
  for (int y = 0; y < bh; ++y) {
    const int gy = rect.y + y;
    const int* lab = labels.ptr<int>(gy);
    const uint8_t* cov = covered.ptr<uint8_t>(gy);
    for (int x = 0; x < bw; ++x) {
      const int gx = rect.x + x;
      const size_t i = static_cast<size_t>(y) * bw + x;
      if (cov[gx]) {
        s.role[i] = 1;
        s.val[i] = height[static_cast<size_t>(gy) * grid_w + gx];
        s.wt[i] = 1;
        any_known = true;
      } else if (lab[gx] == label) {
        s.role[i] = 2;
      }
    }
  }
  auto write_back = [&]() {
    for (int y = 0; y < bh; ++y)
      for (int x = 0; x < bw; ++x)
        if (s.role[static_cast<size_t>(y) * bw + x] == 2)
          height[static_cast<size_t>(rect.y + y) * grid_w + rect.x + x] =
              s.val[static_cast<size_t>(y) * bw + x];
  };
  if (!any_known) {  // nothing to interpolate from: flat at the plane
    for (float& v : s.val) v = 0;
    write_back();
    return;
  }
  const int levels = static_cast<int>(s.level_w.size());
  // Push: weighted averages down the pyramid.
  int top = levels - 1;
  for (int l = 1; l < levels; ++l) {
    const int pw = s.level_w[l - 1], ph = s.level_h[l - 1], lw = s.level_w[l], lh = s.level_h[l];
    const float* pv = s.val.data() + s.level_offset[l - 1];
    const float* pwt = s.wt.data() + s.level_offset[l - 1];
    float* v = s.val.data() + s.level_offset[l];
    float* wt = s.wt.data() + s.level_offset[l];
    bool full = true;
    for (int y = 0; y < lh; ++y)
      for (int x = 0; x < lw; ++x) {
        float sw = 0, sv = 0;
        for (int dy = 0; dy < 2; ++dy)
          for (int dx = 0; dx < 2; ++dx) {
            const int cx = 2 * x + dx, cy = 2 * y + dy;
            if (cx >= pw || cy >= ph) continue;
            const size_t ci = static_cast<size_t>(cy) * pw + cx;
            sw += pwt[ci];
            sv += pwt[ci] * pv[ci];
          }
        const size_t i = static_cast<size_t>(y) * lw + x;
        wt[i] = sw;
        v[i] = sw > 0 ? sv / sw : 0;
        full = full && sw > 0;
      }
    if (full) {
      top = l;
      break;
    }
  }
  // Pull: empty cells take the bilinear interpolation of the coarser level.
  for (int l = top - 1; l >= 0; --l) {
    const int lw = s.level_w[l], lh = s.level_h[l], cw = s.level_w[l + 1], ch = s.level_h[l + 1];
    float* v = s.val.data() + s.level_offset[l];
    const float* wt = s.wt.data() + s.level_offset[l];
    const float* cv = s.val.data() + s.level_offset[l + 1];
    for (int y = 0; y < lh; ++y)
      for (int x = 0; x < lw; ++x) {
        const size_t i = static_cast<size_t>(y) * lw + x;
        if (wt[i] > 0) continue;
        const double fx = std::clamp((x + 0.5) / 2 - 0.5, 0.0, double(cw - 1));
        const double fy = std::clamp((y + 0.5) / 2 - 0.5, 0.0, double(ch - 1));
        const int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
        const int x1 = std::min(x0 + 1, cw - 1), y1 = std::min(y0 + 1, ch - 1);
        const double ax = fx - x0, ay = fy - y0;
        const double top_v = (1 - ax) * cv[static_cast<size_t>(y0) * cw + x0] +
                             ax * cv[static_cast<size_t>(y0) * cw + x1];
        const double bot_v = (1 - ax) * cv[static_cast<size_t>(y1) * cw + x0] +
                             ax * cv[static_cast<size_t>(y1) * cw + x1];
        v[i] = static_cast<float>((1 - ay) * top_v + ay * bot_v);
      }
  }
  // Relax: unknown texels towards the mean of their known / unknown 4-neighbours (Gauss-Seidel
  // over the list of unknown texels, each with its neighbour count).
  float* v = s.val.data();
  s.unknown.clear();
  for (int y = 0; y < bh; ++y)
    for (int x = 0; x < bw; ++x) {
      const size_t i = static_cast<size_t>(y) * bw + x;
      if (s.role[i] != 2) continue;
      const int n = (x > 0 && s.role[i - 1]) + (x + 1 < bw && s.role[i + 1]) +
                    (y > 0 && s.role[i - bw]) + (y + 1 < bh && s.role[i + bw]);
      if (n > 0) s.unknown.push_back(static_cast<uint32_t>(i));
    }
  for (int it = 0; it < iterations; ++it) {
    float change = 0;
    for (const uint32_t i : s.unknown) {
      const int x = static_cast<int>(i % bw), y = static_cast<int>(i / bw);
      float sum = 0;
      int n = 0;
      if (x > 0 && s.role[i - 1]) sum += v[i - 1], ++n;
      if (x + 1 < bw && s.role[i + 1]) sum += v[i + 1], ++n;
      if (y > 0 && s.role[i - bw]) sum += v[i - bw], ++n;
      if (y + 1 < bh && s.role[i + bw]) sum += v[i + bw], ++n;
      const float next = sum / static_cast<float>(n);
      change = std::max(change, std::fabs(next - v[i]));
      v[i] = next;
    }
    if (change < kRelaxToleranceMm) break;
  }
  write_back();
}

}  // namespace

// ---- 4. The outline: the footprint of the canvas mask's quads (drawn, or covered with
// predicted positions of missing samples) and everything it encloses. Holes: uncovered texels
// inside, labelled by connected component.

HoleMap FindHoles(const cv::Mat& covered, Grid<uint8_t>* footprint) {
  const int w = covered.cols, h = covered.rows;
  HoleMap map;
  map.covered = covered;
  cv::Mat& inside = map.inside;
  cv::bitwise_or(covered, cv::Mat(h, w, CV_8U, footprint->data.data()), inside);
  FillEnclosedIslands(inside);
  std::vector<uint8_t>().swap(footprint->data);
  cv::Mat& holes = map.holes;
  cv::bitwise_and(inside, ~covered, holes);
  cv::Mat centroids;
  map.ncomp =
      cv::connectedComponentsWithStats(holes, map.labels, map.comp_stats, centroids, 8, CV_32S);
  return map;
}

// Small holes: components of at most max_hole_area_mm2. Larger components are split: texels
// farther from measured ones than the radius r of a disc of that area are the cores of large
// holes, and everything within r of a core belongs to that large hole (kUnfilled); the rest is
// small gaps (kFilled), e.g. many scattered dropouts joined into one network of thin gaps.

HoleSizes SplitLargeHoles(const HoleMap& map, double pitch, const ResampleOptions& options) {
  const int w = map.covered.cols, h = map.covered.rows, ncomp = map.ncomp;
  const cv::Mat &covered = map.covered, &holes = map.holes, &labels = map.labels,
                &comp_stats = map.comp_stats;
  HoleSizes sizes;
  const double texel_area = pitch * pitch;
  const double thin_radius_tx = std::sqrt(options.max_hole_area_mm2 / kPi) / pitch;
  std::vector<uint8_t>& comp_filled = sizes.comp_filled;
  comp_filled.assign(static_cast<size_t>(std::max(ncomp, 1)), 1);
  bool any_large_component = false;
  for (int k = 1; k < ncomp; ++k)
    if (comp_stats.at<int>(k, cv::CC_STAT_AREA) * texel_area > options.max_hole_area_mm2)
      any_large_component = true;
  cv::Mat& large = sizes.large;
  if (any_large_component) {
    cv::Mat distance, core;
    cv::distanceTransform(~covered, distance, cv::DIST_L2, cv::DIST_MASK_3, CV_32F);
    cv::compare(distance, thin_radius_tx, core, cv::CMP_GT);
    cv::bitwise_and(core, holes, core);
    // Cores only in components larger than the area limit.
    tbb::parallel_for(tbb::blocked_range<int>(0, h, 64), [&](const tbb::blocked_range<int>& r) {
      for (int y = r.begin(); y < r.end(); ++y) {
        const int* lab = labels.ptr<int>(y);
        uint8_t* c = core.ptr<uint8_t>(y);
        for (int x = 0; x < w; ++x)
          if (c[x] && comp_stats.at<int>(lab[x], cv::CC_STAT_AREA) * texel_area <=
                          options.max_hole_area_mm2)
            c[x] = 0;
      }
    });
    if (cv::countNonZero(core) > 0) {
      cv::distanceTransform(~core, distance, cv::DIST_L2, cv::DIST_MASK_3, CV_32F);
      cv::compare(distance, thin_radius_tx + 0.5, large, cv::CMP_LE);
      cv::bitwise_and(large, holes, large);
      for (int y = 0; y < h; ++y) {
        const int* lab = labels.ptr<int>(y);
        const uint8_t* l = large.ptr<uint8_t>(y);
        for (int x = 0; x < w; ++x)
          if (l[x]) comp_filled[static_cast<size_t>(lab[x])] = 0;
      }
    }
  }
  for (int k = 1; k < ncomp; ++k)
    (comp_filled[static_cast<size_t>(k)] ? sizes.holes_filled : sizes.holes_unfilled)++;
  return sizes;
}

// Every hole filled by push-pull interpolation relaxed towards a membrane (harmonic) fill, one
// component per task; large holes get only a few sweeps (continuity).
void FillHoles(const HoleMap& map, const HoleSizes& sizes, float* out) {
  const int w = map.covered.cols, h = map.covered.rows, ncomp = map.ncomp;
  const cv::Mat &covered = map.covered, &labels = map.labels, &comp_stats = map.comp_stats;
  const std::vector<uint8_t>& comp_filled = sizes.comp_filled;
  auto comp_rect = [&](int k) {
    cv::Rect rect(comp_stats.at<int>(k, cv::CC_STAT_LEFT) - 1,
                  comp_stats.at<int>(k, cv::CC_STAT_TOP) - 1,
                  comp_stats.at<int>(k, cv::CC_STAT_WIDTH) + 2,
                  comp_stats.at<int>(k, cv::CC_STAT_HEIGHT) + 2);
    return rect & cv::Rect(0, 0, w, h);
  };
  tbb::enumerable_thread_specific<FillScratch> scratch;
  tbb::parallel_for(
      tbb::blocked_range<int>(1, std::max(ncomp, 1), 64), [&](const tbb::blocked_range<int>& r) {
        FillScratch& s = scratch.local();
        for (int k = r.begin(); k < r.end(); ++k) {
          const cv::Rect rect = comp_rect(k);
          const int iters =
              comp_filled[static_cast<size_t>(k)]
                  ? std::min(kMaxRelaxIterations, 4 * std::max(rect.width, rect.height))
                  : kUnfilledRelaxIterations;
          FillHole(rect, k, labels, covered, out, w, iters, s);
        }
      });
}

// ---- 5. States; outside texels at height 0; never NaN.

StateCounts AssignStates(const HoleMap& map, const cv::Mat& large, HeightField* field_out) {
  const int w = map.covered.cols, h = map.covered.rows;
  const cv::Mat &covered = map.covered, &inside = map.inside, &labels = map.labels;
  HeightField& field = *field_out;
  return tbb::parallel_reduce(
      tbb::blocked_range<int>(0, h), StateCounts{},
      [&](const tbb::blocked_range<int>& rows, StateCounts c) {
        for (int y = rows.begin(); y < rows.end(); ++y) {
          const uint8_t* cov = covered.ptr<uint8_t>(y);
          const uint8_t* ins = inside.ptr<uint8_t>(y);
          const int* lab = labels.ptr<int>(y);
          const uint8_t* large_row = large.empty() ? nullptr : large.ptr<uint8_t>(y);
          float* hrow = field.height_mm.Row(y);
          TexelState* st = field.state.Row(y);
          for (int x = 0; x < w; ++x) {
            if (cov[x]) {
              st[x] = TexelState::kMeasured;
              ++c.measured;
            } else if (ins[x] && lab[x] > 0) {
              const bool small = large_row == nullptr || !large_row[x];
              st[x] = small ? TexelState::kFilled : TexelState::kUnfilled;
              ++(small ? c.filled : c.unfilled);
            } else {
              st[x] = TexelState::kOutside;
              hrow[x] = 0;
              ++c.outside;
            }
            if (!std::isfinite(hrow[x])) hrow[x] = 0;  // defensive: inputs were finite
          }
        }
        return c;
      },
      [](StateCounts a, const StateCounts& b) {
        a.measured += b.measured;
        a.filled += b.filled;
        a.unfilled += b.unfilled;
        a.outside += b.outside;
        return a;
      });
}
}  // namespace digitize::resample_detail
