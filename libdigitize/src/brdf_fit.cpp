// Per-texel one-lobe Lafortune fit: the shared front end (sample filtering, diffuse-only test,
// coarse grid), the fast variable-projection path, and the ceres::Solve reference path.
//
// Notation inside: per texel, N valid samples; per sample s the products ax = vx lx, ay = vy ly,
// az = vz lz (the lobe base is cx ax + cy ay + az), per channel c the irradiance e_c and the
// radiance L_c. For a lobe shape theta = (cx, cy, t = log k) the lobe factor is g_s; the model is
// e_c (a_c + b_c g) with a = rho_d, b = rho_s. The objective, identical on both paths, is
//   F = sum_{s,c} (e_c (a_c + b_c g_s) - L_c)^2 + w2 ((cx + 1)^2 + (cy + 1)^2),
// w2 = lobe_prior_weight^2 * N * (mean L^2): the prior (see brdf_fit.h).
#include "digitize/brdf_fit.h"

#include <ceres/ceres.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

namespace digitize {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kPriorC = -1.0;  // the mirror lobe (cx = cy = -1) the prior pulls towards
// Relative cost decrease, step size and projected gradient below which the fast LM stops
// (Ceres' own defaults for function/parameter tolerance, so both paths stop alike).
constexpr double kFunctionTolerance = 1e-6;
constexpr double kParameterTolerance = 1e-8;
constexpr double kGradientTolerance = 1e-10;
// Grid spacing of the initial search over k (then refined by a parabola): a factor 4 keeps every
// lobe within a factor 2 of a grid point, close enough for LM to start in the right basin even
// for narrow lobes (a factor 2 grid gave the same relighting error at twice the grid cost).
constexpr double kGridFactor = 4.0;
// Lobe exponents (k log base) below this give g = 0 (see SetExponent); kLogZero marks a clamped
// base: times any k >= 0.5 it is far below kMinLobeLog, and finite.
constexpr float kMinLobeLog = -40.0f;
constexpr float kLogZero = -1e30f;
// Texels per parallel task: large enough to amortise the workspace, small enough to balance.
constexpr size_t kTexelGrain = 64;

using ArrayMap = Eigen::Map<Eigen::ArrayXf>;

// Per-thread storage for one texel's samples as arrays (structure of arrays, so Eigen
// vectorises every pass over the samples, exp and log included). Capacity grows, never shrinks.
class Workspace {
 public:
  static constexpr int kArrays = 26;
  float* Reserve(int n) {
    if (n > capacity_) {
      capacity_ = std::max(n, 2 * capacity_);
      storage_.assign(static_cast<size_t>(capacity_) * kArrays, 0.0f);
    }
    return storage_.data();
  }
  int capacity() const { return capacity_; }

