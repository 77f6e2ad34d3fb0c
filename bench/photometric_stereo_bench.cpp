// Photometric stereo and normal integration: speed on a synthetic RTI capture the size of a
// handheld one (0.2 Mpx x 54 images), and a look at a real capture.
//
//   photometric_stereo_bench                       the benchmarks
//   photometric_stereo_bench --lp dirs.lp OUT_DIR  solves a real capture: prints the intensities,
//                                                  writes OUT_DIR/normals.png (RGB = (n + 1) / 2),
//                                                  normals_x4.png (tilt x 4), albedo.png and
//                                                  height.png (integrated, scaled)
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "digitize/image_io.h"
#include "digitize/normal_integration.h"
#include "digitize/photo_set.h"
#include "digitize/photometric_stereo.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/rti_sim.h"

namespace {

using namespace digitize;

// CPU seconds of the whole process (all threads): the machine the benchmarks run on may be
// shared, and the wall time then says little.
double ProcessCpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_utime.tv_sec + u.ru_stime.tv_sec + 1e-6 * (u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

const synth::SyntheticRtiCapture& Capture() {
  static const synth::SyntheticRtiCapture cap = [] {
    synth::PaintingOptions po;
    po.width_mm = 128;
    po.height_mm = 100;
    po.resolution_px = 512;  // 512 x 400 = 0.2 Mpx
    synth::RtiSimOptions o;
    o.lights = 54;
    return synth::SimulateRti(synth::MakePainting(po), o);
  }();
  return cap;
}

std::vector<PhotometricImage> Images(const synth::SyntheticRtiCapture& cap) {
  std::vector<PhotometricImage> v;
  for (size_t i = 0; i < cap.images.size(); ++i) {
    PhotometricImage im;
    im.rgb = &cap.images[i];
    im.light = cap.nominal_directions[i];
    v.push_back(im);
  }
  return v;
}

void BM_PhotometricStereo(benchmark::State& state) {
  const auto images = Images(Capture());
  PhotometricStereoOptions o;
  o.num_threads = static_cast<int>(state.range(0));
  o.estimate_intensities = state.range(1) != 0;
  double cpu = 0;
  for (auto _ : state) {
    const double t0 = ProcessCpuSeconds();
    auto r = SolvePhotometricStereo(images, o);
    cpu += ProcessCpuSeconds() - t0;
    benchmark::DoNotOptimize(r);
  }
  state.counters["Mpx"] = Capture().images[0].size() / 1e6;
  state.counters["images"] = static_cast<double>(images.size());
  state.counters["cpu_s"] = benchmark::Counter(cpu, benchmark::Counter::kAvgIterations);
}
BENCHMARK(BM_PhotometricStereo)
    ->Args({2, 1})
    ->Args({2, 0})
    ->Args({1, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_IntegrateNormals(benchmark::State& state) {
  const auto& cap = Capture();
  NormalIntegrationOptions o;
  o.method = state.range(0) ? NormalIntegrationMethod::kFrankotChellappa
                            : NormalIntegrationMethod::kPoisson;
  for (auto _ : state) {
    auto r = IntegrateNormals(cap.normals, cap.pitch_mm, nullptr, nullptr, o);
    benchmark::DoNotOptimize(r);
  }
}
BENCHMARK(BM_IntegrateNormals)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

Grid<std::array<uint8_t, 3>> ToPng(int w, int h, const auto& value) {
  Grid<std::array<uint8_t, 3>> out(w, h, {0, 0, 0});
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Vec3f v = value(x, y);
      for (int c = 0; c < 3; ++c)
        out(x, y)[c] = static_cast<uint8_t>(std::lround(std::clamp(v[c], 0.0f, 1.0f) * 255));
    }
  return out;
}

int SolveRealCapture(const std::filesystem::path& lp, const std::filesystem::path& out_dir) {
  auto set = ReadRtiCapture(lp);
  if (!set.ok()) {
    std::fprintf(stderr, "%s\n", set.error().message.c_str());
    return 1;
  }
  std::vector<PhotometricImage> images;
  for (const Photo& p : set->photos) {
    PhotometricImage im;
    im.rgb = &p.rgb;
    im.exclude = &p.flags;
    im.light = p.light.direction;
    images.push_back(im);
  }
  PhotometricStereoOptions o;
  o.pitch_mm = set->rti_pitch_mm;
  auto r = SolvePhotometricStereo(images, o);
  if (!r.ok()) {
    std::fprintf(stderr, "%s\n", r.error().message.c_str());
    return 1;
  }
  std::printf("%s\n", set->summary.Brief().c_str());
  std::printf("%s\n", r->Brief().c_str());
  std::printf("intensities:");
  for (double e : r->intensities) std::printf(" %.3f", e);
  std::printf("\n");
  const int w = r->normals.width, h = r->normals.height;
  std::filesystem::create_directories(out_dir);
  Status s = WritePngRgb8(out_dir / "normals.png", ToPng(w, h, [&](int x, int y) {
                            return Vec3f((r->normals(x, y) + Vec3f::Ones()) * 0.5f);
                          }));
  // The tilt x 4 (relief on a painting is shallow: the plain map is nearly uniform).
  if (s.ok())
    s = WritePngRgb8(out_dir / "normals_x4.png", ToPng(w, h, [&](int x, int y) {
                       const Vec3f n = r->normals(x, y);
                       return Vec3f(0.5f + 2 * n.x(), 0.5f + 2 * n.y(), n.z());
                     }));
  float max_albedo = 0;
  for (const Vec3f& a : r->albedo.data) max_albedo = std::max(max_albedo, a.maxCoeff());
  if (s.ok())
    s = WritePngRgb8(out_dir / "albedo.png", ToPng(w, h, [&](int x, int y) {
                       const Vec3f a = r->albedo(x, y) / std::max(max_albedo, 1e-6f);
                       return Vec3f(a.array().pow(1 / 2.2f));
                     }));
  Grid<uint8_t> mask(w, h, 0);
  for (size_t i = 0; i < mask.size(); ++i)
    mask.data[i] = r->status.data[i] == PhotometricStatus::kOk;
  auto z = IntegrateNormals(r->normals, set->rti_pitch_mm, &mask);
  if (s.ok() && z.ok()) {
    std::printf("%s\n", z->Brief().c_str());
    const auto [lo, hi] = std::minmax_element(z->height_mm.data.begin(), z->height_mm.data.end());
    std::printf("height %.3f .. %.3f mm (pitch %.4g mm, %s)\n", *lo, *hi, set->rti_pitch_mm,
                set->rti_pitch_source.c_str());
    s = WritePngRgb8(out_dir / "height.png", ToPng(w, h, [&](int x, int y) {
                       const float v = (z->height_mm(x, y) - *lo) / std::max(*hi - *lo, 1e-6f);
                       return Vec3f::Constant(v);
                     }));
  }
  if (!s.ok()) {
    std::fprintf(stderr, "%s\n", s.message().c_str());
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 4 && std::strcmp(argv[1], "--lp") == 0) return SolveRealCapture(argv[2], argv[3]);
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  return 0;
}
