// Synthetic scan + ground truth on disk (synth_io.h).
#include "digitize_synth/synth_io.h"

#include <algorithm>
#include <nlohmann/json.hpp>
#include <system_error>

#include "digitize/image_io.h"
#include "digitize/scan_io.h"

namespace digitize::synth {
namespace {

using nlohmann::json;

constexpr int kTruthFormatVersion = 1;

json MatrixJson(const Mat3d& m) {
  json rows = json::array();
  for (int r = 0; r < 3; ++r) rows.push_back({m(r, 0), m(r, 1), m(r, 2)});
  return rows;
}

json TransformJson(const RigidTransform& t) {
  json m4 = json::array();
  for (int r = 0; r < 3; ++r)
    m4.push_back({t.rotation(r, 0), t.rotation(r, 1), t.rotation(r, 2), t.translation(r)});
  m4.push_back({0.0, 0.0, 0.0, 1.0});
  return {{"matrix", m4},
          {"rotation", MatrixJson(t.rotation)},
          {"translation", {t.translation.x(), t.translation.y(), t.translation.z()}}};
}

json PaintingOptionsJson(const PaintingOptions& o) {
  return {{"width_mm", o.width_mm},
          {"height_mm", o.height_mm},
          {"resolution_px", o.resolution_px},
          {"seed", o.seed},
          {"weave", o.weave},
          {"weave_period_mm", o.weave_period_mm},
          {"weave_amplitude_mm", o.weave_amplitude_mm},
          {"strokes", o.strokes},
          {"stroke_count", o.stroke_count},
          {"stroke_min_mm", o.stroke_min_mm},
          {"stroke_max_mm", o.stroke_max_mm},
          {"impasto", o.impasto},
          {"impasto_count", o.impasto_count},
          {"impasto_max_mm", o.impasto_max_mm},
          {"craquelure", o.craquelure},
          {"crack_depth_mm", o.crack_depth_mm},
          {"crack_width_mm", o.crack_width_mm},
          {"region_count", o.region_count},
          {"bow_mm", o.bow_mm}};
}

json FrameOptionsJson(const FrameOptions& o) {
  return {
      {"enabled", o.enabled},
      {"raise_mm", o.raise_mm},
      {"width_mm", o.width_mm},
      {"wall_depth_mm", o.wall_depth_mm},
      {"side_widths_mm",
       {{"left", o.Width(0)}, {"right", o.Width(1)}, {"bottom", o.Width(2)}, {"top", o.Width(3)}}},
      {"bevel_width_mm", o.bevel_width_mm},
      {"bevel_height_mm", o.bevel_height_mm},
      {"lip_mm", o.lip_mm},
      {"lip_gap_mm", o.lip_gap_mm}};
}

json ScanOptionsJson(const ScanSimOptions& o) {
  return {{"model", o.model == ScannerModel::kPinhole ? "pinhole" : "orthographic"},
          {"width_px", o.width_px},
          {"height_px", o.height_px},
          {"field_margin", o.field_margin},
          {"tilt_deg", o.tilt_deg},
          {"tilt_axis_deg", o.tilt_axis_deg},
          {"roll_deg", o.roll_deg},
          {"offset_mm", {o.offset_mm.x(), o.offset_mm.y(), o.offset_mm.z()}},
          {"distance_mm", o.distance_mm},
          {"noise_mm", o.noise_mm},
          {"dropout", o.dropout},
          {"hole_blobs", o.hole_blobs},
          {"hole_blob_radius_px", o.hole_blob_radius_px},
          {"border_hole_blobs", o.border_hole_blobs},
          {"outliers", o.outliers},
          {"exposures", o.exposures},
          {"seed", o.seed}};
}

std::vector<std::string> ScanFileNames(const SyntheticScan& scan) {
  std::vector<std::string> names;
  if (scan.exposures.size() == 1) return {"scan.exr"};
  for (size_t e = 0; e < scan.exposures.size(); ++e)
    names.push_back("scan_" + std::to_string(e) + ".exr");
  return names;
}

}  // namespace

std::string SyntheticTruthJson(const Painting& painting, const SyntheticScan& scan) {
  const int scan_w = scan.canvas_mask_scan.width, scan_h = scan.canvas_mask_scan.height;
  size_t canvas_px = 0;
  for (uint8_t m : scan.canvas_mask_scan.data) canvas_px += m != 0;
  float max_h = 0, min_h = 0;
  for (float h : painting.truth.height_mm.data)
    max_h = std::max(max_h, h), min_h = std::min(min_h, h);
  json j = {
      {"format", "digitize.synthetic_truth"},
      {"version", kTruthFormatVersion},
      {"units", "mm"},
      {"frames",
       "canvas: origin at the canvas's lower-left corner, X right, Y up, Z towards the scanner "
       "(height_field.h); scan: scanner frame, looks along +Z, image x = +X, rows = +Y (scan.h)"},
      {"canvas_from_scan", TransformJson(scan.canvas_from_scan)},
      {"canvas",
       {{"width_mm", painting.width_mm},
        {"height_mm", painting.height_mm},
        {"width_px", painting.truth.width()},
        {"height_px", painting.truth.height()},
        {"pitch_mm", painting.truth.pitch_mm},
        {"texel_centre", "X = (x + 0.5) * pitch_mm, Y = (height_px - y - 0.5) * pitch_mm"},
        {"min_height_mm", min_h},
        {"max_height_mm", max_h},
        {"visible_min_mm", {scan.visible_min_mm.x(), scan.visible_min_mm.y()}},
        {"visible_max_mm", {scan.visible_max_mm.x(), scan.visible_max_mm.y()}},
        {"bare_plane",
         {{"normal",
           {painting.bare_plane_normal.x(), painting.bare_plane_normal.y(),
            painting.bare_plane_normal.z()}},
          {"offset_mm", painting.bare_plane_offset_mm},
          {"about",
           "least-squares plane of the bare (bowed) canvas, canvas frame, through "
           "(W/2, H/2, offset_mm)"}}}}},
      {"scan",
       {{"width_px", scan_w},
        {"height_px", scan_h},
        {"exposures", scan.exposures.size()},
        {"model", scan.options.model == ScannerModel::kPinhole ? "pinhole" : "orthographic"},
        {"pixel_pitch_mm", scan.pixel_pitch_mm},
        {"focal_px", scan.focal_px},
        {"principal_point_px", {0.5 * scan_w, 0.5 * scan_h}},
        {"canvas_pixels", canvas_px},
        {"files", ScanFileNames(scan)}}},
      {"hit_codes", {{"0", "none"}, {"1", "canvas"}, {"2", "frame"}, {"3", "wall"}}},
      {"seed", painting.options.seed},
      {"scan_seed", scan.options.seed},
      {"painting_options", PaintingOptionsJson(painting.options)},
      {"frame_options", FrameOptionsJson(scan.frame)},
      {"scan_options", ScanOptionsJson(scan.options)},
      {"files",
       {{"truth_height", "truth_height.exr"},
        {"truth_normals", "truth_normals.exr"},
        {"truth_regions", "truth_regions.png"},
        {"truth_mask_scan", "truth_mask_scan.png"},
        {"truth_hit_scan", "truth_hit_scan.png"}}}};
  return j.dump(2) + "\n";
}

Status WriteSyntheticScan(const std::filesystem::path& dir, const Painting& painting,
                          const SyntheticScan& scan) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return Error{dir.string() + ": cannot create the output directory: " + ec.message()};

