// Per-texel one-lobe Lafortune fit (after McAllister et al. 2002, as in the paper;
// docs/architecture.md, "Fitting reflectance from photos").
//
// Layer: brdf (depends on core and lafortune.h). Ceres stays inside brdf_fit_ceres.cpp.
//
// WHAT IS FITTED. Each sample is one photo's view of one texel: the local view and light
// directions, the observed linear radiance, and the irradiance factor E that multiplies the BRDF
// to give that radiance (E = (n.l) I / d^2 for a point light of intensity I at distance d, or
// (n.l) E_perp for a directional light; per channel, so coloured lights need no special case):
//
//     radiance_c  ~  E_c * (rho_d,c + rho_s,c * max(0, cx vx lx + cy vy ly + vz lz)^k)
//
// The fit minimises the squared error IN RADIANCE SPACE, sum over samples and channels of
// (E_c f_c - radiance_c)^2, rather than in BRDF space (radiance / E): the sensor noise is (about)
// constant in radiance, so dividing by E would multiply the noise of grazing samples by 1/(n.l)
// and let them dominate; here a grazing sample simply weighs little. This is what makes the fit
// well posed near n.l = 0, and why the noise level `noise_sigma` is in radiance units.
//
// Parameters and bounds: gauge cz = 1 (lafortune.h), |cx|, |cy| <= 1 (lobe factor in [0, 1]),
// k in [k_min, k_max] (optimised as log k: k spans four decades), rho_d >= 0, and
// 0 <= rho_s <= max_specular_albedo (k + 2) / (2 pi): energy conservation of the lobe
// (integral of z^k z over the hemisphere = 2 pi / (k + 2)). The bound is what keeps a lobe whose
// peak falls between the lights from growing without limit (a narrow lobe seen only by its
// tails fits them equally well with any height): it assumes radiance and E in consistent
// units (f_r in 1/sr); with uncalibrated light intensities raise max_specular_albedo.
// A weak prior pulls (cx, cy) towards the mirror lobe (-1, -1): with one camera straight above
// the canvas (RTI) vx, vy ~ 0 and the data say little about cx, cy; the prior then keeps the
// mirror lobe instead of leaving them to the noise. It acts like one more residual per sample of
// lobe_prior_weight x (the texel's RMS radiance) x (c - c0): with 0.02, a deviation of 0.1 costs
// about one noise variance in total for a mid-grey texel, far less than what the data say about
// c wherever the cameras do constrain it.
//
// A second weak prior, a ridge on the specular albedo A_c = rho_s,c 2 pi / (k + 2), costing
// specular_prior_weight * noise_sigma^2 * (A_c / 0.1)^2: when the samples miss a narrow lobe's
// peak, lobes of any height fit its tails equally well (up to the noise), and without it the fit
// may pick a tall one whose peak hides between the lights, which relights terribly. It is a
// tie-breaker at the noise level: an observed lobe's data outweigh it by orders of magnitude.
//
// TWO PATHS, one objective (same samples, init, prior and bounds; they differ only in the solver):
//   kCeresReference: ceres::Solve on all 9 parameters (rho_d; rho_s as a fraction in [0, 1] of
//     its energy bound, which turns that bound into a box; cx, cy; log k), one autodiff residual
//     block per sample, DENSE_QR, Levenberg-Marquardt, bounds. The yardstick: ~350 us of CPU per
//     texel of 64 samples here (bench/brdf_fit_bench.cpp).
//   kFast: variable projection. For a fixed lobe shape (cx, cy, k) the model is linear in
//     (rho_d,c, rho_s,c) per channel: a 2-unknown bounded least squares, solved exactly in
//     closed form; only (cx, cy, log k) are optimised, by a small bounded Levenberg-Marquardt
//     (active set + truncated steps) with the Kaufman-projected Gauss-Newton matrix, the sums
//     vectorised over blocks of 8 samples in float. ~5 us of CPU per texel, same relighting error.
// Both start from a coarse grid over log k for the mirror lobe (the variable projection makes
// each grid point a closed-form solve), which is what keeps narrow lobes from being missed.
//
// PER-TEXEL OUTCOMES (data, not errors; STYLE rule 4):
//   - samples that are non-finite, below either horizon, with E <= 0, or saturated are dropped;
//   - fewer than `min_samples` left: kTooFewSamples, fallback = diffuse-only least squares from
//     what is left (rho_s = 0, mirror lobe, k = k_min); all zeros with no sample at all;
//   - a diffuse-only fit within the noise (chi-square test with `noise_sigma`): kDiffuseOnly, the
//     lobe fit is skipped (rho_s = 0, mirror lobe, k = k_min); also when the best lobe carries no
//     energy (all rho_s = 0);
//   - k ends on a bound: kClampedK (the lobe is narrower/wider than the bounds allow);
//   - iteration limit reached: kIterationLimit (best parameters so far kept);
//   - a non-finite value or a solver failure: kFailed, fallback = the diffuse-only fit.
// Outputs are never NaN/Inf (checked: a NaN leaving the fit is a bug and throws).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize/lafortune.h"

