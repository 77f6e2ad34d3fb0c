// A canvas from several overlapping scans ("patches": one pose each, unlike the exposures of one
// pose that MergeExposures takes). A structured-light head covers ~300 x 400 mm, so a large
// painting is scanned as a grid of patches; the rig reports each head pose only roughly (a few mm,
// about a degree). This stage registers the patches rigidly, merges them into one canvas height
// field and measures the residual in every overlap (docs/formats.md, "Patch lists").
//
// Steps, per patch in the order of a breadth-first walk from patch 0 over the overlaps (the
// patch with the largest overlap with those already placed comes next):
//   1. canvas: ExtractCanvas on the patch alone (its canvas mask; the frame and wall that edge
//      patches see stay out of every later step);
//   2. coarse: in the overlap with the placed patches, (a) the patch's plane is turned and moved
//      onto theirs (PCA of both point sets there), then (b) its band-passed heights are
//      correlated (normalised cross-correlation, within search_mm) with each placed patch's, in
//      the two halves of each overlap strip, and the median shift applied (translation only: a
//      rotation from two pieces of a strip is at the mercy of one stroke); twice;
//   3. ICP: point-to-plane ICP with a robust kernel (OpenCV contrib surface_matching,
//      cv::ppf_match_3d::ICP: "Picky ICP" whose correspondences farther than rejection_scale
//      robust sigmas of the median distance are dropped, i.e. a truncated quadratic kernel) on
//      the samples smoothed over smooth_mm, repeated until one round moves no point of the patch
//      by more than converged_mm: it takes the patch from millimetres off to a few tenths;
//   4. polish: Gauss-Newton on the height difference to the placed patches' surface (Huber
//      kernel, IRLS), which holds the in-plane rotation that ICP leaves loose (why: PolishStep);
//   then global_rounds passes polish every patch, patch 0 included, against all the others,
//   which spreads the loop closure error of a grid over all its overlaps;
//   5. canvas frame: the robust plane of every registered canvas point (relief trimmed, as
//      ExtractCanvas does), the in-plane X axis from the patches whose canvas outline was fitted
//      (else the rig's X), the extent from the union of the patches' canvas masks;
//   6. merge: every patch resampled onto the one canvas grid by ResampleToCanvasGrid (the
//      triangles of its own scan grid), then blended per texel with weights that fall to zero
//      over feather_mm at each patch's border (no seam where a residual remains);
//   7. residuals: per overlap (two patches measuring a texel), the RMS, max and mean height
//      difference and the texel count.
// Accuracy (tests/scan_registration_test.cpp, samples ~0.93 mm apart, 0.02 mm noise): the
// registered poses move no canvas point more than 0.25 texel from the truth.
// Why OpenCV's ICP: it is in Debian (libopencv-contrib-dev, next to the OpenCV the canvas layer
// already links), works on plain N x 6 float matrices of points + normals, is point-to-plane
// (a canvas is nearly flat: point-to-point ICP slides along it) and drops outlier
// correspondences by a robust scale. CGAL's registration needs libpointmatcher or OpenGR, neither
// packaged in Debian 12. Its weaknesses are handled here: it always returns 0 and its residual
// mixes normals into the distance, so convergence and residuals are measured by this stage itself;
// its pyramid (icp_levels > 1) and a fixed cloud as sparse as the moving one make it swing between
// calls, hence one level, all fixed samples, and the clouds chosen once per step.
//
// Frames: each patch's scan in its own scan frame; rig_from_scan its nominal pose in the rig frame
// (the frame the poses are given in; patch 0 stays at its nominal pose: the registration fixes the
// patches relative to each other, not the rig). The result's canvas.canvas_from_scan maps the RIG
// frame to the canvas frame (a photo calibration given in the rig frame then lines up).
//
// Errors (naming the scan files): fewer than two patches, a patch whose canvas is not found, a
// patch that overlaps no other by min_overlap_mm2, an overlap with no relief to correlate
// (featureless: every piece's correlation peak below min_correlation_peak), ICP still moving the
// patch by more than 10 converged_mm after max_icp_rounds, the polish not converging in
// polish_iterations, a correction larger than max_correction_mm,
// an overlap whose RMS residual exceeds max_overlap_rms_mm. Never returns NaN/Inf.
#pragma once

#include <string>
#include <vector>

#include "digitize/canvas.h"
#include "digitize/core.h"
#include "digitize/height_field.h"
#include "digitize/resample.h"
#include "digitize/scan_data.h"

