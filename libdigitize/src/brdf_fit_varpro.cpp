// The fast path of the per-texel fit: variable projection (the linear unknowns solved in closed
// form for every lobe shape, brdf_fit_problem.h) and bounded Levenberg-Marquardt on the lobe
// shape (cx, cy, log k) with Kaufman's projected Gauss-Newton matrix.
#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <cmath>
#include <utility>

#include "brdf_fit_problem.h"
#include "brdf_fit_solvers.h"

namespace digitize::brdf_detail {
namespace {

// Relative cost decrease, step size and projected gradient below which the fast LM stops
// (Ceres' own defaults for function/parameter tolerance, so both paths stop alike).
constexpr double kFunctionTolerance = 1e-6;
constexpr double kParameterTolerance = 1e-8;
constexpr double kGradientTolerance = 1e-10;

}  // namespace

// Gauss-Newton system of the reduced problem at the current g and derivatives: gradient
// J^T r (exact for the reduced cost: the residual is orthogonal to the free linear columns at
// their optimum) and Kaufman's projected J^T J = J^T (I - P_Phi) J, where Phi holds the
// columns of the free linear unknowns (the unprojected J^T J overestimates the curvature and
// slows LM), computed as V - Q^T M^-1 Q from sums (one pass per channel).
// A channel whose b sits on the energy bound b_max(k) has b = b_max(t), so its residual also
// moves with t through b: the extra column e g db_max/dt.
void TexelProblem::NormalEquations(const LinearFit& fit, const std::array<ChannelSums, 3>& sums,
                                   const Shape& shape, Eigen::Matrix3d* jtj, Eigen::Vector3d* jtr) {
  jtj->setZero();
  jtr->setZero();
  const double dbmax_dt = max_specular_albedo_ * k_ / (2.0 * kPi);
  const float* g_ptr = Slot(kG);
  const float* d_ptr[3] = {Slot(kD), Slot(kD + 1), Slot(kD + 2)};
  // Pass 1, channels folded: V = sum_s (sum_c b_c^2 e_c^2) dg dg^T (6 sums) and the b dg part
  // of J^T r = sum_s dg sum_c b_c e_c r_c (3 sums).
  float af[3], bf[3];
  for (int c = 0; c < 3; ++c) {
    af[c] = static_cast<float>(fit.channel[c].a);
    bf[c] = static_cast<float>(fit.channel[c].b);
  }
  Block v[6], er[3];
  for (Block& x : v) x.setZero();
  for (Block& x : er) x.setZero();
  for (int i = 0; i < np_; i += kBlock) {
    const Block g = Block::Map(g_ptr + i);
    Block wv = Block::Zero(), wr = Block::Zero();
    for (int c = 0; c < 3; ++c) {
      if (bf[c] <= 0.0f)
        continue;  // no lobe in this channel: its residual does not depend on theta
      const Block e = Block::Map(Slot(kE + c) + i);
      wv += (bf[c] * bf[c]) * Block::Map(Slot(kE2 + c) + i);
      wr += bf[c] * e * (e * (af[c] + bf[c] * g) - Block::Map(Slot(kL + c) + i));
    }
    const Block d0 = Block::Map(d_ptr[0] + i), d1 = Block::Map(d_ptr[1] + i),
                d2 = Block::Map(d_ptr[2] + i);
    const Block wd0 = wv * d0, wd1 = wv * d1;
    v[0] += wd0 * d0;
    v[1] += wd0 * d1;
    v[2] += wd0 * d2;
    v[3] += wd1 * d1;
    v[4] += wd1 * d2;
    v[5] += wv * d2 * d2;
    er[0] += wr * d0;
    er[1] += wr * d1;
    er[2] += wr * d2;
  }
  const int index[3][3] = {{0, 1, 2}, {1, 3, 4}, {2, 4, 5}};
  for (int i = 0; i < 3; ++i) {
    (*jtr)[i] = er[i].sum();
    for (int j = 0; j < 3; ++j) (*jtj)(i, j) = v[index[i][j]].sum();
  }
  // Pass 2, per channel with a lobe: t = sum e^2 dg, u = sum e^2 g dg for the projection.
  for (int c = 0; c < 3; ++c) {
    const ChannelFit& f = fit.channel[c];
    const double b = f.b;
    if (b <= 0.0) continue;
    const ChannelSums& m = sums[c];
    const float* e2_ptr = Slot(kE2 + c);
    Block t[3], u[3];
    for (Block& x : t) x.setZero();
    for (Block& x : u) x.setZero();
    for (int i = 0; i < np_; i += kBlock) {
      const Block e2 = Block::Map(e2_ptr + i), e2g = e2 * Block::Map(g_ptr + i);
      for (int j = 0; j < 3; ++j) {
        const Block dj = Block::Map(d_ptr[j] + i);
        t[j] += e2 * dj;
        u[j] += e2g * dj;
      }
    }
    // Column j of this channel's Jacobian is e w_j, w_j = b dg_j (+ beta g for t when b sits
    // on b_max(t)): scale the sums by b and add the beta terms.
    const double beta = f.b_at_max ? dbmax_dt : 0.0;
    Eigen::Vector3d tj, uj;
    for (int j = 0; j < 3; ++j) {
      tj[j] = b * t[j].sum();
      uj[j] = b * u[j].sum();
    }
    const double s2_data = m.s2 - Ridge(k_);  // the ridge row is not a sample
    Eigen::Matrix3d vv = Eigen::Matrix3d::Zero();
    if (beta > 0.0) {
      const Eigen::Vector3d et(0.0, 0.0, 1.0);
      vv += beta * (uj * et.transpose() + et * uj.transpose()) +
            beta * beta * s2_data * et * et.transpose();
      tj[2] += beta * m.s1;
      uj[2] += beta * s2_data;
      (*jtr)[2] += beta * (f.a * m.s1 + b * s2_data - m.p1);  // sum e g r
    }
    // Projection onto the complement of the free linear columns: subtract Q^T M^-1 Q,
    // Q = Phi^T (e w), M = Phi^T Phi.
    const bool a_free = f.a > 0.0, b_free = !f.b_at_max;
    const double det = m.s0 * m.s2 - m.s1 * m.s1;
    if (a_free && b_free && det > 1e-12 * m.s0 * m.s2 && det > 0.0) {
      vv -= (m.s2 * tj * tj.transpose() - m.s1 * (tj * uj.transpose() + uj * tj.transpose()) +
             m.s0 * uj * uj.transpose()) /
            det;
    } else if (a_free && m.s0 > 0.0) {
      vv -= tj * tj.transpose() / m.s0;
    } else if (b_free && m.s2 > 0.0) {
      vv -= uj * uj.transpose() / m.s2;
    }
    *jtj += vv;
  }
  // Rounding (float sums, then a difference) can leave the projected matrix a hair
  // indefinite; the diagonal must not go negative (LM's damping takes care of the rest).
  for (int i = 0; i < 3; ++i) (*jtj)(i, i) = std::max((*jtj)(i, i), 0.0);
  // Ridge residuals sqrt(ridge(k)) b_c: d sqrt(ridge) / dt = -sqrt(ridge) k / (k + 2). A channel
  // on the energy bound has ridge b_max^2 constant in t: no term.
  const double ridge = Ridge(k_), dridge_root = -std::sqrt(ridge) * k_ / (k_ + 2.0);
  for (const ChannelFit& f : fit.channel) {
    if (f.b <= 0.0 || f.b_at_max) continue;
    (*jtr)[2] += std::sqrt(ridge) * f.b * dridge_root * f.b;
    (*jtj)(2, 2) += dridge_root * f.b * dridge_root * f.b;
  }
  // Prior residuals sqrt(w2) (c - c0) on cx and cy.
  (*jtj)(0, 0) += prior_w2_;
  (*jtj)(1, 1) += prior_w2_;
  (*jtr)[0] += prior_w2_ * (shape.cx - kPriorC);
  (*jtr)[1] += prior_w2_ * (shape.cy - kPriorC);
}

// Fast path: bounded Levenberg-Marquardt on (cx, cy, log k) of the variable-projection cost.
LobeFitOutcome FitLobeVarPro(TexelProblem& problem, Shape shape, const Bounds& bounds,
                             const BrdfFitOptions& options) {
  const int max_iterations = options.max_iterations;
  LobeFitOutcome out;
  std::array<ChannelSums, 3> sums;
  problem.SetShape(shape, true);
  LinearFit linear = problem.SolveLinear(&sums);
  double sse = problem.Sse(linear);
  double cost = sse + problem.Penalty(shape, linear);
  Eigen::Matrix3d jtj;
  Eigen::Vector3d jtr;
  problem.NormalEquations(linear, sums, shape, &jtj, &jtr);
  double lambda = 1e-4, nu = 2.0;
  int it = 0;
  for (; it < max_iterations; ++it) {
    // Projected-gradient test (as Ceres): the step x - clamp(x - g) vanishes at a bounded optimum.
    const Shape pg = bounds.Clamp({shape.cx - jtr[0], shape.cy - jtr[1], shape.t - jtr[2]});
    const double pg_norm = std::max(
        {std::abs(pg.cx - shape.cx), std::abs(pg.cy - shape.cy), std::abs(pg.t - shape.t)});
    if (pg_norm <= kGradientTolerance) {
      out.converged = true;
      break;
    }
    // Bounds by an active set plus a truncated step: a parameter on a bound whose gradient or
    // step pushes outwards is held there and the damped system is solved for the others; the
    // step is then shortened, as a whole, to the first bound it meets. Clamping each component
    // instead turns the coupling of a clamped parameter into a wrong step for the others (the
    // model can even predict an increase), and LM crawls or stops early.
    const double x[3] = {shape.cx, shape.cy, shape.t};
    const double lo[3] = {bounds.c_lo, bounds.c_lo, bounds.t_lo},
                 hi[3] = {bounds.c_hi, bounds.c_hi, bounds.t_hi};
    bool held[3];
    for (int i = 0; i < 3; ++i)
      held[i] = (x[i] <= lo[i] && jtr[i] > 0.0) || (x[i] >= hi[i] && jtr[i] < 0.0);
    Eigen::Vector3d step = Eigen::Vector3d::Zero();
    for (int pass = 0; pass < 3; ++pass) {
      Eigen::Matrix3d a = jtj;
      Eigen::Vector3d rhs = -jtr;
      for (int i = 0; i < 3; ++i) {
        a(i, i) += lambda * std::clamp(jtj(i, i), 1e-6, 1e32);
        if (held[i]) {
          a.row(i).setZero();
          a.col(i).setZero();
          a(i, i) = 1.0;
          rhs[i] = 0.0;
        }
      }
      step = a.ldlt().solve(rhs);
      bool more = false;
      for (int i = 0; i < 3; ++i)
        if (!held[i] && ((x[i] <= lo[i] && step[i] < 0.0) || (x[i] >= hi[i] && step[i] > 0.0)))
          held[i] = more = true;
      if (!more) break;
    }
    if (!step.allFinite()) {
      out.failed = true;
      break;
    }
    double fraction = 1.0;
    int stop = -1;
    for (int i = 0; i < 3; ++i) {
      if (held[i]) continue;
      if (step[i] == 0.0) continue;
      const double reach = ((step[i] < 0.0 ? lo[i] : hi[i]) - x[i]) / step[i];  // >= 0
      if (reach < fraction) {
        fraction = std::max(0.0, reach);
        stop = i;
      }
    }
    Eigen::Vector3d taken = fraction * step;
    for (int i = 0; i < 3; ++i)
      if (held[i]) taken[i] = 0.0;
    Shape trial{x[0] + taken[0], x[1] + taken[1], x[2] + taken[2]};
    if (stop >= 0) {  // land exactly on the bound it met, so it is seen as active next time
      double* component = stop == 0 ? &trial.cx : stop == 1 ? &trial.cy : &trial.t;
      *component = step[stop] < 0.0 ? lo[stop] : hi[stop];
    }
    trial = bounds.Clamp(trial);
    taken = Eigen::Vector3d(trial.cx - shape.cx, trial.cy - shape.cy, trial.t - shape.t);
    const double x_norm = std::sqrt(shape.cx * shape.cx + shape.cy * shape.cy + shape.t * shape.t);
    // Cost F = sum r^2; its Gauss-Newton model predicts a decrease of -2 g.d - d.H.d. When even
    // that is below the function tolerance there is nothing left to gain (and the float cost
    // could not resolve it anyway).
    const double predicted = -2.0 * jtr.dot(taken) - taken.dot(jtj * taken);
    if (taken.norm() <= kParameterTolerance * (x_norm + kParameterTolerance) ||
        (lambda < 1.0 && predicted <= kFunctionTolerance * cost)) {
      out.converged = true;
      break;
    }
    problem.SetShape(trial, false);
    std::array<ChannelSums, 3> trial_sums;
    const LinearFit trial_linear = problem.SolveLinear(&trial_sums);
    const double trial_sse = problem.Sse(trial_linear);
    const double trial_cost = trial_sse + problem.Penalty(trial, trial_linear);
    if (!std::isfinite(trial_cost)) {
      out.failed = true;
      break;
    }
    if (trial_cost < cost) {
      const double rho = predicted > 0.0 ? (cost - trial_cost) / predicted : 0.0;
      const bool small = cost - trial_cost <= kFunctionTolerance * cost;
      shape = trial;
      linear = trial_linear;
      sums = trial_sums;
      sse = trial_sse;
      cost = trial_cost;
      if (small) {
        out.converged = true;
        ++it;
        break;
      }
      problem.SetDerivatives();  // g is the trial's, now the shape's
      problem.NormalEquations(linear, sums, shape, &jtj, &jtr);
      lambda *= std::max(1.0 / 3.0, 1.0 - std::pow(2.0 * rho - 1.0, 3));
      nu = 2.0;
    } else {
      lambda *= nu;
      nu *= 2.0;
      if (lambda > 1e16) {  // no descent left at any step length: a stationary point
        out.converged = true;
        break;
      }
    }
  }
  out.shape = shape;
  out.linear = linear;
  out.sse = sse;
  out.iterations = it;
  return out;
}

}  // namespace digitize::brdf_detail