 private:
  std::vector<float> storage_;
  int capacity_ = 0;
};

// Closed-form least squares of one channel for a fixed lobe: min over a >= 0, 0 <= b <= b_max
// of sum (e (a + b g) - L)^2, from the sums s0 = sum e^2, s1 = sum e^2 g, s2 = sum e^2 g^2,
// p0 = sum e L, p1 = sum e L g (ll = sum L^2 only for reporting costs).
struct ChannelSums {
  double s0 = 0, s1 = 0, s2 = 0, p0 = 0, p1 = 0, ll = 0;
};
struct ChannelFit {
  double a = 0, b = 0;
  bool b_at_max = false;  // b sits on the energy bound b_max(k)
};

// Cost from the sums, up to the constant ll (exact enough to compare candidates; the grid adds ll).
double QuadraticCost(const ChannelSums& m, double a, double b) {
  return -2.0 * (a * m.p0 + b * m.p1) + a * a * m.s0 + 2.0 * a * b * m.s1 + b * b * m.s2;
}

ChannelFit SolveChannel(const ChannelSums& m, double b_max) {
  const double det = m.s0 * m.s2 - m.s1 * m.s1;
  // Interior solution when the 2x2 system is well conditioned (the lobe column is not a
  // multiple of the diffuse one) and it is feasible.
  if (det > 1e-9 * m.s0 * m.s2 && det > 0.0) {
    const double a = (m.s2 * m.p0 - m.s1 * m.p1) / det;
    const double b = (m.s0 * m.p1 - m.s1 * m.p0) / det;
    if (a >= 0.0 && b >= 0.0 && b <= b_max) return {a, b, false};
  }
  // Otherwise the optimum lies on an edge of the feasible box (the objective is convex): the
  // best of each edge's clamped 1-D optimum. Ties (collinear columns) go to diffuse only.
  const double a_only = m.s0 > 0.0 ? std::max(0.0, m.p0 / m.s0) : 0.0;
  const double b_only = m.s2 > 0.0 ? std::clamp(m.p1 / m.s2, 0.0, b_max) : 0.0;
  const double a_at_max = m.s0 > 0.0 ? std::max(0.0, (m.p0 - b_max * m.s1) / m.s0) : 0.0;
  ChannelFit best{a_only, 0.0, false};
  double best_cost = QuadraticCost(m, a_only, 0.0);
  const double slack = 1e-12 * (std::abs(best_cost) + m.ll);
  if (const double c = QuadraticCost(m, 0.0, b_only); c < best_cost - slack) {
    best = {0.0, b_only, b_only >= b_max};
    best_cost = c;
  }
  if (b_max > 0.0)
    if (const double c = QuadraticCost(m, a_at_max, b_max); c < best_cost - slack)
      best = {a_at_max, b_max, true};
  return best;
}

struct Shape {
  double cx = kPriorC, cy = kPriorC, t = 0;  // t = log k
};

struct LinearFit {
  std::array<ChannelFit, 3> channel;
  bool any_lobe() const { return channel[0].b > 0 || channel[1].b > 0 || channel[2].b > 0; }
};

// One texel's valid samples and the kernels both paths share. Arrays live in the workspace
// (slots below), padded with zero samples to a multiple of kBlock: a zero irradiance and zero
// direction products make a padded sample contribute exactly 0 to every sum, so the kernels run
// whole blocks of 8 floats that Eigen maps onto SIMD registers, several sums per pass.
class TexelProblem {
 public:
  static constexpr int kBlock = 8;
  using Block = Eigen::Array<float, kBlock, 1>;

  TexelProblem(std::span<const BrdfSample> samples, const BrdfFitOptions& options, Workspace& ws) {
    const int padded_max = static_cast<int>((samples.size() + kBlock - 1) / kBlock * kBlock);
    p_ = ws.Reserve(std::max(kBlock, padded_max));
    cap_ = ws.capacity();
    const double saturation = options.saturation_radiance;
    for (const BrdfSample& s : samples) {
      if (!(s.view_dir.allFinite() && s.light_dir.allFinite() && s.radiance.allFinite() &&
            s.irradiance.allFinite()))
        continue;
      if ((s.irradiance.array() < 0.0f).any() || !(s.irradiance.maxCoeff() > 0.0f)) continue;
      Vec3f v = s.view_dir, l = s.light_dir;
      // Tolerate slightly non-unit input (the lobe is not scale invariant); the check first
      // because two divisions per sample are a visible part of a 5 us fit.
      const float vn2 = v.squaredNorm(), ln2 = l.squaredNorm();
      if (!(vn2 > 0.0f && ln2 > 0.0f)) continue;
      if (std::abs(vn2 - 1.0f) > 1e-6f) v /= std::sqrt(vn2);
      if (std::abs(ln2 - 1.0f) > 1e-6f) l /= std::sqrt(ln2);
      if (!(v.z() > 0.0f && l.z() > 0.0f)) continue;
      if (s.radiance.maxCoeff() >= saturation) {
        ++saturated_;
        continue;
      }
      const int i = n_++;
      Slot(kAx)[i] = v.x() * l.x();
      Slot(kAy)[i] = v.y() * l.y();
      Slot(kAz)[i] = v.z() * l.z();
      for (int c = 0; c < 3; ++c) {
        Slot(kE + c)[i] = s.irradiance[c];
        Slot(kL + c)[i] = s.radiance[c];
      }
    }
    np_ = std::max(kBlock, (n_ + kBlock - 1) / kBlock * kBlock);
    for (int slot = kAx; slot < kE2; ++slot) std::fill(Slot(slot) + n_, Slot(slot) + np_, 0.0f);
    for (int c = 0; c < 3; ++c) {
      e2(c) = e(c).square();
      el(c) = e(c) * L(c);
      sums_[c].s0 = e2(c).sum();
      sums_[c].p0 = el(c).sum();
      sums_[c].ll = L(c).square().sum();
    }
    const double mean_square =
        n_ > 0 ? (sums_[0].ll + sums_[1].ll + sums_[2].ll) / (3.0 * n_) : 0.0;
    prior_w2_ = options.lobe_prior_weight * options.lobe_prior_weight * n_ * mean_square;
    max_specular_albedo_ = options.max_specular_albedo;
    // w sigma^2 per (specular albedo / 0.1)^2 per channel; see brdf_fit.h.
    albedo_ridge_ =
        options.specular_prior_weight * options.noise_sigma * options.noise_sigma / (0.1 * 0.1);
  }

