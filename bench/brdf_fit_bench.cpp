// Per-texel Lafortune fit benchmark (docs/benchmarks.md, "BRDF fit core"): fit time per texel of
// the ceres::Solve reference path against the fast variable-projection path, on the same synthetic
// texels, with the relighting error of each side by side. Written as CSV (docs/bench_brdf_fit.csv).
//
// Texels: a dome rig of 4 cameras (50 deg elevation) x 16 point lights (Fibonacci dome above
// 15 deg) = 64 samples per texel, turned by a random azimuth per texel; ground truth per texel
// drawn like a painting's regions: 20 % matte (rho_s = 0), the rest one Lafortune lobe with k
// log-uniform in [2, 500], cx, cy in [-1, -0.85], specular albedo 0.02-0.3; Gaussian noise
// sigma = 0.002 on radiance (I = 1), plus a noise-free run. Relighting error: RMSE of f_r (n.l)
// over 16 held-out (view, light) pairs per texel, same elevation range, I = 1.
//
// Two truths and two candidate sets. Truth "lafortune" is the above; truth "ggx" draws paints
// that follow GGX (ggx.h): 20 % Lambertian, 20 % metal (rho_d = 0, coloured F0 0.5-1), the rest
// dielectric (F0 0.04 over rho_d as above), alpha log-uniform in [0.03, 0.6]. Models
// "lafortune" is the one-lobe fit alone (as before GGX existed: fit_ggx = false), "select" the
// default per-texel choice between diffuse, Lafortune and GGX (brdf_fit.h, MODEL CHOICE).
//
//   brdf_fit_bench [--texels=20000] [--threads=2] [--csv-dir=docs] [google benchmark flags]
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "digitize/brdf_fit.h"
#include "digitize/ggx.h"
#include "digitize/lafortune.h"

