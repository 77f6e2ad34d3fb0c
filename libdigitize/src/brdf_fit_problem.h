// The one-lobe Lafortune fit of one texel as both solvers see it: the texel's valid samples as
// arrays, the closed-form linear solve for a fixed lobe shape, the cost and its priors.
// Private to the BRDF layer (brdf_fit.cpp, brdf_fit_varpro.cpp, brdf_fit_ceres.cpp).
//
// Notation inside: per texel, N valid samples; per sample s the products ax = vx lx, ay = vy ly,
// az = vz lz (the lobe base is cx ax + cy ay + az), per channel c the irradiance e_c and the
// radiance L_c. For a lobe shape theta = (cx, cy, t = log k) the lobe factor is g_s; the model is
// e_c (a_c + b_c g) with a = rho_d, b = rho_s. The objective, identical on both paths, is
//   F = sum_{s,c} (e_c (a_c + b_c g_s) - L_c)^2 + w2 ((cx + 1)^2 + (cy + 1)^2),
// w2 = lobe_prior_weight^2 * N * (mean L^2): the prior (see brdf_fit.h).
// Weights: every residual is scaled by sqrt(w_{s,c}), w = sigma_sensor^2 / sigma_{s,c}^2 from
// the noise model (brdf_fit.h, NOISE MODEL); the scaling is folded into e and L themselves
// (e <- sqrt(w) e, L <- sqrt(w) L), so every kernel and both solvers see a plain least-squares
// problem. w = 1 exactly without a quantisation term (float photos), which leaves that case bit
// for bit as it was.
// GGX (ggx.h): for a fixed alpha the specular factor is q_s (F0 (1 - m_s^5) + m_s^5) with
// q = D G1 G1 / (4 n.v n.l) and m = 1 - v.h, so the model e_c (a_c + F0_c u_s + o_s) with
// u = q (1 - m^5), o = q m^5 is linear in (a_c, F0_c) with a known offset: the same closed-form
// channel solve (bounds a >= 0, 0 <= F0 <= 1) on the target L - e o.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <span>
#include <vector>

#include "digitize/brdf_fit.h"
#include "digitize/ggx.h"
#include "digitize/lafortune.h"

namespace digitize::brdf_detail {

constexpr double kPi = 3.14159265358979323846;
constexpr double kPriorC = -1.0;  // the mirror lobe (cx = cy = -1) the prior pulls towards
// Lobe exponents (k log base) below this give g = 0 (see SetExponent); kLogZero marks a clamped
// base: times any k >= 0.5 it is far below kMinLobeLog, and finite.
constexpr float kMinLobeLog = -40.0f;
constexpr float kLogZero = -1e30f;

using ArrayMap = Eigen::Map<Eigen::ArrayXf>;

// Per-thread storage for one texel's samples as arrays (structure of arrays, so Eigen
// vectorises every pass over the samples, exp and log included). Capacity grows, never shrinks.
// Every array starts aligned for Eigen's widest packet (aligned_allocator, a capacity in whole
// 64-byte lines): Eigen sums a map of unknown alignment as a scalar head up to the first aligned
// packet, then packets, so where an array starts would change the order of the sum, and with it
// the rounding: with 8-float (AVX) packets and malloc's 16-byte alignment a texel's fit depended
// on which thread's workspace it ran in.
class Workspace {
 public:
  static constexpr int kArrays = 48;
  static constexpr int kAlignFloats = 16;  // 64 bytes
  float* Reserve(int n) {
    if (n > capacity_) {
      capacity_ = (std::max(n, 2 * capacity_) + kAlignFloats - 1) / kAlignFloats * kAlignFloats;
      storage_.assign(static_cast<size_t>(capacity_) * kArrays, 0.0f);
    }
    return storage_.data();
  }
  int capacity() const { return capacity_; }

