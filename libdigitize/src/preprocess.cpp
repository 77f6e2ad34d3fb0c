#include "digitize/preprocess.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <nlohmann/json.hpp>

#include "digitize/image_io.h"
#include "json_fields.h"
#include "options_json.h"
#include "preprocess_internal.h"

namespace digitize {
namespace {

using preprocess_internal::Clock;

using preprocess_internal::Format;
using preprocess_internal::SecondsSince;

constexpr double kSteps = 6;  // progress: each step counts as one sixth

double Percent(size_t part, size_t whole) { return whole ? 100.0 * part / whole : 0.0; }

template <class T>
bool AllFinite(const Grid<T>& grid) {
  for (const T& v : grid.data) {
    if constexpr (std::is_same_v<T, float>) {
      if (!std::isfinite(v)) return false;
    } else {
      if (!v.allFinite()) return false;
    }
  }
  return true;
}

// Relief and normals of a merged canvas field: the steps Preprocess and PreprocessPatches share.
void FinishPreprocess(PreprocessResult& result, const PreprocessOptions& options,
                      const ProgressCallback& progress) {
  const CanvasResult& c = result.canvas;
  auto step = [&](const char* name, Clock::time_point t0, std::string line) {
    result.steps.push_back({name, SecondsSince(t0), std::move(line)});
  };
  auto t0 = Clock::now();
  ReportProgress(progress, "relief", 4.0 / kSteps);
  result.relief = ClassifyRelief(result.field, PreprocessReliefOptions(options, c.noise_sigma_mm));
  const ReliefResult& r = result.relief;
  step("relief", t0,
       Format("relief: max height %.3f mm, delta0 %.3f mm; %zu texels above in %zu component(s) "
              "(%zu specks removed); %zu boxes of %dx%d texels",
              r.max_height_mm, r.delta0_mm, r.texels_above, r.components_kept, r.components_removed,
              r.boxes.size(), r.cell_px, r.cell_px));

  t0 = Clock::now();
  ReportProgress(progress, "normals", 5.0 / kSteps);
  result.normals = ComputeNormals(result.field);
  step("normals", t0,
       Format("normals: %dx%d from 8-neighbourhood triangles", result.normals.width,
              result.normals.height));
  ReportProgress(progress, "done", 1.0);

  // The contract is "no NaN/Inf ever leaves a stage": a violation is a bug, not bad input.
  DIGITIZE_CHECK(AllFinite(result.field.height_mm), "preprocess produced a non-finite height");
  DIGITIZE_CHECK(AllFinite(result.normals), "preprocess produced a non-finite normal");
}

}  // namespace

ReliefOptions PreprocessReliefOptions(const PreprocessOptions& options, double noise_sigma_mm) {
  ReliefOptions relief = options.relief;
  if (options.noise_margin_from_scan) {
    // The max of N Gaussian samples reaches ~5 sigma for N ~ 10^6: below 8 sigma, the "relief" of
    // a flat canvas is its noise. The margin is capped so it never swallows delta0 itself.
    relief.min_relief_mm = std::max(relief.min_relief_mm, 8.0 * noise_sigma_mm);
    relief.noise_margin_mm = 2.0 * noise_sigma_mm;
  }
  return relief;
}

Status PreprocessOptions::Validate() const {
  for (const auto& [name, status] :
       {std::pair{"merge", merge.Validate()}, std::pair{"sanitize", sanitize.Validate()},
        std::pair{"canvas", canvas.Validate()}, std::pair{"resample", resample.Validate()},
        std::pair{"relief", relief.Validate()}}) {
    if (!status.ok()) return Error{std::string(name) + " options: " + status.message()};
  }
  return Status::Ok();
}

Result<PreprocessResult> Preprocess(std::vector<Scan> exposures, const PreprocessOptions& options,
                                    const ProgressCallback& progress) {
  if (Status s = options.Validate(); !s.ok()) return Error{s.message()};
  if (exposures.empty()) return Error{"preprocess: no scan given"};

  PreprocessResult result;
  const auto start = Clock::now();
  auto step = [&](const char* name, Clock::time_point t0, std::string line) {
    result.steps.push_back({name, SecondsSince(t0), std::move(line)});
  };

  // Merge the exposures of one pose (a single exposure passes through untouched).
  auto t0 = Clock::now();
  ReportProgress(progress, "merge", 0.0 / kSteps);
  Scan scan;
  if (exposures.size() == 1) {
    scan = std::move(exposures.front());
    result.merge.exposures = 1;
  } else {
    Result<Scan> merged = MergeExposures(exposures, options.merge, &result.merge);
    if (!merged.ok()) return merged.error();
    scan = std::move(merged).value();
  }
  exposures = {};  // merged: a scan's worth of memory each
  step("merge", t0,
       Format("merge: %d exposure(s) of %dx%d, %zu samples filled from other exposures, %zu "
              "disagreeing",
              result.merge.exposures, scan.xyz_mm.width, scan.xyz_mm.height,
              result.merge.filled_from_others, result.merge.disagreeing));

  t0 = Clock::now();
  ReportProgress(progress, "sanitize", 1.0 / kSteps);
  result.sanitize = SanitizeScan(scan, options.sanitize);
  const SanitizeStats& ss = result.sanitize;
  step("sanitize", t0,
       Format(
           "sanitize: %zu of %zu samples valid (%.1f %%); %zu missing, %zu non-finite or absurd, "
           "%zu isolated spikes removed",
           ss.valid, ss.total, Percent(ss.valid, ss.total), ss.missing, ss.non_finite, ss.spikes));

  t0 = Clock::now();
  ReportProgress(progress, "canvas", 2.0 / kSteps);
  Result<CanvasResult> canvas = ExtractCanvas(scan, options.canvas);
  if (!canvas.ok()) return canvas.error();
  result.canvas = std::move(canvas).value();
  const CanvasResult& c = result.canvas;
  const Vec3d normal_scan = c.canvas_from_scan.rotation.row(2).transpose();
  step(
      "canvas", t0,
      Format(
          "canvas: %.1f x %.1f mm, plane tilted %.3f deg from the scanner axis, plane RMS %.4f mm, "
          "noise sigma %.4f mm; region %zu px (+%zu islands, +%zu boundary), seed (%d, %d)",
          c.extent_mm.x(), c.extent_mm.y(), AngleDeg(normal_scan, -Vec3d::UnitZ()), c.plane_rms_mm,
          c.noise_sigma_mm, c.grown_px, c.islands_filled_px, c.refined_px, c.seed_x, c.seed_y) +
          (c.outline_fitted ? "; axes and mask from the canvas outline"
                            : "; outline not used (" + c.outline_note + "): PCA axes") +
          [&] {
            // The frame the fit's rays will see, side by side (none: nothing rises around it).
            std::string text = "; frame:";
            bool any = false;
            for (int side = 0; side < 4; ++side) {
              if (c.frame.raise_mm[side] <= 0) continue;
              text += Format("%s %s %.1f mm high x %.1f wide", any ? "," : "",
                             kFrameSideNames[side], c.frame.raise_mm[side], c.frame.width_mm[side]);
              any = true;
            }
            return any ? text : std::string("; frame: none");
          }() +
          [&] {
            std::string text;
            for (const std::string& w : c.warnings) text += "; WARNING: " + w;
            return text;
          }());

  t0 = Clock::now();
  ReportProgress(progress, "resample", 3.0 / kSteps);
  Result<HeightField> field =
      ResampleToCanvasGrid(std::move(scan), result.canvas, options.resample, &result.resample);
  if (!field.ok()) return field.error();
  result.field = std::move(field).value();
  result.field.frame = result.canvas.frame;
  const ResampleStats& rs = result.resample;
  step("resample", t0,
       Format("resample: %dx%d texels at %.4f mm; %zu measured, %zu filled in %zu small hole(s), "
              "%zu unfilled in %zu large hole(s)",
              result.field.width(), result.field.height(), result.field.pitch_mm, rs.measured,
              rs.filled, rs.holes_filled, rs.unfilled, rs.holes_unfilled));
  // Later steps read the canvas grid only: the resample freed the scan's samples once drawn.
  scan = Scan();

  FinishPreprocess(result, options, progress);
  result.total_seconds = SecondsSince(start);
  return result;
}

Result<PreprocessResult> PreprocessPatches(std::vector<ScanPatch> patches,
                                           const PreprocessOptions& options,
                                           const PatchRegistrationOptions& registration,
                                           const ProgressCallback& progress) {
  if (Status s = options.Validate(); !s.ok()) return Error{s.message()};
  if (Status s = registration.Validate(); !s.ok())
    return Error{"registration options: " + s.message()};
  PreprocessResult result;
  const auto start = Clock::now();
  auto t0 = Clock::now();
  ReportProgress(progress, "sanitize", 1.0 / kSteps);
  for (ScanPatch& p : patches) {
    const SanitizeStats ss = SanitizeScan(p.scan, options.sanitize);
    result.sanitize.total += ss.total, result.sanitize.valid += ss.valid;
    result.sanitize.missing += ss.missing, result.sanitize.non_finite += ss.non_finite;
    result.sanitize.spikes += ss.spikes;
  }
  const SanitizeStats& ss = result.sanitize;
  result.steps.push_back(
      {"sanitize", SecondsSince(t0),
       Format("sanitize: %zu patch scans, %zu of %zu samples valid (%.1f %%); %zu missing, %zu "
              "non-finite or absurd, %zu isolated spikes removed",
              patches.size(), ss.valid, ss.total, Percent(ss.valid, ss.total), ss.missing,
              ss.non_finite, ss.spikes)});

  t0 = Clock::now();
  ReportProgress(progress, "register", 2.0 / kSteps);
  Result<PatchRegistrationResult> r =
      RegisterPatches(patches, registration, options.canvas, options.resample);
  if (!r.ok()) return r.error();
  result.canvas = r->canvas;
  result.field = r->field;
  result.resample = r->resample;
  result.merge.exposures = 1;
  std::string line = "register: " + r->brief;
  for (const std::string& w : r->canvas.warnings) line += "; WARNING: " + w;
  result.steps.push_back({"register", SecondsSince(t0), line});
  result.registration = std::move(r).value();
  FinishPreprocess(result, options, progress);
  result.total_seconds = SecondsSince(start);
  return result;
}

nlohmann::json ToJson(const PreprocessOptions& options) {
  return {{"sanitize",
           {{"max_abs_coordinate_mm", options.sanitize.max_abs_coordinate_mm},
            {"spike_mm", options.sanitize.spike_mm}}},
          {"merge", {{"disagree_mm", options.merge.disagree_mm}}},
          {"canvas",
           {{"stop_gradient_mm", options.canvas.stop_gradient_mm},
            {"stop_slope", options.canvas.stop_slope},
            {"refine_step_mm", options.canvas.refine_step_mm},
            {"refine_px", options.canvas.refine_px},
            {"erode_px", options.canvas.erode_px},
            {"trim_sigmas", options.canvas.trim_sigmas},
            {"seed_px", {options.canvas.seed_x, options.canvas.seed_y}}}},
          {"resample",
           {{"pitch_mm", options.resample.pitch_mm},
            {"max_edge_factor", options.resample.max_edge_factor},
            {"max_hole_area_mm2", options.resample.max_hole_area_mm2}}},
          {"relief",
           {{"delta0_fraction", options.relief.delta0_fraction},
            {"min_component_area_mm2", options.relief.min_component_area_mm2},
            {"cell_px", options.relief.cell_px},
            {"cover_px", options.relief.cover_px},
            {"min_relief_mm", options.relief.min_relief_mm},
            {"noise_margin_from_scan", options.noise_margin_from_scan}}}};
}

std::string PreprocessReportJson(const PreprocessResult& result, const PreprocessOptions& options,
                                 const std::vector<std::string>& inputs) {
  using nlohmann::json;
  const CanvasResult& c = result.canvas;
  json steps = json::array();
  for (const StepReport& s : result.steps)
    steps.push_back({{"name", s.name}, {"seconds", s.seconds}, {"summary", s.line}});
  json report = {
      {"format", "digitize.preprocess_report"},
      {"version", 1},
      {"tool_version", DIGITIZE_VERSION},
      {"inputs", inputs},
      {"steps", steps},
      {"total_seconds", result.total_seconds},
      {"sanitize",
       {{"total", result.sanitize.total},
        {"missing", result.sanitize.missing},
        {"non_finite", result.sanitize.non_finite},
        {"spikes", result.sanitize.spikes},
        {"valid", result.sanitize.valid}}},
      {"merge",
       {{"exposures", result.merge.exposures},
        {"filled_from_others", result.merge.filled_from_others},
        {"disagreeing", result.merge.disagreeing}}},
      {"canvas",
       {{"extent_mm", {c.extent_mm.x(), c.extent_mm.y()}},
        {"plane_rms_mm", c.plane_rms_mm},
        {"noise_sigma_mm", c.noise_sigma_mm},
        {"grown_px", c.grown_px},
        {"islands_filled_px", c.islands_filled_px},
        {"refined_px", c.refined_px},
        {"plane_points", c.plane_points},
        {"seed_px", {c.seed_x, c.seed_y}},
        {"outline_fitted", c.outline_fitted},
        {"outline_note", c.outline_note},
        {"hidden_edges", c.hidden_edges},
        {"canvas_from_scan", ToJson(c.canvas_from_scan)}}},
      {"warnings", c.warnings},
      {"resample",
       {{"pitch_mm", result.field.pitch_mm},
        {"size_texels", {result.field.full_width(), result.field.full_height()}},
        {"measured", result.resample.measured},
        {"filled", result.resample.filled},
        {"unfilled", result.resample.unfilled},
        {"outside", result.resample.outside},
        {"holes_filled", result.resample.holes_filled},
        {"holes_unfilled", result.resample.holes_unfilled},
        {"triangles_drawn", result.resample.triangles_drawn},
        {"triangles_skipped", result.resample.triangles_skipped}}},
      {"relief",
       {{"max_height_mm", result.relief.max_height_mm},
        {"delta0_mm", result.relief.delta0_mm},
        {"cell_px", result.relief.cell_px},
        {"boxes", result.relief.boxes.size()},
        {"texels_above", result.relief.texels_above},
        {"components_kept", result.relief.components_kept},
        {"components_removed", result.relief.components_removed}}},
      {"options", ToJson(options)},
  };
  if (result.tiled) {
    const PreprocessResult::Tiled& t = *result.tiled;
    report["tiled"] = {{"tile_texels", t.tile_texels},
                       {"halo_texels", t.halo_texels},
                       {"canvas_stride", t.canvas_stride},
                       {"tiles", t.tiles},
                       {"tiles_without_samples", t.tiles_without_samples},
                       {"scan_spacing_mm", t.scan_spacing_mm}};
  }
  return report.dump(2) + "\n";
}

Status WritePreprocessOutputs(const std::filesystem::path& dir, const PreprocessResult& result,
                              const PreprocessOptions& options,
                              const std::vector<std::string>& inputs) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return Error{dir.string() + ": cannot create the output folder: " + ec.message()};

