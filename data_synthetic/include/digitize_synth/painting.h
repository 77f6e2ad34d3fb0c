// Synthetic paintings with ground truth: the canvas relief (weave, brush strokes, impasto /
// palette-knife blobs, craquelure) on a grid in the canvas frame, and per-texel paint regions.
// Deterministic for a given seed.
//
// The ground truth height field uses the conventions of digitize/height_field.h: canvas frame,
// row 0 at the top, height 0 = the canvas base plane. The true surface between texel centres is
// the triangulated grid (two triangles per quad, the same surface Embree traces), so ground truth
// and what a scanner sees agree exactly. Features whose wavelength is below ~8 texels are faded
// out (they could not be represented by the grid), so normals are meaningful at every resolution.
#pragma once

#include <cstdint>

#include "digitize/core.h"
#include "digitize/height_field.h"

namespace digitize::synth {

struct PaintingOptions {
  double width_mm = 400, height_mm = 300;  // canvas size
  int resolution_px = 1024;                // texels along the longer side (64 .. 16384)
  uint64_t seed = 1;

  bool weave = true;
  double weave_period_mm = 1.0, weave_amplitude_mm = 0.03;
  bool strokes = true;
  int stroke_count = 0;                              // 0 = from the area (about one per 20 cm^2)
  double stroke_min_mm = 0.05, stroke_max_mm = 0.3;  // ridge heights
  bool impasto = true;
  int impasto_count = 0;        // 0 = from the area (about one per 60 cm^2)
  double impasto_max_mm = 2.5;  // blob / knife-stroke heights up to this
  bool craquelure = true;
  double crack_depth_mm = 0.08, crack_width_mm = 0.4;
  int region_count = 6;  // paint regions (0 .. region_count-1)
  // Bowed canvas: the bare canvas sags (negative) or bulges towards the viewer (positive) by
  // bow_mm at its centre and stays at 0 on its outline (a canvas held by its stretcher):
  // bow(X, Y) = bow_mm (1 - u^2) (1 - v^2), u = 2X/W - 1, v = 2Y/H - 1. Part of the truth heights.
  double bow_mm = 0;

  Status Validate() const;
};

struct Painting {
  HeightField truth;     // all texels kMeasured; mm
  Grid<Vec3f> normals;   // analytic normals of the band-limited surface, canvas frame
  Grid<uint8_t> region;  // paint region id per texel
  double width_mm = 0, height_mm = 0;
  // Least-squares plane of the bare canvas (the bow without paint) over the canvas, canvas frame:
  // Z = bare_plane_offset_mm + bare_plane_slope.x() X' + bare_plane_slope.y() Y' with X', Y'
  // relative to the canvas centre; bare_plane_normal its unit normal (Z up). Flat canvas: Z = 0.
  Vec3d bare_plane_normal{0, 0, 1};
  Eigen::Vector2d bare_plane_slope{0, 0};
  double bare_plane_offset_mm = 0;
  PaintingOptions options;
};

Painting MakePainting(const PaintingOptions& options);

}  // namespace digitize::synth
