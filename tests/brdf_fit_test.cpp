// Per-texel Lafortune fit on synthetic samples with known parameters: recovery, the fast path
// against ceres::Solve, and the degenerate and hostile cases a per-texel fit meets.
//
// The samples come from a dome rig rendered here: V cameras x L point lights (Fibonacci points on
// the hemisphere), turned by a random azimuth per texel, radiance = f_r (n.l) I + Gaussian noise
// (I = 1). Accuracy is judged as the issue asks, by relighting: the RMSE of f_r (n.l) over
// held-out directions (random, same elevation range as the rig; for a one-camera rig, that
// camera with held-out lights), in the same radiance units as the noise sigma.
#include "digitize/brdf_fit.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <limits>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "brdf_fit_problem.h"
#include "digitize/lafortune.h"
#include "select_kth.h"
#include "test_paths.h"

namespace digitize {
namespace {

constexpr float kPi = 3.14159265358979f;

Vec3f FromElevationAzimuth(float elevation_rad, float azimuth_rad) {
  return {std::cos(elevation_rad) * std::cos(azimuth_rad),
          std::cos(elevation_rad) * std::sin(azimuth_rad), std::sin(elevation_rad)};
}

// n points spread evenly over the hemisphere above `min_elevation` (Fibonacci spiral).
std::vector<Vec3f> FibonacciDome(int n, float min_elevation_deg) {
  std::vector<Vec3f> out;
  const float z_min = std::sin(min_elevation_deg * kPi / 180.0f);
  const float golden = kPi * (3.0f - std::sqrt(5.0f));
  for (int i = 0; i < n; ++i) {
    const float z = 1.0f - (1.0f - z_min) * (i + 0.5f) / n;
    const float r = std::sqrt(1.0f - z * z);
    out.emplace_back(r * std::cos(golden * i), r * std::sin(golden * i), z);
  }
  return out;
}

struct Rig {
  std::vector<Vec3f> views, lights;
  float min_elevation_deg = 15.0f;
};

// One camera straight above (a texel normal slightly tilted from it, as on real relief), or
// `views` cameras at 50 degrees elevation around the canvas.
Rig DomeRig(int views, int lights) {
  Rig rig;
  rig.lights = FibonacciDome(lights, rig.min_elevation_deg);
  if (views == 1) {
    rig.views.push_back(Vec3f(0.08f, -0.05f, 1.0f).normalized());
  } else {
    for (int i = 0; i < views; ++i)
      rig.views.push_back(
          FromElevationAzimuth(50.0f * kPi / 180.0f, 2.0f * kPi * i / views + 0.3f));
  }
  return rig;
}

// Adds `per_view` lights on rings of `ring_rad` x (1, 2, 3) around each camera's mirror
// direction: a narrow lobe (half width ~ 1/sqrt(k) rad) is then sampled near its peak, which the
// dome's evenly spread lights (~18 degrees apart for 64) cannot do for k >~ 30.
void AddMirrorRings(Rig& rig, float ring_rad, int per_view) {
  for (const Vec3f& v : std::vector<Vec3f>(rig.views)) {
    const Vec3f mirror(-v.x(), -v.y(), v.z());
    const Vec3f a = mirror.cross(Vec3f::UnitZ()).normalized(), b = mirror.cross(a);
    for (int i = 0; i < per_view; ++i) {
      const float angle = ring_rad * (1 + i % 3), phi = 2.0f * kPi * i / per_view;
      rig.lights.push_back((mirror + angle * (std::cos(phi) * a + std::sin(phi) * b)).normalized());
    }
  }
}

using Brdf = std::function<Vec3f(const Vec3f& v, const Vec3f& l)>;

Brdf FromParams(const LafortuneParams& p) {
  return [p](const Vec3f& v, const Vec3f& l) { return EvaluateLafortune(p, v, l); };
}

Vec3f RotateZ(const Vec3f& d, float angle) {
  return {std::cos(angle) * d.x() - std::sin(angle) * d.y(),
          std::sin(angle) * d.x() + std::cos(angle) * d.y(), d.z()};
}

// Multi-camera rigs turn by a random azimuth per texel (texels see the rig from all sides); a
// one-camera rig stays put, so held-out relighting can use that very camera.
std::vector<BrdfSample> Render(const Brdf& brdf, const Rig& rig, float noise_sigma,
                               std::mt19937& rng) {
  std::normal_distribution<float> noise(0.0f, 1.0f);
  const float turn = std::uniform_real_distribution<float>(0.0f, 2.0f * kPi)(rng);
  const float azimuth = rig.views.size() == 1 ? 0.0f : turn;
  std::vector<BrdfSample> out;
  for (const Vec3f& view : rig.views)
    for (const Vec3f& light : rig.lights) {
      BrdfSample s;
      s.view_dir = RotateZ(view, azimuth);
      s.light_dir = RotateZ(light, azimuth);
      s.irradiance = Vec3f::Constant(s.light_dir.z());  // (n.l) I / d^2 with I / d^2 = 1
      s.radiance = brdf(s.view_dir, s.light_dir).cwiseProduct(s.irradiance);
      for (int c = 0; c < 3; ++c) s.radiance[c] += noise_sigma * noise(rng);
      out.push_back(s);
    }
  return out;
}

// Relighting RMSE of `fitted` against `truth` over held-out directions, radiance units (I = 1).
double RelightingRmse(const Brdf& truth, const Brdf& fitted, const Rig& rig, std::mt19937& rng,
                      int count = 400) {
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const float z_min = std::sin(rig.min_elevation_deg * kPi / 180.0f);
  const auto random_dir = [&] {
    const float z = z_min + (1.0f - z_min) * u(rng), phi = 2.0f * kPi * u(rng);
    const float r = std::sqrt(1.0f - z * z);
    return Vec3f(r * std::cos(phi), r * std::sin(phi), z);
  };
  double sum = 0;
  for (int i = 0; i < count; ++i) {
    // One camera: the lobe shape is only seen from it, so judge relighting from it.
    const Vec3f v = rig.views.size() == 1 ? rig.views[0] : random_dir();
    const Vec3f l = random_dir();
    sum += ((fitted(v, l) - truth(v, l)) * l.z()).squaredNorm();
  }
  return std::sqrt(sum / (3.0 * count));
}

double RelightingRmse(const Brdf& truth, const LafortuneParams& fit, const Rig& rig,
                      std::mt19937& rng, int count = 400) {
  const Brdf fitted = [&fit](const Vec3f& v, const Vec3f& l) {
    return EvaluateLafortune(fit, v, l);
  };
  return RelightingRmse(truth, fitted, rig, rng, count);
}

// The same for a fit under the model it chose (Lafortune or GGX).
double RelightingRmse(const Brdf& truth, const TexelFit& fit, const Rig& rig, std::mt19937& rng,
                      int count = 400) {
  if (fit.model != ReflectanceModel::kGgx)
    return RelightingRmse(truth, fit.params, rig, rng, count);
  const Brdf fitted = [&fit](const Vec3f& v, const Vec3f& l) { return EvaluateGgx(fit.ggx, v, l); };
  return RelightingRmse(truth, fitted, rig, rng, count);
}

LafortuneParams Params(Vec3f rho_d, Vec3f rho_s, float cx, float cy, float k) {
  LafortuneParams p;
  p.rho_d = rho_d;
  p.rho_s = rho_s;
  p.cx = cx;
  p.cy = cy;
  p.k = k;
  return p;
}

BrdfFitOptions Options(BrdfFitMethod method, double noise_sigma) {
  BrdfFitOptions o;
  o.method = method;
  o.noise_sigma = noise_sigma;
  return o;
}

void ExpectFinite(const TexelFit& fit) {
  EXPECT_TRUE(fit.params.Validate().ok()) << fit.params.Validate().message();
  EXPECT_TRUE(std::isfinite(fit.rms_error));
}

// Named tolerances and sizes (see each use for the reason of its size).
constexpr float kNoise = 0.002f;  // sensor noise of the tests, radiance units (I = 1): ~8-bit
constexpr int kReps = 6;          // noise draws per recovery case

// Relighting judged against the noise: with ~300 samples and 9 unknowns the fitted function's
// error on held-out directions is a fraction of one sample's noise where the lobe is sampled.
constexpr double kRelightWellSampled = 0.5 * kNoise;

struct RecoveryCase {
  const char* name;
  LafortuneParams truth;
  double log_k_tolerance;  // |log k_fit - log k_true|
  double rho_s_relative;   // |rho_s_fit / rho_s_true - 1|
};

// The noise weights of 8- and 16-bit sRGB and linear codes, vectorised (one log and exp per
// sample, float), against the scalar reference (double pow): the weight scales every residual,
// so a relative error of 1e-5 moves a fit's parameters far less than the noise does; toe, knee,
// clamped (< 0, > 1) and mid-range values.
// The prefilter's median: every rank of small sets with many ties (values drawn from a few
// levels, as a texel's lit samples of one paint are) equals std::nth_element's.
TEST(SelectKth, EveryRankEqualsNthElement) {
  std::mt19937 rng(7);
  for (size_t n = 1; n <= 70; ++n) {
    for (int levels : {1, 3, 1000}) {
      std::uniform_int_distribution<int> level(0, levels - 1);
      std::vector<double> values(n);
      for (double& v : values) v = 0.25 * level(rng);
      for (size_t k = 0; k < n; ++k) {
        std::vector<double> a = values, b(n), c(n), ref = values;
        std::nth_element(ref.begin(), ref.begin() + static_cast<std::ptrdiff_t>(k), ref.end());
        ASSERT_EQ(SelectKth(a.data(), b.data(), c.data(), n, k), ref[k])
            << "n " << n << ", k " << k << ", levels " << levels;
      }
    }
  }
}

TEST(BrdfFit, VectorisedQuantisationWeightsMatchTheReference) {
  using brdf_detail::TexelProblem;
  std::vector<float> x = {-0.5f, 0.0f, 1e-6f, 0.003f, 0.0031308f, 0.00314f,
                          0.01f, 0.2f, 0.5f,  0.999f, 1.0f,       1.7f};
  for (int i = 0; i <= 1000; ++i) x.push_back(std::pow(10.0f, -5.0f + 5.0f * i / 1000.0f));
  for (const int code_max : {255, 65535})
    for (const bool srgb : {true, false})
      for (const double sigma : {0.002, 0.01}) {
        BrdfFitOptions o;
        o.photo_code_max = code_max;
        o.photo_codes_srgb = srgb;
        o.noise_sigma = sigma;
        std::vector<float> w(x.size());
        Eigen::Map<Eigen::ArrayXf> in(x.data(), static_cast<Eigen::Index>(x.size()));
        Eigen::Map<Eigen::ArrayXf> out(w.data(), static_cast<Eigen::Index>(w.size()));
        const double s2 = sigma * sigma;
        TexelProblem::QuantisationRootWeights(in, s2, o, out);
        double worst = 0;
        for (size_t i = 0; i < x.size(); ++i) {
          const double ref = std::sqrt(s2 / (s2 + TexelProblem::QuantisationVariance(x[i], o)));
          worst = std::max(worst, std::abs(w[i] - ref) / ref);
        }
        EXPECT_LT(worst, 1e-5) << "code max " << code_max << (srgb ? " sRGB" : " linear")
                               << " sigma " << sigma;
      }
}

TEST(BrdfFit, RecoversKnownParametersFromADome) {
  // 4 cameras x (64 dome lights + 12 around each mirror direction): every lobe below is seen by
  // several samples near its peak (the rings are what a k = 100 lobe needs).
  Rig rig = DomeRig(4, 64);
  AddMirrorRings(rig, 0.05f, 12);
  // Off-mirror lobes (|c| < 1) only where k is small: the lobe's peak is rho_s |C v|^k, so with
  // k = 100 even c = -0.95 leaves 1 % of rho_s and rho_s, c are then barely separable (a
  // property of the model, not of the fit); glossy paint is a mirror lobe.
  const RecoveryCase cases[] = {
      // Broad lobes trade k against rho_s and the diffuse term, hence the looser tolerances.
      {"broad k=1", Params({0.05f, 0.10f, 0.15f}, {0.3f, 0.2f, 0.1f}, -0.8f, -0.9f, 1.0f), 0.25,
       0.15},
      {"semi-gloss k=10",
       Params({0.10f, 0.08f, 0.06f}, {0.15f, 0.15f, 0.15f}, -0.9f, -0.95f, 10.0f), 0.1, 0.1},
      {"glossy k=100", Params({0.05f, 0.10f, 0.15f}, {0.8f, 0.8f, 0.8f}, -1.0f, -1.0f, 100.0f), 0.1,
       0.1},
  };
  for (const RecoveryCase& c : cases) {
    std::mt19937 rng(21);
    for (int rep = 0; rep < kReps; ++rep) {
      const std::vector<BrdfSample> samples = Render(FromParams(c.truth), rig, kNoise, rng);
      const TexelFit fit = FitBrdfTexel(samples, Options(BrdfFitMethod::kFast, kNoise));
      SCOPED_TRACE(std::string(c.name) + " rep " + std::to_string(rep));
      EXPECT_EQ(fit.status, TexelFitStatus::kConverged);
      EXPECT_EQ(fit.samples_used, static_cast<int>(samples.size()));
      ExpectFinite(fit);
      EXPECT_NEAR(std::log(fit.params.k / c.truth.k), 0.0, c.log_k_tolerance)
          << "k " << fit.params.k;
      for (int ch = 0; ch < 3; ++ch) {
        // rho_d: the diffuse term is seen by all 256 samples: ~1e-3 absolute.
        EXPECT_NEAR(fit.params.rho_d[ch], c.truth.rho_d[ch], 0.01f) << "channel " << ch;
        EXPECT_NEAR(fit.params.rho_s[ch] / c.truth.rho_s[ch], 1.0f, c.rho_s_relative)
            << "channel " << ch;
      }
      EXPECT_NEAR(fit.params.cx, c.truth.cx, 0.05f);
      EXPECT_NEAR(fit.params.cy, c.truth.cy, 0.05f);
      // The fit residual is the noise: RMS within 10 % of sigma (3 x 256 residuals).
      EXPECT_NEAR(fit.rms_error, kNoise, 0.1 * kNoise);
      std::mt19937 held(99);
      EXPECT_LT(RelightingRmse(FromParams(c.truth), fit.params, rig, held), kRelightWellSampled);
    }
  }
}

TEST(BrdfFit, NoiseFreeSamplesAreFittedExactly) {
  const Rig rig = DomeRig(4, 64);
  const LafortuneParams truth =
      Params({0.05f, 0.10f, 0.15f}, {0.8f, 0.6f, 0.4f}, -0.95f, -0.9f, 60.0f);
  std::mt19937 rng(5);
  const std::vector<BrdfSample> samples = Render(FromParams(truth), rig, 0.0f, rng);
  for (BrdfFitMethod m : {BrdfFitMethod::kFast, BrdfFitMethod::kCeresReference}) {
    // noise_sigma only sets the diffuse test and the specular ridge: a floor far below the
    // signal; the lobe prior off (it would pull c towards -1 by ~1e-3 here), so only the solver
    // and float arithmetic stand between the fit and the truth.
    BrdfFitOptions options = Options(m, 1e-5);
    options.lobe_prior_weight = 0;
    const TexelFit fit = FitBrdfTexel(samples, options);
    EXPECT_EQ(fit.status, TexelFitStatus::kConverged);
    // float evaluation of base^60 limits the match to ~1e-5 relative.
    EXPECT_LT(fit.rms_error, 1e-5f);
    EXPECT_NEAR(fit.params.k, truth.k, 0.01f * truth.k);
    EXPECT_NEAR(fit.params.cx, truth.cx, 1e-3f);
    EXPECT_NEAR(fit.params.cy, truth.cy, 1e-3f);
    std::mt19937 held(99);
    EXPECT_LT(RelightingRmse(FromParams(truth), fit.params, rig, held), 1e-4);
  }
}

TEST(BrdfFit, FastPathReachesTheReferenceRelightingError) {
  // Random paint-like texels (the bench's mix, with lobes the dome samples): both paths must
  // end at the same relighting error; the fast one at no higher cost per texel.
  const Rig rig = DomeRig(4, 32);
  std::mt19937 rng(31);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  double sum_sq[2] = {0, 0};
  int fast_worse = 0;
  const int texels = 120;
  for (int t = 0; t < texels; ++t) {
    LafortuneParams truth;
    truth.rho_d = Vec3f(0.02f + 0.18f * u(rng), 0.02f + 0.18f * u(rng), 0.02f + 0.18f * u(rng));
    truth.k = 2.0f * std::pow(40.0f, u(rng));  // 2 .. 80
    truth.cx = -1.0f + 0.15f * u(rng);
    truth.cy = -1.0f + 0.15f * u(rng);
    truth.rho_s = Vec3f::Constant((0.02f + 0.28f * u(rng)) * (truth.k + 2.0f) / (2.0f * kPi));
    const std::vector<BrdfSample> samples = Render(FromParams(truth), rig, kNoise, rng);
    TexelFit fits[2];
    for (int m = 0; m < 2; ++m) {
      fits[m] = FitBrdfTexel(
          samples, Options(m ? BrdfFitMethod::kCeresReference : BrdfFitMethod::kFast, kNoise));
      ExpectFinite(fits[m]);
      std::mt19937 held(1000 + t);  // the same held-out directions for both paths
      const double r = RelightingRmse(FromParams(truth), fits[m].params, rig, held, 200);
      sum_sq[m] += r * r;
    }
    // The objective includes two small priors; the data term alone may differ at 1e-3.
    if (fits[0].rms_error > fits[1].rms_error * 1.001f) ++fast_worse;
  }
  const double rmse_fast = std::sqrt(sum_sq[0] / texels),
               rmse_ceres = std::sqrt(sum_sq[1] / texels);
  std::printf("relighting RMSE over %d texels: fast %.6f, ceres::Solve %.6f\n", texels, rmse_fast,
              rmse_ceres);
  // "Within a few %" of the reference: 5 %.
  EXPECT_LT(rmse_fast, 1.05 * rmse_ceres);
  EXPECT_LE(fast_worse, texels / 20);
}

TEST(BrdfFit, VeryNarrowLobeK1000) {
  // Lights clustered around each camera's mirror direction so a k = 1000 lobe (half width ~2
  // degrees) is sampled; the dome's own 16 lights alone would miss it.
  Rig rig = DomeRig(4, 16);
  AddMirrorRings(rig, 0.015f, 12);
  const LafortuneParams truth =
      Params({0.02f, 0.02f, 0.02f}, {5.0f, 5.0f, 5.0f}, -1.0f, -1.0f, 1000.0f);
  std::mt19937 rng(41);
  for (int rep = 0; rep < kReps; ++rep) {
    const TexelFit fit = FitBrdfTexel(Render(FromParams(truth), rig, kNoise, rng),
                                      Options(BrdfFitMethod::kFast, kNoise));
    ExpectFinite(fit);
    EXPECT_EQ(fit.status, TexelFitStatus::kConverged);
    EXPECT_NEAR(std::log(fit.params.k / truth.k), 0.0, 0.1);
    EXPECT_NEAR(fit.params.rho_s.x() / truth.rho_s.x(), 1.0f, 0.15f);
  }
}

TEST(BrdfFit, OneCameraKeepsTheMirrorLobe) {
  // RTI: one camera above the canvas, so vx, vy ~ 0 and cx, cy are barely observed; the prior
  // keeps them at the mirror lobe and relighting from that camera is right.
  const Rig rig = DomeRig(1, 64);
  const LafortuneParams truth =
      Params({0.10f, 0.08f, 0.06f}, {0.5f, 0.5f, 0.5f}, -1.0f, -1.0f, 30.0f);
  std::mt19937 rng(51);
  for (int rep = 0; rep < kReps; ++rep) {
    const TexelFit fit = FitBrdfTexel(Render(FromParams(truth), rig, kNoise, rng),
                                      Options(BrdfFitMethod::kFast, kNoise));
    ExpectFinite(fit);
    EXPECT_NEAR(fit.params.cx, -1.0f, 0.1f);
    EXPECT_NEAR(fit.params.cy, -1.0f, 0.1f);
    EXPECT_NEAR(std::log(fit.params.k / truth.k), 0.0, 0.2);
    std::mt19937 held(99);
    EXPECT_LT(RelightingRmse(FromParams(truth), fit.params, rig, held), kNoise);
  }
}

TEST(BrdfFit, MatteAndBlackPaintAreDiffuseOnly) {
  const Rig rig = DomeRig(4, 16);
  std::mt19937 rng(61);
  for (const Vec3f& rho_d : {Vec3f(0.15f, 0.10f, 0.05f), Vec3f(0, 0, 0)}) {
    const LafortuneParams truth = Params(rho_d, Vec3f::Zero(), -1, -1, 1);
    for (BrdfFitMethod m : {BrdfFitMethod::kFast, BrdfFitMethod::kCeresReference}) {
      const TexelFit fit =
          FitBrdfTexel(Render(FromParams(truth), rig, kNoise, rng), Options(m, kNoise));
      EXPECT_EQ(fit.status, TexelFitStatus::kDiffuseOnly);
      EXPECT_EQ(fit.iterations, 0);  // the lobe fit was skipped
      EXPECT_EQ(fit.params.rho_s, Vec3f::Zero());
      ExpectFinite(fit);
      // 64 samples with E ~ 0.6: rho_d to ~sigma / (0.6 sqrt(64)) ~ 4e-4; black clamps at 0.
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(fit.params.rho_d[c], rho_d[c], 2e-3f);
    }
  }
}

TEST(BrdfFit, TooFewSamplesFallBackToDiffuse) {
  const LafortuneParams truth = Params({0.1f, 0.2f, 0.3f}, {1, 1, 1}, -1, -1, 20);
  std::mt19937 rng(71);
  const std::vector<BrdfSample> all = Render(FromParams(truth), DomeRig(1, 16), 0.0f, rng);
  for (BrdfFitMethod m : {BrdfFitMethod::kFast, BrdfFitMethod::kCeresReference}) {
    // One sample: diffuse-only from it, rho_d = radiance / E exactly.
    const TexelFit one = FitBrdfTexel(std::span(all).first(1), Options(m, kNoise));
    EXPECT_EQ(one.status, TexelFitStatus::kTooFewSamples);
    EXPECT_EQ(one.samples_used, 1);
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(one.params.rho_d[c], all[0].radiance[c] / all[0].irradiance[c], 1e-5f);
    EXPECT_EQ(one.params.rho_s, Vec3f::Zero());
    EXPECT_NEAR(one.rms_error, 0.0f, 1e-6f);  // float rounding of E rho_d - L
    // min_samples - 1 samples: still the fallback.
    const TexelFit seven = FitBrdfTexel(std::span(all).first(7), Options(m, kNoise));
    EXPECT_EQ(seven.status, TexelFitStatus::kTooFewSamples);
    ExpectFinite(seven);
  }
}

TEST(BrdfFit, AllSamplesFromOneLightAreDiffuseOnly) {
  // 64 photos with the same light and camera: diffuse and lobe are indistinguishable; the
  // samples are explained by a constant, so the texel is diffuse-only (never NaN).
  const LafortuneParams truth = Params({0.1f, 0.1f, 0.1f}, {1, 1, 1}, -1, -1, 20);
  Rig rig;
  rig.views = {Vec3f(0.3f, 0.1f, 0.9f).normalized()};
  rig.lights.assign(64, Vec3f(-0.3f, -0.1f, 0.9f).normalized());
  std::mt19937 rng(81);
  for (BrdfFitMethod m : {BrdfFitMethod::kFast, BrdfFitMethod::kCeresReference}) {
    const TexelFit fit =
        FitBrdfTexel(Render(FromParams(truth), rig, kNoise, rng), Options(m, kNoise));
    EXPECT_EQ(fit.status, TexelFitStatus::kDiffuseOnly);
    ExpectFinite(fit);
    // The one observed value is reproduced: f = radiance / E at that pair.
    const Vec3f f = EvaluateLafortune(fit.params, rig.views[0], rig.lights[0]);
    const Vec3f want = EvaluateLafortune(truth, rig.views[0], rig.lights[0]);
    EXPECT_NEAR(f.x(), want.x(), 0.01f * want.x());
  }
}

TEST(BrdfFit, GrazingLightsStayFinite) {
  // Every light at 89 degrees from the normal: n.l ~ 0.017, the radiance is mostly noise. In
  // radiance space these samples simply weigh little; the fit must stay finite and sane.
  const LafortuneParams truth = Params({0.1f, 0.1f, 0.1f}, {0.5f, 0.5f, 0.5f}, -1, -1, 10);
  Rig rig = DomeRig(4, 1);
  rig.lights.clear();
  for (int i = 0; i < 16; ++i)
    rig.lights.push_back(FromElevationAzimuth(kPi / 180.0f, 2.0f * kPi * i / 16));
  std::mt19937 rng(91);
  for (BrdfFitMethod m : {BrdfFitMethod::kFast, BrdfFitMethod::kCeresReference}) {
    const TexelFit fit =
        FitBrdfTexel(Render(FromParams(truth), rig, kNoise, rng), Options(m, kNoise));
    ExpectFinite(fit);
    EXPECT_NE(fit.status, TexelFitStatus::kFailed);
    EXPECT_EQ(fit.samples_used, 64);
    EXPECT_LT(fit.rms_error, 2.0f * kNoise);
  }
  // Below the horizon (light or camera): dropped, not fitted.
  std::vector<BrdfSample> below = Render(FromParams(truth), DomeRig(4, 16), kNoise, rng);
  for (BrdfSample& s : below) s.light_dir.z() = -s.light_dir.z();
  EXPECT_EQ(FitBrdfTexel(below, Options(BrdfFitMethod::kFast, kNoise)).samples_used, 0);
}

TEST(BrdfFit, SaturatedSamplesAreDropped) {
  // A glossy highlight clipped at 0.3 by the sensor: kept, the clipped values pull rho_s and k
  // down; dropped (saturation_radiance), the lobe is fitted from its unclipped flanks.
  const LafortuneParams truth = Params({0.05f, 0.05f, 0.05f}, {2, 2, 2}, -1, -1, 40);
  const Rig rig = DomeRig(4, 64);
  std::mt19937 rng(101);
  std::vector<BrdfSample> samples = Render(FromParams(truth), rig, kNoise, rng);
  int clipped = 0;
  for (BrdfSample& s : samples)
    if (s.radiance.maxCoeff() >= 0.3f) {
      s.radiance = s.radiance.cwiseMin(0.3f);
      ++clipped;
    }
  ASSERT_GT(clipped, 3);
  BrdfFitOptions keep = Options(BrdfFitMethod::kFast, kNoise), drop = keep;
  drop.saturation_radiance = 0.3;
  const TexelFit kept = FitBrdfTexel(samples, keep), dropped = FitBrdfTexel(samples, drop);
  EXPECT_EQ(dropped.samples_saturated, clipped);
  EXPECT_EQ(dropped.samples_used, static_cast<int>(samples.size()) - clipped);
  ExpectFinite(kept);
  ExpectFinite(dropped);
  std::mt19937 held1(99), held2(99);
  const double relight_kept = RelightingRmse(FromParams(truth), kept.params, rig, held1);
  const double relight_dropped = RelightingRmse(FromParams(truth), dropped.params, rig, held2);
  std::printf("clipped highlight: relighting RMSE kept %.5f, dropped %.5f\n", relight_kept,
              relight_dropped);
  EXPECT_LT(relight_dropped, relight_kept);
  EXPECT_NEAR(std::log(dropped.params.k / truth.k), 0.0, 0.2);
}

TEST(BrdfFit, NonFiniteSamplesAreFilteredOut) {
  const LafortuneParams truth = Params({0.1f, 0.1f, 0.1f}, {0.5f, 0.5f, 0.5f}, -1, -1, 10);
  std::mt19937 rng(111);
  const std::vector<BrdfSample> clean = Render(FromParams(truth), DomeRig(4, 16), kNoise, rng);
  std::vector<BrdfSample> dirty = clean;
  const float nan = std::numeric_limits<float>::quiet_NaN(),
              inf = std::numeric_limits<float>::infinity();
  BrdfSample bad = clean[0];
  bad.radiance.y() = nan;
  dirty.insert(dirty.begin() + 3, bad);
  bad = clean[1];
  bad.view_dir.x() = inf;
  dirty.insert(dirty.begin() + 10, bad);
  bad = clean[2];
  bad.irradiance = Vec3f(nan, nan, nan);
  dirty.push_back(bad);
  bad = clean[3];
  bad.irradiance = Vec3f::Zero();  // no light: no information
  dirty.push_back(bad);
  bad = clean[4];
  bad.light_dir = Vec3f::Zero();
  dirty.push_back(bad);
  for (BrdfFitMethod m : {BrdfFitMethod::kFast, BrdfFitMethod::kCeresReference}) {
    const TexelFit a = FitBrdfTexel(clean, Options(m, kNoise)),
                   b = FitBrdfTexel(dirty, Options(m, kNoise));
    EXPECT_EQ(b.samples_used, static_cast<int>(clean.size()));
    // The same valid samples in the same order: the same fit, bit for bit.
    EXPECT_EQ(a.params.rho_d, b.params.rho_d);
    EXPECT_EQ(a.params.rho_s, b.params.rho_s);
    EXPECT_EQ(a.params.k, b.params.k);
    ExpectFinite(b);
  }
}

// Directions of other lengths are normalised, among samples the fit drops (a direction that
// normalises to below the surface, a saturated one) and keeps: the same fit as from the unit
// directions. Scaling by a power of two is exact, so normalising gives back the unit vectors to
// a rounding or two; the tolerance is a few float roundings of the fitted parameters.
TEST(BrdfFit, DirectionsOfAnyLengthAreNormalised) {
  const LafortuneParams truth = Params({0.1f, 0.1f, 0.1f}, {0.5f, 0.5f, 0.5f}, -1, -1, 10);
  std::mt19937 rng(113);
  const std::vector<BrdfSample> clean = Render(FromParams(truth), DomeRig(4, 16), kNoise, rng);
  std::vector<BrdfSample> scaled;
  for (size_t i = 0; i < clean.size(); ++i) {
    BrdfSample s = clean[i];
    if (i % 3 == 0) s.view_dir *= 4.0f;
    if (i % 5 == 1) s.light_dir *= 0.25f;
    scaled.push_back(s);
    if (i == 7) {  // z so small next to x that it normalises to 0: below the surface
      BrdfSample flat = clean[i];
      flat.view_dir = Vec3f(3e30f, 0.0f, 1e-30f);
      scaled.push_back(flat);
    }
    if (i == 11) {  // a saturated one with long directions: counted as saturated
      BrdfSample bright = clean[i];
      bright.view_dir *= 2.0f;
      bright.radiance.setConstant(10.0f);
      scaled.push_back(bright);
    }
  }
  BrdfFitOptions options = Options(BrdfFitMethod::kFast, kNoise);
  options.saturation_radiance = 5.0;
  const TexelFit a = FitBrdfTexel(clean, options), b = FitBrdfTexel(scaled, options);
  EXPECT_EQ(b.samples_used, static_cast<int>(clean.size()));
  EXPECT_EQ(b.samples_saturated, 1);
  EXPECT_EQ(a.status, b.status);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(a.params.rho_d[c], b.params.rho_d[c], 1e-5f * a.params.rho_d[c]);
    EXPECT_NEAR(a.params.rho_s[c], b.params.rho_s[c], 1e-4f * a.params.rho_s[c]);
  }
  EXPECT_NEAR(a.params.k, b.params.k, 1e-4f * a.params.k);
  ExpectFinite(b);
}

TEST(BrdfFit, MeasuredPaintIsApproximated) {
  // Ground truth the one-lobe model cannot match: Lafortune et al.'s 3-lobe fits of measured
  // paints and felt (per-channel lobe shapes, retro-reflection). The fit must stay finite, beat
  // a diffuse-only fit, and its relighting error is reported (docs/benchmarks.md quotes it).
  const std::filesystem::path path = std::filesystem::path(DIGITIZE_SOURCE_DIR).parent_path() /
                                     "shared" / "data" / "lafortune_measured_fits.txt";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "no " << path;
  Result<std::vector<MeasuredLafortune>> fits = ReadMeasuredLafortuneFits(path);
  ASSERT_TRUE(fits.ok()) << fits.error().message;
  const Rig rig = DomeRig(4, 64);
  for (const MeasuredLafortune& m : *fits) {
    const Brdf truth = [&m](const Vec3f& v, const Vec3f& l) {
      return EvaluateMeasuredLafortune(m, v, l);
    };
    std::mt19937 rng(121);
    const std::vector<BrdfSample> samples = Render(truth, rig, kNoise, rng);
    const TexelFit fit = FitBrdfTexel(samples, Options(BrdfFitMethod::kFast, kNoise));
    BrdfFitOptions diffuse_only = Options(BrdfFitMethod::kFast, kNoise);
    diffuse_only.diffuse_chi2_sigmas = 1e12;  // every texel "explained" by its diffuse fit
    const TexelFit diffuse = FitBrdfTexel(samples, diffuse_only);
    ASSERT_EQ(diffuse.status, TexelFitStatus::kDiffuseOnly);
    ExpectFinite(fit);
    EXPECT_NE(fit.status, TexelFitStatus::kFailed);
    std::mt19937 held(99), held2(99), held3(99);
    const double relight = RelightingRmse(truth, fit, rig, held);
    const double relight_diffuse = RelightingRmse(truth, diffuse.params, rig, held2);
    // Signal scale: RMS of f (n.l) over the same held-out directions.
    const double signal = RelightingRmse(truth, LafortuneParams{}, rig, held3);
    std::printf("%s: %s fit %s: relighting RMSE %.5f (diffuse-only %.5f, signal RMS %.5f)\n",
                m.name.c_str(), ToString(fit.model), ToString(fit.status), relight, relight_diffuse,
                signal);
    EXPECT_LE(relight, relight_diffuse * 1.001);
    EXPECT_LT(relight, 0.6 * signal);  // primer's per-channel lobes are the worst case (~0.55)
  }
}

TEST(BrdfFit, EmptyTexelFallsBackToZeros) {
  for (BrdfFitMethod m : {BrdfFitMethod::kFast, BrdfFitMethod::kCeresReference}) {
    const TexelFit fit = FitBrdfTexel({}, Options(m, kNoise));
    EXPECT_EQ(fit.status, TexelFitStatus::kTooFewSamples);
    EXPECT_EQ(fit.samples_used, 0);
    EXPECT_EQ(fit.params.rho_d, Vec3f::Zero());
    EXPECT_EQ(fit.params.rho_s, Vec3f::Zero());
    ExpectFinite(fit);
  }
}

// ---------------------------------------------------------------------------------------------
// The many-texel entry point.

BrdfSamples MixedTexels(int texels, uint32_t seed) {
  const Rig rig = DomeRig(4, 16);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  BrdfSamples all;
  for (int t = 0; t < texels; ++t) {
    const int kind = t % 4;
    if (kind == 3) {
      const std::vector<BrdfSample> few = Render(FromParams({}), rig, kNoise, rng);
      all.AddTexel(std::span(few).first(t % 7));  // too few
      continue;
    }
    const LafortuneParams truth =
        Params(Vec3f::Constant(0.05f + 0.1f * u(rng)),
               Vec3f::Constant(kind == 0 ? 0.0f : 0.3f + u(rng)), -1, -1, 5.0f + 50.0f * u(rng));
    all.AddTexel(Render(FromParams(truth), rig, kNoise, rng));
  }
  return all;
}

TEST(BrdfFit, FitBrdfReportsEveryTexel) {
  const BrdfSamples samples = MixedTexels(200, 131);
  for (BrdfFitMethod m : {BrdfFitMethod::kFast, BrdfFitMethod::kCeresReference}) {
    std::vector<double> fractions;
    Result<BrdfFitResult> r =
        FitBrdf(samples, Options(m, kNoise), [&](std::string_view step, double f) {
          EXPECT_EQ(step, "fit");
          fractions.push_back(f);
        });
    ASSERT_TRUE(r.ok()) << r.error().message;
    ASSERT_EQ(r->params.size(), 200u);
    ASSERT_EQ(r->status.size(), 200u);
    ASSERT_EQ(r->rms_error.size(), 200u);
    const BrdfFitSummary& s = r->summary;
    size_t total = 0;
    for (size_t n : s.count_by_status) total += n;
    EXPECT_EQ(total, 200u);
    EXPECT_EQ(s.count(TexelFitStatus::kTooFewSamples), 50u);
    EXPECT_GE(s.count(TexelFitStatus::kDiffuseOnly), 45u);  // the 50 matte texels, but noise
    EXPECT_EQ(s.count(TexelFitStatus::kFailed), 0u);
    EXPECT_EQ(s.samples_total, samples.samples.size());
    for (size_t t = 0; t < 200; ++t) EXPECT_TRUE(r->params[t].Validate().ok()) << t;
    ASSERT_FALSE(fractions.empty());
    EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()));
    EXPECT_EQ(fractions.front(), 0.0);
    EXPECT_EQ(fractions.back(), 1.0);
    const std::string brief = s.BriefReport();
    std::printf("%s\n", brief.c_str());
    EXPECT_NE(brief.find("% converged"), std::string::npos) << brief;
    EXPECT_NE(brief.find("% too few samples"), std::string::npos) << brief;
    EXPECT_NE(brief.find(" s"), std::string::npos) << brief;
  }
}