namespace digitize::brdf_detail {

// Fast path, GGX: for each alpha the linear unknowns are closed form, so the reduced cost is a
// smooth function of t = log alpha alone, bracketed by the grid; Brent's method (golden section
// with parabolic steps) finds its minimum to kGgxTolerance in a dozen evaluations. Each
// evaluation measures the error directly (GgxSse), not from the sums: their cancellation in
// float hides the last digits that a narrow lobe's (alpha ~0.03) peak height depends on.
GgxFitOutcome FitGgxVarPro(TexelProblem& problem, const GgxStart& start,
                           const BrdfFitOptions& options) {
  constexpr double kGgxTolerance = 2e-4;  // in log alpha: alpha within 0.02 %
  constexpr double kGolden = 0.3819660112501051;
  LinearFit last, at_x;  // the linear part of the last evaluation, and of x
  const auto cost = [&](double t) {
    last = problem.SolveGgx(std::exp(t));
    return problem.GgxSse(last);
  };
  double a = start.bracket_lo, b = start.bracket_hi;
  double x = std::clamp(start.t, a, b), w = x, v = x;
  double fx = cost(x), fw = fx, fv = fx;
  at_x = last;
  double d = 0, e = 0;
  // Inside the grid the bracket ends are the grid's neighbours of x: Brent's two other points,
  // so its first step is the grid's parabola, not a golden section (a step of the bracket's
  // width "before last" lets the parabola be tried).
  if (a < x && x < b && std::isfinite(start.cost_lo) && std::isfinite(start.cost_hi)) {
    w = a, fw = start.cost_lo, v = b, fv = start.cost_hi;
    if (fv < fw) std::swap(w, v), std::swap(fw, fv);
    e = b - a;
  }
  GgxFitOutcome out;
  int it = 0;
  for (; it < options.max_iterations; ++it) {
    const double m = 0.5 * (a + b);
    const double tol = kGgxTolerance, tol2 = 2.0 * tol;
    if (std::abs(x - m) <= tol2 - 0.5 * (b - a)) {
      out.converged = true;
      break;
    }
    bool golden = true;
    if (std::abs(e) > tol) {  // try a parabola through x, w, v
      double r = (x - w) * (fx - fv), q = (x - v) * (fx - fw), p = (x - v) * q - (x - w) * r;
      q = 2.0 * (q - r);
      if (q > 0.0) p = -p;
      q = std::abs(q);
      const double e_prev = e;
      e = d;
      if (std::abs(p) < std::abs(0.5 * q * e_prev) && p > q * (a - x) && p < q * (b - x)) {
        d = p / q;
        const double u = x + d;
        if (u - a < tol2 || b - u < tol2) d = x < m ? tol : -tol;
        golden = false;
      }
    }
    if (golden) {
      e = (x < m ? b : a) - x;
      d = kGolden * e;
    }
    const double u = std::abs(d) >= tol ? x + d : x + (d > 0 ? tol : -tol);
    const double fu = cost(u);
    if (!std::isfinite(fu)) {
      out.failed = true;
      break;
    }
    if (fu <= fx) {
      (u < x ? b : a) = x;
      v = w, fv = fw, w = x, fw = fx, x = u, fx = fu;
      at_x = last;
    } else {
      (u < x ? a : b) = u;
      if (fu <= fw || w == x) {
        v = w, fv = fw, w = u, fw = fu;
      } else if (fu <= fv || v == x || v == w) {
        v = u, fv = fu;
      }
    }
  }
  out.t = std::clamp(x, start.t_lo, start.t_hi);
  // x was evaluated: its fit and error as they came, not a 22nd evaluation. The problem's arrays
  // hold the last evaluation's u and o; FitTexel sets them again for the alpha it keeps.
  if (out.t == x) {
    out.linear = at_x;
    out.sse = fx;
  } else {
    out.linear = problem.SolveGgx(std::exp(out.t));
    out.sse = problem.GgxSse(out.linear);
  }
  out.iterations = it;
  return out;
}

}  // namespace digitize::brdf_detail