namespace digitize {

struct ScanPatch {
  Scan scan;                     // its own scan frame; source names the file in messages
  RigidTransform rig_from_scan;  // nominal pose (the rig's), mm
};

struct PatchRegistrationOptions {
  double min_overlap_mm2 = 1000;  // a patch must share at least this canvas area with another
  double lowpass_mm = 1.2;        // Gaussian sigma smoothed away before correlating (noise, weave)
  double highpass_mm = 6;         // Gaussian sigma of the low-pass removed before correlating
                                  // (bow, tilt: only relief is correlated)
  double smooth_mm = 0.3;  // Gaussian sigma of the samples ICP and the polish see (noise; more
                           // blunts the strokes' flanks that hold the in-plane fit)
  double search_mm = 6;    // the coarse correlation looks this far from the nominal
  double min_correlation_peak = 0.3;  // normalised correlation peak (-1..1) below which an
                                      // overlap has no relief to register (measured: a bare
                                      // canvas's noise 0.18; painted overlaps 0.42-0.97)
  int icp_iterations = 60;            // per pyramid level of one ICP call
  int icp_levels = 1;                 // ICP pyramid levels (coarser levels subsample both clouds
                                      // alike: on a flat canvas their matches are false and the
                                      // result swings by ~1 mm between calls)
  double icp_rejection_scale = 2.5;   // robust kernel: correspondences beyond this many robust
                                      // sigmas (MAD) of the median distance are dropped
  int max_icp_points = 3000;          // the moving patch's overlap points per ICP call (stride)
  int polish_iterations = 40;         // Gauss-Newton iterations of the polish, at most
  int max_polish_points = 20000;      // moving samples per polish (stride)
  double huber_sigmas = 1.5;          // robust kernel of the polish: Huber at this many MADs
  double converged_mm = 0.02;         // a round that moves no patch point more: converged
                                      // (1/45 texel at 0.9 mm)
  int max_icp_rounds = 12;            // ICP rounds per registration before "did not converge"
  int global_rounds = 4;              // polish passes of every patch against all others
                                      // (block Gauss-Seidel: the in-plane rotation settles
                                      // slowly; 2 / 3 / 4 passes: worst 0.253 / 0.249 / 0.244
                                      // texel over a 2 x 2 grid's seeds 1-24)
  double max_correction_mm = 25;      // a correction moving a canvas point more: an error
  double max_overlap_rms_mm = 0.15;   // an overlap whose height residual RMS is larger: an error
  double feather_mm = 8;              // blend ramp at each patch's border
  Status Validate() const;
};

struct OverlapResidual {
  int patch_a = 0, patch_b = 0;  // indices into the patches, a < b
  size_t texels = 0;             // texels both measured
  double rms_mm = 0;             // RMS of height_a - height_b over them
  double max_mm = 0;             // max |height_a - height_b|
  double mean_mm = 0;            // mean of height_a - height_b (a step between the patches)
};

struct PatchReport {
  std::string source;
  RigidTransform rig_from_scan;  // registered pose
  double correction_deg = 0;     // rotation of registered * nominal^-1
  double correction_mm = 0;      // how far it moved the patch's canvas centroid
  double max_correction_mm = 0;  // how far it moved the farthest canvas point of the patch
  int correlation_pieces = 0;    // overlap pieces whose correlation was used (placement)
  double correlation_peak = 0;   // their lowest normalised correlation peak (-1..1)
  int icp_rounds = 0;            // ICP rounds when it was placed
  double last_icp_move_mm = 0;   // largest point move of the last ICP round
  size_t canvas_points = 0;      // valid canvas samples of the patch
  bool outline_fitted = false;   // its canvas outline gave an in-plane axis
};

struct PatchRegistrationResult {
  CanvasResult canvas;     // canvas_from_scan = canvas_from_RIG; mask_scan of patch 0; extent,
                           // plane RMS, noise sigma (median of the patches'), frame boxes (the
                           // sides' largest over the patches)
  HeightField field;       // merged, canvas grid; never NaN/Inf
  ResampleStats resample;  // of the merged field (triangle counts summed over patches)
  Grid<uint8_t> coverage;  // per texel, how many patches measured it
  std::vector<PatchReport> patches;
  std::vector<OverlapResidual> overlaps;  // every pair sharing >= 1 measured texel
  size_t uncovered_texels = 0;            // grid texels no patch reaches (kOutside)
  std::string brief;  // "4 patches, 4 overlaps: residual RMS <= 0.021 mm, max 0.12 mm; ..."
};

Result<PatchRegistrationResult> RegisterPatches(const std::vector<ScanPatch>& patches,
                                                const PatchRegistrationOptions& options,
                                                const CanvasOptions& canvas_options,
                                                const ResampleOptions& resample_options);

}  // namespace digitize