  int n() const { return n_; }
  int saturated() const { return saturated_; }
  double prior_w2() const { return prior_w2_; }
  double albedo_ridge() const { return albedo_ridge_; }
  // The per-sample data as the reference path's cost functors take it.
  Vec3f Products(int i) const { return {Slot(kAx)[i], Slot(kAy)[i], Slot(kAz)[i]}; }
  Vec3f Irradiance(int i) const { return {Slot(kE)[i], Slot(kE + 1)[i], Slot(kE + 2)[i]}; }
  Vec3f Radiance(int i) const { return {Slot(kL)[i], Slot(kL + 1)[i], Slot(kL + 2)[i]}; }

  // rho_d only, per channel a = max(0, p0 / s0); returns the squared error.
  double FitDiffuse(LinearFit* fit) {
    double sse = 0;
    for (int c = 0; c < 3; ++c) {
      fit->channel[c] = {sums_[c].s0 > 0.0 ? std::max(0.0, sums_[c].p0 / sums_[c].s0) : 0.0, 0.0};
      sse += (e(c) * static_cast<float>(fit->channel[c].a) - L(c)).square().sum();
    }
    return sse;
  }

  // The base for (cx, cy), clamped below at kLobeBaseEps, and its log, kLogZero where the base
  // is clamped (so the lobe there comes out exactly 0 for every k).
  void SetLobeDirection(double cx, double cy) {
    base() = (static_cast<float>(cx) * View(kAx) + static_cast<float>(cy) * View(kAy) + View(kAz));
    log_base() = (base() > kLobeBaseEps).select(base().max(kLobeBaseEps).log(), kLogZero);
    base() = base().max(kLobeBaseEps);
  }
  // g (and dg/dcx, dg/dcy, dg/dt with t = log k) for the direction set last. The exponent is
  // <= 0 here up to rounding (|cx|, |cy| <= 1 keeps the base <= 1). Lobe values below
  // exp(kMinLobeLog) ~ 4e-18 of the peak are set to 0: they change nothing, and left in, their
  // squares and products are float denormals, which cost ~100 cycles each on x86 and made the
  // whole fit several times slower.
  void SetExponent(double k, bool derivatives) {
    k_ = k;
    const float kf = static_cast<float>(k);
    tmp() = kf * log_base();
    g() = (tmp() > kMinLobeLog).select(tmp().max(kMinLobeLog).min(kMaxLobeLog).exp(), 0.0f);
    if (!derivatives) return;
    tmp() = kf * g() / base();  // dg/dc = k g / base * dbase/dc
    d(0) = tmp() * View(kAx);
    d(1) = tmp() * View(kAy);
    d(2) = kf * g() *
           log_base().max(kMinLobeLog);  // dg/dt = k dg/dk = k g log(base); g = 0 where clamped
  }
  void SetShape(const Shape& s, bool derivatives) {
    SetLobeDirection(s.cx, s.cy);
    SetExponent(std::exp(s.t), derivatives);
  }

