// A canvas from overlapping patches (scan_registration.h), against the generator's truth
// (patch_sim.h): registration error, seam residual, unlike cases, degenerate input.
//
// Registration error: synth::MeasureRegistration (ground_truth.h), in patch 0's gauge and in the
// best rigid gauge, in texels of the merged canvas. Seam residual: the merged height against the
// true surface (mapped into the true canvas frame through patch 0), RMS over the texels two or
// more patches measured, compared with the RMS where one patch did.
#include "digitize/scan_registration.h"

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "digitize/preprocess.h"
#include "digitize/scan_io.h"
#include "digitize_synth/ground_truth.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/patch_sim.h"
#include "digitize_synth/scan_sim.h"
#include "test_paths.h"
#include "test_support.h"

namespace digitize {
namespace {

// The issue's target: no canvas point of a registered patch more than a quarter texel (of the
// merged canvas, ~0.93 mm here) from where the true pose puts it. Measured 0.13 and 0.08 texel
// in the two cases below (the in-plane rotation is what is left: a few hundredths of a degree
// over a patch's 180 mm). The seeds here are the ones the work was tuned on;
// OtherSeedsStayWithinAQuarterTexel says what holds on the others.
constexpr double kMaxRegistrationErrorTexels = 0.25;
// Scanner noise of the generator (ScanSimOptions::noise_mm, along the ray).
constexpr double kNoiseMm = 0.02;
// Merged height against the true surface where two or more patches measured it (the seams):
// each patch's resampled height carries about the noise (0.016 mm measured where one patch
// did), the blend averages two; a registration off by a quarter texel adds slope x 0.23 mm on
// the relief's flanks. 1.5 x the noise leaves room for that and fails at a texel's
// misregistration (0.05 mm RMS measured there during development).
constexpr double kMaxSeamRmsMm = 1.5 * kNoiseMm;
// Height residual between two patches over their overlap: the difference of two independent
// noisy fields, sqrt(2) x 0.016 mm ~ 0.023 mm, plus the relief's slope x the registration error.
constexpr double kMaxOverlapRmsMm = 0.035;

using Case = synth::PatchScanCase;
Case BaseCase() { return synth::Orthographic2x2Case(); }

std::vector<ScanPatch> Inputs(const synth::SyntheticPatchScan& scan) {
  std::vector<ScanPatch> in;
  for (const synth::SyntheticPatch& p : scan.patches)
    in.push_back({p.scan.exposures[0], p.nominal_canvas_from_scan});
  return in;
}

struct Measured {
  // Registration error in patch 0's gauge and in the best rigid gauge (synth::MeasureRegistration).
  double max_error_texels = 0, best_gauge_error_texels = 0;
  double seam_rms_mm = 0, single_rms_mm = 0;
  size_t seam_texels = 0, single_texels = 0;
  double worst_overlap_rms_mm = 0;
};

double Bilinear(const Grid<float>& g, double x, double y) {
  x = std::clamp(x, 0.0, g.width - 1.001), y = std::clamp(y, 0.0, g.height - 1.001);
  const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
  const double fx = x - x0, fy = y - y0;
  return (1 - fy) * ((1 - fx) * g(x0, y0) + fx * g(x0 + 1, y0)) +
         fy * ((1 - fx) * g(x0, y0 + 1) + fx * g(x0 + 1, y0 + 1));
}

Measured Measure(const synth::Painting& painting, const synth::SyntheticPatchScan& scan,
                 const PatchRegistrationResult& r) {
  Measured m;
  const synth::RegistrationAccuracy accuracy = synth::MeasureRegistration(scan, r);
  m.max_error_texels = accuracy.max_error_texels;
  m.best_gauge_error_texels = accuracy.best_gauge_error_texels;
  // Heights: estimated canvas -> true canvas through patch 0.
  const RigidTransform to_truth =
      scan.patches[0].scan.canvas_from_scan *
      (r.canvas.canvas_from_scan * r.patches[0].rig_from_scan).Inverse();
  std::vector<double> err;
  std::vector<uint8_t> cov;
  const HeightField& f = r.field;
  const HeightField& t = painting.truth;
  constexpr double kInsideMm = 4;  // away from the frame's edge
  for (int y = 0; y < f.height(); ++y)
    for (int x = 0; x < f.width(); ++x) {
      if (f.state(x, y) != TexelState::kMeasured) continue;
      const Eigen::Vector2d xy = f.TexelCentreMm(x, y);
      const Vec3d q = to_truth.Apply(Vec3d(xy.x(), xy.y(), f.height_mm(x, y)));
      if (q.x() < kInsideMm || q.y() < kInsideMm || q.x() > painting.width_mm - kInsideMm ||
          q.y() > painting.height_mm - kInsideMm)
        continue;
      const Eigen::Vector2d tx = t.TexelFromMm(q.x(), q.y());
      err.push_back(q.z() - Bilinear(t.height_mm, tx.x(), tx.y()));
      cov.push_back(r.coverage(x, y));
    }
  std::vector<double> sorted = err;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double offset = sorted[sorted.size() / 2];
  double seam = 0, single = 0;
  for (size_t i = 0; i < err.size(); ++i) {
    const double e = err[i] - offset;
    if (cov[i] >= 2) {
      seam += e * e, ++m.seam_texels;
    } else {
      single += e * e, ++m.single_texels;
    }
  }
  m.seam_rms_mm = std::sqrt(seam / std::max<size_t>(1, m.seam_texels));
  m.single_rms_mm = std::sqrt(single / std::max<size_t>(1, m.single_texels));
  for (const OverlapResidual& o : r.overlaps)
    m.worst_overlap_rms_mm = std::max(m.worst_overlap_rms_mm, o.rms_mm);
  return m;
}

synth::SyntheticPatchScan Simulate(const Case& c, synth::Painting* painting_out = nullptr) {
  return synth::SimulateCase(c, painting_out);
}

Measured RunCase(const Case& c, double max_error_texels = kMaxRegistrationErrorTexels) {
  SCOPED_TRACE(c.name);
  synth::Painting painting;
  const synth::SyntheticPatchScan scan = Simulate(c, &painting);
  Result<PatchRegistrationResult> r = RegisterPatches(Inputs(scan), {}, {}, {});
  EXPECT_TRUE(r.ok()) << r.error().message;
  if (!r.ok()) return {};
  const Measured m = Measure(painting, scan, *r);
  std::printf("[%s] %s\n", c.name.c_str(), r->brief.c_str());
  for (const OverlapResidual& o : r->overlaps)
    std::printf("[%s]   overlap %d-%d: %zu texels, RMS %.4f mm, max %.3f mm, mean %+.4f mm\n",
                c.name.c_str(), o.patch_a, o.patch_b, o.texels, o.rms_mm, o.max_mm, o.mean_mm);
  for (const PatchReport& p : r->patches)
    std::printf(
        "[%s]   %s: corrected %.3f deg, %.2f mm (max %.2f mm); %d tiles, peak %.3f; %d ICP "
        "rounds, last %.4f mm\n",
        c.name.c_str(), p.source.c_str(), p.correction_deg, p.correction_mm, p.max_correction_mm,
        p.correlation_pieces, p.correlation_peak, p.icp_rounds, p.last_icp_move_mm);
  std::printf(
      "[%s] registration error %.3f texels (best gauge %.3f; pitch %.3f mm); seam RMS %.4f mm "
      "over %zu texels, single-patch RMS %.4f mm over %zu\n",
      c.name.c_str(), m.max_error_texels, m.best_gauge_error_texels, r->field.pitch_mm,
      m.seam_rms_mm, m.seam_texels, m.single_rms_mm, m.single_texels);
  EXPECT_LE(m.max_error_texels, max_error_texels);
  EXPECT_LE(m.best_gauge_error_texels, kMaxRegistrationErrorTexels);
  EXPECT_GT(m.seam_texels, 1000u);
  EXPECT_LE(m.seam_rms_mm, kMaxSeamRmsMm);
  // Single-patch texels: the merge does not spoil what one patch measured.
  EXPECT_LE(m.single_rms_mm, kMaxSeamRmsMm);
  EXPECT_LE(m.worst_overlap_rms_mm, kMaxOverlapRmsMm);
  EXPECT_GE(r->overlaps.size(), scan.patches.size() - 1);
  for (const OverlapResidual& o : r->overlaps) {
    EXPECT_TRUE(std::isfinite(o.rms_mm) && std::isfinite(o.max_mm) && std::isfinite(o.mean_mm));
    EXPECT_GT(o.texels, 0u);
  }
  for (float v : r->field.height_mm.data) EXPECT_TRUE(std::isfinite(v));
  return m;
}

TEST(ScanRegistration, Orthographic2x2) { RunCase(BaseCase()); }

// The same case under other drifts and noise (the grid's seed): what the registration holds on
// cases it was not tuned on. Measured over seeds 1-24: 0.03-0.24 texel (seeds 1-9: 0.03-0.16),
// seam RMS 0.012-0.017 mm. Before patch 0 joined the global passes: 0.03-0.36, 6 of 24 over a
// quarter texel (seeds 6 and 8 here at 0.36 and 0.29).
TEST(ScanRegistration, OtherSeedsStayWithinAQuarterTexel) {
  for (uint64_t seed = 1; seed <= 9; ++seed) {
    Case c = BaseCase();
    c.grid.seed = seed;
    c.name = "ortho 2x2, grid seed " + std::to_string(seed);
    RunCase(c);
  }
}

TEST(ScanRegistration, PinholeBowed3x2WithATiltedPatch) { RunCase(synth::PinholeBowed3x2Case()); }

// A longer chain: 12 patches, the far ones four overlaps from patch 0. Measured 0.30 texel in
// patch 0's gauge (each overlap's error adds up along the chain; 0.34 / 0.27 at 2 / 8 global
// passes) and 0.10 in the best gauge: the patches agree with each other within a tenth of a
// texel, the whole sits 0.3 texel off against patch 0. Asserted: the best gauge within the
// quarter texel (RunCase), patch 0's within half a texel.
TEST(ScanRegistration, Orthographic4x3Chain) {
#ifdef __SANITIZE_ADDRESS__
  // 96 s under ASan (5 s in Release, which runs it): the 2 x 2 and 3 x 2 cases take the same
  // code paths here.
  GTEST_SKIP() << "the 4 x 3 grid runs in the Release build only (18x slower under ASan)";
#endif
  const Case c = synth::Orthographic4x3Case();
  RunCase(c, 0.5);
}

// The degenerate inputs: each a clear error naming the scan file, never a result.
TEST(ScanRegistration, FewerThanTwoPatches) {
  const synth::SyntheticPatchScan scan = Simulate(BaseCase());
  std::vector<ScanPatch> one = Inputs(scan);
  one.resize(1);
  Result<PatchRegistrationResult> r = RegisterPatches(one, {}, {}, {});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("at least 2"), std::string::npos) << r.error().message;
  EXPECT_FALSE(RegisterPatches({}, {}, {}, {}).ok());
}

TEST(ScanRegistration, APatchThatOverlapsNothing) {
  const synth::SyntheticPatchScan scan = Simulate(BaseCase());
  std::vector<ScanPatch> in = Inputs(scan);
  in[3].rig_from_scan.translation.x() += 2000;  // a pose typed wrong in the patch list
  Result<PatchRegistrationResult> r = RegisterPatches(in, {}, {}, {});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("patch_1_1.exr"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("does not overlap"), std::string::npos) << r.error().message;
}

TEST(ScanRegistration, AFeaturelessOverlap) {
  Case c = BaseCase();
  c.painting.strokes = false, c.painting.impasto = false, c.painting.craquelure = false;
  c.painting.weave = false;  // a bare, smooth canvas: only the scanner's noise to correlate
  const synth::SyntheticPatchScan scan = Simulate(c);
  Result<PatchRegistrationResult> r = RegisterPatches(Inputs(scan), {}, {}, {});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("no relief to register"), std::string::npos)
      << r.error().message;
  EXPECT_NE(r.error().message.find(".exr"), std::string::npos) << r.error().message;
}

