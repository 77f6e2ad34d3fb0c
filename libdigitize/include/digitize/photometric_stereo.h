// Robust per-pixel photometric stereo: normals, albedo and per-image light intensities from
// images of a fixed camera under known light directions (an RTI capture: camera straight down,
// one light per image).
//
// Layer: relief (core only). Images are plain grids of LINEAR radiance; nothing here knows about
// files, cameras or PhotoSet, so the stage is testable alone and the caller (the RTI pipeline)
// passes Photo::rgb / Photo::flags and the .lp directions.
//
// MODEL. Pixel p of image i: I_i(p) = a(p) max(0, n(p).l_i(p)) e_i s_i(p), with a the RGB albedo
// (in the units of the images), n the unit normal (canvas frame: x right, y towards row 0, z
// towards the camera), l_i the unit direction to the light, e_i a per-image intensity (grey;
// handheld captures are not calibrated) and s_i = 1, or (d_i(centre) / d_i(p))^2 for a near point
// light. Gauge: the mean of e over the images is 1 (albedo x intensity is all the data fixes).
//
// ESTIMATOR (per pixel, on the grey value g = mean of R, G, B divided by e_i s_i):
//   1. Rank trimming. Shadows only darken a sample and highlights only brighten it, so the
//      outliers are one-sided and the order statistics find them without a model: the samples
//      below max(low_quantile, shadow_ratio x median) and above high_quantile are dropped, the
//      rest give a least-squares b = a n (3x3 normal equations).
//   2. Reselection, `reselect_iterations` times: with the current b, a sample is an inlier when
//      its predicted shading n.l_i >= min_shading (attached shadows and grazing light, where the
//      Lambertian model and the quantisation are worst, are out) and its residual is within
//      outlier_sigmas sigmas (1.4826 MAD of the trimmed set's residuals in the first round, then
//      the RMS residual of the current inliers, which passed the cut; floored at noise_floor x a);
//      then least squares again on the inliers, until the inliers stop changing.
//   Why not IRLS with a symmetric robust loss: at low light elevations a third or more of a
//   pixel's samples can be cast shadows, and a least-squares start that includes them tilts the
//   normal away from the shadowing relief by tens of degrees, further than a Huber / Tukey loss
//   recovers from; rank trimming starts from a clean subset, the reselection then takes back the
//   dark-but-lit samples that trimming dropped (they carry most of the tilt information).
// The RGB albedo is then a per-channel least-squares scale on the inliers with n fixed.
//
// INTENSITIES (estimate_intensities): alternation from e = 1. With the normals of a subsample of
// pixels (every intensity_stride-th row and column), e_i <- e_i x median over the pixels where
// sample i is an inlier with shading >= min_intensity_shading of g_i / (b.l_i s_i); then e is
// normalised to mean 1 and the normals are solved again. `intensity_iterations` rounds, then one
// full-resolution solve. Given intensities (`intensities` non-empty) are used as they are.
// The intensities and a global tilt of the normals are nearly ambiguous: on a flat patch, normals
// tilted by tau (mean n_xy / n_z) with intensities e_i l_z / (l_z + tau . l_xy) explain the data
// exactly, and only the spread of the relief's normals tells them apart (the alternation alone
// left 4 % intensity errors on exact data after 20 rounds). With zero_mean_tilt (default) each
// round fixes that mode by the gauge "the canvas has no net slope" (the camera looks along the
// canvas normal, which is how an RTI capture is taken and what its flat canvas frame assumes):
// e_i *= 1 + tau . l_xy / l_z with tau the mean tilt of the subsample's normals (n_z >= 0.3).
// Point lights use their direction from the canvas centre for this step.
//
// DEGENERATE PIXELS never give NaN: a pixel whose samples do not constrain a normal (fewer than
// min_inliers inliers, lights that span less than a plane's worth of directions -- all equal, two
// images --, an all-black pixel) gets n = (0, 0, 1), albedo from the least-squares fit with that
// normal (0 for a black pixel), and a status saying why. Normals always have n_z >= min_nz: a
// fitted normal pointing away from the camera is flipped towards it (z mirrored) and then tilted
// up to n_z = min_nz.
//
// Cost: about 10 3x3 solves and one sort per pixel per pass; parallel over rows (TBB).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "digitize/core.h"

