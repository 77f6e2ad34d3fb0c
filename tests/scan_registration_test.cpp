// A canvas from overlapping patches (scan_registration.h), against the generator's truth
// (patch_sim.h): registration error, seam residual, unlike cases, degenerate input.
//
// Registration error of a patch: the gauge is fixed by patch 0 (G = true_0 * registered_0^-1: the
// registration places the patches relative to each other, not in the rig), then the largest
// distance, over the patch's true canvas samples p, between G * registered_i * p and true_i * p,
// in texels of the merged canvas. Seam residual: the merged height against the true surface
// (mapped into the true canvas frame through patch 0), RMS over the texels two or more patches
// measured, compared with the RMS where one patch did.
#include "digitize/scan_registration.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "digitize_synth/painting.h"
#include "digitize_synth/patch_sim.h"
#include "digitize_synth/scan_sim.h"

namespace digitize {
namespace {

// The target: no canvas point of a registered patch more than a quarter texel (of the
// merged canvas, ~0.93 mm here) from where the true pose puts it. Measured 0.16-0.21 texel
// (the in-plane rotation is what is left: ~0.05 deg over a patch's 180 mm).
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

struct Case {
  std::string name;
  synth::PaintingOptions painting;
  synth::FrameOptions frame;
  synth::PatchGridOptions grid;
};

Case BaseCase() {
  Case c;
  c.name = "ortho 2x2";
  c.painting.width_mm = 300, c.painting.height_mm = 220;
  c.painting.seed = 3;
  c.painting.stroke_count = 150;
  c.grid.scan.model = synth::ScannerModel::kOrthographic;
  c.grid.scan.width_px = 200;
  c.grid.scan.tilt_deg = 3, c.grid.scan.roll_deg = 1;
  c.grid.scan.offset_mm = Vec3d::Zero();
  c.grid.scan.hole_blobs = 1;
  c.grid.seed = 5;
  return c;
}

std::vector<ScanPatch> Inputs(const synth::SyntheticPatchScan& scan) {
  std::vector<ScanPatch> in;
  for (const synth::SyntheticPatch& p : scan.patches)
    in.push_back({p.scan.exposures[0], p.nominal_canvas_from_scan});
  return in;
}

struct Measured {
  double max_error_texels = 0;
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
  const double pitch = r.field.pitch_mm;
  const RigidTransform gauge =
      scan.patches[0].scan.canvas_from_scan * r.patches[0].rig_from_scan.Inverse();
  for (size_t i = 0; i < scan.patches.size(); ++i) {
    const synth::SyntheticScan& s = scan.patches[i].scan;
    const RigidTransform est = gauge * r.patches[i].rig_from_scan;
    const Grid<Vec3f>& xyz = s.exposures[0].xyz_mm;
    for (size_t k = 0; k < xyz.data.size(); ++k) {
      if (!s.canvas_mask_scan.data[k] || !IsValid(xyz.data[k])) continue;
      const Vec3d p = xyz.data[k].cast<double>();
      m.max_error_texels =
          std::max(m.max_error_texels, (est.Apply(p) - s.canvas_from_scan.Apply(p)).norm() / pitch);
    }
  }
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
  synth::PaintingOptions po = c.painting;
  po.resolution_px = synth::MatchedPatchResolution(po, c.grid);
  const synth::Painting painting = synth::MakePainting(po);
  const synth::Scene scene(painting, c.frame);
  synth::SyntheticPatchScan scan = synth::SimulatePatchScan(scene, c.grid);
  if (painting_out) *painting_out = painting;
  return scan;
}

void RunCase(const Case& c) {
  SCOPED_TRACE(c.name);
  synth::Painting painting;
  const synth::SyntheticPatchScan scan = Simulate(c, &painting);
  Result<PatchRegistrationResult> r = RegisterPatches(Inputs(scan), {}, {}, {});
  ASSERT_TRUE(r.ok()) << r.error().message;
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
        p.correlation_tiles, p.correlation_peak, p.icp_rounds, p.last_icp_move_mm);
  std::printf(
      "[%s] registration error %.3f texels (pitch %.3f mm); seam RMS %.4f mm over %zu "
      "texels, single-patch RMS %.4f mm over %zu\n",
      c.name.c_str(), m.max_error_texels, r->field.pitch_mm, m.seam_rms_mm, m.seam_texels,
      m.single_rms_mm, m.single_texels);
  EXPECT_LE(m.max_error_texels, kMaxRegistrationErrorTexels);
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
  for (float v : r->field.height_mm.data) ASSERT_TRUE(std::isfinite(v));
}

TEST(ScanRegistration, Orthographic2x2) { RunCase(BaseCase()); }

TEST(ScanRegistration, PinholeBowed3x2WithATiltedPatch) {
  Case c = BaseCase();
  c.name = "pinhole 3x2 bowed";
  c.painting.width_mm = 380, c.painting.height_mm = 220;
  c.painting.bow_mm = 3;
  c.painting.seed = 11;
  c.grid.columns = 3;
  c.grid.scan.model = synth::ScannerModel::kPinhole;
  c.grid.scan.distance_mm = 400;
  c.grid.scan.width_px = 170;
  c.grid.tilted_patch = 4, c.grid.tilted_patch_deg = 6;
  c.grid.seed = 8;
  RunCase(c);
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

}  // namespace
}  // namespace digitize