  const std::vector<std::string> names = ScanFileNames(scan);
  for (size_t e = 0; e < scan.exposures.size(); ++e) {
    Status s = WriteScanExr(dir / names[e], scan.exposures[e]);
    if (!s.ok()) return s;
  }
  const ImageMetadata canvas_meta = {
      {"digitize:frame", "canvas"},
      {"digitize:units", "mm"},
      {"digitize:pitch_mm", std::to_string(painting.truth.pitch_mm)}};
  ImageMetadata height_meta = canvas_meta;
  height_meta["digitize:quantity"] = "height";
  if (Status s =
          WriteFloatExr(dir / "truth_height.exr", painting.truth.height_mm, "Y", height_meta);
      !s.ok())
    return s;
  ImageMetadata normal_meta = canvas_meta;
  normal_meta["digitize:quantity"] = "normal";
  normal_meta["digitize:units"] = "unit vector";
  if (Status s =
          WriteFloatExr(dir / "truth_normals.exr", painting.normals, {"X", "Y", "Z"}, normal_meta);
      !s.ok())
    return s;
  if (Status s = WritePng8(dir / "truth_regions.png", painting.region); !s.ok()) return s;
  Grid<uint8_t> mask = scan.canvas_mask_scan;
  for (uint8_t& m : mask.data) m = m ? 255 : 0;
  if (Status s = WritePng8(dir / "truth_mask_scan.png", mask); !s.ok()) return s;
  if (Status s = WritePng8(dir / "truth_hit_scan.png", scan.hit_scan); !s.ok()) return s;
  // truth.json last: its presence says the set is complete.
  return WriteTextFile(dir / "truth.json", SyntheticTruthJson(painting, scan));
}

}  // namespace digitize::synth
