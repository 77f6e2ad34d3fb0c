// Relief classification (paper section 4.3).
//
// Three passes, each parallel over bands of cell rows so a band never shares a cell with another:
//   1. H = max height over texels with height;
//   2. Mv = height > delta0 - margin, and per cell the highest texel (independent of Mv);
//   3. after OpenCV's connected components: speck removal, Mv -> valid, cells -> boxes.
#include "digitize/relief.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <string>
#include <vector>

namespace digitize {
namespace {

// A texel takes part when it has a height. A non-finite height breaks the HeightField
// invariant; it is ignored rather than allowed to poison H (and every box with it).
inline bool Usable(TexelState s, float h) { return HasHeight(s) && std::isfinite(h); }

// Number of n-texel cells covering `extent` texels, without overflow for n near INT_MAX.
int CellCount(int extent, int n) { return extent / n + (extent % n != 0 ? 1 : 0); }

struct CellPeak {
  float h = -std::numeric_limits<float>::infinity();
  int u = -1, v = -1;  // -1: no texel with height in the cell
};

}  // namespace

Status ReliefOptions::Validate() const {
  if (!(std::isfinite(delta0_fraction) && delta0_fraction >= 0.0 && delta0_fraction <= 1.0))
    return Error{"delta0_fraction must be in [0, 1] (fraction of the max canvas height), got " +
                 FormatNumber(delta0_fraction)};
  if (!(std::isfinite(min_component_area_mm2) && min_component_area_mm2 >= 0.0))
    return Error{"min_component_area_mm2 must be a finite area >= 0 mm^2, got " +
                 FormatNumber(min_component_area_mm2)};
  if (cell_px < 1) return Error{"cell_px must be >= 1, got " + std::to_string(cell_px)};
  if (!(std::isfinite(noise_margin_mm) && noise_margin_mm >= 0.0))
    return Error{"noise_margin_mm must be a finite height >= 0 mm, got " +
                 FormatNumber(noise_margin_mm)};
  if (cover_px < 0) return Error{"cover_px must be >= 0 texels, got " + std::to_string(cover_px)};
  if (!(std::isfinite(min_relief_mm) && min_relief_mm >= 0.0))
    return Error{"min_relief_mm must be a finite height >= 0 mm, got " +
                 FormatNumber(min_relief_mm)};
  return Status::Ok();
}

ReliefResult ClassifyRelief(const HeightField& field, const ReliefOptions& options) {
  const Status valid_options = options.Validate();
  DIGITIZE_CHECK(valid_options.ok(), "ClassifyRelief: invalid options: " + valid_options.message());
  const int w = field.width(), h = field.height();
  DIGITIZE_CHECK(field.state.width == w && field.state.height == h &&
                     field.state.size() == field.height_mm.size(),
                 "ClassifyRelief: state and height grids differ in size");
  DIGITIZE_CHECK(
      w == 0 || h == 0 || (std::isfinite(field.pitch_mm) && field.pitch_mm > 0),
      "ClassifyRelief: pitch_mm must be finite and > 0, got " + FormatNumber(field.pitch_mm));

  const int n = options.cell_px;
  ReliefResult result;
  result.cell_px = n;
  result.valid = Grid<uint8_t>(w, h, 0);
  if (w == 0 || h == 0) return result;

  const int cells_x = CellCount(w, n), cells_y = CellCount(h, n);
  const auto& heights = field.height_mm;
  const auto& states = field.state;

  // --- 1. H over texels with height.
  constexpr float kNone = -std::numeric_limits<float>::infinity();
  const float max_h = tbb::parallel_reduce(
      tbb::blocked_range<int>(0, h, 16), kNone,
      [&](const tbb::blocked_range<int>& rows, float m) {
        for (int y = rows.begin(); y < rows.end(); ++y) {
          const float* hr = heights.Row(y);
          const TexelState* sr = states.Row(y);
          for (int x = 0; x < w; ++x)
            if (Usable(sr[x], hr[x]) && hr[x] > m) m = hr[x];
        }
        return m;
      },
      [](float a, float b) { return std::max(a, b); });
  if (max_h == kNone) return result;  // no texel with height
  // A window of a larger canvas (a tile with its halo) takes the canvas's H: delta0, and so which
  // texels are relief, must not depend on the tile.
  const float canvas_h = field.window.full_width > 0 ? field.window.full_max_height_mm : max_h;
  result.max_height_mm = canvas_h;
  // Flat canvas: a highest point within the relief floor is noise or rounding, not relief; boxes
  // built on it would make the viewer relief-map the whole canvas for nothing.
  if (!(canvas_h > options.min_relief_mm)) return result;

  result.delta0_mm = options.delta0_fraction * canvas_h;
  // The margin never takes more than half of delta0: it widens Mv near the threshold, it must not
  // turn the whole canvas into relief when the noise is large against the relief.
  const double threshold =
      result.delta0_mm - std::min(options.noise_margin_mm, 0.5 * result.delta0_mm);

  // --- 2. Mv, and the highest texel (among texels with height) of every cell. Parallel over
  // cell rows so each band owns its cells' peaks.
  cv::Mat mv(h, w, CV_8U);
  std::vector<CellPeak> peaks(static_cast<size_t>(cells_x) * cells_y);
  std::vector<size_t> mv_count(cells_y, 0);
  tbb::parallel_for(tbb::blocked_range<int>(0, cells_y), [&](const tbb::blocked_range<int>& crows) {
    for (int cy = crows.begin(); cy < crows.end(); ++cy) {
      CellPeak* row_peaks = peaks.data() + static_cast<size_t>(cy) * cells_x;
      const int y0 = cy * n, y1 = static_cast<int>(std::min<int64_t>(int64_t{y0} + n, h));
      size_t count = 0;
      for (int y = y0; y < y1; ++y) {
        const float* hr = heights.Row(y);
        const TexelState* sr = states.Row(y);
        uint8_t* mr = mv.ptr<uint8_t>(y);
        for (int cx = 0, x0 = 0; cx < cells_x; ++cx, x0 += n) {
          const int x1 = static_cast<int>(std::min<int64_t>(int64_t{x0} + n, w));
          CellPeak p = row_peaks[cx];
          for (int x = x0; x < x1; ++x) {
            const bool usable = Usable(sr[x], hr[x]);
            const bool above = usable && hr[x] > threshold;
            mr[x] = above ? 1 : 0;
            count += above;
            if (usable && hr[x] > p.h) p = {hr[x], x, y};  // strict: first (row-major) peak wins
          }
          row_peaks[cx] = p;
        }
      }
      mv_count[cy] = count;
    }
  });
  size_t mv_total = 0;
  for (size_t c : mv_count) mv_total += c;
  if (mv_total == 0) return result;

  // --- 3. Speck removal by connected components (8-connectivity), then the boxes.
  cv::Mat labels, stats, centroids;
  const int label_count = cv::connectedComponentsWithStats(mv, labels, stats, centroids, 8, CV_32S);
  const double texel_area_mm2 = field.pitch_mm * field.pitch_mm;
  std::vector<uint8_t> keep(label_count, 0);  // label 0 is the background
  for (int l = 1; l < label_count; ++l) {
    const double area_mm2 = stats.at<int>(l, cv::CC_STAT_AREA) * texel_area_mm2;
    keep[l] = area_mm2 >= options.min_component_area_mm2 ? 1 : 0;
    (keep[l] ? result.components_kept : result.components_removed)++;
  }

  // Mv after speck removal.
  std::vector<size_t> above_count(h, 0);
  tbb::parallel_for(tbb::blocked_range<int>(0, h, 16), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y < rows.end(); ++y) {
      const int32_t* lr = labels.ptr<int32_t>(y);
      uint8_t* vr = result.valid.Row(y);
      size_t count = 0;
      for (int x = 0; x < w; ++x) count += (vr[x] = keep[lr[x]]);
      above_count[y] = count;
    }
  });
  // Boxes cover Mv grown by cover_px texels: a true surface above delta0 that falls between texel
  // centres, or just under the threshold through resampling, is still inside a box.
  cv::Mat valid_mat(h, w, CV_8U, result.valid.data.data());
  cv::Mat cover;  // a new buffer: dilating into a header of valid_mat would overwrite Mv
  if (options.cover_px > 0)
    cv::dilate(valid_mat, cover, cv::Mat(), cv::Point(-1, -1), options.cover_px);
  else
    cover = valid_mat;

  std::vector<std::vector<ReliefBox>> row_boxes(cells_y);
  tbb::parallel_for(tbb::blocked_range<int>(0, cells_y), [&](const tbb::blocked_range<int>& crows) {
    std::vector<uint8_t> cell_has(cells_x);
    for (int cy = crows.begin(); cy < crows.end(); ++cy) {
      std::fill(cell_has.begin(), cell_has.end(), 0);
      const int y0 = cy * n, y1 = static_cast<int>(std::min<int64_t>(int64_t{y0} + n, h));
      for (int y = y0; y < y1; ++y) {
        const uint8_t* cr = cover.ptr<uint8_t>(y);
        for (int cx = 0, x0 = 0; cx < cells_x; ++cx, x0 += n) {
          const int x1 = static_cast<int>(std::min<int64_t>(int64_t{x0} + n, w));
          uint8_t any = 0;
          for (int x = x0; x < x1; ++x) any |= cr[x];
          cell_has[cx] |= any;
        }
      }
      const CellPeak* row_peaks = peaks.data() + static_cast<size_t>(cy) * cells_x;
      for (int cx = 0; cx < cells_x; ++cx) {
        if (!cell_has[cx]) continue;
        const CellPeak& p = row_peaks[cx];
        if (p.u < 0) continue;  // the grown cover reached a cell without any height: nothing to box
        ReliefBox box;
        box.x0 = cx * n;
        box.y0 = y0;
        box.width = static_cast<int>(std::min<int64_t>(int64_t{box.x0} + n, w)) - box.x0;
        box.height = y1 - y0;
        box.h_max_mm = p.h;
        box.u_max = p.u;
        box.v_max = p.v;
        row_boxes[cy].push_back(box);
      }
    }
  });
  size_t box_total = 0;
  for (const auto& r : row_boxes) box_total += r.size();
  result.boxes.reserve(box_total);
  for (const auto& r : row_boxes) result.boxes.insert(result.boxes.end(), r.begin(), r.end());
  for (size_t c : above_count) result.texels_above += c;
  return result;
}

}  // namespace digitize