namespace {

using namespace digitize;

constexpr float kPi = 3.14159265358979f;
constexpr float kMinElevationDeg = 15.0f;
constexpr int kHeldOutPerTexel = 16;

int g_texels = 20000;
int g_threads = 2;

Vec3f RotateZ(const Vec3f& d, float angle) {
  return {std::cos(angle) * d.x() - std::sin(angle) * d.y(),
          std::sin(angle) * d.x() + std::cos(angle) * d.y(), d.z()};
}

enum class Truth { kLafortune, kGgx };

struct TruthBrdf {
  bool ggx = false;
  LafortuneParams lafortune;
  GgxParams g;
  Vec3f Evaluate(const Vec3f& v, const Vec3f& l) const {
    return ggx ? EvaluateGgx(g, v, l) : EvaluateLafortune(lafortune, v, l);
  }
  bool has_lobe() const { return ggx || lafortune.rho_s.maxCoeff() > 0; }
};

struct Dataset {
  BrdfSamples samples;
  std::vector<TruthBrdf> truth;
  std::vector<Vec3f> held_out_view, held_out_light;  // kHeldOutPerTexel per texel
};

Dataset MakeDataset(Truth kind, int texels, float noise_sigma, uint32_t seed) {
  std::vector<Vec3f> lights, views;
  const float z_min = std::sin(kMinElevationDeg * kPi / 180.0f);
  const float golden = kPi * (3.0f - std::sqrt(5.0f));
  for (int i = 0; i < 16; ++i) {
    const float z = 1.0f - (1.0f - z_min) * (i + 0.5f) / 16;
    const float r = std::sqrt(1.0f - z * z);
    lights.emplace_back(r * std::cos(golden * i), r * std::sin(golden * i), z);
  }
  for (int i = 0; i < 4; ++i) {
    const float e = 50.0f * kPi / 180.0f, a = 2.0f * kPi * i / 4 + 0.3f;
    views.emplace_back(std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e));
  }
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::normal_distribution<float> noise(0.0f, 1.0f);
  const auto random_dir = [&] {
    const float z = z_min + (1.0f - z_min) * u(rng), phi = 2.0f * kPi * u(rng);
    const float r = std::sqrt(1.0f - z * z);
    return Vec3f(r * std::cos(phi), r * std::sin(phi), z);
  };
  Dataset d;
  d.samples.samples.reserve(static_cast<size_t>(texels) * 64);
  std::vector<BrdfSample> texel;
  for (int t = 0; t < texels; ++t) {
    TruthBrdf truth;
    LafortuneParams& p = truth.lafortune;
    p.rho_d = Vec3f(0.02f + 0.18f * u(rng), 0.02f + 0.18f * u(rng), 0.02f + 0.18f * u(rng));
    if (kind == Truth::kGgx) {
      const float pick = u(rng);
      if (pick >= 0.2f) {
        truth.ggx = true;
        truth.g.alpha = 0.03f * std::pow(20.0f, u(rng));
        truth.g.rho_d = p.rho_d;
        truth.g.f0 = Vec3f::Constant(0.04f);
        if (pick < 0.4f) {  // a metal
          truth.g.rho_d = Vec3f::Zero();
          truth.g.f0 = Vec3f(0.5f + 0.5f * u(rng), 0.5f + 0.5f * u(rng), 0.5f + 0.5f * u(rng));
        }
      }
    } else if (u(rng) >= 0.2f) {
      p.k = 2.0f * std::pow(250.0f, u(rng));
      p.cx = -1.0f + 0.15f * u(rng);
      p.cy = -1.0f + 0.15f * u(rng);
      const float albedo = 0.02f + 0.28f * u(rng);
      p.rho_s = Vec3f::Constant(albedo * (p.k + 2.0f) / (2.0f * kPi));
      for (int c = 0; c < 3; ++c) p.rho_s[c] *= 0.9f + 0.2f * u(rng);
    }
    d.truth.push_back(truth);
    const float azimuth = 2.0f * kPi * u(rng);
    texel.clear();
    for (const Vec3f& view : views)
      for (const Vec3f& light : lights) {
        BrdfSample s;
        s.view_dir = RotateZ(view, azimuth);
        s.light_dir = RotateZ(light, azimuth);
        s.irradiance = Vec3f::Constant(s.light_dir.z());
        s.radiance = truth.Evaluate(s.view_dir, s.light_dir).cwiseProduct(s.irradiance);
        for (int c = 0; c < 3; ++c) s.radiance[c] += noise_sigma * noise(rng);
        texel.push_back(s);
      }
    d.samples.AddTexel(texel);
    for (int i = 0; i < kHeldOutPerTexel; ++i) {
      d.held_out_view.push_back(random_dir());
      d.held_out_light.push_back(random_dir());
    }
  }
  return d;
}

struct Row {
  std::string truth, models;
  std::string method;
  float noise_sigma = 0;
  double seconds = 0, cpu_seconds = 0;
  double relight_rmse = 0, relight_median = 0, relight_p90 = 0, relight_p99 = 0,
         param_log_k_median = 0;
  BrdfFitSummary summary;
};
std::vector<Row> g_rows;

Vec3f EvaluateFit(const BrdfFitResult& r, size_t t, const Vec3f& v, const Vec3f& l) {
  return r.model[t] == ReflectanceModel::kGgx ? EvaluateGgx(r.ggx[t], v, l)
                                              : EvaluateLafortune(r.params[t], v, l);
}