TEST(ScanRegistration, NonConvergenceIsAnError) {
  const synth::SyntheticPatchScan scan = Simulate(BaseCase());
  PatchRegistrationOptions o;
  o.polish_iterations = 1;  // one Gauss-Newton step cannot settle a patch that was mm off
  Result<PatchRegistrationResult> r = RegisterPatches(Inputs(scan), o, {}, {});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("did not converge"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find(".exr"), std::string::npos) << r.error().message;
}

TEST(ScanRegistration, OptionsValidate) {
  PatchRegistrationOptions o;
  EXPECT_TRUE(o.Validate().ok());
  o.converged_mm = -1;
  EXPECT_NE(o.Validate().message().find("converged_mm"), std::string::npos);
  o = {};
  o.icp_levels = 0;
  EXPECT_FALSE(o.Validate().ok());
}

TEST(ScanRegistration, PatchListErrorsNameTheFileAndKey) {
  const std::filesystem::path dir = test::FreshScratchDir("scan_registration_list");
  const std::filesystem::path list = dir / "poses.json";
  std::ofstream(list) << R"({"format": "digitize.scan_patches", "version": 1, "patches": [
      {"scan": "a.exr", "rig_from_scan": {"rotation": [[1,0,0],[0,1,0],[0,0,1]],
                                          "translation_mm": [0, 0, 500]}},
      {"scan": "b.exr", "rig_from_scan": {"rotation": [[2,0,0],[0,1,0],[0,0,1]],
                                          "translation_mm": [100, 0, 500]}}]})";
  Result<std::vector<PatchListEntry>> r = ReadPatchList(list);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("poses.json"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("patches[1].rig_from_scan"), std::string::npos)
      << r.error().message;
  std::filesystem::remove_all(dir);
}

