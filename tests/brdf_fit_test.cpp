// Per-texel Lafortune fit on synthetic samples with known parameters: recovery, the fast path
// against ceres::Solve, and the degenerate and hostile cases of issue 3 ("Stress").
//
// The samples come from a dome rig rendered here: V cameras x L point lights (Fibonacci points on
// the hemisphere), turned by a random azimuth per texel, radiance = f_r (n.l) I + Gaussian noise
// (I = 1). Accuracy is judged as the issue asks, by relighting: the RMSE of f_r (n.l) over
// held-out directions (random, same elevation range as the rig; for a one-camera rig, that
// camera with held-out lights), in the same radiance units as the noise sigma.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <random>
#include <span>
#include <vector>

#include "digitize/brdf_fit.h"
#include "digitize/lafortune.h"

namespace digitize {
namespace {

constexpr float kPi = 3.14159265358979f;

Vec3f FromElevationAzimuth(float elevation_rad, float azimuth_rad) {
  return {std::cos(elevation_rad) * std::cos(azimuth_rad), std::cos(elevation_rad) * std::sin(azimuth_rad),
          std::sin(elevation_rad)};
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
      rig.views.push_back(FromElevationAzimuth(50.0f * kPi / 180.0f, 2.0f * kPi * i / views + 0.3f));
  }
  return rig;
}

using Brdf = std::function<Vec3f(const Vec3f& v, const Vec3f& l)>;

Brdf FromParams(const LafortuneParams& p) {
  return [p](const Vec3f& v, const Vec3f& l) { return EvaluateLafortune(p, v, l); };
}

Vec3f RotateZ(const Vec3f& d, float angle) {
  return {std::cos(angle) * d.x() - std::sin(angle) * d.y(), std::sin(angle) * d.x() + std::cos(angle) * d.y(), d.z()};
}

std::vector<BrdfSample> Render(const Brdf& brdf, const Rig& rig, float noise_sigma, std::mt19937& rng) {
  std::normal_distribution<float> noise(0.0f, 1.0f);
  const float azimuth = std::uniform_real_distribution<float>(0.0f, 2.0f * kPi)(rng);
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

// Relighting RMSE over held-out directions, radiance units (I = 1).
double RelightingRmse(const Brdf& truth, const LafortuneParams& fit, const Rig& rig, std::mt19937& rng,
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
    const Vec3f v = rig.views.size() == 1 ? RotateZ(rig.views[0], 2.0f * kPi * u(rng)) : random_dir();
    const Vec3f l = random_dir();
    const Vec3f diff = (EvaluateLafortune(fit, v, l) - truth(v, l)) * l.z();
    sum += diff.squaredNorm();
  }
  return std::sqrt(sum / (3.0 * count));
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

// Named tolerances (see each use for the reason of its size).
constexpr float kNoise = 0.002f;  // default sensor noise of the tests (radiance, I = 1)

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


TEST(BrdfFit, Explore) {
  const LafortuneParams truths[] = {
      Params({0.10f, 0.08f, 0.06f}, {0.15f, 0.15f, 0.15f}, -1.0f, -1.0f, 10.0f),
      Params({0.05f, 0.10f, 0.15f}, {0.8f, 0.8f, 0.8f}, -0.95f, -0.9f, 100.0f),
      Params({0.05f, 0.10f, 0.15f}, {0.3f, 0.2f, 0.1f}, -0.8f, -0.9f, 1.0f),
      Params({0.02f, 0.02f, 0.02f}, {5.0f, 5.0f, 5.0f}, -1.0f, -1.0f, 1000.0f),
      Params({0.15f, 0.10f, 0.05f}, {0, 0, 0}, -1.0f, -1.0f, 1.0f),
  };
  for (int views : {1, 4}) for (int lights : {16, 64}) {
    const Rig rig = DomeRig(views, lights);
    for (const LafortuneParams& truth : truths) {
      std::mt19937 rng(11);
      double rm[2] = {0, 0};
      for (int rep = 0; rep < 5; ++rep) {
        const auto samples = Render(FromParams(truth), rig, kNoise, rng);
        for (int m = 0; m < 2; ++m) {
          const TexelFit fit = FitBrdfTexel(samples, Options(m ? BrdfFitMethod::kCeresReference : BrdfFitMethod::kFast, kNoise));
          const double r = RelightingRmse(FromParams(truth), fit.params, rig, rng);
          rm[m] += r / 5;
          if (rep == 0)
            printf("V%d L%d k%6.1f %s: %-16s it %2d rms %.4f relight %.5f  rd %.3f %.3f %.3f rs %.3f %.3f %.3f c %.3f %.3f k %.2f\n",
                   views, lights, truth.k, m ? "ceres" : "fast ", ToString(fit.status), fit.iterations, fit.rms_error, r,
                   fit.params.rho_d.x(), fit.params.rho_d.y(), fit.params.rho_d.z(), fit.params.rho_s.x(),
                   fit.params.rho_s.y(), fit.params.rho_s.z(), fit.params.cx, fit.params.cy, fit.params.k);
        }
      }
      printf("   mean relight fast %.5f ceres %.5f\n", rm[0], rm[1]);
    }
  }
}

}  // namespace
}  // namespace digitize
namespace digitize {
TEST(BrdfFit, Debug1) {
  const LafortuneParams truth = Params({0.05f, 0.10f, 0.15f}, {0.8f, 0.8f, 0.8f}, -0.95f, -0.9f, 100.0f);
  const Rig rig = DomeRig(4, 64);
  std::mt19937 rng(11);
  const auto samples = Render(FromParams(truth), rig, kNoise, rng);
  const TexelFit fit = FitBrdfTexel(samples, Options(BrdfFitMethod::kFast, kNoise));
  printf("%s it %d\n", ToString(fit.status), fit.iterations);
}
}
