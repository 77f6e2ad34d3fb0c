// Reflectance samples (paper section 5; docs/architecture.md, "Fitting reflectance from photos"):
// every canvas texel projected into every photo, with its local view and light directions, its
// colour and the light's irradiance -- the input of the per-texel BRDF fit (brdf_fit.h).
//
// Layer: samples (core, photo_set.h, brdf_fit.h, height_field_tracer.h, tangent_frame.h).
//
// For texel (x, y) (any state but kOutside) and photo i:
//   p   = (TexelCentreMm(x, y), height_mm(x, y)) in the canvas frame -- the TRUE height, so the
//         directions are corrected for the relief (paper 001, section 4.4); p_scan the same point
//         in the scan frame (canvas_from_scan inverse), where cameras and lights live;
//   n   = normals(x, y); directions go to its tangent frame (tangent_frame.h);
//   v   = towards the camera (pinhole: the centre; orthographic: the axis), l = towards the light;
//   rgb = the mean of the photo's pixels that see this texel: with pixel maps (SampleScene::
//         pixel_texels, MapPixelsToTexels) the pixels near the texel's footprint whose camera ray
//         first meets the surface nearest to this texel (the renderers' image model, relief
//         parallax and the frame included); without them the pixels whose centres fall in the
//         footprint (the texel's cell [-1/2, 1/2)^2 mapped by the projection's Jacobian at
//         Camera::Project(p_scan)). Either way a texel next to another paint is not fitted to a
//         blend of both. Texels smaller than a pixel take the bilinear value at p; with pixel
//         maps, where no pixel sees the texel although the photo resolves the grid (an oblique
//         view steps over it, or a steep wall is foreshortened below a pixel and its pixels
//         see a neighbour), that value is kept only where the texel has fewer than
//         min_direct_samples others (counted as "stepped over" when dropped);
//   E   = Light::IrradianceAt(p_scan) * (n.l)   (what multiplies f_r; brdf_fit.h).
// A candidate (texel, photo) is REJECTED, in this order (each counted in SampleStats):
//   behind the camera; outside the image; n.v <= min_cos (texel faces away); n.l <= min_cos
//   (light below the texel's horizon); a NaN/Inf pixel among those averaged; a saturated
//   pixel among them (only a lower bound of the radiance); black (every channel <= black_level:
//   clipped at the sensor's floor, so the value is only an upper bound); hidden from the camera
//   (a ray from p towards the camera meets the relief or the frame); shadowed (a ray from p
//   towards the light meets the relief or the frame). Rays are traced only for candidates that
//   survive the cheaper tests, with the tracer's exact skipping of rays that cannot be blocked
//   (counts in view_rays/light_rays).
// COST (share_view_rays, the default): the camera's tests, the footprints and the view rays
// depend on the camera position alone and are computed once per position (Camera::SameView)
// for all its photos; a photo then costs its light's tests, the pixel averages and the shadow
// rays, of which the per-texel horizon bounds (src/shadow_horizon.h) prove ~99 % free on the
// bench painting before the tracer is asked. Same samples and counts as the per-photo path
// (share_view_rays = false); only the ray counts differ (a view ray per position, not per photo).
// The frame is in these tests when the canvas carries its boxes (HeightField::frame, measured
// from the scan by the canvas stage). Without them (an RTI capture, a canvas from elsewhere),
// frame shadows are removed by the fit stage as samples darker than the diffuse floor
// (reflectance_fit.h), and the strip of canvas the frame hides from an oblique camera is fitted
// from pixels of the frame.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "digitize/brdf_fit.h"
#include "digitize/core.h"
#include "digitize/height_field.h"
#include "digitize/height_field_tracer.h"
#include "digitize/photo_set.h"

