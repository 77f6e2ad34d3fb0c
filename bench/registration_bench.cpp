// Registration of overlapping scan patches (docs/benchmarks.md, "Stitched scans"): run time
// against the registration error, per generator case and number of global polish passes.
// Error of a case: the largest distance, over every patch's true canvas samples, between where
// the registered pose and the true pose put them, in texels of the merged canvas, with the gauge
// fixed by patch 0 (the registration places patches relative to each other, not in the rig):
// the measure of tests/scan_registration_test.cpp.
//
// Cases: the test's orthographic 2 x 2 grid under grid seeds 1..N (each its own drift and noise),
// a pinhole 3 x 2 grid on a bowed canvas with one patch tilted 6 deg, and an orthographic 4 x 3
// grid (a longer chain of overlaps). Each is run with global_rounds in --rounds.
//
//   registration_bench [--seeds=24] [--rounds=2,4,8] [--csv-dir=docs]
#include <Eigen/Geometry>
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "bench_support.h"
#include "digitize/scan_registration.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/patch_sim.h"

namespace {

using namespace digitize;
using bench::Arg;
using bench::Clock;
using bench::Since;

struct Case {
  std::string name;
  synth::PaintingOptions painting;
  synth::PatchGridOptions grid;
};

Case Ortho2x2(uint64_t seed) {
  Case c;
  c.name = "ortho 2x2 seed " + std::to_string(seed);
  c.painting.width_mm = 300, c.painting.height_mm = 220;
  c.painting.seed = 3;
  c.painting.stroke_count = 150;
  c.grid.scan.model = synth::ScannerModel::kOrthographic;
  c.grid.scan.width_px = 200;
  c.grid.scan.tilt_deg = 3, c.grid.scan.roll_deg = 1;
  c.grid.scan.offset_mm = Vec3d::Zero();
  c.grid.scan.hole_blobs = 1;
  c.grid.seed = seed;
  return c;
}

Case Pinhole3x2() {
  Case c = Ortho2x2(8);
  c.name = "pinhole 3x2 bowed, tilted patch";
  c.painting.width_mm = 380, c.painting.height_mm = 220;
  c.painting.bow_mm = 3;
  c.painting.seed = 11;
  c.grid.columns = 3;
  c.grid.scan.model = synth::ScannerModel::kPinhole;
  c.grid.scan.distance_mm = 400;
  c.grid.scan.width_px = 170;
  c.grid.tilted_patch = 4, c.grid.tilted_patch_deg = 6;
  return c;
}

Case Ortho4x3() {
  Case c = Ortho2x2(5);
  c.name = "ortho 4x3";
  c.painting.width_mm = 520, c.painting.height_mm = 330;
  c.painting.stroke_count = 400;
  c.painting.seed = 7;
  c.grid.columns = 4, c.grid.rows = 3;
  return c;
}

std::vector<int> ParseList(const std::string& s) {
  std::vector<int> out;
  std::stringstream in(s);
  for (std::string item; std::getline(in, item, ',');) out.push_back(std::stoi(item));
  return out;
}

// Both gauges: patch 0's (the test's), and the rigid motion that best maps every registered
// sample onto its true place (least squares, Eigen::umeyama without scale), the mosaic's own
// error whatever patch it is read from: a grid's far patches carry the errors of every overlap
// between them and patch 0, and the canvas frame is fitted to all patches, not to patch 0.
struct Errors {
  double patch0_gauge = 0, best_gauge = 0;
};
Errors RegistrationErrorTexels(const synth::SyntheticPatchScan& scan,
                               const PatchRegistrationResult& r) {
  const RigidTransform gauge =
      scan.patches[0].scan.canvas_from_scan * r.patches[0].rig_from_scan.Inverse();
  std::vector<Vec3d> est, truth;
  for (size_t i = 0; i < scan.patches.size(); ++i) {
    const synth::SyntheticScan& s = scan.patches[i].scan;
    const RigidTransform e = gauge * r.patches[i].rig_from_scan;
    const Grid<Vec3f>& xyz = s.exposures[0].xyz_mm;
    for (size_t k = 0; k < xyz.data.size(); ++k) {
      if (!s.canvas_mask_scan.data[k] || !IsValid(xyz.data[k])) continue;
      const Vec3d p = xyz.data[k].cast<double>();
      est.push_back(e.Apply(p));
      truth.push_back(s.canvas_from_scan.Apply(p));
    }
  }
  Eigen::Matrix3Xd a(3, est.size()), b(3, est.size());
  for (size_t k = 0; k < est.size(); ++k) a.col(k) = est[k], b.col(k) = truth[k];
  const Eigen::Matrix4d fit = Eigen::umeyama(a, b, false);
  Errors out;
  for (size_t k = 0; k < est.size(); ++k) {
    out.patch0_gauge = std::max(out.patch0_gauge, (est[k] - truth[k]).norm());
    const Vec3d moved = fit.topLeftCorner<3, 3>() * est[k] + fit.topRightCorner<3, 1>();
    out.best_gauge = std::max(out.best_gauge, (moved - truth[k]).norm());
  }
  out.patch0_gauge /= r.field.pitch_mm;
  out.best_gauge /= r.field.pitch_mm;
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

  std::vector<Case> cases;
  for (int s = 1; s <= seeds; ++s) cases.push_back(Ortho2x2(static_cast<uint64_t>(s)));
  cases.push_back(Pinhole3x2());
  cases.push_back(Ortho4x3());

  std::vector<Row> rows;
  std::printf("%-32s %7s %6s %9s %14s %14s %17s\n", "case", "patches", "rounds", "time (s)",
              "error (texel)", "best gauge", "worst overlap RMS");
  for (const Case& c : cases) {
    synth::PaintingOptions po = c.painting;
    po.resolution_px = synth::MatchedPatchResolution(po, c.grid);
    const synth::Painting painting = synth::MakePainting(po);
    const synth::Scene scene(painting, synth::FrameOptions{});
    const synth::SyntheticPatchScan scan = synth::SimulatePatchScan(scene, c.grid);
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
        const Errors e = RegistrationErrorTexels(scan, *result);
        row.error_texels = e.patch0_gauge;
        row.best_gauge_texels = e.best_gauge;
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
