// Registration of overlapping scan patches (docs/benchmarks.md, "Stitched scans"): run time
// against the registration error, per generator case and number of global polish passes.
// Error of a case: synth::MeasureRegistration (ground_truth.h), the measure of
// tests/scan_registration_test.cpp, in patch 0's gauge and in the best rigid gauge.
//
// Cases (patch_sim.h, shared with the test): the orthographic 2 x 2 grid under grid seeds 1..N
// (each its own drift and noise), the pinhole 3 x 2 grid on a bowed canvas with one patch tilted
// 6 deg, and the orthographic 4 x 3 grid (a longer chain of overlaps). Each is run with
// global_rounds in --rounds.
//
//   registration_bench [--seeds=24] [--rounds=2,4,8] [--csv-dir=docs]
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "bench_support.h"
#include "digitize/scan_registration.h"
#include "digitize_synth/ground_truth.h"
#include "digitize_synth/patch_sim.h"

namespace {

using namespace digitize;
using bench::Arg;
using bench::Clock;
using bench::Since;

synth::PatchScanCase Ortho2x2(uint64_t seed) {
  synth::PatchScanCase c = synth::Orthographic2x2Case();
  c.name = "ortho 2x2 seed " + std::to_string(seed);
  c.grid.seed = seed;
  return c;
}

std::vector<int> ParseList(const std::string& s) {
  std::vector<int> out;
  std::stringstream in(s);
  for (std::string item; std::getline(in, item, ',');) out.push_back(std::stoi(item));
  return out;
}

struct Row {
  std::string name;
  int patches = 0, rounds = 0;
  double seconds = 0, error_texels = 0, best_gauge_texels = 0, worst_overlap_rms_mm = 0;
  bool ok = false;
};

}  // namespace

int main(int argc, char** argv) {
  const int seeds = std::stoi(Arg(argc, argv, "seeds", "24"));
  const std::vector<int> rounds = ParseList(Arg(argc, argv, "rounds", "2,4,8"));
  const std::filesystem::path csv_dir = Arg(argc, argv, "csv-dir", "");

  std::vector<synth::PatchScanCase> cases;
  for (int s = 1; s <= seeds; ++s) cases.push_back(Ortho2x2(static_cast<uint64_t>(s)));
  cases.push_back(synth::PinholeBowed3x2Case());
  cases.push_back(synth::Orthographic4x3Case());

  std::vector<Row> rows;
  std::printf("%-32s %7s %6s %9s %14s %14s %17s\n", "case", "patches", "rounds", "time (s)",
              "error (texel)", "best gauge", "worst overlap RMS");
  for (const synth::PatchScanCase& c : cases) {
    const synth::SyntheticPatchScan scan = synth::SimulateCase(c);
    std::vector<ScanPatch> inputs;
    for (const synth::SyntheticPatch& p : scan.patches)
      inputs.push_back({p.scan.exposures[0], p.nominal_canvas_from_scan});
    for (int r : rounds) {
      PatchRegistrationOptions options;
      options.global_rounds = r;
      Row row;
      row.name = c.name;
      row.patches = static_cast<int>(inputs.size());
      row.rounds = r;
      const auto t0 = Clock::now();
      const Result<PatchRegistrationResult> result = RegisterPatches(inputs, options, {}, {});
      row.seconds = Since(t0);
      row.ok = result.ok();
      if (result.ok()) {
        const synth::RegistrationAccuracy e = synth::MeasureRegistration(scan, *result);
        row.error_texels = e.max_error_texels;
        row.best_gauge_texels = e.best_gauge_error_texels;
        for (const OverlapResidual& o : result->overlaps)
          row.worst_overlap_rms_mm = std::max(row.worst_overlap_rms_mm, o.rms_mm);
        std::printf("%-32s %7d %6d %9.2f %14.3f %14.3f %14.4f mm\n", row.name.c_str(), row.patches,
                    r, row.seconds, row.error_texels, row.best_gauge_texels,
                    row.worst_overlap_rms_mm);
      } else {
        std::printf("%-32s %7d %6d %9.2f  failed: %s\n", row.name.c_str(), row.patches, r,
                    row.seconds, result.error().message.c_str());
      }
      std::fflush(stdout);
      rows.push_back(row);
    }
  }
  // Per number of passes: the worst case and how many are within the quarter texel.
  std::printf("\n%6s %12s %16s %18s %18s\n", "rounds", "total (s)", "worst (texel)",
              "within 1/4 texel", "worst, best gauge");
  for (int r : rounds) {
    double total = 0, worst = 0, worst_best = 0;
    int within = 0, count = 0;
    for (const Row& row : rows) {
      if (row.rounds != r) continue;
      ++count;
      total += row.seconds;
      if (!row.ok) {
        worst = 1e9;
        continue;
      }
      worst = std::max(worst, row.error_texels);
      worst_best = std::max(worst_best, row.best_gauge_texels);
      within += row.error_texels <= 0.25;
    }
    std::printf("%6d %12.2f %16.3f %13d of %d %18.3f\n", r, total, worst, within, count,
                worst_best);
  }
  if (!csv_dir.empty()) {
    std::filesystem::create_directories(csv_dir);
    const std::filesystem::path path = csv_dir / "bench_registration.csv";
    std::ofstream out(path);
    out << "case,patches,global_rounds,seconds,error_texels,error_best_gauge_texels,"
           "worst_overlap_rms_mm,ok\n";
    for (const Row& row : rows)
      out << '"' << row.name << "\"," << row.patches << ',' << row.rounds << ',' << row.seconds
          << ',' << row.error_texels << ',' << row.best_gauge_texels << ','
          << row.worst_overlap_rms_mm << ',' << row.ok << "\n";
    std::printf("wrote %s\n", path.c_str());
  }
  bool all_ok = true;
  for (const Row& row : rows) all_ok = all_ok && row.ok;
  return all_ok ? 0 : 1;
}
