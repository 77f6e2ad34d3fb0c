// Synthetic photo sets of a synthetic painting (docs/formats.md): registered photographs under
// known point lights, rendered with Embree from the framed-painting Scene (scan_sim.h), with their
// ground truth -- per-texel reflectance by paint region, and held-out images (lights and views
// not in the fitting set) rendered without noise for judging a fit.
//
// Rendering, per image pixel (pixel centres, one ray, OpenCV camera convention of photo_set.h):
//   - the camera ray is traced in the Scene (canvas + frame + wall) (a ray that slips through the
//     canvas at an exact grid vertex -- Embree's grid primitive is not watertight there -- is
//     traced again a thousandth of a pixel away);
//   - on the canvas: the texel is the nearest texel of the hit (paint regions and materials are per
//     texel), the normal the painting's analytic normal interpolated bilinearly at the hit, the
//     tangent frame MakeTangentFrame(normal) (tangent_frame.h); the light is a point light,
//     radiance = f_r(v, l) * max(0, n.l) * I / d^2 with f_r the texel's material (0 if n.v <= 0);
//   - frame and wall: Lambertian grey (albedo frame_albedo), same light;
//   - shadows (on by default): a ray from the hit (lifted 2 um along the geometric normal) to the
//     light against the whole Scene, so the relief AND the frame cast shadows (the fit only knows
//     the relief: frame shadows are what its robustness has to cope with, and the held-out masks
//     leave them out of the score: a held-out pixel is masked out when the FIRST thing its shadow
//     ray meets is the frame; relief shadows stay in);
//   - then (fitting images only) Gaussian noise of noise_sigma (linear units), then the encoding:
//     8-bit or 16-bit sRGB (code = round(OETF(clamp(x, 0, 1)) * max), clipped at 1; a pixel with a
//     channel at code 255 / 65535 is flagged kPixelSaturated), or linear float (EXR; no clipping,
//     no flags). The pixels kept are the decoded codes, bit for bit what digitize::LoadPhoto reads
//     back from the written files.
// Deterministic for a seed, independent of thread scheduling (one noise stream per image and row).
// Parallel (TBB) over images and rows; the primary rays of a camera are traced once for all its
// lights. About 5 s for 64 images of 1188 x 891 px (a 1024 x 768-texel painting, default
// options, no held-out images) on 2 cores.
//
// Frames: cameras and lights are placed in the CANVAS frame (around the canvas centre, on the
// front side) and stored in the SCAN frame of the given canvas_from_scan (scan = canvas when it is
// the identity), as a calibration file stores them. Images are upright: canvas +X to the right,
// canvas +Y towards row 0 (as the texel grid).
//
// Intrinsics: pinhole, fx = fy = pixels_per_texel * camera_distance_mm / pitch (so a texel at the
// canvas centre spans pixels_per_texel pixels in the top view), principal point at the image
// centre ((w - 1) / 2, (h - 1) / 2); each camera's image is just large enough (both ways about
// the principal point) to hold the canvas grown by view_margin of its width / height on every
// side. Cameras of an arc therefore differ in size.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize/ggx.h"
#include "digitize/lafortune.h"
#include "digitize/photo_set.h"
#include "digitize/reflectance_maps.h"
#include "digitize_synth/scan_sim.h"

