// "Fit BRDF textures from photo sets" (paper 001 section 5): canvas + registered photos ->
// per-texel reflectance maps with a status per texel and a report.
//
// Layer: samples (reflectance_samples.h, brdf_fit.h, reflectance_maps.h).
//
// The canvas is processed in tiles of tile_texels texels (row-major runs of the canvas's texels,
// kOutside ones left out): gather the tile's samples (reflectance_samples.h, parallel over photos),
// fit them (brdf_fit.h, parallel over texels, each block of texels taking its samples from the
// photo-major gather: no texel-major copy), write the maps; so memory stays ~tile_texels x
// photos x 48 bytes whatever the canvas size.
//
// Unmodelled shadows. Shadows cast by anything but the relief and the frame's boxes (a frame the
// canvas does not carry, a hand, a stand) are invisible to the ray tests, and dark samples pull
// the whole fit down. The
// model bounds radiance from below by the diffuse term (the lobe is >= 0), so, per texel:
//   1. before fitting, the diffuse floor is estimated as the median apparent reflectance
//      q = sum_c radiance / sum_c E of its samples (a lobe only raises q, a shadow drops it to ~0);
//      a sample below dark_outlier_ratio x that floor, by more than dark_outlier_sigmas x
//      noise_sigma x sqrt(3), is removed;
//   2. after the fit, the same test against the fitted E rho_d with dark_outlier_fit_ratio (a
//      lit sample cannot be below it, so this ratio can be close to 1 and also catches samples
//      that straddle a shadow edge); removed samples trigger a refit
//      (at most dark_outlier_rounds times).
// Counted in the report (dark_outliers, texels_refitted = texels that lost samples).
// Texels: kOutside texels are not fitted (zeros, status kTooFewSamples, like texels with no
// usable sample); everything else is (kUnfilled texels too: their heights are inpainted, their
// normals smooth, and their colour is still measured).
#pragma once

#include <filesystem>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "digitize/brdf_fit.h"
#include "digitize/core.h"
#include "digitize/height_field.h"
#include "digitize/photo_set.h"
#include "digitize/reflectance_maps.h"
#include "digitize/reflectance_samples.h"

