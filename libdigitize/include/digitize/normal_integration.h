// Height from normals: a canvas-frame height field (mm) whose gradients match a normal map, for
// captures that have normals but no scan (photometric_stereo.h on an RTI capture).
//
// Layer: relief (core + height_field.h). Eigen's sparse solver and OpenCV's DFT stay in the .cpp.
//
// Frames and units: normals in the canvas frame of height_field.h (x right, y towards row 0, z
// up); pixel (x, y) of the grid is texel (x, y) at pitch_mm. Gradients p = dz/dX = -n_x / n_z,
// q = dz/dY = -n_y / n_z with n_z clamped to >= min_nz first (default 0.1: slopes up to ~84 deg,
// |gradient| <= 10; steeper normals, which photometric stereo gets least right, cannot make a
// spike), so heights come out in mm.
//
// METHODS.
//   kPoisson (default): least squares over every pair of 4-neighbours, (z_b - z_a - g_ab pitch)^2
//     with g_ab the mean of the two pixels' gradients along the pair, solved by Eigen's
//     SimplicialLDLT. The boundary condition is the natural (Neumann) one of that least-squares
//     problem: no assumption about what lies beyond the border, so a canvas whose two sides differ
//     in height (a tilt, a frame on one side) comes out right. Pairs with a pixel outside the
//     mask / weight 0 carry no gradient: they get a tiny membrane weight (gradient 0) instead, so
//     masked-out pixels are filled smoothly and every pixel has a finite height. The default
//     because real canvases are not periodic.
//   kFrankotChellappa: the projection of the gradient field onto integrable fields in the Fourier
//     domain (cv::dft), on the grid mirror-padded to twice its size (even extension of z, so the
//     periodicity FC assumes holds, and the border has no wrap-around artefact). Ignores the mask
//     and the weights; faster (O(N log N)) on large grids.
// GAUGE: heights are defined up to a constant: the result has mean 0 over the mask (the whole
// grid when no mask).
#pragma once

#include <cstdint>
#include <string>

#include "digitize/core.h"
#include "digitize/height_field.h"

namespace digitize {

enum class NormalIntegrationMethod { kPoisson, kFrankotChellappa };
const char* ToString(NormalIntegrationMethod m);  // "poisson", "frankot-chellappa"

struct NormalIntegrationOptions {
  NormalIntegrationMethod method = NormalIntegrationMethod::kPoisson;
  double min_nz = 0.1;            // n_z clamp before the gradients are taken
  double membrane_weight = 1e-3;  // Poisson: weight of pairs without gradient data (and of
                                  // pairs whose weights are 0), relative to full-weight pairs
  // Poisson: grids up to this many pixels are factorised (SimplicialLDLT: exact, ~1 s CPU per
  // 0.2 Mpx; memory grows as n log n); larger ones are solved by conjugate gradients
  // (IncompleteCholesky preconditioner) from the Frankot-Chellappa heights.
  size_t max_direct_pixels = size_t{1} << 21;
  double cg_tolerance = 1e-6;  // relative residual
  int cg_max_iterations = 2000;
  Status Validate() const;  // min_nz in (0, 1], membrane_weight > 0, cg_* > 0
};

struct NormalIntegrationResult {
  Grid<float> height_mm;  // same size as the normals; mean 0 over the mask; never NaN
  NormalIntegrationMethod method = NormalIntegrationMethod::kPoisson;
  // RMS over the data pairs of (height step / pitch - gradient): how far the normals are from
  // integrable (0 for normals of a height field, up to discretisation).
  double rms_gradient_residual = 0;
  int cg_iterations = 0;  // Poisson by conjugate gradients: iterations done (0: factorised)
  bool converged = true;  // false: CG stopped at cg_max_iterations (the heights are usable,
                          // less exact)
  double seconds = 0;
  std::string Brief() const;  // "poisson 400x300: residual 0.012; 0.31 s"
};

// `mask` (optional, nullptr or empty: every pixel): non-zero = the pixel's normal is data.
// `weights` (optional, Poisson only): per-pixel confidence >= 0; a pair's weight is the smaller of
// its two pixels'. Errors: empty or non-finite normals, pitch not > 0, a mask or weights of
// another size, negative / non-finite weights, invalid options.
Result<NormalIntegrationResult> IntegrateNormals(const Grid<Vec3f>& normals, double pitch_mm,
                                                 const Grid<uint8_t>* mask = nullptr,
                                                 const Grid<float>* weights = nullptr,
                                                 const NormalIntegrationOptions& options = {});

// The height field of an integration: heights as given, every texel kMeasured where the mask
// holds (or no mask), else kFilled. Precondition: sizes agree.
HeightField HeightFieldFromIntegration(const NormalIntegrationResult& result, double pitch_mm,
                                       const Grid<uint8_t>* mask = nullptr);

}  // namespace digitize
