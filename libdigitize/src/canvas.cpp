// Canvas extraction (canvas.h; paper section 4.2): the driver, ExtractCanvas, and the canvas
// frame (step 6). The other steps live beside it, one job a file (canvas_steps.h): the plane
// fits (canvas_plane.cpp), the barrier mask and region growing (canvas_region.cpp), the
// boundary refinement (canvas_boundary.cpp) and the outline (canvas_outline.cpp).
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
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "canvas_steps.h"

namespace digitize {
namespace {

using canvas_detail::Outline;
using canvas_detail::Usable;

// Canvas frame: in-plane eigenvalues closer than this (relative) leave the axes undefined (use
// scan +X); points farther than kBoundHeightMm from the plane are not canvas (frames rise 15+
// mm) and do not stretch the bounding rectangle (outliers that survived in the mask).
constexpr double kIsotropicEigen = 0.05;
constexpr double kBoundHeightMm = 15.0;

std::string SourceName(const Scan& scan) { return scan.source.empty() ? "scan" : scan.source; }

// Step 6, axes: Z = the robust normal, X = the outline's side direction (else the in-plane PCA
// axis) closest to scan +X; rows of the rotation canvas_from_scan.
Mat3d CanvasRotation(const PlaneFit& plane, const Outline& outline) {
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
  return rot;
}

// Bounding rectangle (canvas frame) of the mask's points and the mask's counts.
struct Box {
  double x0 = std::numeric_limits<double>::max(), y0 = std::numeric_limits<double>::max();
  double x1 = std::numeric_limits<double>::lowest(), y1 = std::numeric_limits<double>::lowest();
  size_t count = 0;                 // points in the rectangle
  size_t mask_px = 0, kept_px = 0;  // mask pixels; of those, in the grown + filled region
};

// One parallel pass over `final_mask`: its bounding box in the frame `rot` about `c0` (points
// farther than kBoundHeightMm from the plane left out when `bound_height`), and the output mask.
Box BoundMask(const Grid<Vec3f>& xyz, const cv::Mat& final_mask, const cv::Mat& filled,
              const Mat3d& rot, const Vec3d& c0, bool bound_height, Grid<uint8_t>* mask_scan) {
  const int w = xyz.width, h = xyz.height;
  return tbb::parallel_reduce(
      tbb::blocked_range<int>(0, h), Box{},
      [&](const tbb::blocked_range<int>& rows, Box b) {
        for (int y = rows.begin(); y < rows.end(); ++y) {
          const uint8_t* m = final_mask.ptr<uint8_t>(y);
          const uint8_t* f = filled.ptr<uint8_t>(y);
          const Vec3f* row = xyz.Row(y);
          uint8_t* out = mask_scan->Row(y);
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
}

// Closed sides of the outline bound the canvas where its edge is (the samples' box stops up
// to a sample spacing short of it); each side also names the canvas edge it is. Returns the
// names of the sides a frame lip hides.
std::vector<std::string> PlaceOutlineSides(const Outline& outline, const PlaneFit& plane,
                                           const Mat3d& rot, Box* box_out) {
  using canvas_detail::SideNormal;
  const Vec3d x_axis = rot.row(0).transpose(), y_axis = rot.row(1).transpose();
  Box& box = *box_out;
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
  return hidden;
}

// The warning for hidden edges, with the extent seen.
std::string HiddenEdgeWarning(const std::vector<std::string>& hidden,
                              const Eigen::Vector2d& extent_mm) {
  std::string sides;
  for (size_t k = 0; k < hidden.size(); ++k)
    sides += (k == 0 ? "" : k + 1 == hidden.size() ? " and " : ", ") + hidden[k];
  return "the frame overhangs the canvas along its " + sides +
         (hidden.size() > 1 ? " edges" : " edge") +
         ": the canvas goes on under it, so it is larger than the " +
         std::to_string(static_cast<int>(std::lround(extent_mm.x()))) + " x " +
         std::to_string(static_cast<int>(std::lround(extent_mm.y()))) +
         " mm seen (scan it out of the frame for the whole canvas)";
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
  if (max_frame_points < 1000)
    return fail("max_frame_points must be >= 1000, got " + std::to_string(max_frame_points));
  return Status::Ok();
}

namespace {

// Steps 1-6: the canvas's plane, mask, frame of reference and extent. A function of its own so
// the steps' masks (a byte per scan sample each) are gone before step 7 scans the frame.
Result<CanvasResult> LocateCanvas(const Grid<Vec3f>& xyz, const CanvasOptions& options,
                                  const std::string& src) {
  using namespace canvas_detail;
  const int w = xyz.width, h = xyz.height;
  Result<PlaneFit> rough = FitRoughPlane(xyz, src);
  if (!rough.ok()) return rough.error();
  Result<GrownRegion> region = GrowCanvasRegion(xyz, *rough, options, src);
  if (!region.ok()) return region.error();
  Result<CanvasPlane> fitted = FitCanvasPlane(xyz, *region, *rough, options, src);
  if (!fitted.ok()) return fitted.error();
  const PlaneFit& plane = fitted->plane;
  const LocalFrame frame(plane);
  const double noise_sigma =
      EstimateNoiseSigma(xyz, fitted->fit_mask, fitted->fit_mask_count, frame);
  // Made again for the outline (a byte per scan sample: not held through the boundary's step).
  fitted->fit_mask.release();
  RefinedBoundary boundary =
      RefineBoundary(xyz, *region, frame, noise_sigma, fitted->fit_mask_count, options);
  // Each step's masks (a byte per scan sample) go once no later step reads them.
  region->grow.release();
  JoinMissingSamples(region->filled, region->valid, boundary.mask);
  const Outline outline =
      FitOutline(xyz, boundary.mask, region->valid, PlaneFitMask(*region, options), frame,
                 noise_sigma, std::min(boundary.spacing_x, boundary.spacing_y));
  region->valid.release();
  if (outline.ok) boundary.mask.release();
  const cv::Mat& final_mask = outline.ok ? outline.mask : boundary.mask;

  // ---- 6. Canvas frame.
  const Mat3d rot = CanvasRotation(plane, outline);
  const Vec3d c0 = plane.centroid;
  CanvasResult result;
  result.mask_scan = Grid<uint8_t>(w, h, 0);
  Box box = BoundMask(xyz, final_mask, region->filled, rot, c0, true, &result.mask_scan);
  if (box.count == 0)
    box = BoundMask(xyz, final_mask, region->filled, rot, c0, false, &result.mask_scan);
  if (box.count == 0) return Error{src + ": the canvas mask holds no valid sample"};
  const std::vector<std::string> hidden =
      outline.ok ? PlaceOutlineSides(outline, plane, rot, &box) : std::vector<std::string>{};

  result.canvas_from_scan.rotation = rot;
  result.canvas_from_scan.translation = -(rot * c0) - Vec3d(box.x0, box.y0, 0);
  result.extent_mm = Eigen::Vector2d(box.x1 - box.x0, box.y1 - box.y0);
  result.plane_rms_mm = std::sqrt(plane.eigenvalues(2));
  result.noise_sigma_mm = noise_sigma;
  result.grown_px = static_cast<size_t>(region->grown);
  result.islands_filled_px = region->islands_px;
  result.refined_px = box.mask_px - box.kept_px;
  result.plane_points = plane.count;
  result.outline_fitted = outline.ok;
  result.outline_note = outline.ok ? "" : outline.note;
  if (!hidden.empty()) {
    result.hidden_edges = hidden;
    result.warnings.push_back(HiddenEdgeWarning(hidden, result.extent_mm));
  }
  result.seed_x = region->seed_x;
  result.seed_y = region->seed_y;
  return result;
}

}  // namespace

Result<CanvasResult> ExtractCanvas(const Scan& scan, const CanvasOptions& options) {
  const std::string src = SourceName(scan);
  if (Status st = options.Validate(); !st.ok()) return Error{src + ": " + st.message()};
  const Grid<Vec3f>& xyz = scan.xyz_mm;
  const int w = xyz.width, h = xyz.height;
  if (xyz.empty() || xyz.data.size() != static_cast<size_t>(w) * static_cast<size_t>(h))
    return Error{src + ": empty scan (" + std::to_string(w) + "x" + std::to_string(h) + ")"};
  Result<CanvasResult> result = LocateCanvas(xyz, options, src);
  if (!result.ok()) return result;
  // ---- 7. The frame's boxes.
  result->frame = canvas_detail::MeasureFrameBoxes(xyz, result->mask_scan, result->canvas_from_scan,
                                                   result->extent_mm, result->noise_sigma_mm,
                                                   options.max_frame_points);
  return result;
}

}  // namespace digitize
