// A large painting scanned as a grid of overlapping patches (scan_registration.h): each patch its
// own SimulateScan with a nominal pose (the one the rig reports; the rig frame is the painting's
// canvas frame) and a true pose that drifted from it by a few mm and a fraction of a degree.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/scan_sim.h"

namespace digitize::synth {

struct PatchGridOptions {
  int columns = 2, rows = 2;  // the grid, row 0 at the canvas top
  double overlap = 0.25;      // share of a patch's width (height) it shares with its neighbour
  double margin_mm = 12;      // the grid reaches this far beyond the canvas outline
  // Per patch: model, width_px (height_px follows the field's aspect), tilt, roll, distance,
  // noise, losses; aim_mm, field_mm, pose_error and seed are set per patch.
  ScanSimOptions scan;
  double drift_mm = 2.0;   // true - nominal translation, uniform in +-drift_mm (Z: +-drift_mm/2)
  double drift_deg = 0.6;  // true - nominal tilt about a random in-plane axis, uniform in
                           // [0, drift_deg]; in-plane rotation uniform in +-drift_deg/2
  int tilted_patch = -1;   // this patch (row-major index) is scanned with an extra tilt
  double tilted_patch_deg = 0;
  uint64_t seed = 1;
  Status Validate() const;
};

struct SyntheticPatch {
  SyntheticScan scan;                       // one exposure; scan.canvas_from_scan is the TRUE pose
  RigidTransform nominal_canvas_from_scan;  // what the rig reports (the patch list's pose)
  int column = 0, row = 0;
  Eigen::Vector2d centre_mm{0, 0};  // nominal aim point on the canvas, canvas frame
};

struct SyntheticPatchScan {
  std::vector<SyntheticPatch> patches;  // row-major from the top left
  PatchGridOptions options;
  Eigen::Vector2d field_mm{0, 0};  // each patch's field of view at the canvas
};

// Invalid options throw (validate first). Deterministic for options.seed.
SyntheticPatchScan SimulatePatchScan(const Scene& scene, const PatchGridOptions& options);

// Painting resolution whose texel pitch is about 1.1x the patches' sample spacing.
int MatchedPatchResolution(const PaintingOptions& painting, const PatchGridOptions& options);

// The registration cases that tests/scan_registration_test.cpp and bench/registration_bench.cpp
// share: a painting, its frame and a patch grid, unlike each other.
struct PatchScanCase {
  std::string name;
  PaintingOptions painting;
  FrameOptions frame;
  PatchGridOptions grid;
};
// 2 x 2 orthographic patches of 200 samples (3 deg tilt, 1 deg roll, a hole blob each) over a
// 300 x 220 mm painting; grid seed 5.
PatchScanCase Orthographic2x2Case();
// 3 x 2 pinhole patches (400 mm away, 170 samples) over a 380 x 220 mm canvas bowed 3 mm, patch 4
// tilted 6 deg more; grid seed 8.
PatchScanCase PinholeBowed3x2Case();
// 4 x 3 orthographic patches over 520 x 330 mm: its far patches four overlaps from patch 0.
PatchScanCase Orthographic4x3Case();
// The case's painting (at MatchedPatchResolution) and its patch scan.
SyntheticPatchScan SimulateCase(const PatchScanCase& c, Painting* painting_out = nullptr);

// dir: patch_R_C.exr (R row, C column), patches.json (the patch list with the NOMINAL poses,
// docs/formats.md), truth_height.exr, truth_patches.json (the TRUE canvas_from_scan per patch).
Status WriteSyntheticPatchScan(const std::filesystem::path& dir, const Painting& painting,
                               const SyntheticPatchScan& scan);

}  // namespace digitize::synth
