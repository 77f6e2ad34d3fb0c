// Preprocessing benchmark: run time per step against scan size, and accuracy against noise level,
// measured on synthetic paintings with ground truth. Google Benchmark times the whole pipeline;
// each run also records per-step times and the accuracy of its last iteration, written as CSV
// (docs/bench_preprocess_sizes.csv, docs/bench_preprocess_noise.csv) for bench/plot.gp.
//
//   preprocess_bench [--sizes=512,2048,4096,8192] [--csv-dir=docs] [google benchmark flags]
#include <benchmark/benchmark.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "digitize/preprocess.h"
#include "digitize/scan_io.h"
#include "digitize_synth/ground_truth.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/scan_sim.h"

namespace {

using namespace digitize;

struct Case {
  synth::Painting painting;
  std::unique_ptr<synth::Scene> scene;
  synth::SyntheticScan scan;
};

// The same synthetic painting at a given scan size; the painting's resolution matches the scan's
// sampling (synth::MatchedResolution) so the truth holds no detail the scan cannot resolve.
std::unique_ptr<Case> MakeCase(int scan_px, double noise_mm, uint64_t seed) {
  auto c = std::make_unique<Case>();
  synth::ScanSimOptions so;
  so.width_px = so.height_px = scan_px;
  so.noise_mm = noise_mm;
  so.seed = seed;
  synth::PaintingOptions po;
  po.resolution_px = synth::MatchedResolution(po, synth::FrameOptions{}, so);
  po.seed = seed;
  c->painting = synth::MakePainting(po);
  c->scene = std::make_unique<synth::Scene>(c->painting, synth::FrameOptions{});
  c->scan = synth::SimulateScan(*c->scene, so);
  return c;
}

struct Row {
  std::map<std::string, double> step_seconds;
  double total_seconds = 0, read_seconds = 0, write_seconds = 0;
  double noise_mm = 0;
  int scan_px = 0;
  size_t texels = 0;
  synth::PreprocessAccuracy accuracy;
};
std::vector<Row> g_size_rows, g_noise_rows;

const std::vector<std::string> kSteps = {"merge",    "sanitize", "canvas",
                                         "resample", "relief",   "normals"};

void RecordSteps(const PreprocessResult& r, Row& row, int iterations) {
  for (const StepReport& s : r.steps) row.step_seconds[s.name] += s.seconds / iterations;
  row.total_seconds += r.total_seconds / iterations;
}

// The timed loop of both benchmarks: the copy of the input scans is not preprocessing.
// Returns false (and marks the benchmark failed) on an error.
bool TimePreprocess(benchmark::State& state, const Case& c, PreprocessResult& last, Row* row) {
  const PreprocessOptions options;
  for (auto _ : state) {
    state.PauseTiming();
    std::vector<Scan> scans = c.scan.exposures;
    state.ResumeTiming();
    Result<PreprocessResult> r = Preprocess(std::move(scans), options);
    if (!r.ok()) {
      state.SkipWithError(r.error().message.c_str());
      return false;
    }
    last = std::move(r).value();
    if (row) RecordSteps(last, *row, static_cast<int>(state.max_iterations));
  }
  return true;
}

void BM_PreprocessSize(benchmark::State& state) {
  const int px = static_cast<int>(state.range(0));
  const auto c = MakeCase(px, 0.02, 7);
  Row row;
  row.scan_px = px;
  row.noise_mm = 0.02;
  PreprocessResult last;
  if (!TimePreprocess(state, *c, last, &row)) return;
  row.texels = last.field.height_mm.size();
  row.accuracy = synth::MeasureAccuracy(last, c->painting, c->scan);

  // I/O is reported apart from compute: write and read the scan as a float EXR.
  const auto path =
      std::filesystem::temp_directory_path() / ("digitize_bench_" + std::to_string(px) + ".exr");
  auto t0 = std::chrono::steady_clock::now();
  if (WriteScanExr(path, c->scan.exposures.front()).ok()) {
    row.write_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    t0 = std::chrono::steady_clock::now();
    Result<Scan> back = ReadScan(path, ScanReadOptions{});
    row.read_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::filesystem::remove(path);
  }
  for (const std::string& s : kSteps) state.counters[s + "_s"] = row.step_seconds[s];
  state.counters["read_exr_s"] = row.read_seconds;
  state.counters["iou"] = row.accuracy.mask_iou;
  state.counters["tilt_err_deg"] = row.accuracy.normal_error_deg;
  state.counters["rmse_mm"] = row.accuracy.height_rmse_mm;
  g_size_rows.push_back(row);
}

void BM_PreprocessNoise(benchmark::State& state) {
  const double noise_mm = static_cast<double>(state.range(0)) / 1000.0;
  const auto c = MakeCase(1024, noise_mm, 11);
  PreprocessResult last;
  if (!TimePreprocess(state, *c, last, nullptr)) return;
  Row row;
  row.scan_px = 1024;
  row.noise_mm = noise_mm;
  RecordSteps(last, row, 1);
  row.texels = last.field.height_mm.size();
  row.accuracy = synth::MeasureAccuracy(last, c->painting, c->scan);
  state.counters["iou"] = row.accuracy.mask_iou;
  state.counters["tilt_err_deg"] = row.accuracy.normal_error_deg;
  state.counters["rmse_mm"] = row.accuracy.height_rmse_mm;
  state.counters["normals_med_deg"] = row.accuracy.normals_median_deg;
  g_noise_rows.push_back(row);
}

void WriteCsv(const std::filesystem::path& path, const std::vector<Row>& rows) {
  std::ostringstream out;
  out << "scan_px,noise_mm,texels";
  for (const std::string& s : kSteps) out << "," << s << "_s";
  out << ",total_s,read_exr_s,write_exr_s,tilt_err_deg,mask_iou,frame_px_kept,height_rmse_mm,"
         "height_offset_mm,normals_median_deg,normals_p90_deg,relief_texels,relief_uncovered,"
         "frame_px_max_height_mm\n";
  for (const Row& r : rows) {
    out << r.scan_px << "," << r.noise_mm << "," << r.texels;
    for (const std::string& s : kSteps) out << "," << r.step_seconds.at(s);
    const auto& a = r.accuracy;
    out << "," << r.total_seconds << "," << r.read_seconds << "," << r.write_seconds << ","
        << a.normal_error_deg << "," << a.mask_iou << "," << a.frame_pixels_kept << ","
        << a.height_rmse_mm << "," << a.height_offset_mm << "," << a.normals_median_deg << ","
        << a.normals_p90_deg << "," << a.relief_texels_true << "," << a.relief_texels_uncovered
        << "," << a.frame_pixels_max_height_mm << "\n";
  }
  std::ofstream(path) << out.str();
  std::printf("wrote %s\n", path.c_str());
}

std::vector<int> ParseSizes(const std::string& text) {
  std::vector<int> sizes;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) sizes.push_back(std::stoi(item));
  return sizes;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<int> sizes = {512, 2048, 4096, 8192};
  std::filesystem::path csv_dir = "docs";
  std::vector<char*> rest;
  for (int i = 0; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg.rfind("--sizes=", 0) == 0)
      sizes = ParseSizes(arg.substr(8));
    else if (arg.rfind("--csv-dir=", 0) == 0)
      csv_dir = arg.substr(10);
    else
      rest.push_back(argv[i]);
  }
  for (int px : sizes)
    benchmark::RegisterBenchmark("preprocess/size", BM_PreprocessSize)
        ->Arg(px)
        ->Unit(benchmark::kMillisecond)
        ->Iterations(3)
        ->UseRealTime();
  for (int noise_um : {0, 5, 10, 20, 50, 100, 200})
    benchmark::RegisterBenchmark("preprocess/noise_um", BM_PreprocessNoise)
        ->Arg(noise_um)
        ->Unit(benchmark::kMillisecond)
        ->Iterations(1)
        ->UseRealTime();
  int rest_argc = static_cast<int>(rest.size());
  benchmark::Initialize(&rest_argc, rest.data());
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  std::filesystem::create_directories(csv_dir);
  if (!g_size_rows.empty()) WriteCsv(csv_dir / "bench_preprocess_sizes.csv", g_size_rows);
  if (!g_noise_rows.empty()) WriteCsv(csv_dir / "bench_preprocess_noise.csv", g_noise_rows);
  return 0;
}