  const HeightField& f = result.field;
  if (Status s = WriteFloatExr(dir / "height.exr", f.height_mm, "Y",
                               preprocess_internal::HeightMapMetadata(f.pitch_mm));
      !s.ok())
    return s;
  if (Status s = WriteFloatExr(dir / "normals.exr", result.normals, {"R", "G", "B"},
                               preprocess_internal::NormalMapMetadata(f.pitch_mm));
      !s.ok())
    return s;
  Grid<uint8_t> mask(f.width(), f.height());
  for (size_t i = 0; i < mask.size(); ++i)
    mask.data[i] = preprocess_internal::MaskPngCode(f.state.data[i]);
  if (Status s = WritePng8(dir / "mask.png", mask); !s.ok()) return s;
  return WritePreprocessSideFiles(dir, result, options, inputs);
}

Status WritePreprocessSideFiles(const std::filesystem::path& dir, const PreprocessResult& result,
                                const PreprocessOptions& options,
                                const std::vector<std::string>& inputs) {
  const HeightField& f = result.field;
  Grid<uint8_t> scan_mask = result.canvas.mask_scan;
  for (uint8_t& v : scan_mask.data) v = v ? 255 : 0;
  if (Status s = WritePng8(dir / "canvas_mask_scan.png", scan_mask); !s.ok()) return s;
  using nlohmann::json;
  json boxes = json::array();
  for (const ReliefBox& b : result.relief.boxes)
    boxes.push_back({{"x0", b.x0},
                     {"y0", b.y0},
                     {"width", b.width},
                     {"height", b.height},
                     {"h_max_mm", b.h_max_mm},
                     {"u_max", b.u_max},
                     {"v_max", b.v_max}});
  json boxes_doc = {{"format", "digitize.boxes"},
                    {"version", 1},
                    {"units", "texels; heights in mm"},
                    {"grid_size_texels", {f.full_width(), f.full_height()}},
                    {"pitch_mm", f.pitch_mm},
                    {"cell_px", result.relief.cell_px},
                    {"delta0_mm", result.relief.delta0_mm},
                    {"max_height_mm", result.relief.max_height_mm},
                    {"boxes", boxes}};
  if (Status s = WriteTextFile(dir / "boxes.json", boxes_doc.dump(1) + "\n"); !s.ok()) return s;

  json transform = {
      {"format", "digitize.transform"},
      {"version", 1},
      {"canvas_from_scan", ToJson(result.canvas.canvas_from_scan)},
      {"pitch_mm", f.pitch_mm},
      {"size_texels", {f.full_width(), f.full_height()}},
      {"extent_mm", {result.canvas.extent_mm.x(), result.canvas.extent_mm.y()}},
      {"texel_centre", "X = (x + 0.5) * pitch_mm, Y = (rows - y - 0.5) * pitch_mm, Z = height_mm"}};
  if (f.frame.any()) {
    json frame = json::object();
    for (int side = 0; side < 4; ++side)
      if (f.frame.raise_mm[side] > 0)
        frame[kFrameSideNames[side]] = {{"raise_mm", f.frame.raise_mm[side]},
                                        {"width_mm", f.frame.width_mm[side]},
                                        {"gap_mm", f.frame.gap_mm[side]}};
    transform["frame"] = frame;
  }
  if (Status s = WriteTextFile(dir / "transform.json", transform.dump(2) + "\n"); !s.ok()) return s;

  if (result.registration) {
    if (Status s = WriteTextFile(dir / "registration.json",
                                 PatchRegistrationJson(*result.registration, inputs));
        !s.ok())
      return s;
  }
  return WriteTextFile(dir / "report.json", PreprocessReportJson(result, options, inputs));
}

}  // namespace digitize

