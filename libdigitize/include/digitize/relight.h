// Relighting: renders a canvas with its reflectance maps under a given camera and light, by ray
// tracing the height field (HeightFieldTracer) -- what the held-out evaluation of `digitize fit`
// compares with real (or ground-truth) photographs, and the Embree reference the viewer (viewer/)
// is measured against.
//
// Layer: samples (core, photo_set.h, reflectance_maps.h, height_field_tracer.h, tangent_frame.h).
//
// Per image pixel (u, v): the camera ray through the pixel CENTRE (OpenCV convention, photo_set.h)
// is moved to the canvas frame (canvas_from_scan), intersected with the height field; at the hit:
//   - texel = the nearest texel of the hit's continuous texel coordinates (reflectance maps are
//     per texel: no interpolation of k across decades), skipped (mask 0) when kOutside;
//   - normal = bilinear interpolation of `normals` at the hit, renormalised; tangent frame from it;
//   - v = towards the camera, l = light.DirectionTo(hit) (both in the scan frame, then rotated into
//     the canvas and tangent frames), E = light.IrradianceAt(hit) (scan frame, mm);
//   - radiance = f_r(v, l) * max(0, n.l) * E (0 when n.v <= 0 or n.l <= 0), and 0 when
//     `shadows` is on and the light is blocked by the relief (Occluded, with skipping).
// Pixels whose ray misses the canvas get radiance 0 and mask 0. Never NaN/Inf.
#pragma once

#include <cstdint>

#include "digitize/core.h"
#include "digitize/height_field.h"
#include "digitize/height_field_tracer.h"
#include "digitize/photo_set.h"
#include "digitize/reflectance_maps.h"

namespace digitize {

struct RelightOptions {
  bool shadows = true;  // cast shadow rays against the relief
  int num_threads = 0;  // 0 = all cores

  Status Validate() const;  // num_threads >= 0 (RenderRelit throws InvariantError otherwise)
};

struct RelitImage {
  Grid<Vec3f> rgb;     // linear radiance, camera size
  Grid<uint8_t> mask;  // 1 where the pixel sees a canvas texel (not kOutside), else 0
  // Canvas pixels whose light was blocked. Shadow rays are cast only from pixels that face both
  // the camera and the light (n.v > 0, n.l > 0): the others are dark anyway and not counted.
  size_t shadowed_pixels = 0;
};

// `tracer` must be built from `canvas`; `normals` and `maps` have the canvas's size (checked:
// throws InvariantError otherwise -- a programming error, not input). Orthographic cameras cast
// their rays from their z = 0 plane (what is behind it is not seen, as in Camera::InFront).
// Pixels on the canvas's outer half-texel (between the border texel centres and the canvas
// outline, see height_field_tracer.h) take the border texels' reflectance and normals.
RelitImage RenderRelit(const HeightFieldTracer& tracer, const HeightField& canvas,
                       const Grid<Vec3f>& normals, const ReflectanceMaps& maps,
                       const RigidTransform& canvas_from_scan, const Camera& camera,
                       const Light& light, const RelightOptions& options = {});

// PSNR (dB) of `test` against `reference` over the pixels where mask != 0 (and both are finite),
// all three channels, peak `peak` (linear radiance units): 10 log10(peak^2 / MSE). +inf for
// identical images, 0 when the mask is empty (nothing compared: callers check the count).
struct ImageComparison {
  double psnr_db = 0;
  double rmse = 0;
  size_t pixels = 0;  // compared
};
ImageComparison CompareImages(const Grid<Vec3f>& test, const Grid<Vec3f>& reference,
                              const Grid<uint8_t>& mask, double peak);

}  // namespace digitize