  // Energy bound on rho_s for the current k: the lobe's reflected fraction at normal view,
  // rho_s * integral of z^k z over the hemisphere = rho_s 2 pi / (k + 2), at most A.
  double BMax() const { return max_specular_albedo_ * (k_ + 2.0) / (2.0 * kPi); }
  // Ridge on rho_s for exponent k: the albedo ridge on A = rho_s 2 pi / (k + 2), per rho_s^2.
  double Ridge(double k) const {
    const double to_albedo = 2.0 * kPi / (k + 2.0);
    return albedo_ridge_ * to_albedo * to_albedo;
  }
  // Both priors: the lobe direction's and the specular albedo's.
  double Penalty(const Shape& s, const LinearFit& fit) const {
    double b2 = 0;
    for (const ChannelFit& f : fit.channel) b2 += f.b * f.b;
    return prior_w2_ * ((s.cx - kPriorC) * (s.cx - kPriorC) + (s.cy - kPriorC) * (s.cy - kPriorC)) +
           Ridge(std::exp(s.t)) * b2;
  }

  // Variable projection: the best (a, b) per channel for the current g, and the sums it used
  // (s2 including the ridge). One pass per channel for s1, s2, p1.
  LinearFit SolveLinear(std::array<ChannelSums, 3>* sums_out = nullptr) {
    LinearFit fit;
    const float* g_ptr = Slot(kG);
    for (int c = 0; c < 3; ++c) {
      const float* e2_ptr = Slot(kE2 + c);
      const float* el_ptr = Slot(kEL + c);
      Block s1 = Block::Zero(), s2 = Block::Zero(), p1 = Block::Zero();
      for (int i = 0; i < np_; i += kBlock) {
        const Block g = Block::Map(g_ptr + i), w = Block::Map(e2_ptr + i) * g;
        s1 += w;
        s2 += w * g;
        p1 += Block::Map(el_ptr + i) * g;
      }
      ChannelSums m = sums_[c];
      m.s1 = s1.sum();
      m.s2 =
          s2.sum() + Ridge(k_);  // the ridge is one more (fake) residual sqrt(ridge) b per channel
      m.p1 = p1.sum();
      fit.channel[c] = SolveChannel(m, BMax());
      if (sums_out) (*sums_out)[c] = m;
    }
    return fit;
  }

  // Exact squared error of the model for the current g (direct, no cancellation), one pass.
  double Sse(const LinearFit& fit) {
    const float* g_ptr = Slot(kG);
    float a[3], b[3];
    for (int c = 0; c < 3; ++c) {
      a[c] = static_cast<float>(fit.channel[c].a);
      b[c] = static_cast<float>(fit.channel[c].b);
    }
    Block acc = Block::Zero();
    for (int i = 0; i < np_; i += kBlock) {
      const Block g = Block::Map(g_ptr + i);
      for (int c = 0; c < 3; ++c)
        acc += (Block::Map(Slot(kE + c) + i) * (a[c] + b[c] * g) - Block::Map(Slot(kL + c) + i))
                   .square();
    }
    return acc.sum();
  }

