// Canvas extraction (paper section 4.2): find the canvas in a scan of a framed painting
// and the rigid transform into the canvas frame (see height_field.h for that frame).
//
// Steps: PCA plane of all valid points -> heights along its normal -> Sobel magnitude -> region
// growing from the seed (the scan centre) that stops at strong gradients -> enclosed islands
// (impasto walls, holes) filled -> boundary refined by a height-step test -> eroded copy used
// for a second, robust plane fit on the canvas points alone (relief trimmed) -> outline: the
// visible canvas as a rectangle in the plane (in-plane axes from its edges, mask = the pixels
// inside it, frame overhangs detected) -> canvas frame -> the frame's boxes (height_field.h): per
// side, from the scan points outside the outline.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize/height_field.h"
#include "digitize/scan.h"

namespace digitize {

struct CanvasOptions {
  double stop_gradient_mm = 3.0;  // Sobel magnitude (mm of height per pixel) that ends the growth;
                                  // a frame step is 10+ mm, canvas relief is < 1 mm per pixel
  double stop_slope = 4.0;        // surface slope (height / in-plane distance, tan 76 deg) that
                                  // also ends the growth: a frame wall seen obliquely is vertical
                                  // in the canvas frame even where its per-pixel step is small
  double refine_step_mm = 3.0;    // boundary refinement: a pixel next to the region joins it when
                                  // its height differs from its region neighbour by less than this
  int refine_px = 3;              // how far (pixels) the refinement may move the boundary outwards
  int erode_px = 3;               // erosion (pixels) of the region before the second plane fit
  double trim_sigmas = 3.0;       // robust plane: points more than this many MADs above the plane
                                  // (relief) are left out of the refit
  int seed_x = -1, seed_y = -1;   // growth seed in scan pixels; -1 = nearest valid to the centre
  double min_canvas_fraction = 0.05;  // a region smaller than this share of the valid samples is
                                      // an error (seed landed on the frame or a speck)
  // The frame's boxes (step 7) are quantiles of the frame's samples, per side at most this many
  // (evenly spaced in the scan): beyond ~5e5 their rank error (~1e-3) no longer shrinks, while a
  // scan's whole frame would hold 16 bytes a sample (1.2 GB for an 8192-texel canvas's scan).
  size_t max_frame_points = size_t{1} << 19;
  Status Validate() const;
};

struct CanvasResult {
  Grid<uint8_t> mask_scan;          // per scan pixel: 1 = canvas (holes inside included), 0 = not
  RigidTransform canvas_from_scan;  // scan frame -> canvas frame (height_field.h)
  Eigen::Vector2d extent_mm{0, 0};  // visible canvas in its plane (X, Y): the outline rectangle
                                    // (else the mask points' bounding rectangle)
  double plane_rms_mm = 0;          // RMS distance of the trimmed canvas points to the plane
  double noise_sigma_mm = 0;        // robust estimate of the scan noise on the canvas
  size_t grown_px = 0;              // region after growing
  size_t islands_filled_px = 0;     // enclosed pixels added back
  size_t refined_px = 0;            // pixels added by the boundary refinement
  size_t plane_points = 0;          // points used by the final plane fit
  int seed_x = 0, seed_y = 0;       // seed actually used
  // Outline (step 5b): the visible canvas as a rectangle in the plane gave the in-plane axes,
  // the extent and the mask (false: the grown region and PCA axes were kept; why in the note).
  bool outline_fitted = false;
  std::string outline_note;
  std::vector<std::string> hidden_edges;  // "left", "right", "top", "bottom": the frame overhangs
  // The frame as boxes the ray tests see (canvas_frame.cpp): per side, the top of the scan points
  // within 150 mm outside the outline; none on a side the scan does not cover or where nothing
  // rises above the canvas plane (a canvas on a wall, an unframed stretcher).
  FrameBoxes frame;
  std::vector<std::string> warnings;  // one line each, for the report and the console
};

// Errors (naming scan.source): too few valid samples, no valid sample near the seed, or a
// region below min_canvas_fraction. A canvas that fills the whole scan (no frame) is not an error.
Result<CanvasResult> ExtractCanvas(const Scan& scan, const CanvasOptions& options);

// Plane of a point set by PCA (Eigen's self-adjoint solver). normal is the unit eigenvector of the
// smallest eigenvalue, oriented to have a negative Z (towards a scanner looking along +Z).
struct PlaneFit {
  Vec3d centroid = Vec3d::Zero();
  Mat3d axes = Mat3d::Identity();     // columns: major in-plane, minor in-plane, normal
  Vec3d eigenvalues = Vec3d::Zero();  // descending
  size_t count = 0;
};
PlaneFit FitPlanePca(const std::vector<Vec3d>& points);

}  // namespace digitize
