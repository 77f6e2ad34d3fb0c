// Per-texel reflectance fit: diffuse only, one-lobe Lafortune (after McAllister et al. 2002, as
// in the paper) or GGX (ggx.h), chosen per texel (docs/architecture.md, "Fitting reflectance
// from photos").
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
// Where the Lafortune lobe does not explain the samples (chi-square test failed) and no sample
// sees half its peak, the peak is not trusted: the lobe is widened to the k at which the
// best-placed sample sees half the peak before the model choice (brdf_fit.cpp, ResolveLobe).
//
// TWO PATHS, one objective (same samples, init, prior and bounds; they differ only in the solver):
//   kCeresReference: ceres::Solve on all 9 parameters (rho_d; rho_s as a fraction in [0, 1] of
//     its energy bound, which turns that bound into a box; cx, cy; log k), one autodiff residual
//     block per sample, DENSE_QR, Levenberg-Marquardt, bounds. The yardstick: ~690 us of CPU per
//     texel of 64 samples here (bench/brdf_fit_bench.cpp).
//   kFast: variable projection. For a fixed lobe shape (cx, cy, k) the model is linear in
//     (rho_d,c, rho_s,c) per channel: a 2-unknown bounded least squares, solved exactly in
//     closed form; only (cx, cy, log k) are optimised, by a small bounded Levenberg-Marquardt
//     (active set + truncated steps) with the Kaufman-projected Gauss-Newton matrix, the sums
//     vectorised over blocks of 8 samples in float. ~5 us of CPU per texel (x86-64-v3 build),
//     a lower relighting error.
// Both start from a coarse grid over log k for the mirror lobe (the variable projection makes
// each grid point a closed-form solve), which is what keeps narrow lobes from being missed.
// With the GGX candidate too (the default), bench/brdf_fit_bench.cpp at 2 threads, 64 samples,
// noise 0.002 (2026-12-07, x86-64-v3): 9.3 us of CPU per texel (Lafortune-like texels; 5.3 us
// with Lafortune alone) and 10.9 us (GGX-like texels) against 1.3 ms and 2.8 ms for
// kCeresReference, at the same relighting error (GGX texels: RMSE 0.0043 fast, 0.0044
// reference; 0.43 with Lafortune alone).
//
// NOISE MODEL. Each residual is weighted by 1 / sigma^2 of its sample and channel:
//   sigma^2 = noise_sigma^2 + step(L)^2 (1/12 + photo_compression_sigma_codes^2),
// step(L) = one code of the photos' encoding in linear radiance at the sample's value L, i.e.
// (dL/dcode) / photo_code_max; for sRGB codes dL/dcode is the EOTF's slope, tiny in the shadows
// and ~2 near white, so 8-bit rounding (step^2 / 12 = 5e-6 at L = 0.8, more than a 0.002
// sensor's 4e-6) dominates bright samples. Without it a Lambertian texel's rounding error looked
// like signal: the chi-square test failed on a third of matte texels and they got lobes fitted
// to the rounding. The weights are sigma_sensor^2 / sigma^2 (<= 1, exactly 1 without a
// quantisation term), so squared errors stay in radiance^2 at the sensor's level and the
// chi-square test and the priors keep their meaning. They are fixed from the observed L (not the
// model's), so the problem stays a plain least squares. Display weighting (error as seen in sRGB,
// linear error x d(srgb)/d(linear)) is NOT applied: the weights above already follow the
// encoding (a code step is one display step), and a fit weighted beyond the noise model is no
// longer the maximum-likelihood one that the model choice below needs.
//
// MODEL CHOICE (when the diffuse chi-square test fails): each candidate (diffuse only with 3
// parameters, Lafortune with 9, GGX with 7: rho_d, F0 RGB and alpha) is fitted, and the texel
// takes the least chi2 + model_penalty_per_parameter x parameters, chi2 = weighted squared error
// / noise_sigma^2 (no priors). The default penalty is BIC's ln(3 N) (~5.7 for 96 samples): with
// the noise model right, a spurious lobe gains about its parameter count in chi2 (a few times
// that for the searched k or alpha), far below 6 ln(3 N), while a real lobe gains orders of
// magnitude more. AIC's 2 per parameter does not grow with N, so it lets more noise through as
// the photo count grows; held-out samples would take photos from sparse sets (48-64 lights)
// that the lobes need. Measured: 0 of 200 noisy Lambertian texels get a lobe with BIC even
// without the diffuse shortcut, and 8-bit rounding gave lobes to 97 of 100 bright Lambertian
// texels before (no quantisation term, a lobe whenever the chi-square test failed), 0 with
// either the quantisation term or BIC (tests/reflectance_fit_ggx_test.cpp).
// GGX is fitted like Lafortune by variable projection: for a fixed alpha the model is linear in
// (rho_d,c, F0,c) per channel, Schlick's F0 + (1 - F0) m^5 = F0 (1 - m^5) + m^5 being linear in F0
// with an offset; bounds rho_d >= 0, 0 <= F0 <= 1 (no prior: F0 <= 1 bounds the energy), and
// log alpha alone is searched (a grid, then Brent's method; kCeresReference: ceres::Solve on
// all 7 unknowns from the same grid point, the same weighted objective).
//
// PER-TEXEL OUTCOMES (data, not errors; STYLE rule 4):
//   - samples that are non-finite, below either horizon, with E <= 0, or saturated are dropped;
//   - fewer than `min_samples` left: kTooFewSamples, fallback = diffuse-only least squares from
//     what is left (rho_s = 0, mirror lobe, k = k_min); all zeros with no sample at all;
//   - a diffuse-only fit within the noise (chi-square test with `noise_sigma`): kDiffuseOnly, the
//     lobe fit is skipped (rho_s = 0, mirror lobe, k = k_min); also when the best lobe carries no
//     energy (all rho_s = 0);
//   - the chosen model is diffuse only: kDiffuseOnly;
//   - k (GGX: alpha) ends on a bound: kClampedK (the lobe is narrower/wider than allowed);
//   - iteration limit reached: kIterationLimit (best parameters so far kept);
//   - a non-finite value or a solver failure of every lobe candidate: kFailed, fallback = the
//     diffuse-only fit (a failed candidate is simply not chosen).
// Outputs are never NaN/Inf (checked: a NaN leaving the fit is a bug and throws).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize/ggx.h"
#include "digitize/lafortune.h"