 private:
  std::vector<float, Eigen::aligned_allocator<float>> storage_;
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
inline double QuadraticCost(const ChannelSums& m, double a, double b) {
  return -2.0 * (a * m.p0 + b * m.p1) + a * a * m.s0 + 2.0 * a * b * m.s1 + b * b * m.s2;
}

inline ChannelFit SolveChannel(const ChannelSums& m, double b_max) {
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
    const double sensor2 = options.noise_sigma * options.noise_sigma;
    const bool weighted = options.photo_code_max > 0 && sensor2 > 0.0;
    const int padded_max = static_cast<int>((samples.size() + kBlock - 1) / kBlock * kBlock);
    p_ = ws.Reserve(std::max(kBlock, padded_max));
    cap_ = ws.capacity();
    Load(samples, options.saturation_radiance);
    for (int j = 0; j < 3; ++j)
      ArrayMap(Slot(kAx + j), n_) = ArrayMap(Slot(kV + j), n_) * ArrayMap(Slot(kLd + j), n_);
    for (int c = 0; c < 3; ++c) {
      ArrayMap w(Slot(kW + c), n_), e(Slot(kE + c), n_), radiance(Slot(kL + c), n_);
      if (!weighted) {
        w.setOnes();
        continue;
      }
      QuantisationRootWeights(radiance, sensor2, options, w);
      e *= w;
      radiance *= w;
    }
    np_ = std::max(kBlock, (n_ + kBlock - 1) / kBlock * kBlock);
    for (int slot = kAx; slot < kE2; ++slot) std::fill(Slot(slot) + n_, Slot(slot) + np_, 0.0f);
    for (int slot = kV; slot < kV + 6; ++slot) std::fill(Slot(slot) + n_, Slot(slot) + np_, 0.0f);
    for (int c = 0; c < 3; ++c) std::fill(Slot(kW + c) + n_, Slot(kW + c) + np_, 1.0f);
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

  // Variance of the photo encoding's rounding at linear value x (brdf_fit.h, NOISE MODEL): one
  // code step in linear units, dx/dcode, squared over 12, plus the compression error.
  static double QuantisationVariance(float x, const BrdfFitOptions& o) {
    if (o.photo_code_max <= 0) return 0.0;
    const double lin = std::clamp(static_cast<double>(x), 0.0, 1.0);
    // d(code)/d(linear) / code_max: the sRGB OETF's slope (12.92 on its linear toe).
    const double slope = !o.photo_codes_srgb ? 1.0
                         : lin <= 0.0031308
                             ? 12.92
                             : 1.055 / 2.4 * std::pow(std::max(lin, 0.0031308), 1.0 / 2.4 - 1.0);
    const double step = 1.0 / (slope * o.photo_code_max);
    const double c = o.photo_compression_sigma_codes;
    return step * step * (1.0 / 12.0 + c * c);
  }

  // sqrt(w) = sqrt(sigma^2 / (sigma^2 + QuantisationVariance(x))) for linear radiances x,
  // vectorised: the reference's pow per sample and channel, in double, was ~15 % of the fit
  // (measured). On the sRGB curve's power segment 1 / slope grows as lin^(1 - 1/2.4), so the
  // variance there is its value at 1 times lin^(2 - 2/2.4): one log and one exp per sample.
  // Agrees with the reference to float rounding.
  static void QuantisationRootWeights(const ArrayMap& x, double sensor2, const BrdfFitOptions& o,
                                      ArrayMap& out) {
    const float s2 = static_cast<float>(sensor2);
    if (!o.photo_codes_srgb) {  // one code step everywhere
      out.setConstant(std::sqrt(s2 / (s2 + static_cast<float>(QuantisationVariance(1.0f, o)))));
      return;
    }
    constexpr double kToe = 0.0031308;
    // The largest float <= toe: the curve's slope jumps there (12.92 vs 12.73), so the branch
    // must be the reference's for every float.
    const float toe = static_cast<float>(kToe) > kToe
                          ? std::nextafter(static_cast<float>(kToe), 0.0f)
                          : static_cast<float>(kToe);
    const float toe_var = static_cast<float>(QuantisationVariance(0.0f, o));
    const float var_at_one = static_cast<float>(QuantisationVariance(1.0f, o));
    const float exponent = static_cast<float>(2.0 - 2.0 / 2.4);
    out = var_at_one * (exponent * x.max(toe).min(1.0f).log()).exp();
    out = (x <= toe).select(toe_var, out);
    out = (s2 / (s2 + out)).sqrt();
  }

  int n() const { return n_; }
  int saturated() const { return saturated_; }
  double prior_w2() const { return prior_w2_; }
  double albedo_ridge() const { return albedo_ridge_; }
  // The per-sample data as the reference path's cost functors take it.
  Vec3f Products(int i) const { return {Slot(kAx)[i], Slot(kAy)[i], Slot(kAz)[i]}; }
  Vec3f Irradiance(int i) const { return {Slot(kE)[i], Slot(kE + 1)[i], Slot(kE + 2)[i]}; }
  Vec3f Radiance(int i) const { return {Slot(kL)[i], Slot(kL + 1)[i], Slot(kL + 2)[i]}; }
  Vec3f ViewDir(int i) const { return {Slot(kV)[i], Slot(kV + 1)[i], Slot(kV + 2)[i]}; }
  Vec3f LightDir(int i) const { return {Slot(kLd)[i], Slot(kLd + 1)[i], Slot(kLd + 2)[i]}; }
  Vec3f RootWeight(int i) const { return {Slot(kW)[i], Slot(kW + 1)[i], Slot(kW + 2)[i]}; }

  // rho_d only, per channel a = max(0, p0 / s0); returns the (weighted) squared error.
  double FitDiffuse(LinearFit* fit) {
    double sse = 0;
    for (int c = 0; c < 3; ++c) {
      fit->channel[c] = {sums_[c].s0 > 0.0 ? std::max(0.0, sums_[c].p0 / sums_[c].s0) : 0.0, 0.0};
      sse += (e(c) * static_cast<float>(fit->channel[c].a) - L(c)).square().sum();
    }
    return sse;
  }

  // The squared error in RADIANCE (weights undone) of the model e (a + b g + o) for the g (and,
  // GGX, the offset o) of `kind`: what the fit reports as rms_error.
  enum class Columns { kDiffuse, kLobe, kGgx };
  double RadianceSse(const LinearFit& fit, Columns kind) {
    double sse = 0;
    for (int c = 0; c < 3; ++c) {
      const float a = static_cast<float>(fit.channel[c].a),
                  b = static_cast<float>(fit.channel[c].b);
      if (kind == Columns::kDiffuse)
        sse += ((e(c) * a - L(c)) / View(kW + c)).square().sum();
      else if (kind == Columns::kLobe)
        sse += ((e(c) * (a + b * g()) - L(c)) / View(kW + c)).square().sum();
      else
        sse += ((e(c) * (a + b * View(kU) + View(kO)) - L(c)) / View(kW + c)).square().sum();
    }
    return sse;
  }

  // GGX: the alpha-independent cosines, once per texel (clamped as GgxSpecular clamps them).
  void PrepareGgx() {
    auto vx = View(kV), vy = View(kV + 1), vz = View(kV + 2);
    auto lx = View(kLd), ly = View(kLd + 1), lz = View(kLd + 2);
    auto hx = View(kTmp);
    // |v + l|^2 = 2 + 2 v.l for unit vectors; padded samples (all zero) get a harmless 1.
    hx = ((vx + lx).square() + (vy + ly).square() + (vz + lz).square()).max(1e-12f).rsqrt();
    View(kNh2) = ((vz + lz) * hx).square();
    auto m = View(kM5);
    m = 1.0f - (vx * (vx + lx) + vy * (vy + ly) + vz * (vz + lz)) * hx;
    m = m.max(0.0f).min(1.0f);
    m = m.square().square() * m;
    View(kNv) = vz.max(kGgxMinCos);
    View(kNl) = lz.max(kGgxMinCos);
  }
  // GGX for roughness alpha: the F0 column u and the offset o (above), then the best (a, F0)
  // per channel; the sums it used in *sums_out; returns the weighted squared error (from the
  // sums: exact enough to compare alphas; GgxSse measures it directly).
  LinearFit SolveGgx(double alpha, std::array<ChannelSums, 3>* sums_out = nullptr,
                     double* sse_out = nullptr) {
    const float a2 = static_cast<float>(alpha * alpha), one_minus_a2 = 1.0f - a2;
    const float d_scale = a2 / static_cast<float>(kPi);
    const float *nh2 = Slot(kNh2), *m5 = Slot(kM5), *nv = Slot(kNv), *nl = Slot(kNl);
    float *u_ptr = Slot(kU), *o_ptr = Slot(kO);
    // A pass for u and o, then a pass per channel for its five sums: an Eigen expression per sum
    // was 15 passes of a few blocks each, whose setup and tails cost more than the arithmetic
    // (measured).
    // Per channel, with the target r = L - e o: s1 = sum e^2 u, s2 = sum e^2 u^2,
    // p0 = sum e r, p1 = sum e r u, ll = sum r^2.
    for (int i = 0; i < np_; i += kBlock) {
      // q = D G1(v) G1(l) / (4 n.v n.l) with G1(x) = 2 x / (x + S(x)), S(x) = sqrt(a2 + (1 -
      // a2) x^2): the 2 n.v 2 n.l cancel the 4 n.v n.l, which leaves one division per sample.
      const Block v = Block::Map(nv + i), l = Block::Map(nl + i);
      const Block den = (a2 - 1.0f) * Block::Map(nh2 + i) + 1.0f;  // D's denominator
      const Block q = d_scale / (den.square() * (v + (a2 + one_minus_a2 * v.square()).sqrt()) *
                                 (l + (a2 + one_minus_a2 * l.square()).sqrt()));
      const Block m = Block::Map(m5 + i);
      Block::Map(u_ptr + i) = q * (1.0f - m);
      Block::Map(o_ptr + i) = q * m;
    }
    LinearFit fit;
    double sse = 0;
    for (int c = 0; c < 3; ++c) {
      // A pass per channel: its five sums stay in registers (all fifteen in one pass spilled).
      std::array<Block, 5> acc;
      for (Block& x : acc) x.setZero();
      const float *e_ptr = Slot(kE + c), *l_ptr = Slot(kL + c), *e2_ptr = Slot(kE2 + c);
      for (int i = 0; i < np_; i += kBlock) {
        // Padded samples have e = L = 0: their u, o are finite and contribute nothing.
        const Block u = Block::Map(u_ptr + i), o = Block::Map(o_ptr + i);
        const Block e = Block::Map(e_ptr + i);
        const Block r = Block::Map(l_ptr + i) - e * o, er = e * r;
        const Block e2u = Block::Map(e2_ptr + i) * u;
        acc[0] += e2u;
        acc[1] += e2u * u;
        acc[2] += er;
        acc[3] += er * u;
        acc[4] += r.square();
      }
      ChannelSums m = sums_[c];
      m.s1 = acc[0].sum();
      m.s2 = acc[1].sum();
      m.p0 = acc[2].sum();
      m.p1 = acc[3].sum();
      m.ll = acc[4].sum();
      fit.channel[c] = SolveChannel(m, 1.0);
      sse += m.ll + QuadraticCost(m, fit.channel[c].a, fit.channel[c].b);
      if (sums_out) (*sums_out)[c] = m;
    }
    if (sse_out) *sse_out = std::max(0.0, sse);
    return fit;
  }
  // Exact weighted squared error of the GGX model for the alpha set last (SolveGgx), one pass.
  double GgxSse(const LinearFit& fit) {
    float a[3], b[3];
    for (int c = 0; c < 3; ++c) {
      a[c] = static_cast<float>(fit.channel[c].a);
      b[c] = static_cast<float>(fit.channel[c].b);
    }
    Block acc = Block::Zero();
    for (int i = 0; i < np_; i += kBlock) {
      const Block u = Block::Map(Slot(kU) + i), o = Block::Map(Slot(kO) + i);
      for (int c = 0; c < 3; ++c)
        acc += (Block::Map(Slot(kE + c) + i) * (a[c] + b[c] * u + o) - Block::Map(Slot(kL + c) + i))
                   .square();
    }
    return acc.sum();
  }

  // The base for (cx, cy), clamped below at kLobeBaseEps, and its log, kLogZero where the base
  // is clamped (so the lobe there comes out exactly 0 for every k).
  void SetLobeDirection(double cx, double cy) {
    base() = (static_cast<float>(cx) * View(kAx) + static_cast<float>(cy) * View(kAy) + View(kAz));
    // The log before the select: Eigen 3.4 evaluates a select's operands a coefficient at a time,
    // so a log inside it was libm's scalar logf (measured: ~1 s of a 1 Mtexel fit).
    log_base() = base().max(kLobeBaseEps).log();
    log_base() = (base() > kLobeBaseEps).select(log_base(), kLogZero);
    base() = base().max(kLobeBaseEps);
  }
  // The largest base over the samples for the direction set last: the lobe factor a sample
  // nearest the peak sees is MaxBase()^k.
  double MaxBase() { return static_cast<double>(View(kBase).head(n_).maxCoeff()); }
  // g (and dg/dcx, dg/dcy, dg/dt with t = log k) for the direction set last. The exponent is
  // <= 0 here up to rounding (|cx|, |cy| <= 1 keeps the base <= 1). Lobe values below
  // exp(kMinLobeLog) ~ 4e-18 of the peak are set to 0: they change nothing, and left in, their
  // squares and products are float denormals, which cost ~100 cycles each on x86 and made the
  // whole fit several times slower.
  void SetExponent(double k, bool derivatives) {
    k_ = k;
    const float kf = static_cast<float>(k);
    tmp() = kf * log_base();
    g() = tmp().max(kMinLobeLog).min(kMaxLobeLog).exp();  // vectorised, then the select
    g() = (tmp() > kMinLobeLog).select(g(), 0.0f);
    if (derivatives) SetDerivatives();
  }
  // The derivatives of g for the shape set last, when SetShape left them out: LM measures a trial
  // shape without them and needs them only once it takes the step.
  void SetDerivatives() {
    const float kf = static_cast<float>(k_);
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

  // Gauss-Newton system of the reduced problem at the current g and derivatives (the
  // variable-projection solver's; defined in brdf_fit_varpro.cpp).
  void NormalEquations(const LinearFit& fit, const std::array<ChannelSums, 3>& sums,
                       const Shape& shape, Eigen::Matrix3d* jtj, Eigen::Vector3d* jtr);

 private:
  // Load's tests, per sample: verdict 0 unusable, 1 usable, 2 usable but saturated, 3 or 4: 1 or
  // 2 once its directions are normalised. Returns the count of 1s; *unit_out the count of 1s and
  // 2s. The arrays as restrict parameters, flags as int and the tests folded into a few
  // comparisons: otherwise GCC 12 does not vectorise the loop (restrict locals, bool flags and a
  // nested ?: each stopped it).
  static int Verdicts(int count, const float* __restrict vx, const float* __restrict vy,
                      const float* __restrict vz, const float* __restrict lx,
                      const float* __restrict ly, const float* __restrict lz,
                      const float* __restrict e0, const float* __restrict e1,
                      const float* __restrict e2, const float* __restrict r0,
                      const float* __restrict r1, const float* __restrict r2, float saturation,
                      float* __restrict verdict, int* unit_out) {
    int usable = 0, unit = 0;
    for (int i = 0; i < count; ++i) {
      // x * 0 is 0 for a finite x, NaN for NaN and the infinities.
      const float zero = vx[i] * 0.0f + vy[i] * 0.0f + vz[i] * 0.0f + lx[i] * 0.0f + ly[i] * 0.0f +
                         lz[i] * 0.0f + e0[i] * 0.0f + e1[i] * 0.0f + e2[i] * 0.0f + r0[i] * 0.0f +
                         r1[i] * 0.0f + r2[i] * 0.0f;
      const float vn2 = vx[i] * vx[i] + vy[i] * vy[i] + vz[i] * vz[i];
      const float ln2 = lx[i] * lx[i] + ly[i] * ly[i] + lz[i] * lz[i];
      const float e_min = std::min(e0[i], std::min(e1[i], e2[i]));
      const float e_max = std::max(e0[i], std::max(e1[i], e2[i]));
      const float positive = std::min(std::min(vn2, ln2), std::min(vz[i], lz[i]));
      const int ok = (zero == 0.0f) & (e_min >= 0.0f) & (e_max > 0.0f) & (positive > 0.0f);
      const int saturated = std::max(r0[i], std::max(r1[i], r2[i])) >= saturation;
      const int is_unit = std::max(std::abs(vn2 - 1.0f), std::abs(ln2 - 1.0f)) <= 1e-6f;
      verdict[i] = static_cast<float>(ok * (1 + saturated + 2 * (1 - is_unit)));
      usable += ok & (1 - saturated) & is_unit;
      unit += ok & is_unit;
    }
    *unit_out = unit;
    return usable;
  }

  // The usable samples into the arrays, in order, and saturated_ counted. Usable: every value
  // finite, irradiance >= 0 and not all 0, both directions of non-zero length (normalised where
  // they are not unit: the lobe is not scale invariant) and above the surface, the radiance
  // below saturation. Every sample is first copied in as it is, then the tests run over the
  // arrays, which the compiler vectorises, and only where some sample fails are the others moved
  // down. Tested sample by sample, the branches and scattered stores were a tenth of the fit
  // (measured).
  void Load(std::span<const BrdfSample> samples, double saturation_radiance) {
    const int count = static_cast<int>(samples.size());
    // The least float x with x >= saturation_radiance in double: the same test in float.
    float saturation = static_cast<float>(saturation_radiance);
    if (static_cast<double>(saturation) < saturation_radiance)
      saturation = std::nextafter(saturation, std::numeric_limits<float>::infinity());
    float* col[12];
    for (int j = 0; j < 3; ++j) {
      col[j] = Slot(kV + j);
      col[3 + j] = Slot(kLd + j);
      col[6 + j] = Slot(kE + j);
      col[9 + j] = Slot(kL + j);
    }
    for (int i = 0; i < count; ++i) {
      const BrdfSample& s = samples[static_cast<size_t>(i)];
      for (int j = 0; j < 3; ++j) {
        col[j][i] = s.view_dir[j];
        col[3 + j][i] = s.light_dir[j];
        col[6 + j][i] = s.irradiance[j];
        col[9 + j][i] = s.radiance[j];
      }
    }
    float* verdict = Slot(kTmp);
    int unit = 0;
    const int usable =
        Verdicts(count, col[0], col[1], col[2], col[3], col[4], col[5], col[6], col[7], col[8],
                 col[9], col[10], col[11], saturation, verdict, &unit);
    n_ = usable;
    saturated_ = unit - usable;
    if (usable == count) return;  // the common texel: every sample usable as it is
    n_ = 0;
    saturated_ = 0;
    for (int i = 0; i < count; ++i) {
      float v = verdict[i];
      if (v >= 3.0f) {  // normalise, as the sample's own test did; a direction may underflow
        const float vn2 = col[0][i] * col[0][i] + col[1][i] * col[1][i] + col[2][i] * col[2][i];
        const float ln2 = col[3][i] * col[3][i] + col[4][i] * col[4][i] + col[5][i] * col[5][i];
        if (std::abs(vn2 - 1.0f) > 1e-6f)
          for (int j = 0; j < 3; ++j) col[j][i] /= std::sqrt(vn2);
        if (std::abs(ln2 - 1.0f) > 1e-6f)
          for (int j = 3; j < 6; ++j) col[j][i] /= std::sqrt(ln2);
        v = col[2][i] > 0.0f && col[5][i] > 0.0f ? v - 2.0f : 0.0f;
      }
      if (v == 2.0f) ++saturated_;
      if (v != 1.0f) continue;
      for (int j = 0; j < 12; ++j) col[j][n_] = col[j][i];
      ++n_;
    }
  }

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
    kW,              // sqrt of the noise weight per channel (3)
    kV = kW + 3,     // view direction (3)
    kLd = kV + 3,    // light direction (3)
    kNh2 = kLd + 3,  // GGX: (n.h)^2, (1 - v.h)^5, clamped n.v and n.l, the F0 column, the offset
    kM5,
    kNv,
    kNl,
    kU,
    kO,
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

}  // namespace digitize::brdf_detail