// Global RMSE over texels x held-out pairs x channels, and the per-texel median and 90th
// percentile, of f_r (n.l).
void MeasureRelighting(const Dataset& d, const BrdfFitResult& r, Row* row) {
  double sum = 0;
  std::vector<double> per_texel(d.truth.size());
  std::vector<double> log_k_error;
  for (size_t t = 0; t < d.truth.size(); ++t) {
    double texel_sum = 0;
    for (int i = 0; i < kHeldOutPerTexel; ++i) {
      const Vec3f& v = d.held_out_view[t * kHeldOutPerTexel + i];
      const Vec3f& l = d.held_out_light[t * kHeldOutPerTexel + i];
      texel_sum += ((EvaluateFit(r, t, v, l) - d.truth[t].Evaluate(v, l)) * l.z()).squaredNorm();
    }
    sum += texel_sum;
    per_texel[t] = std::sqrt(texel_sum / (3.0 * kHeldOutPerTexel));
    const LafortuneParams& truth = d.truth[t].lafortune;
    if (!d.truth[t].ggx && truth.rho_s.maxCoeff() > 0 &&
        r.model[t] == ReflectanceModel::kLafortune && r.params[t].rho_s.maxCoeff() > 0)
      log_k_error.push_back(std::abs(std::log(r.params[t].k / truth.k)));
  }
  row->relight_rmse = std::sqrt(sum / (3.0 * kHeldOutPerTexel * d.truth.size()));
  std::sort(per_texel.begin(), per_texel.end());
  row->relight_median = per_texel[per_texel.size() / 2];
  row->relight_p90 = per_texel[per_texel.size() * 9 / 10];
  row->relight_p99 = per_texel[per_texel.size() * 99 / 100];
  if (!log_k_error.empty()) {
    std::sort(log_k_error.begin(), log_k_error.end());
    row->param_log_k_median = log_k_error[log_k_error.size() / 2];
  }
}

void BM_Fit(benchmark::State& state, Truth truth, bool select, BrdfFitMethod method,
            float noise_sigma) {
  const Dataset d = MakeDataset(truth, g_texels, noise_sigma, 1234);
  BrdfFitOptions options;
  options.method = method;
  options.fit_ggx = select;
  options.noise_sigma = std::max(noise_sigma, 1e-4f);  // noise-free: a floor for the chi2 test
  options.num_threads = g_threads;
  BrdfFitResult last;
  double seconds = 0;
  const std::clock_t cpu_start = std::clock();
  for (auto _ : state) {
    Result<BrdfFitResult> r = FitBrdf(d.samples, options);
    if (!r.ok()) {
      state.SkipWithError(r.error().message.c_str());
      return;
    }
    last = std::move(r).value();
    seconds += last.summary.seconds;
  }
  Row row;
  // Process CPU time of all threads: on a machine shared with other jobs, wall time stretches
  // while CPU time per texel stays the work done (wall = CPU / threads when the cores are free).
  row.cpu_seconds = static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC /
                    static_cast<double>(state.iterations());
  row.method = method == BrdfFitMethod::kFast ? "fast" : "ceres";
  row.truth = truth == Truth::kGgx ? "ggx" : "lafortune";
  row.models = select ? "select" : "lafortune";
  row.noise_sigma = noise_sigma;
  row.seconds = seconds / static_cast<double>(state.iterations());
  row.summary = last.summary;
  MeasureRelighting(d, last, &row);
  state.counters["us_per_texel"] = 1e6 * row.seconds / g_texels;
  state.counters["cpu_us_per_texel"] = 1e6 * row.cpu_seconds / g_texels;
  state.counters["relight_rmse"] = row.relight_rmse;
  state.counters["relight_median"] = row.relight_median;
  state.counters["mean_iters"] = last.summary.mean_iterations;
  state.SetLabel(last.summary.BriefReport());
  g_rows.push_back(row);
}

