// The Lafortune BRDF (seed 001, per-texel fit; Lafortune et al. 1997, McAllister et al. 2002): the
// one-lobe model the per-texel fit stores, and the multi-lobe model of published gonioreflectometer
// fits, used as ground truth that the one-lobe model cannot match exactly.
//
// Layer: brdf (depends on core; io reads the measured fits file).
//
// Frame: every direction is a unit vector in the texel's local tangent frame (z = the normal),
// pointing AWAY from the surface: v towards the camera, l towards the light. Both models are
// reflection-only: a direction with z <= 0 gives f = 0 (callers multiply by max(0, n.l) anyway).
//
// One-lobe model, per RGB channel:
//   f_r(v, l) = rho_d + rho_s * max(0, cx vx lx + cy vy ly + cz vz lz)^k
//
// THE GAUGE. The plain model is degenerate: (C, rho_s) and (s C, s^-k rho_s) are the same
// function for every s > 0, so a fit that leaves both free wanders along that curve and k, rho_s
// can run off to huge/tiny values. LafortuneParams stores the gauge cz = 1:
//   - cz == 1 exactly, (cx, cy) free: cx = cy = -1 is the mirror lobe (peak where v is the mirror
//     image of l, value 1 there), cx = cy = -a with a < 1 moves the peak towards the normal and
//     lowers it towards grazing, positive cx/cy bend it backwards;
//   - the fit (brdf_fit.h) keeps |cx|, |cy| <= 1: then |cx vx lx + cy vy ly + vz lz| <= |v||l| = 1
//     (Cauchy-Schwarz), so the lobe factor lies in [0, 1] for every k and rho_s is the largest
//     value the specular term can take. Lobes that grow towards grazing (|Cxy| > Cz, as in some
//     of Lafortune's measured fits) are representable here but outside the fitted family;
//   - a general lobe (Cx, Cy, Cz > 0, k, rho_s) converts exactly with LafortuneFromGeneral:
//     C' = C / Cz, rho_s' = rho_s * Cz^k. Lobes with Cz <= 0 (retro-reflection / grazing-only
//     lobes) have no cz = 1 form; they live in the multi-lobe model.
//
// Units: rho_d and rho_s are BRDF values (1/sr), not albedos: a Lambertian surface of albedo A
// has rho_d = A / pi.
//
// Numerical contract: for finite parameters with rho >= 0, k >= 0, every evaluation returns a
// finite, non-negative value: the negative base is clamped to 0 (and bases below kLobeBaseEps
// count as 0, so pow(0, k) and log(0) never happen), k = 0 gives the step "1 where the base is
// > 0", k up to 1e4 (or any k) is evaluated as exp(k log base) with the exponent capped at
// kMaxLobeLog, and the sum is capped at kMaxBrdf. Non-finite directions give the diffuse term.
#pragma once

#include <cmath>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "digitize/core.h"

namespace digitize {

// Lobe bases at or below this count as 0. For k >= 0.5 the lobe there is <= 1e-10: dropping it
// changes nothing measurable, and it keeps log(base) and k base^(k-1) finite.
inline constexpr float kLobeBaseEps = 1e-20f;
// Cap on k log(base): exp(80) ~ 5.5e34 still leaves room for rho_s * lobe in float. Reached only
// by lobes outside the fitted family (base > 1 with a huge k).
inline constexpr float kMaxLobeLog = 80.0f;
// Cap on any returned BRDF value (1/sr); far above any physical value, far below float's max.
inline constexpr float kMaxBrdf = 1e30f;

struct LafortuneParams {
  Vec3f rho_d = Vec3f::Zero();  // diffuse BRDF value per channel (1/sr), >= 0
  Vec3f rho_s = Vec3f::Zero();  // specular lobe weight per channel (1/sr), >= 0
  float cx = -1.0f;             // lobe, tangent-frame x (gauge: cz = 1; mirror lobe cx = cy = -1)
  float cy = -1.0f;             // lobe, tangent-frame y
  float cz = 1.0f;              // always 1 in the stored gauge
  float k = 1.0f;               // lobe exponent (dimensionless), >= 0

