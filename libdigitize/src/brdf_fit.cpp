// Per-texel one-lobe Lafortune fit, the front end: the diffuse-only test, the coarse grid over k,
// the texel's status, the fit over all texels and the public API (the samples are filtered into
// a TexelProblem, brdf_fit_problem.h). The lobe itself is fitted by a
// solver behind brdf_fit_solvers.h: the fast variable-projection path (brdf_fit_varpro.cpp) or
// the ceres::Solve reference (brdf_fit_ceres.cpp). Notation: brdf_fit_problem.h.
#include "digitize/brdf_fit.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <string>
#include <vector>

#include "brdf_fit_problem.h"
#include "brdf_fit_solvers.h"

namespace digitize {
namespace brdf_detail {

LobeSolver LobeSolverFor(BrdfFitMethod method) {
  return method == BrdfFitMethod::kCeresReference ? FitLobeCeres : FitLobeVarPro;
}

GgxSolver GgxSolverFor(BrdfFitMethod method) {
  return method == BrdfFitMethod::kCeresReference ? FitGgxCeres : FitGgxVarPro;
}

}  // namespace brdf_detail

namespace {

using brdf_detail::Bounds;
using brdf_detail::ChannelSums;
using brdf_detail::GgxFitOutcome;
using brdf_detail::GgxSolverFor;
using brdf_detail::GgxStart;
using brdf_detail::kPriorC;
using brdf_detail::LinearFit;
using brdf_detail::LobeFitOutcome;
using brdf_detail::LobeSolverFor;
using brdf_detail::QuadraticCost;
using brdf_detail::Shape;
using brdf_detail::TexelProblem;
using brdf_detail::Workspace;

// Grid spacing of the initial search over k (then refined by a parabola): a factor 4 keeps every
// lobe within a factor 2 of a grid point, close enough for LM to start in the right basin even
// for narrow lobes (a factor 2 grid gave the same relighting error at twice the grid cost).
constexpr double kGridFactor = 4.0;
// Texels per parallel task: large enough to amortise the workspace, small enough to balance.
constexpr size_t kTexelGrain = 64;

// Coarse search over k for the mirror lobe: each point is a closed-form solve. The best grid
// point is refined by the vertex of the parabola (in log k) through it and its neighbours, so
// LM starts within a fraction of the grid step.
Shape GridInit(TexelProblem& problem, const Bounds& bounds) {
  problem.SetLobeDirection(kPriorC, kPriorC);
  const double step = std::log(kGridFactor);
  std::array<double, 32> costs{}, ts{};  // log(1e6 / 0.5) / log(4) < 11 points
  const int count = std::min<int>(
      costs.size(), 1 + static_cast<int>(std::ceil((bounds.t_hi - bounds.t_lo) / step - 1e-9)));
  int best = 0;
  for (int i = 0; i < count; ++i) {
    ts[i] = std::min(bounds.t_lo + i * step, bounds.t_hi);
    problem.SetExponent(std::exp(ts[i]), false);
    std::array<ChannelSums, 3> sums;
    const LinearFit fit = problem.SolveLinear(&sums);
    costs[i] = 0;
    for (int c = 0; c < 3; ++c)
      costs[i] += sums[c].ll + QuadraticCost(sums[c], fit.channel[c].a, fit.channel[c].b);
    if (costs[i] < costs[best]) best = i;
  }
  Shape init;
  init.t = ts[best];
  if (best > 0 && best + 1 < count) {
    const double h1 = ts[best] - ts[best - 1], h2 = ts[best + 1] - ts[best];
    const double d1 = (costs[best] - costs[best - 1]) / h1,
                 d2 = (costs[best + 1] - costs[best]) / h2;
    const double curvature = (d2 - d1) / (0.5 * (h1 + h2));
    if (curvature > 0.0)
      init.t = std::clamp(ts[best] - 0.5 * (d1 + d2) / curvature, ts[best - 1], ts[best + 1]);
  }
  return init;
}

// The GGX grid over log alpha: a factor 1.5 between points (12 points over 0.01 .. 1) keeps
// the reduced cost unimodal between a point's neighbours in every case we measured, so Brent's
// method on that bracket finds the minimum the grid points at. Tried 2026-12-07, not kept: a
// factor 2.25 (7 points) made the fit 7-8 % faster on synthetic paints at the same error, but on
// the real capture (rti_bench, rti_icon) it gained no time and lost 0.003 dB held out.
constexpr double kGgxGridFactor = 1.5;

GgxStart GgxGridInit(TexelProblem& problem, const BrdfFitOptions& options) {
  GgxStart start;
  start.t_lo = std::log(options.ggx_alpha_min);
  start.t_hi = std::log(options.ggx_alpha_max);
  const double step = std::log(kGgxGridFactor);
  std::array<double, 64> costs{}, ts{};
  const int count = std::min<int>(
      costs.size(), 1 + static_cast<int>(std::ceil((start.t_hi - start.t_lo) / step - 1e-9)));
  int best = 0;
  for (int i = 0; i < count; ++i) {
    ts[i] = std::min(start.t_lo + i * step, start.t_hi);
    problem.SolveGgx(std::exp(ts[i]), nullptr, &costs[i]);
    if (costs[i] < costs[best]) best = i;
  }
  start.t = ts[best];
  start.bracket_lo = ts[std::max(0, best - 1)];
  start.bracket_hi = ts[std::min(count - 1, best + 1)];
  if (best > 0) start.cost_lo = costs[best - 1];
  if (best + 1 < count) start.cost_hi = costs[best + 1];
  return start;
}

// Free parameters of each candidate, for the model choice (per texel, all three channels).
constexpr int kDiffuseParameters = 3;    // rho_d
constexpr int kLafortuneParameters = 9;  // rho_d, rho_s, cx, cy, k
constexpr int kGgxParameters = 7;        // rho_d, F0, alpha

LafortuneParams DiffuseParams(const LinearFit& fit, double k) {
  LafortuneParams p;
  for (int c = 0; c < 3; ++c) p.rho_d[c] = static_cast<float>(fit.channel[c].a);
  p.k = static_cast<float>(k);
  return p;
}

bool Finite(const LafortuneParams& p) {
  return p.rho_d.allFinite() && p.rho_s.allFinite() && std::isfinite(p.cx) && std::isfinite(p.cy) &&
         std::isfinite(p.cz) && std::isfinite(p.k);
}

float Rms(double sse, int n) {
  return n > 0 ? static_cast<float>(std::sqrt(std::max(0.0, sse) / (3.0 * n))) : 0.0f;
}

// A lobe whose peak no sample sees (every sample's lobe factor below kResolvedLobeFactor) is
// extrapolated there from its tails. That is sound where the lobe explains the samples (within
// the noise: noise-free samples of a k = 60 lobe are fitted exactly without its peak), not where
// it does not (a texel whose samples mix paints, a paint the model cannot follow): the solver then
// follows the misfit towards tall narrow lobes, up to the energy bound, which relight a held-out
// light near the peak far too bright (measured on the GGX painting: one such boundary texel of
// 9 k, k 450 at rho_s 72, was 83 % of the held-out squared error). Such a lobe is widened to the
// sharpest the samples resolve, the k at which the best-placed sample sees kResolvedLobeFactor of
// the peak, and its linear part refitted there; the model choice then weighs that lobe.
constexpr double kResolvedLobeFactor = 0.5;

void ResolveLobe(TexelProblem& problem, const BrdfFitOptions& options, double explained_sse,
                 LobeFitOutcome& lobe) {
  if (lobe.sse <= explained_sse) return;
  problem.SetLobeDirection(lobe.shape.cx, lobe.shape.cy);
  const double base = problem.MaxBase();
  const double k = std::exp(lobe.shape.t);
  // base is in [kLobeBaseEps, 1]: below the factor means base < 1, so its log is negative.
  if (std::pow(base, k) >= kResolvedLobeFactor) return;
  const double k_resolved = std::max(options.k_min, std::log(kResolvedLobeFactor) / std::log(base));
  if (k_resolved >= k) return;
  lobe.shape.t = std::log(k_resolved);
  problem.SetExponent(k_resolved, false);
  lobe.linear = problem.SolveLinear();
  lobe.sse = problem.Sse(lobe.linear);
}

TexelFit FitTexel(std::span<const BrdfSample> samples, const BrdfFitOptions& options,
                  Workspace& ws) {
  using Columns = TexelProblem::Columns;
  TexelProblem problem(samples, options, ws);
  TexelFit out;
  out.samples_used = problem.n();
  out.samples_saturated = problem.saturated();
  LinearFit diffuse;
  const double diffuse_sse = problem.FitDiffuse(&diffuse);
  out.params = DiffuseParams(diffuse, options.k_min);
  out.rms_error = Rms(problem.RadianceSse(diffuse, Columns::kDiffuse), problem.n());
  if (problem.n() < options.min_samples) {
    out.status = TexelFitStatus::kTooFewSamples;
    return out;
  }
  // Chi-square test: with Gaussian noise sigma, the squared error of a right model over
  // dof = 3N - 3 residuals has mean dof sigma^2 and std sqrt(2 dof) sigma^2. The squared error
  // is weighted by the noise model (quantisation included), so sigma is the sensor's.
  // A model with p parameters leaves dof = 3N - p; what its squared error stays under:
  const double sigma2 = options.noise_sigma * options.noise_sigma;
  const auto chi2_bound = [&](double dof) {
    return sigma2 * (dof + std::max(0.0, options.diffuse_chi2_sigmas) * std::sqrt(2.0 * dof));
  };
  if (options.diffuse_chi2_sigmas >= 0.0 &&
      diffuse_sse <= chi2_bound(3.0 * problem.n() - kDiffuseParameters)) {
    out.status = TexelFitStatus::kDiffuseOnly;
    return out;
  }
  // The model choice (brdf_fit.h, MODEL CHOICE): chi-square plus a cost per free parameter.
  // Without a noise level (sigma 0) the smallest error wins.
  const double chi2_scale = 1.0 / std::max(sigma2, 1e-30);
  const double penalty = options.model_penalty_per_parameter >= 0.0
                             ? options.model_penalty_per_parameter
                             : std::log(3.0 * problem.n());
  double best_score = diffuse_sse * chi2_scale + penalty * kDiffuseParameters;
  bool any_candidate = false, all_failed = true;
  const double t_tolerance = 1e-4;  // in log k / log alpha: within 0.01 % of a bound
  TexelFit best = out;
  best.status = TexelFitStatus::kDiffuseOnly;
  int iterations = 0;

  if (options.fit_lafortune) {
    any_candidate = true;
    const Bounds bounds{-1.0, 1.0, std::log(options.k_min), std::log(options.k_max)};
    const Shape init = GridInit(problem, bounds);
    LobeFitOutcome lobe = LobeSolverFor(options.method)(problem, init, bounds, options);
    iterations += lobe.iterations;
    if (!lobe.failed)
      ResolveLobe(problem, options,
                  chi2_bound(std::max(1.0, 3.0 * problem.n() - kLafortuneParameters)), lobe);
    LafortuneParams p;
    for (int c = 0; c < 3; ++c) {
      p.rho_d[c] = static_cast<float>(lobe.linear.channel[c].a);
      p.rho_s[c] = static_cast<float>(lobe.linear.channel[c].b);
    }
    p.cx = static_cast<float>(lobe.shape.cx);
    p.cy = static_cast<float>(lobe.shape.cy);
    p.cz = 1.0f;
    p.k = static_cast<float>(std::exp(lobe.shape.t));
    // A solver that ends worse than the diffuse fit (a feasible point with no penalty; the slack
    // is float rounding of two sums) is not trusted, nor a non-finite one.
    const bool failed = lobe.failed || !Finite(p) || !std::isfinite(lobe.sse) ||
                        lobe.sse > diffuse_sse * (1.0 + 1e-5) + 1e-30;
    if (!failed) {
      all_failed = false;
      if (lobe.linear.any_lobe()) {
        problem.SetShape(lobe.shape, false);
        const double score = lobe.sse * chi2_scale + penalty * kLafortuneParameters;
        if (score < best_score) {
          best_score = score;
          best.model = ReflectanceModel::kLafortune;
          best.params = p;
          best.rms_error = Rms(problem.RadianceSse(lobe.linear, Columns::kLobe), problem.n());
          if (lobe.shape.t <= bounds.t_lo + t_tolerance ||
              lobe.shape.t >= bounds.t_hi - t_tolerance)
            best.status = TexelFitStatus::kClampedK;
          else if (!lobe.converged)
            best.status = TexelFitStatus::kIterationLimit;
          else
            best.status = TexelFitStatus::kConverged;
        }
      }
    }
  }
  if (options.fit_ggx) {
    any_candidate = true;
    problem.PrepareGgx();
    const GgxStart start = GgxGridInit(problem, options);
    const GgxFitOutcome ggx = GgxSolverFor(options.method)(problem, start, options);
    iterations += ggx.iterations;
    GgxParams g;
    for (int c = 0; c < 3; ++c) {
      g.rho_d[c] = static_cast<float>(ggx.linear.channel[c].a);
      g.f0[c] = static_cast<float>(ggx.linear.channel[c].b);
    }
    g.alpha = static_cast<float>(std::exp(ggx.t));
    const bool failed = ggx.failed || !std::isfinite(ggx.sse) || !g.rho_d.allFinite() ||
                        !g.f0.allFinite() || !std::isfinite(g.alpha);
    if (!failed) {
      all_failed = false;
      const double score = ggx.sse * chi2_scale + penalty * kGgxParameters;
      if (score < best_score) {
        best_score = score;
        best.model = ReflectanceModel::kGgx;
        best.ggx = g;
        best.params = LafortuneParams{};  // the diffuse floor, for callers that read params only
        best.params.rho_d = g.rho_d;
        best.params.k = static_cast<float>(options.k_min);
        problem.SolveGgx(g.alpha);
        best.rms_error = Rms(problem.RadianceSse(ggx.linear, Columns::kGgx), problem.n());
        if (ggx.t <= start.t_lo + t_tolerance || ggx.t >= start.t_hi - t_tolerance)
          best.status = TexelFitStatus::kClampedK;
        else if (!ggx.converged)
          best.status = TexelFitStatus::kIterationLimit;
        else
          best.status = TexelFitStatus::kConverged;
      }
    }
  }
  best.iterations = iterations;
  if (any_candidate && all_failed) best.status = TexelFitStatus::kFailed;  // diffuse fallback
  return best;
}

}  // namespace

const char* ToString(TexelFitStatus status) {
  switch (status) {
    case TexelFitStatus::kConverged:
      return "converged";
    case TexelFitStatus::kDiffuseOnly:
      return "diffuse-only";
    case TexelFitStatus::kTooFewSamples:
      return "too few samples";
    case TexelFitStatus::kClampedK:
      return "clamped k";
    case TexelFitStatus::kIterationLimit:
      return "iteration limit";
    case TexelFitStatus::kFailed:
      return "failed";
  }
  return "unknown";
}

Status BrdfFitOptions::Validate() const {
  if (min_samples < 1)
    return Error{"min_samples must be >= 1 (samples per texel), got " +
                 std::to_string(min_samples)};
  if (!(std::isfinite(noise_sigma) && noise_sigma >= 0.0))
    return Error{"noise_sigma must be finite and >= 0 (radiance units), got " +
                 FormatNumber(noise_sigma)};
  if (std::isnan(diffuse_chi2_sigmas) || std::isinf(diffuse_chi2_sigmas))
    return Error{"diffuse_chi2_sigmas must be finite (standard deviations; < 0 disables), got " +
                 FormatNumber(diffuse_chi2_sigmas)};
  if (!(saturation_radiance > 0.0))
    return Error{"saturation_radiance must be > 0 (radiance units; +inf = no clipping), got " +
                 FormatNumber(saturation_radiance)};
  if (!(std::isfinite(k_min) && k_min >= 0.5))
    return Error{"k_min must be finite and >= 0.5 (lobe exponent), got " + FormatNumber(k_min)};
  if (!(std::isfinite(k_max) && k_max > k_min && k_max <= 1e6))
    return Error{"k_max must be finite, > k_min and <= 1e6 (lobe exponent), got " +
                 FormatNumber(k_max)};
  if (!(std::isfinite(max_specular_albedo) && max_specular_albedo > 0.0))
    return Error{"max_specular_albedo must be finite and > 0 (fraction of the irradiance), got " +
                 FormatNumber(max_specular_albedo)};
  if (!(std::isfinite(specular_prior_weight) && specular_prior_weight >= 0.0))
    return Error{"specular_prior_weight must be finite and >= 0 (noise variances), got " +
                 FormatNumber(specular_prior_weight)};
  if (!(std::isfinite(lobe_prior_weight) && lobe_prior_weight >= 0.0))
    return Error{"lobe_prior_weight must be finite and >= 0, got " +
                 FormatNumber(lobe_prior_weight)};
  if (!(std::isfinite(ggx_alpha_min) && ggx_alpha_min >= kGgxMinAlpha))
    return Error{"ggx_alpha_min must be finite and >= " + FormatNumber(kGgxMinAlpha) +
                 " (GGX roughness), got " + FormatNumber(ggx_alpha_min)};
  if (!(std::isfinite(ggx_alpha_max) && ggx_alpha_max > ggx_alpha_min &&
        ggx_alpha_max <= kGgxMaxAlpha))
    return Error{
        "ggx_alpha_max must be finite, > ggx_alpha_min and <= " + FormatNumber(kGgxMaxAlpha) +
        " (GGX roughness), got " + FormatNumber(ggx_alpha_max)};
  if (std::isnan(model_penalty_per_parameter) || std::isinf(model_penalty_per_parameter))
    return Error{"model_penalty_per_parameter must be finite (chi-square units; < 0 = BIC), got " +
                 FormatNumber(model_penalty_per_parameter)};
  if (photo_code_max < 0)
    return Error{"photo_code_max must be >= 0 (top code of the photos; 0 = float photos), got " +
                 std::to_string(photo_code_max)};
  if (!(std::isfinite(photo_compression_sigma_codes) && photo_compression_sigma_codes >= 0.0))
    return Error{"photo_compression_sigma_codes must be finite and >= 0 (codes), got " +
                 FormatNumber(photo_compression_sigma_codes)};
  if (max_iterations < 1)
    return Error{"max_iterations must be >= 1, got " + std::to_string(max_iterations)};
  if (num_threads < 0)
    return Error{"num_threads must be >= 0 (0 = all cores), got " + std::to_string(num_threads)};
  return Status::Ok();
}

std::string BrdfFitSummary::BriefReport() const {
  std::string out;
  char buffer[96];
  for (int s = 0; s < kTexelFitStatusCount; ++s) {
    const size_t n = count_by_status[s];
    if (n == 0 && s != 0) continue;
    const double percent =
        texels > 0 ? 100.0 * static_cast<double>(n) / static_cast<double>(texels) : 0.0;
    // A class that exists but rounds to 0.0 % reads "< 0.1 %", so it is not mistaken for none.
    if (n > 0 && percent < 0.05)
      std::snprintf(buffer, sizeof buffer, "%s< 0.1 %% %s", out.empty() ? "" : ", ",
                    ToString(static_cast<TexelFitStatus>(s)));
    else
      std::snprintf(buffer, sizeof buffer, "%s%.1f %% %s", out.empty() ? "" : ", ", percent,
                    ToString(static_cast<TexelFitStatus>(s)));
    out += buffer;
  }
  // Which model carries the lobes, when GGX is among them (Lafortune-only fits read as before).
  if (lobes_by_model[static_cast<size_t>(ReflectanceModel::kGgx)] > 0) {
    const double n = static_cast<double>(texels);
    std::snprintf(buffer, sizeof buffer, "; lobes: %.1f %% lafortune, %.1f %% ggx",
                  100.0 * static_cast<double>(lobes_by_model[0]) / n,
                  100.0 * static_cast<double>(lobes_by_model[1]) / n);
    out += buffer;
  }
  std::snprintf(buffer, sizeof buffer, "; %.3g s", seconds);
  return out + buffer;
}

TexelFit FitBrdfTexel(std::span<const BrdfSample> samples, const BrdfFitOptions& options) {
  return BrdfTexelFitter(options).Fit(samples);
}

struct BrdfTexelFitter::Scratch {
  Workspace ws;
};

BrdfTexelFitter::BrdfTexelFitter(const BrdfFitOptions& options)
    : options_(options), scratch_(std::make_unique<Scratch>()) {
  const Status valid = options.Validate();
  DIGITIZE_CHECK(valid.ok(), "BrdfTexelFitter: " + valid.message());
}

BrdfTexelFitter::~BrdfTexelFitter() = default;

TexelFit BrdfTexelFitter::Fit(std::span<const BrdfSample> samples) {
  return FitTexel(samples, options_, scratch_->ws);
}

Result<BrdfFitResult> FitBrdf(const BrdfSamples& samples, const BrdfFitOptions& options,
                              const ProgressCallback& progress) {
  const auto start = std::chrono::steady_clock::now();
  if (Status s = options.Validate(); !s.ok()) return Error{"brdf fit options: " + s.message()};
  const std::vector<size_t>& begin = samples.texel_begin;
  if (begin.empty() || begin.front() != 0 || begin.back() != samples.samples.size())
    return Error{"brdf samples: texel_begin must start at 0 and end at the sample count (" +
                 std::to_string(samples.samples.size()) + ")"};
  for (size_t t = 1; t < begin.size(); ++t)
    if (begin[t] < begin[t - 1])
      return Error{"brdf samples: texel_begin decreases at texel " + std::to_string(t - 1)};

  const size_t texels = samples.texel_count();
  BrdfFitResult result;
  result.params.resize(texels);
  result.model.resize(texels, ReflectanceModel::kLafortune);
  result.ggx.resize(texels);
  result.status.resize(texels, TexelFitStatus::kTooFewSamples);
  result.rms_error.resize(texels, 0.0f);
  std::vector<int> iterations(texels, 0), used(texels, 0), saturated(texels, 0);

  std::atomic<size_t> done{0};
  std::mutex progress_mutex;
  size_t last_reported = 0;
  ReportProgress(progress, "fit", 0.0);
  const auto body = [&](const tbb::blocked_range<size_t>& range) {
    BrdfTexelFitter fitter(options);
    for (size_t t = range.begin(); t != range.end(); ++t) {
      const TexelFit fit = fitter.Fit(samples.Texel(t));
      result.params[t] = fit.params;
      result.model[t] = fit.model;
      result.ggx[t] = fit.ggx;
      result.status[t] = fit.status;
      result.rms_error[t] = fit.rms_error;
      iterations[t] = fit.iterations;
      used[t] = fit.samples_used;
      saturated[t] = fit.samples_saturated;
    }
    const size_t now = done.fetch_add(range.size()) + range.size();
    if (progress && progress_mutex.try_lock()) {
      // At most ~100 reports; one thread at a time, as ProgressCallback requires.
      if (now - last_reported >= std::max<size_t>(1, texels / 100) && now < texels) {
        last_reported = now;
        progress("fit", static_cast<double>(now) / static_cast<double>(texels));
      }
      progress_mutex.unlock();
    }
  };
  tbb::task_arena arena(options.num_threads > 0 ? options.num_threads : tbb::task_arena::automatic);
  arena.execute(
      [&] { tbb::parallel_for(tbb::blocked_range<size_t>(0, texels, kTexelGrain), body); });

  BrdfFitSummary& s = result.summary;
  s.method = options.method;
  s.texels = texels;
  s.samples_total = samples.samples.size();
  double rms_sum = 0, iteration_sum = 0;
  size_t lobe_fits = 0;
  for (size_t t = 0; t < texels; ++t) {
    DIGITIZE_CHECK(Finite(result.params[t]) && std::isfinite(result.rms_error[t]),
                   "non-finite BRDF fit output at texel " + std::to_string(t));
    DIGITIZE_CHECK(result.ggx[t].rho_d.allFinite() && result.ggx[t].f0.allFinite() &&
                       std::isfinite(result.ggx[t].alpha),
                   "non-finite GGX fit output at texel " + std::to_string(t));
    ++s.count_by_status[static_cast<size_t>(result.status[t])];
    if (result.status[t] != TexelFitStatus::kDiffuseOnly &&
        result.status[t] != TexelFitStatus::kTooFewSamples &&
        result.status[t] != TexelFitStatus::kFailed)
      ++s.lobes_by_model[static_cast<size_t>(result.model[t])];
    s.samples_used += used[t];
    s.samples_saturated += saturated[t];
    rms_sum += result.rms_error[t];
    if (iterations[t] > 0) {
      iteration_sum += iterations[t];
      ++lobe_fits;
    }
  }
  s.mean_rms_error = texels > 0 ? rms_sum / static_cast<double>(texels) : 0.0;
  s.mean_iterations = lobe_fits > 0 ? iteration_sum / static_cast<double>(lobe_fits) : 0.0;
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ReportProgress(progress, "fit", 1.0);
  return result;
}

}  // namespace digitize