namespace digitize {

// The reflectance model of a texel (reflectance_maps.h stores either in the same channels).
enum class ReflectanceModel : uint8_t {
  kLafortune = 0,  // one-lobe Lafortune (the paper's model); every pack before models existed
  kGgx = 1,        // GGX + Schlick Fresnel + Smith (ggx.h)
};
inline constexpr int kReflectanceModelCount = 2;
const char* ToString(ReflectanceModel model);  // "lafortune", "ggx"

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
  double noise_sigma = 0.002;        // std of the sensor's radiance noise per channel,
                                     // radiance units; quantisation is added (NOISE MODEL)
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
  // Candidate models besides diffuse-only (see MODEL CHOICE above); at least one lobe model is
  // tried unless both are off (then every texel is diffuse-only).
  bool fit_lafortune = true;
  bool fit_ggx = true;
  double ggx_alpha_min = 0.01;  // GGX roughness bounds searched (dimensionless, within
  double ggx_alpha_max = 1.0;   // [kGgxMinAlpha, kGgxMaxAlpha])
  // Chi-square cost of one free parameter in the model choice; < 0 = BIC's ln(3 N) (N samples).
  double model_penalty_per_parameter = -1.0;
  // Quantisation of the photos (NOISE MODEL above): the top code of their integer encoding
  // (255 for 8-bit, 65535 for 16-bit; 0 = float photos, no quantisation term), whether the
  // codes are sRGB (else linear), and the extra error of lossy compression (JPEG) as a standard
  // deviation in codes (0 for lossless files).
  int photo_code_max = 0;
  bool photo_codes_srgb = true;
  double photo_compression_sigma_codes = 0.0;
  int num_threads = 0;  // worker threads; 0 = all cores
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
  ReflectanceModel model = ReflectanceModel::kLafortune;  // which of the two below is the fit
  LafortuneParams params;  // stored gauge, finite; diffuse-only and fallbacks: rho_s = 0
  GgxParams ggx;           // model kGgx only (else zeros), finite
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
  // Texels whose chosen model has a lobe, by model (the rest are diffuse-only or too few).
  std::array<size_t, kReflectanceModelCount> lobes_by_model{};
  size_t samples_total = 0, samples_used = 0, samples_saturated = 0;
  double mean_rms_error = 0;   // over texels, radiance units
  double mean_iterations = 0;  // over texels with a lobe fit
  double seconds = 0;          // wall time of FitBrdf
  size_t count(TexelFitStatus s) const { return count_by_status[static_cast<size_t>(s)]; }
  // "97.8 % converged, 1.9 % diffuse-only, 0.3 % too few samples; 41 s" (zero classes left out).
  std::string BriefReport() const;
};

struct BrdfFitResult {
  std::vector<ReflectanceModel> model;  // one per texel
  std::vector<LafortuneParams> params;  // one per texel, stored gauge (cz = 1)
  std::vector<GgxParams> ggx;           // one per texel (zeros unless model kGgx)
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

// Fits texel after texel in one scratch space (FitBrdfTexel allocates one a call), for callers
// that run their own loop over texels (FitReflectance filters each texel's samples on the way
// in and refits after, in one pass over them). One per thread; `options` as FitBrdfTexel's.
class BrdfTexelFitter {
 public:
  explicit BrdfTexelFitter(const BrdfFitOptions& options);
  ~BrdfTexelFitter();
  BrdfTexelFitter(const BrdfTexelFitter&) = delete;
  BrdfTexelFitter& operator=(const BrdfTexelFitter&) = delete;
  TexelFit Fit(std::span<const BrdfSample> samples);

 private:
  struct Scratch;
  BrdfFitOptions options_;
  std::unique_ptr<Scratch> scratch_;
};

}  // namespace digitize