  // Gauss-Newton system of the reduced problem at the current g and derivatives: gradient
  // J^T r (exact for the reduced cost: the residual is orthogonal to the free linear columns at
  // their optimum) and Kaufman's projected J^T J = J^T (I - P_Phi) J, where Phi holds the
  // columns of the free linear unknowns (the unprojected J^T J overestimates the curvature and
  // slows LM), computed as V - Q^T M^-1 Q from sums (one pass per channel).
  // A channel whose b sits on the energy bound b_max(k) has b = b_max(t), so its residual also
  // moves with t through b: the extra column e g db_max/dt.
  void NormalEquations(const LinearFit& fit, const std::array<ChannelSums, 3>& sums,
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

 private:
  // Workspace slots: sample data, then scratch.
  enum : int {
    kAx = 0,
    kAy,
    kAz,
    kE,
    kL = kE + 3,
    kE2 = kL + 3,
    kEL = kE2 + 3,
    kLogBase = kEL + 3,
    kG,
    kD,
    kBase = kD + 3,
    kTmp,
    kSlots
  };
  static_assert(kSlots <= Workspace::kArrays);
  float* Slot(int i) { return p_ + static_cast<size_t>(i) * cap_; }
  const float* Slot(int i) const { return p_ + static_cast<size_t>(i) * cap_; }
  ArrayMap View(int i) { return ArrayMap(Slot(i), np_); }
  ArrayMap e(int c) { return View(kE + c); }
  ArrayMap L(int c) { return View(kL + c); }
  ArrayMap e2(int c) { return View(kE2 + c); }
  ArrayMap el(int c) { return View(kEL + c); }
  ArrayMap log_base() { return View(kLogBase); }
  ArrayMap g() { return View(kG); }
  ArrayMap d(int j) { return View(kD + j); }  // dg/dcx, dg/dcy, dg/dt
  ArrayMap base() { return View(kBase); }
  ArrayMap tmp() { return View(kTmp); }

  float* p_ = nullptr;
  int cap_ = 0;
  int n_ = 0;   // valid samples
  int np_ = 0;  // padded length of every array, a multiple of kBlock
  int saturated_ = 0;
  double prior_w2_ = 0;
  double albedo_ridge_ = 0;
  double max_specular_albedo_ = 1;
  double k_ = 1;  // exponent of the current g
  std::array<ChannelSums, 3> sums_;
};

struct Bounds {
  double c_lo = -1.0, c_hi = 1.0, t_lo = 0, t_hi = 0;
  Shape Clamp(Shape s) const {
    s.cx = std::clamp(s.cx, c_lo, c_hi);
    s.cy = std::clamp(s.cy, c_lo, c_hi);
    s.t = std::clamp(s.t, t_lo, t_hi);
    return s;
  }
};

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

struct LobeFitOutcome {
  Shape shape;
  LinearFit linear;
  double sse = 0;
  int iterations = 0;
  bool converged = false;
  bool failed = false;
};

// Fast path: bounded Levenberg-Marquardt on (cx, cy, log k) of the variable-projection cost.
LobeFitOutcome FitLobeFast(TexelProblem& problem, Shape shape, const Bounds& bounds,
                           int max_iterations) {
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
      problem.SetShape(shape, true);
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

// ---------------------------------------------------------------------------------------------
// Reference path: ceres::Solve on the full problem.

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

LobeFitOutcome FitLobeCeres(TexelProblem& problem, Shape shape, const Bounds& bounds,
                            int max_iterations, double max_albedo) {
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

  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.minimizer_type = ceres::TRUST_REGION;
  so.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  so.max_num_iterations = max_iterations;
  so.num_threads = 1;  // parallel over texels instead
  so.logging_type = ceres::SILENT;
  so.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &cp, &summary);

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

// ---------------------------------------------------------------------------------------------

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

TexelFit FitTexel(std::span<const BrdfSample> samples, const BrdfFitOptions& options,
                  Workspace& ws) {
  TexelProblem problem(samples, options, ws);
  TexelFit out;
  out.samples_used = problem.n();
  out.samples_saturated = problem.saturated();
  LinearFit diffuse;
  const double diffuse_sse = problem.FitDiffuse(&diffuse);
  out.params = DiffuseParams(diffuse, options.k_min);
  out.rms_error = Rms(diffuse_sse, problem.n());
  if (problem.n() < options.min_samples) {
    out.status = TexelFitStatus::kTooFewSamples;
    return out;
  }
  // Chi-square test: with Gaussian noise sigma, the squared error of a right model over
  // dof = 3N - 3 residuals has mean dof sigma^2 and std sqrt(2 dof) sigma^2.
  const double dof = 3.0 * problem.n() - 3.0;
  const double sigma2 = options.noise_sigma * options.noise_sigma;
  if (options.diffuse_chi2_sigmas >= 0.0 &&
      diffuse_sse <= sigma2 * (dof + options.diffuse_chi2_sigmas * std::sqrt(2.0 * dof))) {
    out.status = TexelFitStatus::kDiffuseOnly;
    return out;
  }
  const Bounds bounds{-1.0, 1.0, std::log(options.k_min), std::log(options.k_max)};
  const Shape init = GridInit(problem, bounds);
  const LobeFitOutcome lobe =
      options.method == BrdfFitMethod::kCeresReference
          ? FitLobeCeres(problem, init, bounds, options.max_iterations, options.max_specular_albedo)
          : FitLobeFast(problem, init, bounds, options.max_iterations);
  out.iterations = lobe.iterations;
  LafortuneParams p;
  for (int c = 0; c < 3; ++c) {
    p.rho_d[c] = static_cast<float>(lobe.linear.channel[c].a);
    p.rho_s[c] = static_cast<float>(lobe.linear.channel[c].b);
  }
  p.cx = static_cast<float>(lobe.shape.cx);
  p.cy = static_cast<float>(lobe.shape.cy);
  p.cz = 1.0f;
  p.k = static_cast<float>(std::exp(lobe.shape.t));
  if (lobe.failed || !Finite(p) || !std::isfinite(lobe.sse)) {
    out.status = TexelFitStatus::kFailed;  // keeps the diffuse fallback set above
    return out;
  }
  if (lobe.sse > diffuse_sse * (1.0 + 1e-5) + 1e-30) {
    // Cannot happen for a true minimiser (the diffuse fit is a feasible point with no penalty;
    // the slack is float rounding of two sums); a solver that ends worse is not trusted.
    out.status = TexelFitStatus::kFailed;
    return out;
  }
  out.rms_error = Rms(lobe.sse, problem.n());
  if (!lobe.linear.any_lobe()) {
    out.params = DiffuseParams(lobe.linear, options.k_min);
    out.status = TexelFitStatus::kDiffuseOnly;
    return out;
  }
  out.params = p;
  const double t_tolerance = 1e-4;  // in log k: k within 0.01 % of a bound
  if (lobe.shape.t <= bounds.t_lo + t_tolerance || lobe.shape.t >= bounds.t_hi - t_tolerance)
    out.status = TexelFitStatus::kClampedK;
  else if (!lobe.converged)
    out.status = TexelFitStatus::kIterationLimit;
  else
    out.status = TexelFitStatus::kConverged;
  return out;
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
    return Error{"noise_sigma must be finite and >= 0 (radiance units), got " + FormatNumber(noise_sigma)};
  if (std::isnan(diffuse_chi2_sigmas) || std::isinf(diffuse_chi2_sigmas))
    return Error{"diffuse_chi2_sigmas must be finite (standard deviations; < 0 disables), got " +
                 FormatNumber(diffuse_chi2_sigmas)};
  if (!(saturation_radiance > 0.0))
    return Error{"saturation_radiance must be > 0 (radiance units; +inf = no clipping), got " +
                 FormatNumber(saturation_radiance)};
  if (!(std::isfinite(k_min) && k_min >= 0.5))
    return Error{"k_min must be finite and >= 0.5 (lobe exponent), got " + FormatNumber(k_min)};
  if (!(std::isfinite(k_max) && k_max > k_min && k_max <= 1e6))
    return Error{"k_max must be finite, > k_min and <= 1e6 (lobe exponent), got " + FormatNumber(k_max)};
  if (!(std::isfinite(max_specular_albedo) && max_specular_albedo > 0.0))
    return Error{"max_specular_albedo must be finite and > 0 (fraction of the irradiance), got " +
                 FormatNumber(max_specular_albedo)};
  if (!(std::isfinite(specular_prior_weight) && specular_prior_weight >= 0.0))
    return Error{"specular_prior_weight must be finite and >= 0 (noise variances), got " +
                 FormatNumber(specular_prior_weight)};
  if (!(std::isfinite(lobe_prior_weight) && lobe_prior_weight >= 0.0))
    return Error{"lobe_prior_weight must be finite and >= 0, got " + FormatNumber(lobe_prior_weight)};
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
  std::snprintf(buffer, sizeof buffer, "; %.3g s", seconds);
  return out + buffer;
}

TexelFit FitBrdfTexel(std::span<const BrdfSample> samples, const BrdfFitOptions& options) {
  const Status valid = options.Validate();
  DIGITIZE_CHECK(valid.ok(), "FitBrdfTexel: " + valid.message());
  Workspace ws;
  return FitTexel(samples, options, ws);
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
  result.status.resize(texels, TexelFitStatus::kTooFewSamples);
  result.rms_error.resize(texels, 0.0f);
  std::vector<int> iterations(texels, 0), used(texels, 0), saturated(texels, 0);

  std::atomic<size_t> done{0};
  std::mutex progress_mutex;
  size_t last_reported = 0;
  ReportProgress(progress, "fit", 0.0);
  const auto body = [&](const tbb::blocked_range<size_t>& range) {
    Workspace ws;
    for (size_t t = range.begin(); t != range.end(); ++t) {
      const TexelFit fit = FitTexel(samples.Texel(t), options, ws);
      result.params[t] = fit.params;
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
    ++s.count_by_status[static_cast<size_t>(result.status[t])];
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