namespace digitize {

struct BrdfSample {
  Vec3f view_dir = Vec3f::UnitZ();   // unit, tangent frame (z = normal), towards the camera
  Vec3f light_dir = Vec3f::UnitZ();  // unit, tangent frame, towards the light
  Vec3f radiance = Vec3f::Zero();    // observed linear RGB (sRGB linearised), any radiance unit
  Vec3f irradiance = Vec3f::Zero();  // E per channel, same unit system: radiance = f_r * E
};

// The samples of many texels, texel by texel (compressed rows): texel t owns
// samples[texel_begin[t] .. texel_begin[t + 1]). texel_begin has texels + 1 entries, starts at 0,
// never decreases, ends at samples.size(). Texels map to the canvas grid by the caller.
struct BrdfSamples {
  std::vector<BrdfSample> samples;
  std::vector<size_t> texel_begin = {0};

  size_t texel_count() const { return texel_begin.empty() ? 0 : texel_begin.size() - 1; }
  std::span<const BrdfSample> Texel(size_t t) const {
    return {samples.data() + texel_begin[t], texel_begin[t + 1] - texel_begin[t]};
  }
  void AddTexel(std::span<const BrdfSample> texel_samples) {
    samples.insert(samples.end(), texel_samples.begin(), texel_samples.end());
    texel_begin.push_back(samples.size());
  }
};

enum class BrdfFitMethod : uint8_t {
  kFast,            // variable projection + small LM (default)
  kCeresReference,  // ceres::Solve, autodiff, DENSE_QR
};

struct BrdfFitOptions {
  BrdfFitMethod method = BrdfFitMethod::kFast;
  int min_samples = 8;               // valid samples per texel needed to fit a lobe (9 unknowns
                                     // share 3 x samples residuals)
  double noise_sigma = 0.002;        // std of the radiance noise per channel, radiance units
                                     // (0.002 ~ 8-bit quantisation + sensor at mid-grey, 0..1)
  double diffuse_chi2_sigmas = 3.0;  // a diffuse fit "explains the samples" when its squared
                                     // error is below the chi-square mean + this many stds;
                                     // < 0 disables the diffuse-only shortcut
  // Radiance (units of the samples) at which the sensor clips: a sample with any channel >= this
  // is dropped and counted; +inf = no clipping.
  double saturation_radiance = std::numeric_limits<double>::infinity();
  double k_min = 0.5;  // lobe exponent bounds (dimensionless)
  double k_max = 1.0e4;
  double max_specular_albedo = 1.0;    // energy bound: rho_s 2 pi / (k + 2) <= this (the lobe's
                                       // reflected fraction at normal view; radiance / E units)
  double lobe_prior_weight = 0.02;     // pull of (cx, cy) towards (-1, -1), see above
  double specular_prior_weight = 1.0;  // cost, in noise variances (noise_sigma^2), of a
                                       // specular albedo of 0.1 per channel, see above
  int max_iterations = 50;             // per texel, either path
  int num_threads = 0;                 // worker threads; 0 = all cores
  Status Validate() const;
};

enum class TexelFitStatus : uint8_t {
  kConverged = 0,
  kDiffuseOnly,
  kTooFewSamples,
  kClampedK,
  kIterationLimit,
  kFailed,
};
inline constexpr int kTexelFitStatusCount = 6;
const char* ToString(TexelFitStatus status);  // "converged", "diffuse-only", "too few samples", ...

struct TexelFit {
  LafortuneParams params;  // stored gauge, finite
  TexelFitStatus status = TexelFitStatus::kTooFewSamples;
  float rms_error = 0;        // radiance RMS over the used samples and 3 channels
  int samples_used = 0;       // after dropping invalid and saturated ones
  int samples_saturated = 0;  // dropped as clipped
  int iterations = 0;         // solver iterations (0 when no lobe was fitted)
};

struct BrdfFitSummary {
  BrdfFitMethod method = BrdfFitMethod::kFast;
  size_t texels = 0;
  std::array<size_t, kTexelFitStatusCount> count_by_status{};  // indexed by TexelFitStatus
  size_t samples_total = 0, samples_used = 0, samples_saturated = 0;
  double mean_rms_error = 0;   // over texels, radiance units
  double mean_iterations = 0;  // over texels with a lobe fit
  double seconds = 0;          // wall time of FitBrdf
  size_t count(TexelFitStatus s) const { return count_by_status[static_cast<size_t>(s)]; }
  // "97.8 % converged, 1.9 % diffuse-only, 0.3 % too few samples; 41 s" (zero classes left out).
  std::string BriefReport() const;
};

struct BrdfFitResult {
  std::vector<LafortuneParams> params;  // one per texel, stored gauge (cz = 1)
  std::vector<TexelFitStatus> status;   // one per texel
  std::vector<float> rms_error;         // one per texel, radiance units
  BrdfFitSummary summary;
};

// Fits every texel, in parallel over texels, reporting progress as step "fit". Errors (no fit
// done): invalid options, or a texel_begin that does not describe `samples`. Zero texels give an
// empty result.
Result<BrdfFitResult> FitBrdf(const BrdfSamples& samples, const BrdfFitOptions& options,
                              const ProgressCallback& progress = {});

// One texel; `options` must be valid (checked: throws InvariantError otherwise). Thread-safe.
TexelFit FitBrdfTexel(std::span<const BrdfSample> samples, const BrdfFitOptions& options);

}  // namespace digitize
