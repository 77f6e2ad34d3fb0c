// The reference path of the per-texel fit: ceres::Solve on the full problem (every unknown
// free, automatic derivatives). The only file of the library that includes Ceres.
#include <ceres/ceres.h>

#include <algorithm>
#include <cmath>

#include "brdf_fit_problem.h"
#include "brdf_fit_solvers.h"
#include "digitize/ggx.h"
#include "digitize/lafortune.h"

namespace digitize::brdf_detail {
namespace {

// One sample's 3 residuals e_c (rho_d,c + rho_s,c g(v, l; cx, cy, k)) - L_c. rho_s enters as
// the fraction s of its energy bound, rho_s = s A (k + 2) / (2 pi) with s in [0, 1]: the same
// feasible set as the fast path's, expressed with box bounds, which is all Ceres takes.
struct LafortuneSampleCost {
  // products = (vx lx, vy ly, vz lz): all the lobe needs of the two directions.
  LafortuneSampleCost(const Vec3f& products, const Vec3f& e, const Vec3f& radiance,
                      double max_albedo)
      : max_albedo_(max_albedo) {
    for (int i = 0; i < 3; ++i) {
      products_[i] = products[i];
      e_[i] = e[i];
      radiance_[i] = radiance[i];
    }
  }
  template <class T>
  bool operator()(const T* rho_d, const T* specular_fraction, const T* lobe, T* residual) const {
    using std::exp;
    static constexpr double kOnes[3] = {1.0, 1.0, 1.0};
    const T k = exp(lobe[2]);
    const T g = LafortuneLobe(lobe[0], lobe[1], T(1.0), k, products_, kOnes);
    const T b_max = T(max_albedo_ / (2.0 * kPi)) * (k + T(2.0));
    for (int c = 0; c < 3; ++c)
      residual[c] = T(e_[c]) * (rho_d[c] + specular_fraction[c] * b_max * g) - T(radiance_[c]);
    return true;
  }
  static ceres::CostFunction* Create(const Vec3f& products, const Vec3f& e, const Vec3f& radiance,
                                     double max_albedo) {
    return new ceres::AutoDiffCostFunction<LafortuneSampleCost, 3, 3, 3, 3>(
        new LafortuneSampleCost(products, e, radiance, max_albedo));
  }
  double products_[3], e_[3], radiance_[3];
  double max_albedo_;
};

// The prior sqrt(w2) (c - c0) on cx, cy.
struct MirrorLobePriorCost {
  explicit MirrorLobePriorCost(double weight) : weight_(weight) {}
  template <class T>
  bool operator()(const T* lobe, T* residual) const {
    residual[0] = T(weight_) * (lobe[0] - T(kPriorC));
    residual[1] = T(weight_) * (lobe[1] - T(kPriorC));
    return true;
  }
  static ceres::CostFunction* Create(double weight) {
    return new ceres::AutoDiffCostFunction<MirrorLobePriorCost, 2, 3>(
        new MirrorLobePriorCost(weight));
  }
  double weight_;
};

// The specular albedo ridge: A_c = s_c A_max, residual sqrt(ridge) A_c (brdf_fit.h).
struct SpecularAlbedoPriorCost {
  explicit SpecularAlbedoPriorCost(double weight) : weight_(weight) {}
  template <class T>
  bool operator()(const T* specular_fraction, T* residual) const {
    for (int c = 0; c < 3; ++c) residual[c] = T(weight_) * specular_fraction[c];
    return true;
  }
  static ceres::CostFunction* Create(double weight) {
    return new ceres::AutoDiffCostFunction<SpecularAlbedoPriorCost, 3, 3>(
        new SpecularAlbedoPriorCost(weight));
  }
  double weight_;
};

// One sample's 3 residuals of the GGX model, e_c (rho_d,c + GgxSpecular(F0_c, alpha)) - L_c with
// alpha = exp(t): the very function the renderers use (ggx.h). e and L carry the noise weights
// (brdf_fit_problem.h), as on the fast path.
struct GgxSampleCost {
  GgxSampleCost(const Vec3f& v, const Vec3f& l, const Vec3f& e, const Vec3f& radiance) {
    for (int i = 0; i < 3; ++i) {
      v_[i] = v[i];
      l_[i] = l[i];
      e_[i] = e[i];
      radiance_[i] = radiance[i];
    }
  }
  template <class T>
  bool operator()(const T* rho_d, const T* f0, const T* log_alpha, T* residual) const {
    using std::exp;
    const T alpha = exp(log_alpha[0]);
    for (int c = 0; c < 3; ++c)
      residual[c] = T(e_[c]) * (rho_d[c] + GgxSpecular(f0[c], alpha, v_, l_)) - T(radiance_[c]);
    return true;
  }
  static ceres::CostFunction* Create(const Vec3f& v, const Vec3f& l, const Vec3f& e,
                                     const Vec3f& radiance) {
    return new ceres::AutoDiffCostFunction<GgxSampleCost, 3, 3, 3, 1>(
        new GgxSampleCost(v, l, e, radiance));
  }
  double v_[3], l_[3], e_[3], radiance_[3];
};

ceres::Solver::Options ReferenceSolverOptions(int max_iterations) {
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.minimizer_type = ceres::TRUST_REGION;
  so.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  so.max_num_iterations = max_iterations;
  so.num_threads = 1;  // parallel over texels instead
  so.logging_type = ceres::SILENT;
  so.minimizer_progress_to_stdout = false;
  return so;
}

}  // namespace

GgxFitOutcome FitGgxCeres(TexelProblem& problem, const GgxStart& start,
                          const BrdfFitOptions& options) {
  const double t0 = std::clamp(start.t, start.t_lo, start.t_hi);
  const LinearFit init = problem.SolveGgx(std::exp(t0));
  double rho_d[3], f0[3], log_alpha[1] = {t0};
  for (int c = 0; c < 3; ++c) {
    rho_d[c] = init.channel[c].a;
    f0[c] = std::clamp(init.channel[c].b, 0.0, 1.0);
  }
  ceres::Problem cp;
  for (int i = 0; i < problem.n(); ++i)
    cp.AddResidualBlock(GgxSampleCost::Create(problem.ViewDir(i), problem.LightDir(i),
                                              problem.Irradiance(i), problem.Radiance(i)),
                        nullptr, rho_d, f0, log_alpha);
  for (int c = 0; c < 3; ++c) {
    cp.SetParameterLowerBound(rho_d, c, 0.0);
    cp.SetParameterLowerBound(f0, c, 0.0);
    cp.SetParameterUpperBound(f0, c, 1.0);
  }
  cp.SetParameterLowerBound(log_alpha, 0, start.t_lo);
  cp.SetParameterUpperBound(log_alpha, 0, start.t_hi);
  ceres::Solver::Summary summary;
  ceres::Solve(ReferenceSolverOptions(options.max_iterations), &cp, &summary);

  GgxFitOutcome out;
  out.iterations = static_cast<int>(summary.iterations.size());
  out.converged = summary.termination_type == ceres::CONVERGENCE;
  out.failed = !summary.IsSolutionUsable();
  out.t = std::clamp(log_alpha[0], start.t_lo, start.t_hi);
  problem.SolveGgx(std::exp(out.t));  // sets u, o for the error kernel
  for (int c = 0; c < 3; ++c)
    out.linear.channel[c] = {std::max(0.0, rho_d[c]), std::clamp(f0[c], 0.0, 1.0), false};
  out.sse = problem.GgxSse(out.linear);
  return out;
}

LobeFitOutcome FitLobeCeres(TexelProblem& problem, Shape shape, const Bounds& bounds,
                            const BrdfFitOptions& options) {
  const int max_iterations = options.max_iterations;
  const double max_albedo = options.max_specular_albedo;
  problem.SetShape(shape, false);
  const LinearFit init = problem.SolveLinear();
  double rho_d[3], rho_s[3], lobe[3] = {shape.cx, shape.cy, shape.t};  // rho_s: fraction of b_max
  for (int c = 0; c < 3; ++c) {
    rho_d[c] = init.channel[c].a;
    rho_s[c] = std::clamp(init.channel[c].b / problem.BMax(), 0.0, 1.0);
  }
  ceres::Problem cp;
  for (int i = 0; i < problem.n(); ++i)
    cp.AddResidualBlock(LafortuneSampleCost::Create(problem.Products(i), problem.Irradiance(i),
                                                    problem.Radiance(i), max_albedo),
                        nullptr, rho_d, rho_s, lobe);
  if (problem.prior_w2() > 0.0)
    cp.AddResidualBlock(MirrorLobePriorCost::Create(std::sqrt(problem.prior_w2())), nullptr, lobe);
  if (problem.albedo_ridge() > 0.0)
    cp.AddResidualBlock(
        SpecularAlbedoPriorCost::Create(std::sqrt(problem.albedo_ridge()) * max_albedo), nullptr,
        rho_s);
  for (int c = 0; c < 3; ++c) {
    cp.SetParameterLowerBound(rho_d, c, 0.0);
    cp.SetParameterLowerBound(rho_s, c, 0.0);
    cp.SetParameterUpperBound(rho_s, c, 1.0);
  }
  for (int i = 0; i < 2; ++i) {
    cp.SetParameterLowerBound(lobe, i, bounds.c_lo);
    cp.SetParameterUpperBound(lobe, i, bounds.c_hi);
  }
  cp.SetParameterLowerBound(lobe, 2, bounds.t_lo);
  cp.SetParameterUpperBound(lobe, 2, bounds.t_hi);

  ceres::Solver::Summary summary;
  ceres::Solve(ReferenceSolverOptions(max_iterations), &cp, &summary);

  LobeFitOutcome out;
  out.iterations = static_cast<int>(summary.iterations.size());
  out.converged = summary.termination_type == ceres::CONVERGENCE;
  out.failed = !summary.IsSolutionUsable();
  out.shape = bounds.Clamp({lobe[0], lobe[1], lobe[2]});
  // The error is measured by the same kernel as on the fast path, so both report alike.
  problem.SetShape(out.shape, false);
  for (int c = 0; c < 3; ++c)
    out.linear.channel[c] = {std::max(0.0, rho_d[c]),
                             std::clamp(rho_s[c], 0.0, 1.0) * problem.BMax(), false};
  out.sse = problem.Sse(out.linear);
  return out;
}

}  // namespace digitize::brdf_detail
