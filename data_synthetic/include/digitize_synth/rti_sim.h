// Synthetic RTI captures of a synthetic painting: an orthographic camera straight down over the
// canvas (image pixel (x, y) = texel (x, y) of the painting, the grid ReadRtiCapture assumes), one
// light per image on a dome, rendered with the painting's analytic normals, relief shadows from
// the Embree height-field tracer (height_field_tracer.h), and the defects of a handheld capture:
// light directions off their nominal (.lp) values, per-image intensity errors, sensor noise and
// 8-bit sRGB quantisation. With ground-truth normals, heights, albedo, true directions and
// intensities, for judging photometric stereo (photometric_stereo.h) and normal integration.
//
// Rendering, per pixel of image i (texel centre, canvas frame):
//   radiance = f(n, l_i) max(0, n.l_i) E e_i V_i  (+ noise), then the encoding,
// with n the painting's normal at the texel, l_i the TRUE light direction (nominal jittered), E
// such that a white Lambertian (albedo 1) at normal incidence reads white_level, e_i the true
// intensity factor (truth: mean 1), V_i = 0 when the relief blocks the light (shadow ray from the
// texel's surface point), f = albedo / pi for `lambertian`, else the region's paint material
// (photo_sim.h DefaultPaintMaterials: diffuse + specular lobe, seen from straight above).
// Point lights (light_distance_mm > 0): l_i and the 1 / d^2 falloff per texel, E at the canvas
// centre. Deterministic for a seed; parallel over images and rows.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize_synth/painting.h"

namespace digitize::synth {

enum class RtiEncoding { kSrgb8, kLinearFloat };

struct RtiSimOptions {
  // Dome: a Fibonacci spiral of `lights` directions over elevations [min, max] deg (as
  // photo_sim.h: sin(elevation) evenly spaced, azimuth stepping by the golden angle).
  int lights = 48;
  double min_elevation_deg = 15, max_elevation_deg = 75;
  // 0: directional lights. > 0: point lights at this distance from the canvas centre along the
  // nominal direction (the .lp still gets the direction from the canvas centre).
  double light_distance_mm = 0;
  double direction_jitter_deg = 2.0;  // handheld: true direction = nominal turned by an angle
                                      // of this standard deviation (Rayleigh), random axis
  double intensity_error = 0.15;      // true e_i uniform in [1 - x, 1 + x], then scaled to mean 1
  double white_level = 0.7;           // linear value of a white Lambertian at normal incidence
  double noise_sigma = 0.003;         // Gaussian, linear units, before encoding
  RtiEncoding encoding = RtiEncoding::kSrgb8;
  bool shadows = true;
  bool lambertian = false;  // true: diffuse albedo only (the photometric-stereo model)
  uint64_t seed = 1;
  Status Validate() const;
};

struct SyntheticRtiCapture {
  std::vector<Grid<Vec3f>> images;        // linear radiance as a reader returns it after decoding
  std::vector<Vec3d> nominal_directions;  // what the .lp says (unit, canvas frame)
  std::vector<Vec3d> true_directions;     // what lit the image
  std::vector<double> true_intensities;   // e_i, mean 1
  std::vector<Grid<uint8_t>> shadowed;    // 1 where the relief blocks the light
  Grid<Vec3f> normals;                    // truth, canvas frame (the painting's)
  Grid<float> height_mm;                  // truth (the painting's)
  Grid<Vec3f> albedo;                     // diffuse albedo (pi rho_d) x white_level: what a
                                          // Lambertian fit finds (image units, e = 1)
  double pitch_mm = 0;
  std::vector<std::string> image_names;  // "img_NNN.png" / ".exr", as WriteSyntheticRti names
  RtiSimOptions options;
  size_t saturated_pixels = 0;  // 8-bit: pixels with a channel at code 255
  double render_seconds = 0;
  // "48 images 400x300 (srgb8, directional, jitter 2 deg, e 0.86..1.13), 3.1 % shadowed px; 0.4 s"
  std::string Brief() const;
};

// Invalid options throw (validate first).
SyntheticRtiCapture SimulateRti(const Painting& painting, const RtiSimOptions& options);

// Writes into `dir` (created): img_NNN.png (8-bit sRGB) or .exr (linear float), dirs.lp
// (first line the count, then `img_NNN.png x y z` with the NOMINAL directions, ReadRtiCapture's
// frame), truth/normals.exr (RGB = x, y, z), truth/height.exr (mm), truth/albedo.exr,
// truth/lights.txt (per image: true direction and intensity; the pitch in its first line). The
// PNGs carry no resolution tag: read them with PhotoSetOptions::rti_pixel_pitch_mm = pitch_mm.
// Every file atomically; errors name the file.
Status WriteSyntheticRti(const std::filesystem::path& dir, const SyntheticRtiCapture& capture);

}  // namespace digitize::synth
