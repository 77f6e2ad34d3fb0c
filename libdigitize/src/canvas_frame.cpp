// Step 7 of canvas extraction: the frame around the canvas as boxes (canvas_steps.h).
#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "canvas_steps.h"

namespace digitize::canvas_detail {
namespace {

// How far outside the outline a point still counts as frame: mouldings are 30-60 mm wide, and
// beyond ~150 mm a scan sees the wall or the easel, not the frame.
constexpr double kFrameBandMm = 150;
// Fewer points than this on a side: the scan does not cover that side (no box, rather than a
// box from a handful of stray points).
constexpr size_t kMinFramePoints = 50;
// The moulding's top, as a quantile of the heights: a few spikes do not move it, and the top of a
// profile is a fair share of its points.
constexpr double kRaiseQuantile = 0.98;
// The inner and outer edges of the top: it is sampled about evenly across its width, so the
// q-quantile of the outward distance of its points is near inner + q x width. Two quantiles well
// inside (0.1 and 0.9) give both edges, unmoved by the few points an oblique scanner puts on the
// drop to the wall. The inner edge is off the outline where the frame hides a strip of canvas
// from an oblique scanner (CanvasResult::hidden_edges): the visible outline is then inside the
// real one, by that strip.
constexpr double kLowQuantile = 0.1, kHighQuantile = 0.9;
// A raise below this (or below 6 noise sigmas) is the canvas plane's own scatter, not a frame.
constexpr double kMinRaiseMm = 1.0;

double Quantile(std::vector<double>& v, double q) {
  const size_t i = std::min(v.size() - 1, static_cast<size_t>(q * static_cast<double>(v.size())));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(i), v.end());
  return v[i];
}

}  // namespace

FrameBoxes MeasureFrameBoxes(const Grid<Vec3f>& xyz, const Grid<uint8_t>& mask_scan,
                             const RigidTransform& canvas_from_scan,
                             const Eigen::Vector2d& extent_mm, double noise_sigma_mm,
                             size_t max_points) {
  const double W = extent_mm.x(), H = extent_mm.y();
  const Mat3d R = canvas_from_scan.rotation;
  const Vec3d t = canvas_from_scan.translation;
  // The side of the frame sample i lies beside (-1: none), its outward distance and height.
  auto classify = [&](size_t i, double* d, double* z) {
    if (mask_scan.data[i] || !Usable(xyz.data[i])) return -1;
    const Vec3d p = R * xyz.data[i].cast<double>() + t;
    const bool in_x = p.x() >= 0 && p.x() <= W, in_y = p.y() >= 0 && p.y() <= H;
    // Corners (outside along both axes) belong to no side: they hold the mitre, seen obliquely.
    int side = -1;
    if (in_y && p.x() < 0) side = 0, *d = -p.x();
    if (in_y && p.x() > W) side = 1, *d = p.x() - W;
    if (in_x && p.y() < 0) side = 2, *d = -p.y();
    if (in_x && p.y() > H) side = 3, *d = p.y() - H;
    *z = p.z();
    return side >= 0 && *d <= kFrameBandMm ? side : -1;
  };
  // Per side, every stride-th of its points (in scan order: an even spread over the band), at
  // most max_points (CanvasOptions::max_frame_points).
  std::array<size_t, 4> count{};
  double out = 0, height = 0;
  for (size_t i = 0; i < xyz.data.size(); ++i)
    if (const int side = classify(i, &out, &height); side >= 0) ++count[static_cast<size_t>(side)];
  std::array<size_t, 4> stride{}, seen{};
  std::array<std::vector<std::array<double, 2>>, 4> band;  // (outward distance, height)
  for (size_t s = 0; s < 4; ++s) {
    stride[s] = (count[s] + max_points - 1) / max_points;
    band[s].reserve(stride[s] ? count[s] / stride[s] + 1 : 0);
  }
  for (size_t i = 0; i < xyz.data.size(); ++i) {
    const int side = classify(i, &out, &height);
    if (side < 0) continue;
    const auto s = static_cast<size_t>(side);
    if (seen[s]++ % stride[s] == 0) band[s].push_back({out, height});
  }
  FrameBoxes boxes;
  const double min_raise = std::max(kMinRaiseMm, 6.0 * noise_sigma_mm);
  for (int side = 0; side < 4; ++side) {
    if (band[side].size() < kMinFramePoints) continue;
    std::vector<double> heights;
    heights.reserve(band[side].size());
    for (const auto& [d, z] : band[side]) heights.push_back(z);
    const double raise = Quantile(heights, kRaiseQuantile);
    if (!(raise >= min_raise) || raise > 1000.0) continue;
    std::vector<double> reach;
    for (const auto& [d, z] : band[side])
      if (z > 0.5 * raise) reach.push_back(d);
    if (reach.empty()) continue;
    const double lo = Quantile(reach, kLowQuantile), hi = Quantile(reach, kHighQuantile);
    const double width = (hi - lo) / (kHighQuantile - kLowQuantile);
    const double gap = std::max(0.0, lo - kLowQuantile * width);
    boxes.raise_mm[side] = static_cast<float>(raise);
    boxes.gap_mm[side] = static_cast<float>(std::min(gap, kFrameBandMm));
    boxes.width_mm[side] = static_cast<float>(std::clamp(width, 0.0, kFrameBandMm));
  }
  return boxes;
}

}  // namespace digitize::canvas_detail