namespace digitize {

struct SampleOptions {
  double min_cos = 0.0;         // n.v and n.l must exceed this (0: anything above the horizon)
  float black_level = 0.0f;     // linear value at or below which a channel counts as black
  bool reject_black = true;     // drop samples black in every channel (clipped at the floor)
  bool visibility_rays = true;  // trace rays towards the camera (hidden texels)
  bool shadow_rays = true;      // trace rays towards the light (self-shadowing)
  // With pixel maps, a texel no pixel sees in a photo that resolves the grid (stepped over by an
  // oblique view, a wall foreshortened below a pixel) gets the bilinear value, its neighbours'
  // paint as much as its own; such samples are dropped from a texel with at least this many
  // direct ones.
  int min_direct_samples = 8;
  // What depends on the camera alone (its tests, footprints, view rays) once per camera position
  // (Camera::SameView) instead of once per photo; the same samples either way (tested). false:
  // the per-photo path, kept as the reference the benchmark and tests compare with.
  bool share_view_rays = true;
  // With share_view_rays and trace.skip_unblockable: azimuth sectors of the per-texel horizon
  // bounds that prove rays free without the tracer (src/shadow_horizon.h; exact: a ray is
  // skipped only where nothing can block it, so the samples do not change; counted as skipped
  // rays); 0: every ray goes to the tracer. At most 32.
  int horizon_sectors = 16;
  TraceOptions trace;  // skip_unblockable etc.
  Status Validate() const;
};

struct SampleStats {
  size_t texels = 0;      // texels sampled
  size_t candidates = 0;  // texels x photos
  size_t behind_camera = 0, outside_image = 0, facing_away = 0, light_below_horizon = 0;
  size_t non_finite = 0, saturated = 0, black = 0, hidden = 0, shadowed = 0;
  size_t stepped_over = 0;  // interpolated samples dropped: the texel had enough direct ones
  size_t kept = 0;
  TraceStats view_rays, light_rays;
  SampleStats& operator+=(const SampleStats& o);
  // "61.2 M candidates, 58.0 M kept (94.8 %); rejected: 1.2 M shadowed, ...; rays: 120 M, 91 %
  // skipped"
  std::string Brief() const;
};

// What the samples are taken from. Everything must outlive the call; sizes are checked by
// ValidateSampleScene, which FitReflectance calls (GatherSamples only asserts them).
// Which texel every pixel of a photo sees: the texel nearest to where the pixel's camera ray first
// meets the canvas surface, kNoTexel where it meets the frame, a kOutside texel or nothing. One
// map per camera position (Camera::SameView), shared by its photos: RTI domes and photo sets
// with few camera positions trace it once per position, not per photo. 4 bytes per pixel.
inline constexpr uint32_t kNoTexel = 0xFFFFFFFFu;
struct PixelTexelMaps {
  std::vector<Grid<uint32_t>> maps;  // texel index y * width + x per pixel
  std::vector<uint32_t> of_photo;    // map index per photo of the set
  size_t rays = 0;                   // camera rays traced
};
PixelTexelMaps MapPixelsToTexels(const PhotoSet& photos, const HeightField& canvas,
                                 const RigidTransform& canvas_from_scan,
                                 const HeightFieldTracer& tracer);

struct SampleScene {
  const HeightField* canvas = nullptr;
  const Grid<Vec3f>* normals = nullptr;  // unit, canvas frame, canvas size
  RigidTransform canvas_from_scan;
  const PhotoSet* photos = nullptr;              // pixels loaded
  const HeightFieldTracer* tracer = nullptr;     // built from *canvas
  const PixelTexelMaps* pixel_texels = nullptr;  // null: the footprint rule (see above)
  // The photos are parts of photos (LoadPhotoRegion) whose wholes were checked against the canvas
  // (CheckCamerasSeeCanvas): a part that sees a corner of the canvas need not pass the check.
  bool cameras_checked = false;
};

// Input errors: sizes differ, photos not loaded, a camera that does not see the canvas or sits
// behind it (the error names the calibration entry and file), a non-finite normal.
Status ValidateSampleScene(const SampleScene& scene);

// Scratch space GatherSamples can reuse from call to call (a tile of 32 k texels x 64 photos is
// 100 MB that would otherwise be allocated and initialised per call), and the samples of its
// last call photo by photo: slot i * texels + t is photo i's sample of texel t, kept when
// 0 < keep[i * texels + t] <= least[t]; count[t] such samples.
struct SampleBuffers {
  std::vector<BrdfSample> slots;
  std::vector<uint8_t> keep;
  std::vector<uint8_t> least;
  std::vector<uint32_t> count;
  size_t texels = 0, photos = 0;
  // The samples of texels [first, first + n) (in photo order, as GatherSamples lists them),
  // appended to `out`; every photo's slots of the range are read as one run.
  void AppendTexels(size_t first, size_t n, BrdfSamples& out) const;
};

// Samples of `texels` (indices y * width + x, any order, none kOutside), texel by texel in that
// order, APPENDED to `out` (one AddTexel per texel, possibly empty). Parallel over photos (TBB)
// when `parallel`. Stats are added to *stats.
void GatherSamples(const SampleScene& scene, std::span<const uint32_t> texels,
                   const SampleOptions& options, BrdfSamples& out, SampleStats& stats,
                   bool parallel = true, SampleBuffers* buffers = nullptr);
// GatherSamples without its texel-major copy: the samples stay in `buffers`, photo by photo,
// for a caller that takes them a few texels at a time (SampleBuffers::AppendTexels; the fit does,
// so the tile's samples are never written out texel-major and read back).
void GatherSampleSlots(const SampleScene& scene, std::span<const uint32_t> texels,
                       const SampleOptions& options, SampleStats& stats, bool parallel,
                       SampleBuffers& buffers);

}  // namespace digitize