namespace digitize {

// One image of the capture.
struct PhotometricImage {
  const Grid<Vec3f>* rgb = nullptr;  // linear radiance, >= 0; every image the same size
  // Optional, same size as rgb: a non-zero value marks a pixel never to use (saturated, NaN in
  // the file: Photo::flags fits). nullptr or an empty grid: every pixel usable.
  const Grid<uint8_t>* exclude = nullptr;
  // Directional light (point_light false): unit direction towards the light, canvas frame.
  // Point light (point_light true): light_mm is the light's position, canvas frame (mm); pixel
  // (x, y) sits at ((x + 0.5) pitch, (height - y - 0.5) pitch, 0) as in height_field.h.
  bool point_light = false;
  Vec3d light = Vec3d::UnitZ();
};

struct PhotometricStereoOptions {
  double low_quantile = 0.2;    // share of each pixel's samples dropped from the dark end (step 1)
  double high_quantile = 0.9;   // samples above this quantile dropped (step 1): highlights
  double shadow_ratio = 0.25;   // and samples darker than this x the pixel's median (step 1)
  int reselect_iterations = 3;  // step 2 rounds
  double min_shading = 0.05;    // inliers need n.l_i >= this (attached shadow / grazing light)
  double outlier_sigmas = 3.0;  // step 2 residual threshold, robust sigmas
  double noise_floor = 0.01;    // robust sigma >= this x the pixel's grey albedo (quantised data
                                // whose fit is exact must not reject every sample)
  int min_inliers = 4;          // >= 3; fewer: the pixel is degenerate
  double min_light_spread = 1e-3;  // smallest eigenvalue of the inliers' mean l l^T below this:
                                   // the lights do not constrain a normal (degenerate)
  double min_nz = 0.05;            // normals have n_z >= this (about 87 deg from the camera axis)
  double black_level = 1e-6;       // a pixel whose brightest sample is below this is black

  bool estimate_intensities = true;    // alternate normals <-> e_i (else e_i = 1 or given)
  int intensity_iterations = 4;        // rounds of the alternation
  int intensity_stride = 4;            // subsample (rows and columns) used by the rounds
  double min_intensity_shading = 0.3;  // e_i from samples with n.l_i >= this only
  bool zero_mean_tilt = true;          // fix the tilt gauge (INTENSITIES above)
  std::vector<double> intensities;     // given e_i (one per image, > 0); empty: 1 or estimated
  double pitch_mm = 1.0;               // mm per pixel: positions for point lights
  int num_threads = 0;                 // 0: all cores

  // Quantiles in [0, 1] with low < high, ratios >= 0, min_inliers >= 3, pitch > 0, ...; names
  // the option.
  Status Validate() const;
};

enum class PhotometricStatus : uint8_t {
  kOk = 0,
  kTooFewInliers = 1,  // fewer than min_inliers samples survive the rejection
  kDegenerate = 2,     // the inliers' lights do not constrain a normal (too few / equal lights)
  kBlack = 3,          // no sample above black_level (no light reached it, or no paint)
};
const char* ToString(PhotometricStatus s);  // "ok", "too few inliers", "degenerate", "black"

struct PhotometricStereoResult {
  Grid<Vec3f> normals;    // unit, canvas frame, n_z >= min_nz; (0, 0, 1) where status != kOk
  Grid<Vec3f> albedo;     // RGB, image units / intensity (>= 0)
  Grid<uint8_t> inliers;  // samples used per pixel (0 .. 255, clamped)
  Grid<float> residual;   // RMS grey residual of the inliers / grey albedo (0 if none)
  Grid<PhotometricStatus> status;   // per pixel
  std::vector<double> intensities;  // e_i per image, mean 1 (1 where not estimated)
  int intensity_rounds = 0;         // alternation rounds done
  size_t ok_pixels = 0, too_few_pixels = 0, degenerate_pixels = 0, black_pixels = 0;
  double seconds = 0;
  // "160000 px x 54 images: 99.2 % ok, 0.5 % too few inliers, 0 % degenerate, 0.3 % black;
  // intensities 0.86 .. 1.14 (4 rounds); 0.21 s"
  std::string Brief() const;
};

// Errors (bad input): no image, a null or empty grid, sizes that differ, an exclude grid of
// another size, a non-finite or zero light, `intensities` of the wrong size or not > 0, invalid
// options. Fewer than 3 images is not an error: every pixel comes out degenerate.
Result<PhotometricStereoResult> SolvePhotometricStereo(
    const std::vector<PhotometricImage>& images, const PhotometricStereoOptions& options = {});

}  // namespace digitize