namespace digitize {
namespace {

// A canvas folder's JSON file (docs/formats.md), whose "format" must be `format`.
nlohmann::json ReadFormatFile(const std::filesystem::path& path, const char* format) {
  auto text = ReadTextFile(path, std::string(format) + " file");
  if (!text.ok()) Fail(text.error().message);
  nlohmann::json doc = ParseJson(*text, path.string());
  if (!doc.is_object() || !doc.contains("format") || doc["format"] != format)
    Fail(path.string() + ": not a " + format + " file");
  return doc;
}

// transform.json: the pitch and canvas_from_scan.
void ReadTransformFile(const std::filesystem::path& path, PreprocessedCanvas& out) {
  const std::string file = path.string();
  const nlohmann::json doc = ReadFormatFile(path, "digitize.transform");
  const Fields top(doc, file);
  const double pitch = top.Number("pitch_mm");
  if (!(pitch > 0)) Fail(file + ": pitch_mm must be > 0, got " + FormatNumber(pitch));
  out.field.pitch_mm = pitch;
  out.canvas_from_scan = TransformFrom(top.Object("canvas_from_scan"));
  const Mat3d& R = out.canvas_from_scan.rotation;
  if ((R * R.transpose() - Mat3d::Identity()).norm() > 1e-4 || R.determinant() < 0)
    Fail(file + ": canvas_from_scan.rotation is not a rotation");
  // Optional (older folders have none): the frame's boxes, per side present.
  if (top.Has("frame")) {
    const Fields frame = top.Object("frame");
    frame.OnlyKeys({"left", "right", "bottom", "top"});
    for (int side = 0; side < 4; ++side) {
      if (!frame.Has(kFrameSideNames[side])) continue;
      const Fields box = frame.Object(kFrameSideNames[side]);
      box.OnlyKeys({"raise_mm", "width_mm", "gap_mm"});
      out.field.frame.raise_mm[side] = static_cast<float>(box.Number("raise_mm"));
      out.field.frame.width_mm[side] = static_cast<float>(box.Number("width_mm"));
      out.field.frame.gap_mm[side] = static_cast<float>(box.Number("gap_mm"));
    }
    if (Status s = out.field.frame.Validate(); !s.ok()) Fail(file + ": " + s.message());
  }
}

// boxes.json: the bump plane, H, the cell size and the boxes, each inside the w x h grid.
void ReadBoxesFile(const std::filesystem::path& path, int w, int h, PreprocessedCanvas& out) {
  const std::string file = path.string();
  const nlohmann::json doc = ReadFormatFile(path, "digitize.boxes");
  const Fields top(doc, file);
  constexpr int64_t kIntMax = std::numeric_limits<int>::max();
  out.delta0_mm = top.Number("delta0_mm");
  out.max_height_mm = top.Number("max_height_mm");
  out.cell_px = static_cast<int>(top.Integer("cell_px", -kIntMax, kIntMax));
  if (out.cell_px < 1) Fail(file + ": delta0_mm, max_height_mm must be finite, cell_px >= 1");
  const nlohmann::json& boxes = top.Array("boxes");
  for (size_t i = 0; i < boxes.size(); ++i) {
    const Fields b(boxes[i], file + ": boxes[" + std::to_string(i) + "]");
    ReliefBox box;
    for (auto [key, target] : {std::pair<const char*, int*>{"x0", &box.x0},
                               {"y0", &box.y0},
                               {"width", &box.width},
                               {"height", &box.height},
                               {"u_max", &box.u_max},
                               {"v_max", &box.v_max}})
      *target = static_cast<int>(b.Integer(key, -kIntMax, kIntMax));
    box.h_max_mm = static_cast<float>(b.Number("h_max_mm"));
    if (box.x0 < 0 || box.y0 < 0 || box.width < 1 || box.height < 1 ||
        int64_t{box.x0} + box.width > w || int64_t{box.y0} + box.height > h ||
        !std::isfinite(box.h_max_mm))
      Fail(file + ": box " + std::to_string(i) + " is not inside the " + std::to_string(w) + "x" +
           std::to_string(h) + " grid");
    out.boxes.push_back(box);
  }
}

}  // namespace

Status CheckCanvasFolder(const std::filesystem::path& dir) {
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec))
    return Error{dir.string() + ": " +
                 (std::filesystem::exists(dir, ec) ? "not a folder" : "no such folder") +
                 " (a canvas folder written by `digitize preprocess` was expected)"};
  for (const char* name : kCanvasFolderFiles) {
    if (!std::filesystem::is_regular_file(dir / name, ec))
      return Error{dir.string() + ": not a canvas folder (written by `digitize preprocess`): " +
                   name + " is missing"};
  }
  return Status::Ok();
}