// The command line: `digitize synth --patches` writes a set, `digitize preprocess --patches`
// registers it, and its registration.json holds poses within a quarter texel of the truth the
// synth wrote beside the scans. Then the refusals: too few patches, a missing scan, an output
// folder the tool did not write; each non-zero, naming the file, and no output left behind.
struct Cli {
  int exit_code = -1;
  std::string text;
};

Cli RunCli(const std::string& args, const std::filesystem::path& log) {
  const std::string command =
      "(" + std::string(DIGITIZE_CLI) + " " + args + ") > " + log.string() + " 2>&1";
  const int status = std::system(command.c_str());
  Cli out;
  out.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream in(log);
  std::stringstream ss;
  ss << in.rdbuf();
  out.text = ss.str();
  return out;
}

RigidTransform PoseOf(const nlohmann::json& j) {
  RigidTransform t;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) t.rotation(r, c) = j["rotation"][r][c].get<double>();
    t.translation[r] = j["translation_mm"][r].get<double>();
  }
  return t;
}

nlohmann::json ReadJson(const std::filesystem::path& path) {
  std::ifstream in(path);
  return nlohmann::json::parse(in);
}

TEST(ScanRegistration, Cli) {
  const std::filesystem::path dir = test::FreshScratchDir("scan_registration_cli");
  const std::filesystem::path log = dir / "log.txt";
  const std::string set = (dir / "set").string(), out = (dir / "canvas").string();
  Cli synth = RunCli("synth -o " + set +
                         " --width-mm 300 --height-mm 220 --patches 2x2 --scan-size 200 150 "
                         "--tilt-deg 3 --roll-deg 1 --seed 3",
                     log);
  ASSERT_EQ(synth.exit_code, 0) << synth.text;
  Cli pre = RunCli("preprocess --patches " + set + "/patches.json -o " + out, log);
  ASSERT_EQ(pre.exit_code, 0) << pre.text;
  EXPECT_NE(pre.text.find("register: 4 patches registered, 6 overlaps"), std::string::npos)
      << pre.text;
  for (const char* f : kCanvasFolderFiles) EXPECT_TRUE(std::filesystem::exists(dir / "canvas" / f));
  const nlohmann::json reg = ReadJson(dir / "canvas" / "registration.json");
  EXPECT_EQ(reg["format"], "digitize.patch_registration");
  ASSERT_EQ(reg["patches"].size(), 4u);
  ASSERT_GE(reg["overlaps"].size(), 3u);
  for (const nlohmann::json& o : reg["overlaps"]) {
    EXPECT_GT(o["texels"].get<double>(), 0);
    EXPECT_LE(o["rms_mm"].get<double>(), kMaxOverlapRmsMm);
  }
  // Registration error against truth_patches.json, as Measure does (gauge: patch 0), over the
  // patches' own sample grids: the scans are read back for their points.
  const nlohmann::json truth = ReadJson(dir / "set" / "truth_patches.json");
  const double pitch = reg["pitch_mm"].get<double>();
  const RigidTransform gauge = PoseOf(truth["patches"][0]["canvas_from_scan"]) *
                               PoseOf(reg["patches"][0]["rig_from_scan"]).Inverse();
  double worst = 0;
  for (size_t i = 0; i < 4; ++i) {
    Result<Scan> scan = ReadScan(dir / "set" / truth["patches"][i]["scan"].get<std::string>(), {});
    ASSERT_TRUE(scan.ok()) << scan.error().message;
    const RigidTransform est = gauge * PoseOf(reg["patches"][i]["rig_from_scan"]);
    const RigidTransform tru = PoseOf(truth["patches"][i]["canvas_from_scan"]);
    for (const Vec3f& p : scan->xyz_mm.data) {
      if (!IsValid(p)) continue;
      const Vec3d q = p.cast<double>();
      const Vec3d c = tru.Apply(q);
      // Canvas points only (the frame and wall are no part of the registration).
      if (c.x() < 0 || c.y() < 0 || c.x() > 300 || c.y() > 220 || std::abs(c.z()) > 10) continue;
      worst = std::max(worst, (est.Apply(q) - c).norm() / pitch);
    }
  }
  std::printf("CLI: registration error %.3f texels (pitch %.3f mm)\n", worst, pitch);
  EXPECT_LE(worst, kMaxRegistrationErrorTexels);

  // One patch only: refused, naming the list, nothing written.
  nlohmann::json list = ReadJson(dir / "set" / "patches.json");
  nlohmann::json one = list;
  one["patches"] = nlohmann::json::array({list["patches"][0]});
  std::ofstream(dir / "set" / "one.json") << one.dump();
  const std::string out2 = (dir / "canvas2").string();
  Cli few = RunCli("preprocess --patches " + set + "/one.json -o " + out2, log);
  EXPECT_NE(few.exit_code, 0);
  EXPECT_NE(few.text.find("one.json"), std::string::npos) << few.text;
  EXPECT_NE(few.text.find("at least 2"), std::string::npos) << few.text;
  EXPECT_FALSE(std::filesystem::exists(out2));
  // A scan the list names that is not there.
  nlohmann::json missing = list;
  missing["patches"][2]["scan"] = "nope.exr";
  std::ofstream(dir / "set" / "missing.json") << missing.dump();
  Cli gone = RunCli("preprocess --patches " + set + "/missing.json -o " + out2, log);
  EXPECT_NE(gone.exit_code, 0);
  EXPECT_NE(gone.text.find("nope.exr"), std::string::npos) << gone.text;
  EXPECT_FALSE(std::filesystem::exists(out2));
  // An output folder holding something the tool did not write: left alone.
  std::filesystem::create_directories(out2);
  std::ofstream(dir / "canvas2" / "notes.txt") << "mine";
  Cli keep = RunCli("preprocess --patches " + set + "/patches.json -o " + out2, log);
  EXPECT_NE(keep.exit_code, 0);
  EXPECT_TRUE(std::filesystem::exists(dir / "canvas2" / "notes.txt"));
  EXPECT_FALSE(std::filesystem::exists(dir / "canvas2" / "registration.json"));
  // Scans and a patch list at once: a usage error.
  Cli both = RunCli("preprocess " + set + "/patch_0_0.exr --patches " + set + "/patches.json -o " +
                        (dir / "canvas3").string(),
                    log);
  EXPECT_NE(both.exit_code, 0);
  EXPECT_FALSE(std::filesystem::exists(dir / "canvas3"));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace digitize
