// The GGX microfacet BRDF (Walter et al. 2007) with Schlick's Fresnel and the separable Smith
// shadowing term: the lobe real varnishes, satins and metals follow, which a one-lobe Lafortune
// cannot (its lobe has no long tail and no Fresnel rise towards grazing). One definition, used by
// the synthetic photographs (ground truth), the per-texel fit, the Embree reference renderer and
// the viewer's shader (viewer/shaders), so that all four shade a GGX texel the same way.
//
// Layer: brdf (depends on core).
//
// Frame: as lafortune.h -- unit directions in the texel's tangent frame (z = normal), pointing
// away from the surface; v or l with z <= 0 gives 0 (reflection only).
//
//   f_r(v, l) = rho_d + F(v.h) D(n.h) G1(n.v) G1(n.l) / (4 (n.v) (n.l)),  h = (v + l) / |v + l|
//   D(c)  = alpha^2 / (pi ((alpha^2 - 1) c^2 + 1)^2)             (GGX / Trowbridge-Reitz)
//   F(c)  = F0 + (1 - F0) (1 - c)^5                                (Schlick, per channel)
//   G1(c) = 2 c / (c + sqrt(alpha^2 + (1 - alpha^2) c^2))          (Smith, GGX)
//
// Units: rho_d in 1/sr (as lafortune.h), F0 in [0, 1] per channel (a dielectric varnish ~0.04
// grey, a metal its coloured reflectance at normal incidence with rho_d = 0), alpha the GGX
// roughness in [kGgxMinAlpha, 1].
//
// Numerical contract: for finite parameters in range every evaluation is finite and >= 0; the
// denominators are bounded away from 0 (alpha >= kGgxMinAlpha, n.v and n.l clamped at
// kGgxMinCos) and the value is capped at kMaxBrdf.
#pragma once

#include <algorithm>
#include <cmath>

#include "digitize/core.h"
#include "digitize/lafortune.h"

namespace digitize {

inline constexpr float kGgxMinAlpha = 0.005f;  // below this the peak (1 / (pi alpha^2)) is a
                                               // mirror no photo set samples
inline constexpr float kGgxMaxAlpha = 1.0f;
inline constexpr float kGgxMinCos = 1e-4f;

struct GgxParams {
  Vec3f rho_d = Vec3f::Zero();  // diffuse BRDF value per channel (1/sr), >= 0
  Vec3f f0 = Vec3f::Zero();     // Fresnel reflectance at normal incidence per channel, [0, 1]
  float alpha = 0.3f;           // GGX roughness, [kGgxMinAlpha, kGgxMaxAlpha]
};

// The specular factor F(v.h) D G1 G1 / (4 n.v n.l) for one channel's F0, for any scalar T (float,
// double or ceres::Jet). v, l: unit tangent-frame directions as 3 plain numbers each, both with
// z > 0 (callers test the hemisphere).
template <class T, class D>
T GgxSpecular(const T& f0, const T& alpha, const D* v, const D* l) {
  using std::sqrt;
  const T hx = T(v[0] + l[0]), hy = T(v[1] + l[1]), hz = T(v[2] + l[2]);
  const T h_len2 = hx * hx + hy * hy + hz * hz;
  if (!(h_len2 > T(1e-12))) return T(0.0);  // v = -l: no half vector (cannot happen for z > 0)
  const T inv_h = T(1.0) / sqrt(h_len2);
  const T nh = hz * inv_h;
  const T vh = std::max(T(0.0), T(v[0]) * hx * inv_h + T(v[1]) * hy * inv_h + T(v[2]) * hz * inv_h);
  const T nv = std::max(T(kGgxMinCos), T(v[2]));
  const T nl = std::max(T(kGgxMinCos), T(l[2]));
  const T a2 = alpha * alpha;
  const T d_den = (a2 - T(1.0)) * nh * nh + T(1.0);
  const T d = a2 / (T(kPi) * d_den * d_den);
  const T m = T(1.0) - vh;
  const T m2 = m * m;
  const T fresnel = f0 + (T(1.0) - f0) * (m2 * m2 * m);
  const T g1v = T(2.0) * nv / (nv + sqrt(a2 + (T(1.0) - a2) * nv * nv));
  const T g1l = T(2.0) * nl / (nl + sqrt(a2 + (T(1.0) - a2) * nl * nl));
  return fresnel * d * g1v * g1l / (T(4.0) * nv * nl);
}

// f_r(v, l) per channel (1/sr). 0 when v or l is below the horizon (z <= 0).
inline Vec3f EvaluateGgx(const GgxParams& p, const Vec3f& v, const Vec3f& l) {
  if (!(v.z() > 0.0f && l.z() > 0.0f)) return Vec3f::Zero();
  const float alpha = std::clamp(p.alpha, kGgxMinAlpha, kGgxMaxAlpha);
  const float vv[3] = {v.x(), v.y(), v.z()}, ll[3] = {l.x(), l.y(), l.z()};
  Vec3f f;
  for (int c = 0; c < 3; ++c)
    f[c] = std::min(kMaxBrdf, p.rho_d[c] + GgxSpecular(p.f0[c], alpha, vv, ll));
  return f;
}

}  // namespace digitize
