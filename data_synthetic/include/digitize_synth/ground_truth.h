// Accuracy of preprocessing, and of patch registration, against the generator's ground truth
// (tests and benchmarks use it).
//
// Frames: T = truth.canvas_from_scan * estimate.canvas_from_scan.Inverse() maps the estimated
// canvas frame into the true one. Estimated texels are mapped through T and compared with the true
// surface there (bilinear on the truth grid, height_field.h conventions); true texels are mapped
// back through T^-1 to be looked up in the estimate's grid and boxes.
#pragma once

#include "digitize/preprocess.h"
#include "digitize/scan_registration.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/patch_sim.h"
#include "digitize_synth/scan_sim.h"

namespace digitize::synth {

struct PreprocessAccuracy {
  double normal_error_deg = 0;            // canvas plane normal vs truth
  double mask_iou = 0;                    // estimated vs true canvas mask in scan pixels
  size_t frame_pixels_kept = 0;           // true frame/wall pixels in the estimated mask
  double frame_pixels_max_height_mm = 0;  // of those, the largest |height| above the true canvas
                                          // plane (a wall foot within noise of the plane is
                                          // indistinguishable from canvas)
  double height_rmse_mm = 0;      // on texels with height, true surface vs estimate, along the
                                  // true normal, after removing the constant offset (the zero
                                  // of heights is a convention: see height_field.h)
  double height_offset_mm = 0;    // that constant offset
  double normals_median_deg = 0;  // per-texel normal error, median
  double normals_p90_deg = 0;
  size_t relief_texels_true = 0;       // true texels above delta0 (outside specks)
  size_t relief_texels_uncovered = 0;  // of those, not inside any box
  size_t texels_compared = 0;
  // Added for diagnostics:
  size_t relief_texels_outside = 0;  // true relief texels landing where the estimate has no
                                     // canvas (off its grid or on kOutside texels); not counted
                                     // as uncovered: the mask IoU reports that loss
  size_t normals_compared = 0;       // texels whose 3x3 neighbourhood has height
  // Frame errors (they show on scans unlike the default):
  double axis_error_deg = 0;       // estimated canvas X axis vs the canvas edges (in-plane)
  double extent_error_mm = 0;      // max over X, Y of |estimated extent - visible extent|
  double bare_plane_tilt_deg = 0;  // estimated normal vs the bare canvas's least-squares plane
};

struct AccuracyOptions {
  // True relief components smaller than this are specks the estimate may drop: set it to the
  // ReliefOptions::min_component_area_mm2 the estimate used.
  double min_component_area_mm2 = ReliefOptions{}.min_component_area_mm2;
};

// Definitions:
//   normal_error_deg: angle between the Z axes of the two canvas frames (scan frame).
//   axis_error_deg: |angle| of the estimated X axis, rotated into the true canvas frame, from the
//     true X axis (the canvas's bottom and top edges) about the true normal.
//   extent_error_mm: against scan.visible_max_mm - scan.visible_min_mm.
//   bare_plane_tilt_deg: angle between the estimated Z axis and painting.bare_plane_normal (both
//     in the scan frame); equals normal_error_deg on a flat canvas.
//   mask_iou / frame_pixels_kept: over scan pixels, estimate.canvas.mask_scan vs
//     scan.canvas_mask_scan; kept = estimated canvas where the ray hit the frame or the wall.
//   height: every estimated texel with HasHeight() whose mapped point lies on the true canvas;
//     error = (mapped height - true height there) * true n_z (distance along the true normal);
//     height_offset_mm = median error, height_rmse_mm = RMS of (error - offset).
//   normals: estimated normal rotated by T vs the true normal (bilinear, renormalised) at the
//     mapped point; texels whose 3x3 neighbourhood all has height.
//   relief: true texels whose height in the estimate's frame (through T^-1) exceeds
//     estimate.relief.delta0_mm (at least 1 um), in 8-connected components of at least
//     min_component_area_mm2; each is looked up (nearest texel) in the estimate's grid and boxes.
// Metrics with nothing to compare are NaN (so that a threshold test on them fails); a mask of
// another size than the scan gives IoU 0.
PreprocessAccuracy MeasureAccuracy(const PreprocessResult& result, const Painting& painting,
                                   const SyntheticScan& scan, const AccuracyOptions& options = {});

// Registration error of patches (scan_registration.h) against their true poses: the farthest any
// registered canvas sample lies from its true place, in texels of the merged canvas (pitch of
// result.field), with two gauges (the registration places the patches relative to each other,
// not in the rig):
//   patch 0's: G = true_0 * registered_0^-1 maps every registered pose into the truth;
//   best: the rigid motion (least squares, no scale) that best maps the whole registered mosaic
//     onto its truth, the mosaic's own error however far a patch is from patch 0 (the canvas
//     frame is fitted to all patches, not to patch 0).
struct RegistrationAccuracy {
  double max_error_texels = 0;
  double best_gauge_error_texels = 0;
};
RegistrationAccuracy MeasureRegistration(const SyntheticPatchScan& scan,
                                         const PatchRegistrationResult& result);

}  // namespace digitize::synth
