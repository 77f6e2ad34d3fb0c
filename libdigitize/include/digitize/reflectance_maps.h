// Per-texel reflectance maps: the product of `digitize fit` and, with the canvas, the content of a
// texture pack (docs/formats.md). One value per canvas texel (same grid as the HeightField).
//
// Layer: brdf (core + lafortune.h + brdf_fit.h).
//
// Per texel, one of two models (`model`), directions in the texel's tangent frame
// (tangent_frame.h):
//   kLafortune: the one-lobe Lafortune model in its stored gauge cz = 1 (lafortune.h);
//   kGgx: the GGX microfacet model (ggx.h) in the same channels: rho_d the diffuse term, rho_s
//     holds F0 (in [0, 1]), lobe = (0, 0, 1, alpha). Texels the fit did not cover (kOutside, or no
//     usable sample)
// hold zeros with status kTooFewSamples: they relight black, never NaN.
#pragma once

#include <array>
#include <cstdint>

#include "digitize/brdf_fit.h"
#include "digitize/core.h"
#include "digitize/ggx.h"
#include "digitize/lafortune.h"

namespace digitize {

// ReflectanceModel: brdf_fit.h (the fit chooses it per texel).
struct ReflectanceMaps {
  Grid<Vec3f> rho_d;                // 1/sr, RGB, >= 0
  Grid<Vec3f> rho_s;                // 1/sr, RGB, >= 0
  Grid<std::array<float, 4>> lobe;  // (cx, cy, cz = 1, k)
  Grid<float> fit_error;            // radiance RMS of the fit over its used samples (0 if none)
  Grid<TexelFitStatus> status;      // per texel
  Grid<ReflectanceModel> model;     // per texel (see above)

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
    model(x, y) = ReflectanceModel::kLafortune;
  }
  GgxParams GgxAt(int x, int y) const { return GgxParams{rho_d(x, y), rho_s(x, y), lobe(x, y)[3]}; }
  void SetGgx(int x, int y, const GgxParams& p) {
    rho_d(x, y) = p.rho_d;
    rho_s(x, y) = p.f0;
    lobe(x, y) = {0.0f, 0.0f, 1.0f, p.alpha};
    model(x, y) = ReflectanceModel::kGgx;
  }
  // f_r(v, l) of texel (x, y) under its model (1/sr).
  Vec3f Evaluate(int x, int y, const Vec3f& v, const Vec3f& l) const {
    return model(x, y) == ReflectanceModel::kGgx ? EvaluateGgx(GgxAt(x, y), v, l)
                                                 : EvaluateLafortune(At(x, y), v, l);
  }

  // Every grid the same size, every value finite, rho >= 0, cz == 1, k >= 0; GGX texels with F0 in
  // [0, 1] and alpha in [kGgxMinAlpha, kGgxMaxAlpha]. Names the texel.
  Status Validate() const;
};

}  // namespace digitize