namespace digitize::synth {

// Ground-truth reflectance of one paint region: one-lobe Lafortune (stored gauge), GGX (ggx.h),
// or, to judge the fit where no fitted model can match, a measured 3-lobe Lafortune fit.
struct PaintMaterial {
  std::string name;           // "matte", "satin", ..., "bluepaint (measured)"
  bool is_measured = false;   // true: `measured` is the truth, `lafortune` unused
  bool is_ggx = false;        // true (and not is_measured): `ggx` is the truth
  LafortuneParams lafortune;  // cz = 1
  GgxParams ggx;
  MeasuredLafortune measured;
  Vec3f Evaluate(const Vec3f& v, const Vec3f& l) const;  // tangent frame, 1/sr
};

// Region materials, matte to glossy varnish: region i gets materials[i % size]. Colours differ per
// region. One-lobe set, in this order: matte (rho_s = 0), satin (k 6), semi-gloss (k 30), gloss
// (k 100), varnish (k 400, 4 % specular albedo), anisotropic off-specular (cx = -0.95,
// cy = -0.55, k 20); diffuse albedos 0.05 .. 0.8, specular albedo a_s = rho_s 2 pi / (k + 2)
// of 4-8 % (<= 1, and albedo + a_s < 1), grey specular, no black paint. With `with_measured` a
// 7th material follows: a published measured paint (bluepaint, Lafortune et al. 1997; its numbers
// are embedded), not in the fitted family -- give the painting at least 7 regions for it to
// appear (`digitize synth --measured` does).
std::vector<PaintMaterial> DefaultPaintMaterials(bool with_measured);

// Paints whose truth is GGX (ggx.h), in this order: varnish (alpha 0.05, dielectric F0 0.04
// over dark umber), satin (alpha 0.15, F0 0.04 over vermilion), green earth (alpha 0.3, F0 0.04),
// yellow ochre (alpha 0.6, F0 0.04), gold leaf (a metal: rho_d = 0, coloured F0 (1.0, 0.78,
// 0.34), alpha 0.2), a Lambertian paint (lead white, no specular at all: a one-lobe material
// with rho_s = 0), and a high-gloss glaze (alpha 0.02, F0 0.04 over a deep red) that only a
// painting with 7 regions shows.
std::vector<PaintMaterial> GgxPaintMaterials();

// kJpeg: the 8-bit sRGB codes of kSrgb8, written as JPEG (quality jpeg_quality, 4:4:4) so that a
// tiled set of a large painting stays a few GB on disk. The in-memory pixels are the codes before
// compression; the files read back within JPEG's loss of them.
enum class PhotoEncoding { kSrgb8, kSrgb16, kLinearExr, kJpeg };
const char* ToString(PhotoEncoding e);  // "srgb8", "srgb16", "exr", "jpeg"

struct PhotoSimOptions {
  // Cameras (pinhole) on an arc in the canvas XZ plane through the canvas normal, all aimed at the
  // canvas centre: 1 camera = straight above; n > 1 = evenly from -arc_deg to +arc_deg (tilted
  // towards canvas +X for positive angles). A camera that would see part of the grown canvas
  // behind it throws.
  int cameras = 1;
  double camera_arc_deg = 30;
  // A tiled photo set, as a large painting is photographed: grid_cols x grid_rows >= 1 puts one
  // camera straight above the centre of each of that many equal cells of the canvas (row by row
  // from the top-left cell), its image covering the cell grown by grid_overlap of the cell's size
  // on every side, under its own `lights` lights: the spiral dome below, centred on its cell.
  // cameras must then be 1 (the arc is not used). The held-out images look at a cell-sized patch
  // (with the overlap) at the canvas centre: from straight above and tilted by
  // held_out_camera_deg, lights on the dome around the canvas centre. 0 x 0: the arc.
  int grid_cols = 0, grid_rows = 0;
  double grid_overlap = 0.1;
  double camera_distance_mm = 1200;  // from the canvas centre
  double pixels_per_texel = 1.0;     // image sampling on the canvas at the centre (top view)
  double view_margin = 0.08;         // share of canvas width / height added on each side (frame
                                     // partly in view)
  // Point lights on a dome around the canvas centre: a Fibonacci spiral over elevations
  // [min, max] (deg above the canvas plane), each light used with every camera. Light j of n sits
  // at spiral position s = j: sin(elevation) = sin(min) + (s + 0.5) / n (sin(max) - sin(min)),
  // azimuth = s x the golden angle (137.5 deg) from canvas +X; white (grey) point lights.
  int lights = 64;
  double light_min_elevation_deg = 15, light_max_elevation_deg = 85;
  double light_distance_mm = 900;
  double white_level = 0.8;  // intensity such that a white Lambertian (albedo 1) at the canvas
                             // centre, lit at normal incidence, reads this (linear):
                             // I = white_level pi light_distance_mm^2
  // Held-out images: lights on the same dome between the fitting ones (held-out light j of m at
  // spiral position floor((j + 0.5) n / m) + 0.5: half-way between two fitting lights, spread
  // over the spiral; with fewer fitting lights than held-out ones, (j + 0.5) n / m - 0.5), seen
  // by the first camera and by one extra camera (azimuth 90 deg off the arc, towards canvas +Y,
  // at held_out_camera_deg from the normal) that is not in the fitting set. Order: first camera
  // x every held-out light, then the extra camera x every held-out light.
  int held_out_lights = 8;
  double held_out_camera_deg = 20;
  double noise_sigma = 0.002;  // fitting images: Gaussian, linear radiance units, before encoding
  PhotoEncoding encoding = PhotoEncoding::kSrgb8;
  int jpeg_quality = 95;  // kJpeg only, 50 .. 100
  bool shadows = true;
  double frame_albedo = 0.35;
  uint64_t seed = 1;
  bool grid() const { return grid_cols > 0; }
  int camera_positions() const { return grid() ? grid_cols * grid_rows : cameras; }
  Status Validate() const;
};

struct SyntheticPhotoSet {
  PhotoSet fit;       // pixels loaded as a reader would return them after decoding the encoded
                      // files (quantised, linearised, saturated pixels flagged); entry names
                      // "synthetic: images[i]"; order: camera c x light j at c * lights + j;
                      // paths "images/img_NNN.{png,exr,jpg}" (as WriteSyntheticPhotoSet names them)
  PhotoSet held_out;  // noise-free linear renders (encoding kLinear, no flags)
  // Per held-out image: 1 where the pixel shows a canvas texel that no frame shadow darkens (the
  // pixels a fit of the canvas alone can be judged on), else 0.
  std::vector<Grid<uint8_t>> held_out_mask;
  // Ground truth on the PAINTING's texel grid: one-lobe maps (status kConverged; measured-material
  // texels hold the material's diffuse term only, status kDiffuseOnly, and are marked in
  // `measured_texel`), the material index per texel, and the materials. `truth` is
  // MaterialTruth(materials) at each texel's material_index; empty for a set rendered into a sink
  // (its writer makes the truth files from material_index).
  ReflectanceMaps truth;
  Grid<uint8_t> material_index;
  Grid<uint8_t> measured_texel;
  std::vector<PaintMaterial> materials;
  RigidTransform canvas_from_scan;
  PhotoSimOptions options;
  size_t saturated_pixels = 0;  // over the fitting images, after encoding
  // Over the fitting images: canvas pixels facing the light (n.l > 0, n.v > 0), and those of them
  // whose shadow ray is blocked (relief or frame).
  size_t canvas_lit_pixels = 0, shadowed_pixels = 0;
  double render_seconds = 0;  // wall time of SimulatePhotoSet
  // Set when SimulatePhotoSet was given a sink: the photos' pixels were handed to it and released
  // (photo.rgb and flags empty); the first error the sink returned, after which rendering stopped.
  bool pixels_released = false;
  Status sink_status = Status::Ok();
  // "64 images 1188x891 (1 camera(s) x 64 lights, srgb8) + 16 held-out; 67.7 Mpx; 1234 saturated
  // px (0.00 %), 2.1 % of lit canvas px in shadow; 8.10 s"
  std::string Brief() const;
};

// The "GGX painting": a square 400 mm canvas (96 x 96 texels by default) in 6 regions painted with
// GgxPaintMaterials() (varnish, satin, green, ochre, gold, Lambertian), photographed by 2
// cameras (arc +-30 deg) under 48 point lights at ~1.2 px per texel, 8-bit sRGB, sensor noise
// sigma 0.002, 16 held-out images.
struct GgxPaintingCase {
  PaintingOptions painting;
  PhotoSimOptions photos;
  std::vector<PaintMaterial> materials;
};
GgxPaintingCase MakeGgxPaintingCase(int resolution_px = 96, uint64_t seed = 1);

// The truth of each material, as a texel painted with it holds it: maps of materials.size() x 1
// texels (texel i = materials[i]).
ReflectanceMaps MaterialTruth(const std::vector<PaintMaterial>& materials);

// Receives each image as soon as its camera position is rendered (held_out_mask: null for a
// fitting image, the image's mask for a held-out one; index into fit.photos or held_out.photos).
// Called from several threads at once, for different images.
using PhotoSink =
    std::function<Status(const Photo& photo, const Grid<uint8_t>* held_out_mask, int index)>;

// Invalid options throw (validate first). `materials` empty: DefaultPaintMaterials(false).
// With a sink, every image goes to it once its camera position is done and its pixels are then
// released, so memory holds one camera position's images instead of the whole set.
SyntheticPhotoSet SimulatePhotoSet(const Scene& scene, const RigidTransform& canvas_from_scan,
                                   const PhotoSimOptions& options,
                                   std::vector<PaintMaterial> materials = {},
                                   const ProgressCallback& progress = nullptr,
                                   const PhotoSink& sink = nullptr);

// Writes, each file atomically, into `dir` (created):
//   calib.json + images/img_NNN.{png,exr,jpg}         the fitting set (docs/formats.md calibration)
//   held_out/calib.json + held_out/img_NNN.exr       held-out renders (linear EXR; the JSON only
//                                                    when there are held-out images)
//   held_out/mask_NNN.png                            held_out_mask (0/255)
//   truth/rho_d.exr, rho_s.exr (RGB, 1/sr), lobe.exr (channels cx, cy, k; cz = 1),
//   truth/material.png (material index), materials.json
// Image paths in the JSON files are relative to the JSON's folder. calib.json is written last
// (its presence means the set is complete) and carries the generator's options, the
// canvas_from_scan and the paths of the held-out set and the truth under "generator" (ignored by
// ReadCalibration). PNGs are written as 8- or 16-bit RGB codes; every file reads back to the
// in-memory pixels exactly. Errors name the file; files already written stay.
Status WriteSyntheticPhotoSet(const std::filesystem::path& dir, const SyntheticPhotoSet& set);

// SimulatePhotoSet and WriteSyntheticPhotoSet in one, in the memory of one camera position: each
// image is written as soon as its camera position is rendered (the same files, byte for byte).
// This is how `digitize synth --photos` writes, so a tiled set of a 8k x 6k-texel painting
// (gigapixels in all) needs no more memory than one of its cells. `summary`, when given, gets the
// set without pixels or truth maps (cameras, lights, counts, material_index).
Status RenderSyntheticPhotoSet(const std::filesystem::path& dir, const Scene& scene,
                               const RigidTransform& canvas_from_scan,
                               const PhotoSimOptions& options,
                               std::vector<PaintMaterial> materials = {},
                               const ProgressCallback& progress = nullptr,
                               SyntheticPhotoSet* summary = nullptr);

}  // namespace digitize::synth
