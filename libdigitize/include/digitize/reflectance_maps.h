// Per-texel reflectance maps: the product of `digitize fit` and, with the canvas, the content of a
// texture pack (docs/formats.md). One value per canvas texel (same grid as the HeightField).
//
// Layer: brdf (core + lafortune.h + brdf_fit.h).
//
// Stored gauge: the one-lobe Lafortune model with cz = 1 (lafortune.h), directions in the texel's
// tangent frame (tangent_frame.h). Texels the fit did not cover (kOutside, or no usable sample)
// hold zeros with status kTooFewSamples: they relight black, never NaN.
#pragma once

#include <array>
#include <cstdint>

#include "digitize/brdf_fit.h"
#include "digitize/core.h"
#include "digitize/lafortune.h"

namespace digitize {

struct ReflectanceMaps {
  Grid<Vec3f> rho_d;                // 1/sr, RGB, >= 0
  Grid<Vec3f> rho_s;                // 1/sr, RGB, >= 0
  Grid<std::array<float, 4>> lobe;  // (cx, cy, cz = 1, k)
  Grid<float> fit_error;            // radiance RMS of the fit over its used samples (0 if none)
  Grid<TexelFitStatus> status;      // per texel

  int width() const { return rho_d.width; }
  int height() const { return rho_d.height; }
  bool empty() const { return rho_d.empty(); }

  // Maps of the given size, every texel zero with status kTooFewSamples.
  static ReflectanceMaps Zeros(int width, int height);

  LafortuneParams At(int x, int y) const {
    LafortuneParams p;
    p.rho_d = rho_d(x, y);
    p.rho_s = rho_s(x, y);
    const auto& c = lobe(x, y);
    p.cx = c[0];
    p.cy = c[1];
    p.cz = c[2];
    p.k = c[3];
    return p;
  }
  void Set(int x, int y, const LafortuneParams& p) {
    rho_d(x, y) = p.rho_d;
    rho_s(x, y) = p.rho_s;
    lobe(x, y) = {p.cx, p.cy, p.cz, p.k};
  }

  // Every grid the same size, every value finite, rho >= 0, cz == 1, k >= 0. Names the texel.
  Status Validate() const;
};

}  // namespace digitize
