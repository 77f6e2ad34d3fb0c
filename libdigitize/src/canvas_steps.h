// The steps of canvas extraction (canvas.cpp: the driver, ExtractCanvas) and what passes between
// them. Private to the canvas layer: OpenCV types. The steps are numbered as in canvas.cpp's
// header comment (paper section 4.2; docs/architecture.md, "What each step does").
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "digitize/canvas.h"
#include "digitize/core.h"

namespace digitize::canvas_detail {

// Coordinates beyond this are sensor garbage even when the scan was not sanitised (1e30).
constexpr float kMaxAbsCoordinateMm = 1e6f;
// MAD -> sigma for a Gaussian.
constexpr double kMadToSigma = 1.4826;
constexpr double kPi = 3.14159265358979323846;

inline bool Usable(const Vec3f& p) {
  return std::fabs(p.x()) <= kMaxAbsCoordinateMm && std::fabs(p.y()) <= kMaxAbsCoordinateMm &&
         std::fabs(p.z()) <= kMaxAbsCoordinateMm;  // false for NaN and Inf too
}

// Stride giving about `target` samples out of `count`.
inline int SampleStride(size_t count, size_t target) {
  return std::max(1, static_cast<int>(std::sqrt(static_cast<double>(count) / target)));
}

inline double Median(std::vector<double>& v) {
  if (v.empty()) return 0;
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  return v[mid];
}

// Median absolute deviation about `center`.
inline double Mad(const std::vector<double>& v, double center) {
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

// ---- 1. Rough plane of every usable sample (the frame and the wall included; only a rough
// normal). Errors: too few valid samples, collinear samples.
Result<PlaneFit> FitRoughPlane(const Grid<Vec3f>& xyz, const std::string& src);

// ---- 2-3. Barrier mask and region growing from the seed, enclosed islands added back
// (canvas_region.cpp). Errors: the seed outside the scan or on no growable sample, a region that
// is a frame ring, encloses more than itself or is too small.
struct GrownRegion {
  cv::Mat grow;    // barrier test, flood-filled: 0 = barrier, 1 = growable, 2 = grown
  cv::Mat valid;   // 1 where the sample is usable
  cv::Mat filled;  // 255: the grown region with its enclosed islands
  size_t valid_count = 0;
  int grown = 0;  // pixels the flood fill reached
  size_t islands_px = 0;
  int seed_x = -1, seed_y = -1;  // the seed used
};
Result<GrownRegion> GrowCanvasRegion(const Grid<Vec3f>& xyz, const PlaneFit& rough,
                                     const CanvasOptions& options, const std::string& src);

// ---- 4. Robust plane on the eroded region: PCA, then trimmed refits (relief above, outliers
// below). Error: too few canvas samples.
// The samples the plane is fitted to: the grown region eroded by erode_px, valid ones only (all
// of the region's valid ones on a tiny canvas). A function of the region alone, so it can be
// made again rather than held through the steps between its users.
cv::Mat PlaneFitMask(const GrownRegion& region, const CanvasOptions& options);
struct CanvasPlane {
  cv::Mat fit_mask;  // the eroded region's valid samples the plane is fitted to
  size_t fit_mask_count = 0;
  PlaneFit plane;
};
Result<CanvasPlane> FitCanvasPlane(const Grid<Vec3f>& xyz, const GrownRegion& region,
                                   const PlaneFit& rough, const CanvasOptions& options,
                                   const std::string& src);

// Noise sigma (mm) of the heights over `fit_mask` (Immerkaer's mask); 0 when nothing to measure.
double EstimateNoiseSigma(const Grid<Vec3f>& xyz, const cv::Mat& fit_mask, size_t fit_mask_count,
                          const LocalFrame& frame);

// ---- 5. Boundary: the region peeled and regrown by the strict test, missing samples it encloses
// added (canvas_boundary.cpp).
struct RefinedBoundary {
  cv::Mat mask;                         // 255 = canvas
  double spacing_x = 0, spacing_y = 0;  // median in-plane sample spacing (mm) along x and y
};
// The missing samples are not added yet: JoinMissingSamples does, after the caller has released
// region.grow (read here only), so the two steps' masks are not held at once.
RefinedBoundary RefineBoundary(const Grid<Vec3f>& xyz, const GrownRegion& region,
                               const LocalFrame& frame, double noise_sigma, size_t fit_mask_count,
                               const CanvasOptions& options);
// Missing samples into the refined mask: those the grown region (`filled`) encloses, those with
// mask pixels on both sides within kConvexReachPx along a row or a column, then everything the
// mask encloses.
constexpr int kConvexReachPx = 3;
void JoinMissingSamples(const cv::Mat& filled, const cv::Mat& valid, cv::Mat& mask);

// ---- 5b. Outline: the visible canvas as a rectangle in the plane (canvas_outline.cpp).
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
Eigen::Vector2d SideNormal(int s, double angle);

// The rectangle fitted to `mask` (the refined boundary; `valid`: usable samples, `fit_mask`: the
// samples the plane was fitted to, released once read: a caller that passes its only reference
// frees it), its sides, hidden edges and mask; not ok (and why in `note`) when no rectangle fits
// or it disagrees with the mask.
Outline FitOutline(const Grid<Vec3f>& xyz, const cv::Mat& mask, const cv::Mat& valid,
                   cv::Mat fit_mask, const LocalFrame& frame, double noise_sigma, double spacing);

// ---- 7. The frame's boxes (canvas_frame.cpp). Per side, the scan points outside the canvas
// outline, at most kFrameBandMm from it, within the side's span along the outline: the box's
// raise is a high quantile of their heights (the moulding's top; a quantile, so that a few
// spikes do not lift it), its width from a quantile of the outward distance of the points above
// half that raise (canvas_frame.cpp says why). A side with too few points, or whose raise is within
// the scan noise of the canvas plane, gets no box. Quantiles of at most max_points a side, evenly
// spaced (CanvasOptions::max_frame_points).
FrameBoxes MeasureFrameBoxes(const Grid<Vec3f>& xyz, const Grid<uint8_t>& mask_scan,
                             const RigidTransform& canvas_from_scan,
                             const Eigen::Vector2d& extent_mm, double noise_sigma_mm,
                             size_t max_points);

}  // namespace digitize::canvas_detail