  // Finite values, rho >= 0, k >= 0, cz == 1. Names the offending field.
  Status Validate() const;
};

// The lobe factor max(0, cx vx lx + cy vy ly + cz vz lz)^k for any scalar type T (float, double,
// or ceres::Jet: the fit's reference path differentiates this very function). v, l: unit
// tangent-frame directions as 3 plain numbers each. No hemisphere test here (see the callers).
// max(0, base)^k under the numerical contract above.
template <class T>
T ClampedLobe(const T& base, const T& k) {
  using std::exp;
  using std::log;
  if (!(base > T(kLobeBaseEps))) return T(0.0);  // also catches a NaN base
  T e = k * log(base);
  if (e > T(kMaxLobeLog)) e = T(kMaxLobeLog);
  return exp(e);
}

template <class T, class D>
T LafortuneLobe(const T& cx, const T& cy, const T& cz, const T& k, const D* v, const D* l) {
  return ClampedLobe(T(cx * T(v[0] * l[0]) + cy * T(v[1] * l[1]) + cz * T(v[2] * l[2])), k);
}

// f_r(v, l) per channel (1/sr). 0 when v or l is below the horizon (z <= 0).
Vec3f EvaluateLafortune(const LafortuneParams& params, const Vec3f& v, const Vec3f& l);

// The lobe factor and its analytic partial derivatives (what the fast fit path uses, checked
// against numeric differences in the tests). All 0 where the base is clamped (the derivative
// of the clamp is taken as 0 on the flat side), or below the horizon.
struct LobeDerivatives {
  double value = 0;  // max(0, base)^k
  double d_cx = 0, d_cy = 0, d_cz = 0;
  double d_k = 0;  // d/dk = value * log(base)
};
LobeDerivatives LafortuneLobeDerivatives(const LafortuneParams& params, const Vec3f& v,
                                         const Vec3f& l);

// General (ungauged) one-lobe form: f = rho_d + rho_s * max(0, C . (v * l))^k, C = (cx, cy, cz).
// Converts to the stored gauge (cz = 1) without changing the function: C' = C / cz,
// rho_s' = rho_s * cz^k (computed in log space in double; a value beyond float's range is an
// error rather than a silent Inf or 0 -- it cannot be stored). Errors: non-finite input,
// negative rho or k, cz <= 0 (no cz = 1 form).
Result<LafortuneParams> LafortuneFromGeneral(const Vec3f& rho_d, const Vec3f& rho_s, double cx,
                                             double cy, double cz, double k);

// ---------------------------------------------------------------------------------------------
// Multi-lobe Lafortune (the published 3-lobe fits in ../shared/data/lafortune_measured_fits.txt).
//
// Per channel c: f_c = diffuse_albedo_c / pi + sum_i max(0, cxy_ic (vx lx + vy ly) + cz_ic vz
// lz)^n_ic. Convention: the file lists the diffuse term as an ALBEDO; the renderers that ship these
// numbers (pbrt-v1 `Lafortune::f`, LuxRender) return `R * INV_PI + sum of lobes`, so the BRDF's
// diffuse value is albedo / pi. Each lobe's weight is folded into C (no separate rho_s), and
// lobes may have cz <= 0 (e.g. felt's retro-reflective lobe), which is why this is not a sum of
// LafortuneParams.
struct MeasuredLafortuneLobe {
  Vec3f cxy = Vec3f::Zero();  // per channel, Cx = Cy = cxy
  Vec3f cz = Vec3f::Zero();   // per channel
  Vec3f n = Vec3f::Zero();    // exponent per channel, >= 0
};

struct MeasuredLafortune {
  std::string name;                          // "bluepaint"
  Vec3f diffuse_albedo = Vec3f::Zero();      // as listed; BRDF diffuse value = albedo / pi
  std::vector<MeasuredLafortuneLobe> lobes;  // lobe 0, 1, ... in file order
};

// f_r(v, l) per channel (1/sr), same numerical contract and hemisphere rule as the one-lobe model.
Vec3f EvaluateMeasuredLafortune(const MeasuredLafortune& brdf, const Vec3f& v, const Vec3f& l);

// Format (one record per line; '#' starts a comment line; blank lines ignored):
//   <material> diffuse <R> <G> <B>
//   <material> <lobe index> <Cxy> <Cz> <n>
// where each of Cxy, Cz, n is either "r,g,b" or one number for all three channels (grey).
// Lobe indices of a material run 0, 1, 2, ... without gaps or repeats; each material needs
// exactly one diffuse row. Errors name the source and the line: "fits.txt:9: lobe 1 of primer:
// Cz: 'abc' is not a number". Materials come back in order of first appearance.
Result<std::vector<MeasuredLafortune>> ParseMeasuredLafortuneFits(std::string_view text,
                                                                  std::string_view source_name);
Result<std::vector<MeasuredLafortune>> ReadMeasuredLafortuneFits(const std::filesystem::path& path);

}  // namespace digitize