namespace digitize {

struct ReflectanceFitOptions {
  SampleOptions samples;
  BrdfFitOptions fit;
  int tile_texels = 32768;  // texels gathered and fitted at a time (memory bound)
  // Sample each texel from the pixels whose camera rays see it (reflectance_samples.h,
  // MapPixelsToTexels: one map per camera position, 4 bytes per pixel, held for the whole fit);
  // false: from the pixels whose centres fall in its projected cell.
  bool pixel_texel_maps = true;
  double dark_outlier_ratio = 0.5;      // before the fit, vs the median floor; <= 0 disables the
                                        // unmodelled-shadow removal (see above)
  double dark_outlier_fit_ratio = 0.7;  // after the fit, vs the fitted diffuse floor (a lit
                                        // sample is never below it but for noise)
  double dark_outlier_sigmas = 6.0;
  int dark_outlier_rounds = 2;
  // The noise model's quantisation term (brdf_fit.h, NOISE MODEL) taken from the photos
  // (DetectPhotoQuantisation): fit.photo_code_max, photo_codes_srgb and
  // photo_compression_sigma_codes are then set from them, overriding what `fit` holds.
  bool quantisation_from_photos = true;
  double jpeg_sigma_codes = 1.0;  // JPEG's error, std in codes (about 1 at quality 90)
  Status Validate() const;
};

// How the photos were quantised, found from the photos themselves (the reader keeps only linear
// values): a photo is on 8-bit (16-bit) codes when every probed value (a few thousand pixels,
// spread over the image) decodes from one; the coarsest over the set is taken (samples do not
// say which photo they came from). JPEG files (.jpg/.jpeg) are lossy. Float photos: code_max 0.
struct PhotoQuantisation {
  int code_max = 0;  // 255, 65535, or 0 (float or not on codes: no quantisation term)
  bool srgb = true;  // the codes are sRGB (else linear)
  bool lossy = false;
};
PhotoQuantisation DetectPhotoQuantisation(const PhotoSet& photos);

// A photo set constrains the fit only through its distinct (light, view) pairs: the fit classifies
// a texel (diffuse-only or glossy) only from min_samples usable samples, so a set with fewer
// distinct pairs than max(min_samples, kMinDistinctPhotoDirections) would make every texel "too
// few samples" (a one-photo capture gave a black pack and exit 0): FitReflectance refuses it. Two
// photos are one pair when both their light and their view directions, at the canvas centre and
// in the canvas frame, are within kSameDirectionDeg; photos whose light is at or below the canvas
// plane (canvas Z <= 0: a point light's position, a directional light's direction) give no sample
// and do not count.
inline constexpr int kMinDistinctPhotoDirections = 2;  // a diffuse fit's chi-square test needs
                                                       // 3 N - 3 > 0 degrees of freedom
inline constexpr double kSameDirectionDeg = 0.5;

struct ReflectanceFitReport {
  size_t photos = 0;            // in the set
  int distinct_directions = 0;  // distinct (light, view) pairs with the light above the canvas
  // Photos whose light is at or below the canvas plane: a warning, not an error (their samples
  // are rejected, n.l <= 0); their entries, in set order.
  std::vector<std::string> light_below_canvas;
  SampleStats samples;
  BrdfFitSummary fit;              // over the fitted texels; fit.seconds = wall time fitting
  PhotoQuantisation quantisation;  // what the noise model used (quantisation_from_photos)
  size_t dark_outliers = 0;        // samples removed as unmodelled shadows
  size_t texels_refitted = 0;      // texels that lost samples to it
  size_t texels_outside = 0;       // kOutside texels, not fitted
  double seconds_tracer = 0;       // building the ray-tracing structure
  double seconds_samples = 0;      // gathering samples, rays included (wall)
  double seconds_fit = 0;          // fitting (wall)
  double seconds_total = 0;
  // One line: "1.05 M texels x 64 photos: 97.8 % converged, 1.9 % diffuse-only, ...; samples
  // 2.1 s, fit 4.9 s, total 7.4 s".
  std::string Brief() const;
  // What the user should know although the fit ran ("3 of 40 photos have their light at or below
  // the canvas plane ..."); empty when nothing is amiss. Printed by `fit` and `run`, and in
  // report.json ("warnings").
  std::vector<std::string> Warnings() const;
};

struct ReflectanceFitResult {
  ReflectanceMaps maps;
  ReflectanceFitReport report;
};

// Errors (nothing fitted): invalid options; sizes that differ; photos not loaded; a camera that
// does not see the canvas or sees it at an absurd scale (CheckCamerasSeeCanvas; names the
// calibration entry); fewer distinct (light, view) pairs than the fit needs (above; names the
// photo set, the count and the minimum); a tracer build failure. Never NaN/Inf in the maps
// (checked).
Result<ReflectanceFitResult> FitReflectance(const HeightField& canvas, const Grid<Vec3f>& normals,
                                            const RigidTransform& canvas_from_scan,
                                            const PhotoSet& photos,
                                            const ReflectanceFitOptions& options,
                                            const ProgressCallback& progress = nullptr);

// A rectangle of canvas texels: columns [x, x + width), rows [y, y + height).
struct TexelRect {
  int x = 0, y = 0, width = 0, height = 0;
  size_t texels() const { return static_cast<size_t>(width) * static_cast<size_t>(height); }
  bool operator==(const TexelRect&) const = default;
};

// FitReflectance on parts of the canvas (the tiles of a tile plan, tile_plan.h), in order, with
// one tracer and one set of pixel maps for all of them: each region's texels are sampled and
// fitted as FitReflectance would (every texel's samples, fit and status are its own, so a
// region's maps are BIT-IDENTICAL to the same texels of the whole canvas's fit), and `done` gets
// the region's maps (the region's size) and its report (its samples, texels and times; the
// photo-set fields as the whole fit's) before the next region starts -- so a caller that writes
// each one out can be killed and resume. A `done` error stops the run and is returned. Errors as
// FitReflectance; a region not inside the canvas or empty. `whole_set`: when `photos` are parts
// of photos (LoadPhotoRegion, a tile at a time), the set they were cut from (headers only): the
// set-wide checks and counts (cameras against the canvas, distinct directions, lights below the
// canvas) are of it, as the whole canvas's fit makes them. Null: of `photos`.
using RegionFitted = std::function<Status(size_t region, ReflectanceFitResult&& result)>;
Status FitReflectanceRegions(const HeightField& canvas, const Grid<Vec3f>& normals,
                             const RigidTransform& canvas_from_scan, const PhotoSet& photos,
                             const ReflectanceFitOptions& options,
                             std::span<const TexelRect> regions, const RegionFitted& done,
                             const ProgressCallback& progress = nullptr,
                             const PhotoSet* whole_set = nullptr);

// The report as JSON text (docs/formats.md, "fit report").
std::string ReflectanceReportJson(const ReflectanceFitResult& result,
                                  const ReflectanceFitOptions& options,
                                  const std::vector<std::string>& inputs);

// Writes rho_d.exr, rho_s.exr (RGB, 1/sr), lobe.exr (channels cx, cy, cz, k), fit_error.exr,
// fit_status.png (TexelFitStatus values x 40, readable by eye), model.png (ReflectanceModel
// values x 100: 0 Lafortune, 100 GGX; GGX texels hold F0 in rho_s and alpha in k, as
// ReflectanceMaps) and report.json into dir, each atomically (the CLI wraps the folder in
// WriteDirectoryAtomically).
Status WriteReflectanceOutputs(const std::filesystem::path& dir, const ReflectanceFitResult& result,
                               const ReflectanceFitOptions& options,
                               const std::vector<std::string>& inputs);

// Judging a fit on held-out photographs (lights and views not fitted): each photo is re-rendered
// from the canvas and the maps (RenderRelit, shadows by the relief on) and compared with the photo
// over the pixels that see a canvas texel, are not flagged (NaN, saturated) in the photo, and are
// non-zero in the optional per-photo mask (e.g. the generator's frame-shadow masks). Both images
// are clipped to [0, peak] first -- what a camera or a display shows -- and PSNR uses that peak
// (1 = the white of an 8-bit photo). The pooled figure is over all compared pixels of all photos.
// Beside the linear figure, the one RTI tools and viewers show: both images divided by the peak,
// sRGB-encoded and rounded to 8 bits, PSNR with peak 255 (dark pixels weigh more there, as they
// do to the eye).
struct HeldOutImageScore {
  std::string entry;  // the photo's calibration entry
  double psnr_db = 0, rmse = 0;
  double psnr_srgb8_db = 0;
  size_t pixels = 0;
};
struct HeldOutScore {
  std::vector<HeldOutImageScore> images;
  double psnr_db = 0, rmse = 0;  // pooled
  double psnr_srgb8_db = 0;      // pooled
  size_t pixels = 0;
  double seconds = 0;
  // "held-out PSNR 41.3 dB linear, 38.2 dB 8-bit sRGB (RMSE 0.0086) over 8 photos, 1.2 M px"
  std::string Brief() const;
};
// Errors: photos not loaded, masks of the wrong count or size, a tracer build failure.
// `relit` (optional): each photo's relit image (linear, unclipped, the photo's size), in order.
Result<HeldOutScore> EvaluateHeldOut(const HeightField& canvas, const Grid<Vec3f>& normals,
                                     const ReflectanceMaps& maps,
                                     const RigidTransform& canvas_from_scan,
                                     const PhotoSet& held_out,
                                     const std::vector<Grid<uint8_t>>& masks = {},
                                     double peak = 1.0, std::vector<Grid<Vec3f>>* relit = nullptr);

// Writes each relit held-out photo into `dir` under its photo's file-name stem, in the photo's
// encoding: 8-bit sRGB PNG for sRGB photos, linear float EXR for linear ones. Errors: sizes or
// counts that differ, two photos with one stem (the second would overwrite the first), a write
// error naming the file.
Status WriteRelitImages(const std::filesystem::path& dir, const PhotoSet& held_out,
                        const std::vector<Grid<Vec3f>>& relit);

// Reads what WriteReflectanceOutputs wrote (the maps only). Errors name the file: missing,
// wrong size or channels, a value the maps may not hold.
Result<ReflectanceMaps> ReadReflectanceMaps(const std::filesystem::path& dir);

// Texels [x0, x0 + width) x [y0, y0 + height) of the maps in `dir`, read through `reader`
// (image_io.h: a bounded cache), so that a band of maps costs the band, not the files. The same
// checks of every value as ReadReflectanceMaps; the files' sizes are not compared with each
// other (ReadReflectanceMaps does), only each found to hold the window.
Result<ReflectanceMaps> ReadReflectanceMapsWindow(const std::filesystem::path& dir, int x0, int y0,
                                                  int width, int height, ImageRegionReader& reader);

}  // namespace digitize
