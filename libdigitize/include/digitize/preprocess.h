// "Preprocess scanned height maps": scan exposures -> canvas height field, normals, relief boxes,
// and a report. Strings the stages together (paper 001 sections 4-5: canvas frame and extraction,
// relief, normals) and times each step.
#pragma once

#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "digitize/canvas.h"
#include "digitize/height_field.h"
#include "digitize/normals.h"
#include "digitize/relief.h"
#include "digitize/resample.h"
#include "digitize/scan.h"
#include "digitize/scan_registration.h"

namespace digitize {

class ImageRegionReader;  // image_io.h

struct PreprocessOptions {
  MergeOptions merge;
  SanitizeOptions sanitize;
  CanvasOptions canvas;
  ResampleOptions resample;
  ReliefOptions relief;
  bool noise_margin_from_scan = true;  // relief.noise_margin_mm = 2 x the estimated noise sigma
  Status Validate() const;             // validates every part, message says which option
};

// The relief options the preprocess classifies with: options.relief, with the floor and the
// noise margin from the scan's noise when options.noise_margin_from_scan.
ReliefOptions PreprocessReliefOptions(const PreprocessOptions& options, double noise_sigma_mm);

struct StepReport {
  std::string name;    // "merge", "sanitize", "canvas", "resample", "relief", "normals"
  double seconds = 0;  // wall time
  std::string line;    // one human-readable line: what was done and found
};

struct PreprocessResult {
  CanvasResult canvas;
  HeightField field;
  Grid<Vec3f> normals;
  ReliefResult relief;
  SanitizeStats sanitize;
  MergeStats merge;
  ResampleStats resample;
  std::vector<StepReport> steps;
  double total_seconds = 0;
  // PreprocessPatches only: the registration (per patch, per overlap). canvas.canvas_from_scan
  // is then canvas_from_RIG (the frame of the patch list's poses).
  std::optional<PatchRegistrationResult> registration;
  // PreprocessScanTiled only (preprocess_tiled.h): how the canvas was cut. Its sanitize counts
  // are the canvas pass's (every canvas_stride-th sample), its hole, triangle and component
  // counts summed over the tiles' windows (a hole two windows hold counts twice); texel states,
  // boxes and texels above are the canvas's.
  struct Tiled {
    int tile_texels = 0, halo_texels = 0, canvas_stride = 0, tiles = 0, tiles_without_samples = 0;
    double scan_spacing_mm = 0;
  };
  std::optional<Tiled> tiled;
};

// Errors: invalid options, exposures that cannot be merged, no canvas found (messages name the
// scan's source). Never returns NaN/Inf in any grid. Takes the scans by value: move them in to
// save a copy of a big scan (clean-up works in place).
Result<PreprocessResult> Preprocess(std::vector<Scan> exposures, const PreprocessOptions& options,
                                    const ProgressCallback& progress = nullptr);

// Several overlapping scans of one painting (patches, one pose each; scan_registration.h):
// each sanitised, then registered and merged (RegisterPatches: canvas, resample and blend), then
// relief and normals as Preprocess. Errors: those of RegisterPatches, naming the scan file.
// options.merge is unused (no exposures to merge).
Result<PreprocessResult> PreprocessPatches(std::vector<ScanPatch> patches,
                                           const PreprocessOptions& options,
                                           const PatchRegistrationOptions& registration,
                                           const ProgressCallback& progress = nullptr);

// A patch list (docs/formats.md, "patch list"): format "digitize.scan_patches", version 1, a
// "patches" array of {"scan": path relative to the list's folder, "rig_from_scan": {"rotation",
// "translation_mm"}}. Errors name the file and the key path; a rotation that is not one is an
// error. The scan paths come back resolved against the list's folder.
struct PatchListEntry {
  std::filesystem::path scan;
  RigidTransform rig_from_scan;
};
Result<std::vector<PatchListEntry>> ReadPatchList(const std::filesystem::path& path);

// registration.json (docs/formats.md, "registration report"): per patch its registered pose and
// correction, per overlap its residual. `sources` name the patches (the scan paths as given).
std::string PatchRegistrationJson(const PatchRegistrationResult& registration,
                                  const std::vector<std::string>& sources);

// The report as JSON text (docs/formats.md, "preprocess report").
std::string PreprocessReportJson(const PreprocessResult& result, const PreprocessOptions& options,
                                 const std::vector<std::string>& inputs);

// Writes height.exr, mask.png, normals.exr, boxes.json, transform.json, report.json into dir
// (created if needed), each atomically, and registration.json for patches. Returns the first
// error.
Status WritePreprocessOutputs(const std::filesystem::path& dir, const PreprocessResult& result,
                              const PreprocessOptions& options,
                              const std::vector<std::string>& inputs);

// What WritePreprocessOutputs writes besides the three texel maps: canvas_mask_scan.png and the
// JSON files (boxes.json, transform.json, report.json, and registration.json for patches), for a
// result whose maps were written as they were made (preprocess_tiled.h: its field holds no
// grids, field.window says the canvas's size).
Status WritePreprocessSideFiles(const std::filesystem::path& dir, const PreprocessResult& result,
                                const PreprocessOptions& options,
                                const std::vector<std::string>& inputs);

// What later stages need from a preprocess output folder (WritePreprocessOutputs): the height
// field (height.exr + mask.png states), the normals and canvas_from_scan (transform.json).
struct PreprocessedCanvas {
  HeightField field;
  Grid<Vec3f> normals;
  RigidTransform canvas_from_scan;
  // boxes.json (a flat canvas: no boxes, delta0 = 0)
  double delta0_mm = 0;
  double max_height_mm = 0;
  int cell_px = 16;
  std::vector<ReliefBox> boxes;
};
// A canvas folder: what every reader of one (`fit --canvas`, `pack --canvas`, the demo) requires,
// and so the one definition of it (docs/formats.md). WritePreprocessOutputs writes these and
// canvas_mask_scan.png, which no later stage needs. report.json is required although only the
// pack reads it (for its provenance: the preprocess options), so that a folder `fit` accepts is
// one `pack` accepts too.
inline constexpr std::array<const char*, 6> kCanvasFolderFiles = {
    "height.exr", "mask.png", "normals.exr", "transform.json", "boxes.json", "report.json"};
// Errors name the folder and the first missing file: "c/: not a canvas folder (written by
// `digitize preprocess`): boxes.json is missing". Checks presence only; ReadPreprocessOutputs
// checks the content.
Status CheckCanvasFolder(const std::filesystem::path& dir);

// Reads a canvas folder (CheckCanvasFolder first). Errors name the file: missing, unreadable,
// sizes that differ, a mask value that is no texel state, NaN/Inf heights or normals, a transform
// whose rotation is not a rotation, boxes outside the grid.
Result<PreprocessedCanvas> ReadPreprocessOutputs(const std::filesystem::path& dir);

// The window [x0, x0 + width) x [y0, y0 + height) of a canvas folder (a tile and its halo), its
// maps read through `reader` (image_io.h: a bounded cache, so a canvas larger than memory is read
// a part at a time); field.window says where it lies, transform, frame and boxes are the whole
// canvas's. Errors as ReadPreprocessOutputs, and a window not inside the canvas.
Result<PreprocessedCanvas> ReadPreprocessWindow(const std::filesystem::path& dir, int x0, int y0,
                                                int width, int height, ImageRegionReader& reader);

}  // namespace digitize