TEST(BrdfFit, ThreadCountDoesNotChangeTheResult) {
  const BrdfSamples samples = MixedTexels(300, 141);
  BrdfFitOptions one = Options(BrdfFitMethod::kFast, kNoise), two = one;
  one.num_threads = 1;
  two.num_threads = 2;
  Result<BrdfFitResult> a = FitBrdf(samples, one), b = FitBrdf(samples, two);
  ASSERT_TRUE(a.ok() && b.ok());
  for (size_t t = 0; t < a->params.size(); ++t) {
    ASSERT_EQ(a->params[t].rho_s, b->params[t].rho_s) << t;
    ASSERT_EQ(a->params[t].k, b->params[t].k) << t;
    ASSERT_EQ(a->status[t], b->status[t]) << t;
  }
}

// One fitter's scratch, reused from texel to texel (largest first, so later texels sit in a
// workspace sized for another), must not change any texel's fit: each equals a fresh
// FitBrdfTexel, bit for bit, GGX candidates and 8-bit sRGB weights included.
TEST(BrdfFit, AReusedFitterFitsEachTexelAsAFreshOne) {
  const BrdfSamples samples = MixedTexels(120, 77);
  BrdfFitOptions o = Options(BrdfFitMethod::kFast, kNoise);
  o.photo_code_max = 255;
  o.photo_codes_srgb = true;
  std::vector<size_t> order(samples.texel_count());
  for (size_t t = 0; t < order.size(); ++t) order[t] = t;
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return samples.Texel(a).size() > samples.Texel(b).size();
  });
  ASSERT_GT(samples.Texel(order.front()).size(), samples.Texel(order.back()).size() + 8);
  BrdfTexelFitter fitter(o);
  size_t lobes = 0;
  for (const size_t t : order) {
    const TexelFit a = fitter.Fit(samples.Texel(t)), b = FitBrdfTexel(samples.Texel(t), o);
    ASSERT_EQ(a.status, b.status) << t;
    ASSERT_EQ(a.model, b.model) << t;
    ASSERT_EQ(a.params.rho_d, b.params.rho_d) << t;
    ASSERT_EQ(a.params.rho_s, b.params.rho_s) << t;
    ASSERT_EQ(a.params.k, b.params.k) << t;
    ASSERT_EQ(a.ggx.alpha, b.ggx.alpha) << t;
    ASSERT_EQ(a.ggx.f0, b.ggx.f0) << t;
    ASSERT_EQ(a.rms_error, b.rms_error) << t;
    lobes += a.params.rho_s.maxCoeff() > 0 || a.model == ReflectanceModel::kGgx;
  }
  EXPECT_GT(lobes, 10u);  // the texels exercise the lobe solvers, not only the diffuse test
}