void WriteCsv(const std::filesystem::path& path) {
  std::ostringstream out;
  out << "truth,models,method,noise_sigma,texels,samples_per_texel,threads,seconds,us_per_texel,"
         "cpu_us_per_"
         "texel,relight_rmse,"
         "relight_median_texel,relight_p90_texel,relight_p99_texel,log_k_error_median,converged_"
         "pct,diffuse_only_pct,"
         "too_few_pct,clamped_k_pct,iteration_limit_pct,failed_pct,mean_iterations,lafortune_lobe_"
         "pct,"
         "ggx_lobe_pct\n";
  for (const Row& r : g_rows) {
    const BrdfFitSummary& s = r.summary;
    out << r.truth << "," << r.models << "," << r.method << "," << r.noise_sigma << "," << s.texels
        << "," << (s.texels ? s.samples_total / s.texels : 0) << "," << g_threads << ","
        << r.seconds << "," << 1e6 * r.seconds / static_cast<double>(s.texels) << ","
        << 1e6 * r.cpu_seconds / static_cast<double>(s.texels) << "," << r.relight_rmse << ","
        << r.relight_median << "," << r.relight_p90 << "," << r.relight_p99 << ","
        << r.param_log_k_median;
    for (int i = 0; i < kTexelFitStatusCount; ++i)
      out << ","
          << 100.0 * static_cast<double>(s.count_by_status[i]) / static_cast<double>(s.texels);
    out << "," << s.mean_iterations;
    for (int m = 0; m < kReflectanceModelCount; ++m)
      out << ","
          << 100.0 * static_cast<double>(s.lobes_by_model[m]) / static_cast<double>(s.texels);
    out << "\n";
  }
  std::ofstream(path) << out.str();
  std::printf("wrote %s\n", path.c_str());
}

void PrintSideBySide() {
  // One heading per column of the rows below (they were two short: printf read past them).
  std::printf("\n%-9s %-9s %-6s %-7s %9s %13s %13s %15s %12s %12s  %s\n", "truth", "models",
              "method", "noise", "us/texel", "CPU us/texel", "relight RMSE", "median (texel)",
              "p90 (texel)", "p99 (texel)", "brief");
  for (const Row& r : g_rows)
    std::printf("%-9s %-9s %-6s %-7.4f %9.2f %13.2f %13.5f %15.5f %12.5f %12.5f  %s\n",
                r.truth.c_str(), r.models.c_str(), r.method.c_str(), r.noise_sigma,
                1e6 * r.seconds / static_cast<double>(r.summary.texels),
                1e6 * r.cpu_seconds / static_cast<double>(r.summary.texels), r.relight_rmse,
                r.relight_median, r.relight_p90, r.relight_p99, r.summary.BriefReport().c_str());
}

}  // namespace

int main(int argc, char** argv) {
  std::filesystem::path csv_dir = "docs";
  std::vector<char*> rest;
  for (int i = 0; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg.rfind("--texels=", 0) == 0)
      g_texels = std::max(1, std::stoi(arg.substr(9)));
    else if (arg.rfind("--threads=", 0) == 0)
      g_threads = std::max(0, std::stoi(arg.substr(10)));
    else if (arg.rfind("--csv-dir=", 0) == 0)
      csv_dir = arg.substr(10);
    else
      rest.push_back(argv[i]);
  }
  for (Truth truth : {Truth::kLafortune, Truth::kGgx})
    for (bool select : {false, true})
      for (float noise : {0.002f, 0.0f}) {
        const std::string suffix = std::string(truth == Truth::kGgx ? "/truth_ggx" : "") +
                                   (select ? "/select" : "/lafortune") +
                                   (noise > 0 ? "/noise_0.002" : "/noise_free");
        benchmark::RegisterBenchmark(("brdf_fit/fast" + suffix).c_str(), BM_Fit, truth, select,
                                     BrdfFitMethod::kFast, noise)
            ->Unit(benchmark::kMillisecond)
            ->Iterations(5)
            ->UseRealTime();
        benchmark::RegisterBenchmark(("brdf_fit/ceres" + suffix).c_str(), BM_Fit, truth, select,
                                     BrdfFitMethod::kCeresReference, noise)
            ->Unit(benchmark::kMillisecond)
            ->Iterations(1)
            ->UseRealTime();
      }
  int rest_argc = static_cast<int>(rest.size());
  benchmark::Initialize(&rest_argc, rest.data());
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  PrintSideBySide();
  if (!g_rows.empty()) {
    std::filesystem::create_directories(csv_dir);
    WriteCsv(csv_dir / "bench_brdf_fit.csv");
  }
  return 0;
}
