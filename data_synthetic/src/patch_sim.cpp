// A painting scanned in overlapping patches (patch_sim.h).
#include "digitize_synth/patch_sim.h"

#include <Eigen/Geometry>
#include <cmath>
#include <nlohmann/json.hpp>
#include <numbers>
#include <random>

#include "digitize/image_io.h"
#include "digitize/scan_io.h"

namespace digitize::synth {
namespace {

Eigen::Vector2d FieldOf(const PaintingOptions& painting, const PatchGridOptions& o) {
  const double fx =
      (painting.width_mm + 2 * o.margin_mm) / (o.columns - (o.columns - 1) * o.overlap);
  const double fy = (painting.height_mm + 2 * o.margin_mm) / (o.rows - (o.rows - 1) * o.overlap);
  return {fx, fy};
}

nlohmann::json PoseJson(const RigidTransform& t) {
  nlohmann::json rows = nlohmann::json::array();
  for (int r = 0; r < 3; ++r)
    rows.push_back({t.rotation(r, 0), t.rotation(r, 1), t.rotation(r, 2)});
  return {{"rotation", rows},
          {"translation_mm", {t.translation.x(), t.translation.y(), t.translation.z()}}};
}

}  // namespace

Status PatchGridOptions::Validate() const {
  auto fail = [](const std::string& what) { return Status(Error{"patch grid options: " + what}); };
  if (columns < 1 || rows < 1 || columns * rows < 2 || columns > 16 || rows > 16)
    return fail("columns x rows must be 2..256 patches (each 1..16), got " +
                std::to_string(columns) + " x " + std::to_string(rows));
  if (!(overlap >= 0 && overlap < 0.9)) return fail("overlap must be in [0, 0.9)");
  if (!(std::isfinite(margin_mm) && margin_mm >= 0)) return fail("margin_mm must be >= 0");
  if (!(std::isfinite(drift_mm) && drift_mm >= 0 && drift_mm <= 100))
    return fail("drift_mm must be in [0, 100]");
  if (!(std::isfinite(drift_deg) && drift_deg >= 0 && drift_deg <= 20))
    return fail("drift_deg must be in [0, 20]");
  if (!std::isfinite(tilted_patch_deg) || std::abs(tilted_patch_deg) > 45)
    return fail("tilted_patch_deg must be in [-45, 45]");
  return scan.Validate();
}

int MatchedPatchResolution(const PaintingOptions& painting, const PatchGridOptions& options) {
  const Eigen::Vector2d field = FieldOf(painting, options);
  const double pitch = field.x() / std::max(options.scan.width_px, 1);
  const double long_side = std::max(painting.width_mm, painting.height_mm);
  return std::clamp(static_cast<int>(long_side / (1.1 * pitch)), 64, 8192);
}

PatchScanCase Orthographic2x2Case() {
  PatchScanCase c;
  c.name = "ortho 2x2";
  c.painting.width_mm = 300, c.painting.height_mm = 220;
  c.painting.seed = 3;
  c.painting.stroke_count = 150;
  c.grid.scan.model = ScannerModel::kOrthographic;
  c.grid.scan.width_px = 200;
  c.grid.scan.tilt_deg = 3, c.grid.scan.roll_deg = 1;
  c.grid.scan.offset_mm = Vec3d::Zero();
  c.grid.scan.hole_blobs = 1;
  c.grid.seed = 5;
  return c;
}

PatchScanCase PinholeBowed3x2Case() {
  PatchScanCase c = Orthographic2x2Case();
  c.name = "pinhole 3x2 bowed, tilted patch";
  c.painting.width_mm = 380, c.painting.height_mm = 220;
  c.painting.bow_mm = 3;
  c.painting.seed = 11;
  c.grid.columns = 3;
  c.grid.scan.model = ScannerModel::kPinhole;
  c.grid.scan.distance_mm = 400;
  c.grid.scan.width_px = 170;
  c.grid.tilted_patch = 4, c.grid.tilted_patch_deg = 6;
  c.grid.seed = 8;
  return c;
}

PatchScanCase Orthographic4x3Case() {
  PatchScanCase c = Orthographic2x2Case();
  c.name = "ortho 4x3";
  c.painting.width_mm = 520, c.painting.height_mm = 330;
  c.painting.stroke_count = 400;
  c.painting.seed = 7;
  c.grid.columns = 4, c.grid.rows = 3;
  return c;
}

SyntheticPatchScan SimulateCase(const PatchScanCase& c, Painting* painting_out) {
  PaintingOptions po = c.painting;
  po.resolution_px = MatchedPatchResolution(po, c.grid);
  const Painting painting = MakePainting(po);
  const Scene scene(painting, c.frame);
  SyntheticPatchScan scan = SimulatePatchScan(scene, c.grid);
  if (painting_out) *painting_out = painting;
  return scan;
}

SyntheticPatchScan SimulatePatchScan(const Scene& scene, const PatchGridOptions& options) {
  const Status valid = options.Validate();
  DIGITIZE_CHECK(valid.ok(), "SimulatePatchScan: " + valid.message());
  const Painting& painting = scene.painting();
  SyntheticPatchScan out;
  out.options = options;
  out.field_mm = FieldOf(painting.options, options);
  const double deg = std::numbers::pi / 180;
  std::mt19937_64 rng(options.seed * 0x9E3779B97F4A7C15ull + 17);
  std::uniform_real_distribution<double> unit(-1, 1);
  for (int r = 0; r < options.rows; ++r) {
    for (int c = 0; c < options.columns; ++c) {
      const int index = r * options.columns + c;
      SyntheticPatch p;
      p.column = c, p.row = r;
      const Eigen::Vector2d f = out.field_mm;
      p.centre_mm = {
          -options.margin_mm + 0.5 * f.x() + c * (1 - options.overlap) * f.x(),
          painting.height_mm + options.margin_mm - 0.5 * f.y() - r * (1 - options.overlap) * f.y()};
      ScanSimOptions s = options.scan;
      s.height_px = std::max(8, static_cast<int>(std::lround(s.width_px * f.y() / f.x())));
      s.aim_mm = p.centre_mm;
      s.field_mm = f;
      s.seed = options.seed * 1000 + static_cast<uint64_t>(index);
      s.exposures = 1;
      if (index == options.tilted_patch) s.tilt_deg += options.tilted_patch_deg;
      // The drift: about the aim point, canvas frame.
      const double axis_angle = std::numbers::pi * unit(rng);
      const Vec3d axis(std::cos(axis_angle), std::sin(axis_angle), 0);
      const double tilt = options.drift_deg * 0.5 * (1 + unit(rng)) * deg;
      const double spin = 0.5 * options.drift_deg * unit(rng) * deg;
      const Mat3d rot = (Eigen::AngleAxisd(tilt, axis) * Eigen::AngleAxisd(spin, Vec3d::UnitZ()))
                            .toRotationMatrix();
      const Vec3d shift(options.drift_mm * unit(rng), options.drift_mm * unit(rng),
                        0.5 * options.drift_mm * unit(rng));
      const Vec3d centre(p.centre_mm.x(), p.centre_mm.y(), 0);
      s.pose_error.rotation = rot;
      s.pose_error.translation = centre - rot * centre + shift;
      p.scan = SimulateScan(scene, s);
      p.scan.exposures[0].source = "patch_" + std::to_string(r) + "_" + std::to_string(c) + ".exr";
      p.nominal_canvas_from_scan = s.pose_error.Inverse() * p.scan.canvas_from_scan;
      out.patches.push_back(std::move(p));
    }
  }
  return out;
}

Status WriteSyntheticPatchScan(const std::filesystem::path& dir, const Painting& painting,
                               const SyntheticPatchScan& scan) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return Error{dir.string() + ": cannot create the output directory: " + ec.message()};
  nlohmann::json list = nlohmann::json::array(), truth = nlohmann::json::array();
  for (const SyntheticPatch& p : scan.patches) {
    const std::string name = p.scan.exposures[0].source;
    if (Status s = WriteScanExr(dir / name, p.scan.exposures[0]); !s.ok()) return s;
    list.push_back({{"scan", name}, {"rig_from_scan", PoseJson(p.nominal_canvas_from_scan)}});
    truth.push_back(
        {{"scan", name},
         {"row", p.row},
         {"column", p.column},
         {"canvas_from_scan", PoseJson(p.scan.canvas_from_scan)},
         {"nominal_canvas_from_scan", PoseJson(p.nominal_canvas_from_scan)},
         {"model", p.scan.options.model == ScannerModel::kPinhole ? "pinhole" : "orthographic"},
         {"size_px", {p.scan.options.width_px, p.scan.options.height_px}}});
  }
  const ImageMetadata meta = {{"digitize:frame", "canvas"},
                              {"digitize:units", "mm"},
                              {"digitize:quantity", "height"},
                              {"digitize:pitch_mm", std::to_string(painting.truth.pitch_mm)}};
  if (Status s = WriteFloatExr(dir / "truth_height.exr", painting.truth.height_mm, "Y", meta);
      !s.ok())
    return s;
  const nlohmann::json truth_doc = {
      {"format", "digitize.synthetic_patch_truth"},
      {"version", 1},
      {"canvas_mm", {painting.width_mm, painting.height_mm}},
      {"pitch_mm", painting.truth.pitch_mm},
      {"size_texels", {painting.truth.width(), painting.truth.height()}},
      {"grid", {scan.options.columns, scan.options.rows}},
      {"overlap", scan.options.overlap},
      {"drift_mm", scan.options.drift_mm},
      {"drift_deg", scan.options.drift_deg},
      {"seed", scan.options.seed},
      {"frame", "rig frame = the true canvas frame; canvas_from_scan = true pose"},
      {"patches", truth}};
  if (Status s = WriteTextFile(dir / "truth_patches.json", truth_doc.dump(2) + "\n"); !s.ok())
    return s;
  // The patch list last: its presence says the set is complete.
  const nlohmann::json doc = {{"format", "digitize.scan_patches"},
                              {"version", 1},
                              {"frame", "rig"},
                              {"units", "mm"},
                              {"patches", list}};
  return WriteTextFile(dir / "patches.json", doc.dump(2) + "\n");
}

}  // namespace digitize::synth