TEST(BrdfFit, EmptyInputAndBadInputs) {
  Result<BrdfFitResult> empty = FitBrdf(BrdfSamples{}, BrdfFitOptions{});
  ASSERT_TRUE(empty.ok());
  EXPECT_TRUE(empty->params.empty());
  EXPECT_EQ(empty->summary.texels, 0u);
  EXPECT_NE(empty->summary.BriefReport().find("0.0 % converged"), std::string::npos);

  BrdfSamples broken = MixedTexels(4, 1);
  broken.texel_begin[2] = broken.texel_begin[1] - 1;
  Result<BrdfFitResult> r = FitBrdf(broken, BrdfFitOptions{});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("texel_begin decreases at texel 1"), std::string::npos)
      << r.error().message;
  broken = MixedTexels(4, 1);
  broken.texel_begin.back() += 1;
  EXPECT_FALSE(FitBrdf(broken, BrdfFitOptions{}).ok());

  struct Bad {
    void (*set)(BrdfFitOptions&);
    const char* name;
  } bad[] = {
      {[](BrdfFitOptions& o) { o.min_samples = 0; }, "min_samples"},
      {[](BrdfFitOptions& o) { o.noise_sigma = -1; }, "noise_sigma"},
      {[](BrdfFitOptions& o) { o.noise_sigma = std::nan(""); }, "noise_sigma"},
      {[](BrdfFitOptions& o) { o.diffuse_chi2_sigmas = std::numeric_limits<double>::infinity(); },
       "diffuse_chi2_sigmas"},
      {[](BrdfFitOptions& o) { o.saturation_radiance = 0; }, "saturation_radiance"},
      {[](BrdfFitOptions& o) { o.k_min = 0.1; }, "k_min"},
      {[](BrdfFitOptions& o) { o.k_max = 0.4; }, "k_max"},
      {[](BrdfFitOptions& o) { o.k_max = 1e9; }, "k_max"},
      {[](BrdfFitOptions& o) { o.max_specular_albedo = 0; }, "max_specular_albedo"},
      {[](BrdfFitOptions& o) { o.specular_prior_weight = -1; }, "specular_prior_weight"},
      {[](BrdfFitOptions& o) { o.lobe_prior_weight = -1; }, "lobe_prior_weight"},
      {[](BrdfFitOptions& o) { o.max_iterations = 0; }, "max_iterations"},
      {[](BrdfFitOptions& o) { o.num_threads = -1; }, "num_threads"},
  };
  for (const Bad& b : bad) {
    BrdfFitOptions o;
    b.set(o);
    const Status s = o.Validate();
    EXPECT_FALSE(s.ok()) << b.name;
    EXPECT_NE(s.message().find(b.name), std::string::npos) << s.message();
    EXPECT_FALSE(FitBrdf(MixedTexels(2, 1), o).ok()) << b.name;
    EXPECT_THROW(FitBrdfTexel({}, o), InvariantError) << b.name;
  }
}

}  // namespace
}  // namespace digitize