namespace {

// The canvas folder `dir`, all of it (reader null) or the window [x0, x0 + ww) x [y0, y0 + wh) of
// it read through `reader`; texels named in errors are the full canvas's.
Result<PreprocessedCanvas> ReadCanvasFolder(const std::filesystem::path& dir,
                                            ImageRegionReader* reader, int x0, int y0, int ww,
                                            int wh) {
  if (Status s = CheckCanvasFolder(dir); !s.ok()) return Error{s.message()};
  PreprocessedCanvas out;
  const auto height_path = dir / "height.exr";
  const auto mask_path = dir / "mask.png";
  const auto normals_path = dir / "normals.exr";
  int w = 0, h = 0;  // the full canvas
  auto read = [&](const std::filesystem::path& path) -> Result<FloatImage> {
    if (!reader) return ReadImage(path);
    return reader->Read(path, x0, y0, ww, wh);
  };
  if (reader) {
    auto header = ReadImageHeader(height_path);
    if (!header.ok()) return header.error();
    w = header->width;
    h = header->height;
    if (ww <= 0 || wh <= 0 || x0 < 0 || y0 < 0 || x0 > w - ww || y0 > h - wh)
      return Error{height_path.string() + ": the window (" + std::to_string(x0) + ", " +
                   std::to_string(y0) + ", " + std::to_string(ww) + "x" + std::to_string(wh) +
                   ") is not inside the " + std::to_string(w) + "x" + std::to_string(h) +
                   " canvas"};
    for (const auto& path : {mask_path, normals_path}) {
      auto other = ReadImageHeader(path);
      if (!other.ok()) return other.error();
      if (other->width != w || other->height != h)
        return Error{path.string() + ": " + std::to_string(other->width) + "x" +
                     std::to_string(other->height) + ", height.exr is " + std::to_string(w) + "x" +
                     std::to_string(h)};
    }
  }
  auto height = read(height_path);
  if (!height.ok()) return height.error();
  if (height->channels != 1)
    return Error{height_path.string() + ": " + std::to_string(height->channels) +
                 " channels, expected 1 (height in mm)"};
  if (!reader) {
    w = height->width;
    h = height->height;
    x0 = y0 = 0;
  }
  const int gw = height->width, gh = height->height;  // the grid read
  auto size_error = [&](const std::filesystem::path& p, int pw, int ph) {
    return Error{p.string() + ": " + std::to_string(pw) + "x" + std::to_string(ph) +
                 ", height.exr is " + std::to_string(w) + "x" + std::to_string(h)};
  };
  auto mask = read(mask_path);
  if (!mask.ok()) return mask.error();
  if (mask->width != gw || mask->height != gh)
    return size_error(mask_path, mask->width, mask->height);
  if (mask->channels != 1) return Error{mask_path.string() + ": expected a 1-channel mask"};
  auto normals = read(normals_path);
  if (!normals.ok()) return normals.error();
  if (normals->width != gw || normals->height != gh)
    return size_error(normals_path, normals->width, normals->height);
  if (normals->channels != 3)
    return Error{normals_path.string() + ": expected 3 channels (nx, ny, nz)"};

  out.field.height_mm = Grid<float>(gw, gh);
  out.field.state = Grid<TexelState>(gw, gh, TexelState::kOutside);
  out.normals = Grid<Vec3f>(gw, gh);
  if (reader) out.field.window = TexelWindow{x0, y0, w, h};
  auto texel = [&](size_t i) {
    return std::to_string(x0 + static_cast<int>(i % gw)) + ", " +
           std::to_string(y0 + static_cast<int>(i / gw));
  };
  for (size_t i = 0; i < out.field.height_mm.size(); ++i) {
    const float z = height->pixels[i];
    if (!std::isfinite(z))
      return Error{height_path.string() + ": non-finite height at texel " + texel(i)};
    out.field.height_mm.data[i] = z;
    const int code = static_cast<int>(std::lround(mask->pixels[i] * 255.0f));
    switch (code) {
      case 0:
        out.field.state.data[i] = TexelState::kOutside;
        break;
      case 85:
        out.field.state.data[i] = TexelState::kUnfilled;
        break;
      case 170:
        out.field.state.data[i] = TexelState::kFilled;
        break;
      case 255:
        out.field.state.data[i] = TexelState::kMeasured;
        break;
      default:
        return Error{mask_path.string() + ": value " + std::to_string(code) + " at texel " +
                     texel(i) + " is not a texel state (0, 85, 170, 255)"};
    }
    const Vec3f n(normals->pixels[3 * i], normals->pixels[3 * i + 1], normals->pixels[3 * i + 2]);
    if (!IsValid(n) || std::abs(n.norm() - 1.0f) > 1e-3f)
      return Error{normals_path.string() + ": normal at texel " + texel(i) +
                   " is not a unit vector"};
    out.normals.data[i] = n;
  }

  const Result<bool> json_read = CatchBadInput([&] {
    ReadTransformFile(dir / "transform.json", out);
    ReadBoxesFile(dir / "boxes.json", w, h, out);
    return true;
  });
  if (!json_read.ok()) return json_read.error();
  return out;
}

}  // namespace

Result<PreprocessedCanvas> ReadPreprocessOutputs(const std::filesystem::path& dir) {
  return ReadCanvasFolder(dir, nullptr, 0, 0, 0, 0);
}

Result<PreprocessedCanvas> ReadPreprocessWindow(const std::filesystem::path& dir, int x0, int y0,
                                                int width, int height, ImageRegionReader& reader) {
  return ReadCanvasFolder(dir, &reader, x0, y0, width, height);
}

}  // namespace digitize
