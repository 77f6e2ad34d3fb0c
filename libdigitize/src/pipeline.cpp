// The pipeline end to end (pipeline.h): what `digitize fit`, `pack` and `run` call.
#include "digitize/pipeline.h"

#include <nlohmann/json.hpp>

#include "digitize/image_io.h"
#include "digitize/output_dir.h"
#include "digitize/provenance.h"
#include "digitize/relight.h"
#include "options_json.h"

namespace digitize {

namespace fs = std::filesystem;

Result<PhotoSet> ReadPhotoSetFile(const fs::path& path, const PhotoSetOptions& options,
                                  const ProgressCallback& progress) {
  if (path.extension() == ".lp" || path.extension() == ".LP")
    return ReadRtiCapture(path, options, progress);
  return ReadCalibration(path, options, progress);
}

Result<std::vector<Scan>> ReadScans(const std::vector<std::string>& paths,
                                    const ScanReadOptions& options) {
  if (Status s = options.Validate(); !s.ok()) return Error{s.message()};
  std::vector<Scan> exposures;
  for (const std::string& path : paths) {
    Result<Scan> scan = ReadScan(path, options);
    if (!scan.ok()) return scan.error();
    exposures.push_back(std::move(scan).value());
  }
  return exposures;
}

PreprocessedCanvas CanvasFromPreprocess(const PreprocessResult& result) {
  PreprocessedCanvas canvas;
  canvas.field = result.field;
  canvas.normals = result.normals;
  canvas.canvas_from_scan = result.canvas.canvas_from_scan;
  canvas.delta0_mm = result.relief.delta0_mm;
  canvas.max_height_mm = result.relief.max_height_mm;
  canvas.cell_px = result.relief.cell_px > 0 ? result.relief.cell_px : 16;
  canvas.boxes = result.relief.boxes;
  return canvas;
}

Result<PreprocessedCanvas> FlatCanvasFor(const PhotoSet& rti) {
  auto flat = FlatCanvasForRti(rti);
  if (!flat.ok()) return flat.error();
  PreprocessedCanvas canvas;
  canvas.field = std::move(flat).value();
  canvas.normals = Grid<Vec3f>(canvas.field.width(), canvas.field.height(), Vec3f::UnitZ());
  return canvas;
}

Result<PreprocessedCanvas> LoadFitCanvas(const fs::path& canvas_dir, const PhotoSet& set) {
  if (!canvas_dir.empty()) return ReadPreprocessOutputs(canvas_dir);
  if (!set.is_rti)
    return Error{"--canvas is required for a calibration file (" + set.source.string() +
                 "); only an RTI capture (.lp) can be fitted on a flat canvas without one"};
  return FlatCanvasFor(set);
}

ReflectanceFitOptions FitOptionsFor(const PhotoSet& set, ReflectanceFitOptions options,
                                    bool dark_outlier_ratio_chosen) {
  if (set.is_rti && !dark_outlier_ratio_chosen) {
    options.dark_outlier_ratio = 0;
    options.dark_outlier_fit_ratio = 0;
  }
  return options;
}

Result<PackSummary> PackFromFolders(const fs::path& canvas_dir, const fs::path& fit_dir,
                                    const fs::path& out, const PackWriteOptions& options) {
  if (Status s = options.Validate(); !s.ok()) return Error{s.message()};
  if (Status s = CheckOutputPath(out, {canvas_dir, fit_dir}); !s.ok()) return Error{s.message()};
  auto maps = ReadReflectanceMaps(fit_dir);
  if (!maps.ok()) return maps.error();
  if (canvas_dir.empty())
    return Error{
        "--canvas is required (for an RTI capture, preprocess a height map or use "
        "`digitize run --photos capture.lp`)"};
  auto canvas = ReadPreprocessOutputs(canvas_dir);
  if (!canvas.ok()) return canvas.error();
  auto provenance = ProvenanceFromOutputs(canvas_dir, fit_dir, options);
  if (!provenance.ok()) return provenance.error();
  auto pack = AssemblePack(std::move(canvas).value(), std::move(maps).value(),
                           std::move(provenance).value());
  if (!pack.ok()) return Error{fit_dir.string() + ": " + pack.error().message};
  if (Status s = WritePack(out, *pack, options); !s.ok()) return Error{s.message()};
  return InspectPack(out);
}

// The patch list, then every scan it names, all before any work; the folder checked against
// all of them first.
static Result<PreprocessResult> PreprocessPatchesToFolder(const PreprocessFolderOptions& options,
                                                          const ProgressCallback& progress) {
  if (!options.scans.empty())
    return Error{"preprocess: give either scans or a patch list (--patches " + options.patches +
                 "), not both"};
  if (!options.read.mask.empty())
    return Error{"preprocess: --mask applies to one scan, not to a patch list (" + options.patches +
                 ")"};
  if (Status s = options.registration.Validate(); !s.ok())
    return Error{"registration options: " + s.message()};
  Result<std::vector<PatchListEntry>> list = ReadPatchList(options.patches);
  if (!list.ok()) return list.error();
  if (list->size() < 2)
    return Error{options.patches + ": " + std::to_string(list->size()) +
                 " patch(es) listed, registration needs at least 2"};
  FolderOutput output{"preprocess", "canvas", {fs::path(options.patches)}};
  std::vector<std::string> sources;
  for (const PatchListEntry& e : *list) {
    output.inputs.push_back(e.scan);
    sources.push_back(e.scan.string());
  }
  if (Status s = CheckFolderOutput(options.out, output); !s.ok()) return Error{s.message()};
  std::vector<ScanPatch> patches;
  for (const PatchListEntry& e : *list) {
    Result<Scan> scan = ReadScan(e.scan, options.read);
    if (!scan.ok()) return scan.error();
    patches.push_back({std::move(scan).value(), e.rig_from_scan});
  }
  Result<PreprocessResult> result =
      PreprocessPatches(std::move(patches), options.preprocess, options.registration, progress);
  if (!result.ok()) return result.error();
  Status written = WriteDirectoryAtomically(options.out, output, [&](const fs::path& dir) {
    return WritePreprocessOutputs(dir, *result, options.preprocess, sources);
  });
  if (!written.ok()) return Error{written.message()};
  return result;
}

Result<PreprocessResult> PreprocessToFolder(const PreprocessFolderOptions& options,
                                            const ProgressCallback& progress) {
  if (Status s = options.preprocess.Validate(); !s.ok()) return Error{s.message()};
  if (!options.patches.empty()) return PreprocessPatchesToFolder(options, progress);
  FolderOutput output{"preprocess", "canvas", {options.scans.begin(), options.scans.end()}};
  if (!options.read.mask.empty()) output.inputs.emplace_back(options.read.mask);
  if (Status s = CheckFolderOutput(options.out, output); !s.ok()) return Error{s.message()};
  if (options.tiled) {
    if (options.scans.size() != 1 || !options.read.mask.empty())
      return Error{
          "a tiled preprocess takes one XYZ scan, without --mask (exposures are merged "
          "and masks applied whole)"};
    std::optional<PreprocessResult> tiled;
    Status written = WriteDirectoryAtomically(options.out, output, [&](const fs::path& dir) {
      auto r = PreprocessScanTiled(options.scans.front(), options.preprocess, *options.tiled, dir,
                                   options.scans, progress);
      if (!r.ok()) return Status(r.error());
      tiled = std::move(r).value();
      return Status::Ok();
    });
    if (!written.ok()) return Error{written.message()};
    return std::move(*tiled);
  }
  // A scan image too large to hold whole: say what to do (the reader's own refusal names the
  // limit only). Other files (PLY) are checked by the reader.
  for (const std::string& scan : options.scans) {
    const Result<ImageHeader> header = ReadImageHeader(scan);
    if (!header.ok()) continue;
    const uint64_t samples =
        static_cast<uint64_t>(header->width) * static_cast<uint64_t>(header->height);
    if (samples > options.read.max_samples)
      return Error{scan + ": " + std::to_string(header->width) + "x" +
                   std::to_string(header->height) + " = " + std::to_string(samples) +
                   " samples, more than the " + std::to_string(options.read.max_samples) +
                   " a whole preprocess takes (--max-scan-samples; ~22 bytes of memory a sample, " +
                   std::to_string((samples * 22) >> 20) + " MB): " +
                   (header->channels == 3 && !header->integer_samples
                        ? "preprocess it in tiles (--tile-texels 2048), or raise the limit"
                        : "raise the limit (only an XYZ float scan is preprocessed in tiles)")};
  }
  Result<std::vector<Scan>> exposures = ReadScans(options.scans, options.read);
  if (!exposures.ok()) return exposures.error();
  Result<PreprocessResult> result =
      Preprocess(std::move(exposures).value(), options.preprocess, progress);
  if (!result.ok()) return result.error();
  Status written = WriteDirectoryAtomically(options.out, output, [&](const fs::path& dir) {
    return WritePreprocessOutputs(dir, *result, options.preprocess, options.scans);
  });
  if (!written.ok()) return Error{written.message()};
  return result;
}

namespace {

struct PhotosToFit {
  PhotoSet photos;
  std::optional<PhotoSet> held;  // none without a held-out path
  ReflectanceFitOptions fit;     // FitOptionsFor the photos
  // The photo-set files and every image they name: inputs no output may touch.
  std::vector<fs::path> inputs;
};

// The photos and then the held-out ones, both before any fit: a bad file fails before minutes
// of work. `Options`: FitFolderOptions or PipelineOptions (the same photo fields).
template <typename Options>
Result<PhotosToFit> ReadPhotosToFit(const Options& options, const ProgressCallback& progress) {
  PhotosToFit read;
  Result<PhotoSet> set = ReadPhotoSetFile(options.photos, options.photo, progress);
  if (!set.ok()) return set.error();
  read.photos = std::move(set).value();
  read.fit = FitOptionsFor(read.photos, options.fit, options.dark_outlier_ratio_chosen);
  if (!options.held_out.empty()) {
    Result<PhotoSet> held = ReadPhotoSetFile(options.held_out, options.photo, progress);
    if (!held.ok()) return held.error();
    read.held = std::move(held).value();
  }
  if (!options.held_out_out.empty() && options.held_out.empty())
    return Error{"--held-out-out " + options.held_out_out + " needs --held-out photos to relight"};
  read.inputs.emplace_back(options.photos);
  for (const Photo& p : read.photos.photos) read.inputs.push_back(p.path);
  if (read.held) {
    read.inputs.emplace_back(options.held_out);
    for (const Photo& p : read.held->photos) read.inputs.push_back(p.path);
  }
  return read;
}

// The relit held-out photos' folder: what it may not touch (every input and the other outputs).
FolderOutput RelitFolder(const char* command, std::vector<fs::path> inputs) {
  return FolderOutput{command, "relit", std::move(inputs)};
}

Status WriteRelitFolder(const std::string& dir, const FolderOutput& output, const PhotoSet& held,
                        const std::vector<Grid<Vec3f>>& relit) {
  if (dir.empty()) return Status::Ok();
  return WriteDirectoryAtomically(
      dir, output, [&](const fs::path& tmp) { return WriteRelitImages(tmp, held, relit); });
}

// The fit, and the photo check after it. For an RTI capture (rti set) the photos' intensities are
// first refined against the fit (RtiCanvasOptions::refine_intensity_rounds), and then `held`
// (optional) gets the intensities its lights' directions predict.
struct CheckedFit {
  ReflectanceFitResult fit;
  std::optional<PhotoResidualReport> check;
};
template <typename Options>
Result<CheckedFit> FitAndCheck(const PreprocessedCanvas& canvas, PhotoSet& photos,
                               std::optional<RtiCanvas>& rti, std::optional<PhotoSet>& held,
                               const ReflectanceFitOptions& fit_options, const Options& options,
                               const ProgressCallback& progress) {
  CheckedFit out;
  auto fit = [&]() -> Status {
    auto r = FitReflectance(canvas.field, canvas.normals, canvas.canvas_from_scan, photos,
                            fit_options, progress);
    if (!r.ok()) return r.error();
    out.fit = std::move(r).value();
    return Status::Ok();
  };
  auto check = [&]() -> Status {
    auto r = CheckPhotoResiduals(canvas.field, canvas.normals, out.fit.maps,
                                 canvas.canvas_from_scan, photos, options.photo_check);
    if (!r.ok()) return r.error();
    out.check = std::move(r).value();
    return Status::Ok();
  };
  if (Status s = fit(); !s.ok()) return Error{s.message()};
  const int rounds = rti && options.rti.normals ? options.rti.refine_intensity_rounds : 0;
  for (int round = 0; round < rounds; ++round) {
    if (Status s = check(); !s.ok()) return Error{s.message()};
    std::vector<double> gains;
    for (const PhotoResidual& p : out.check->photos)
      gains.push_back(p.flags & kResidualTooFewPixels ? 1.0 : p.gain);
    ScaleRtiIntensities(photos, rti->intensities, gains);
    if (Status s = fit(); !s.ok()) return Error{s.message()};
  }
  if (rti && held)
    ApplyPredictedIntensities(photos, rti->intensities, options.rti.intensity_kernel_deg, *held);
  out.check.reset();
  if (options.check_photos)
    if (Status s = check(); !s.ok()) return Error{s.message()};
  return out;
}

}  // namespace

Result<FitFolderResult> FitToFolder(const FitFolderOptions& options,
                                    const ProgressCallback& progress) {
  if (Status s = options.photo.Validate(); !s.ok()) return Error{s.message()};
  if (Status s = options.fit.Validate(); !s.ok()) return Error{s.message()};
  if (Status s = options.rti.Validate(); !s.ok()) return Error{s.message()};
  if (Status s = options.photo_check.Validate(); !s.ok()) return Error{s.message()};
  if (!options.canvas.empty())
    if (Status s = CheckCanvasFolder(options.canvas); !s.ok()) return Error{s.message()};

  FitFolderResult result;
  Result<PhotosToFit> read = ReadPhotosToFit(options, progress);
  if (!read.ok()) return read.error();
  result.photos = std::move(read->photos);
  const PhotoSet& photos = result.photos;
  const ReflectanceFitOptions& fit_options = read->fit;
  std::optional<PhotoSet>& held = read->held;
  FolderOutput output{"fit", "fit", {}};
  if (!options.canvas.empty()) output.inputs.emplace_back(options.canvas);
  output.inputs.insert(output.inputs.end(), read->inputs.begin(), read->inputs.end());
  if (Status s = CheckFolderOutput(options.out, output); !s.ok()) return Error{s.message()};
  std::vector<fs::path> relit_keeps_off = output.inputs;
  relit_keeps_off.emplace_back(options.out);
  const FolderOutput relit_output = RelitFolder("fit", relit_keeps_off);
  if (!options.held_out_out.empty()) {
    if (Status s = CheckFolderOutput(options.held_out_out, relit_output); !s.ok())
      return Error{s.message()};
    if (Status s = CheckOutputPath(options.out, {options.held_out_out}); !s.ok())
      return Error{s.message()};
  }

  Result<PreprocessedCanvas> canvas = PreprocessedCanvas{};
  if (options.canvas.empty() && photos.is_rti) {
    auto rti = RtiCanvasFor(result.photos, options.rti, progress);
    if (!rti.ok()) return rti.error();
    canvas = rti->canvas;
    result.rti = std::move(rti).value();
  } else {
    canvas = LoadFitCanvas(options.canvas, photos);
  }
  if (!canvas.ok()) return canvas.error();
  auto checked =
      FitAndCheck(*canvas, result.photos, result.rti, held, fit_options, options, progress);
  if (!checked.ok()) return checked.error();
  result.photo_check = std::move(checked->check);
  ReflectanceFitResult* fit = &checked->fit;
  std::vector<Grid<Vec3f>> relit;
  if (held) {
    auto score = EvaluateHeldOut(canvas->field, canvas->normals, fit->maps,
                                 canvas->canvas_from_scan, *held, {}, 1.0, &relit);
    if (!score.ok()) return score.error();
    result.held_out = *score;
  }
  std::vector<std::string> inputs = {options.photos};
  if (!options.canvas.empty()) inputs.insert(inputs.begin(), options.canvas);
  Status written = WriteDirectoryAtomically(options.out, output, [&](const fs::path& dir) {
    return WriteReflectanceOutputs(dir, *fit, fit_options, inputs);
  });
  if (!written.ok()) return Error{written.message()};
  if (held) {
    if (Status s = WriteRelitFolder(options.held_out_out, relit_output, *held, relit); !s.ok())
      return Error{s.message()};
  }
  result.fit = std::move(fit->report);
  return result;
}

Status PipelineOptions::Validate() const {
  for (const Status& s : {pack.Validate(), photo.Validate(), rti.Validate(), fit.Validate(),
                          photo_check.Validate(), preprocess.Validate()})
    if (!s.ok()) return s;
  return Status::Ok();
}

namespace {

// What `run` records as a pack's provenance: every input file hashed, named relative to the photo
// set's folder (as its image paths are, not where they lay here), the fit's brief, and every
// stage's options as it ran (an RTI capture's pitch with where it came from: the pack's physical
// size rests on it).
Result<PackProvenance> RunProvenance(const PipelineOptions& options, const PhotoSet& set,
                                     const ReflectanceFitOptions& fit_options,
                                     const ReflectanceFitReport& fit,
                                     const std::optional<RtiCanvas>& rti) {
  PackProvenance provenance = NewProvenance();
  std::vector<fs::path> files(options.scans.begin(), options.scans.end());
  files.emplace_back(options.photos);
  for (const Photo& p : set.photos) files.push_back(p.path);
  if (Status s = AddProvenanceInputs(provenance, files, fs::absolute(options.photos).parent_path());
      !s.ok())
    return Error{s.message()};
  provenance.fit_brief = fit.Brief();
  nlohmann::json stages = {
      {"preprocess", options.scans.empty() ? nlohmann::json::object() : ToJson(options.preprocess)},
      {"fit", ToJson(fit_options)},
      {"pack", ToJson(options.pack)}};
  if (set.is_rti)
    stages["fit"]["rti_pitch"] = {{"mm", set.rti_pitch_mm},
                                  {"source", set.rti_pitch_source},
                                  {"assumed", set.rti_pitch_assumed}};
  if (rti)
    stages["rti"] = {{"normals", options.rti.normals},
                     {"height", options.rti.height},
                     {"intensity_kernel_deg", options.rti.intensity_kernel_deg},
                     {"refine_intensity_rounds", options.rti.refine_intensity_rounds},
                     {"intensities", rti->intensities},
                     {"brief", rti->Brief()}};
  provenance.options_json = stages.dump();
  return provenance;
}

}  // namespace

Result<PipelineResult> RunPipeline(const PipelineOptions& options,
                                   const ProgressCallback& progress) {
  constexpr const char* kCommand = "run";  // recorded in the --work folders' markers
  if (Status s = options.Validate(); !s.ok()) return Error{s.message()};
  PipelineResult result;

  // 1. Photos first: a bad calibration fails before minutes of preprocessing.
  Result<PhotosToFit> read = ReadPhotosToFit(options, progress);
  if (!read.ok()) return read.error();
  result.photos = std::move(read->photos);
  const PhotoSet& photos = result.photos;
  const ReflectanceFitOptions& fit_options = read->fit;
  std::optional<PhotoSet>& held = read->held;

  // Every file read is an input no output may touch; --work holds only its own canvas/ and fit/.
  std::vector<fs::path> inputs(options.scans.begin(), options.scans.end());
  if (!options.read.mask.empty()) inputs.push_back(options.read.mask);
  inputs.insert(inputs.end(), read->inputs.begin(), read->inputs.end());
  const fs::path work(options.work);
  const FolderOutput work_canvas{kCommand, "canvas", inputs}, work_fit{kCommand, "fit", inputs};
  std::vector<fs::path> pack_keeps_off = inputs;
  if (!options.work.empty()) {
    if (Status s = CheckFolderOutput(work / "canvas", work_canvas); !s.ok())
      return Error{s.message()};
    if (Status s = CheckFolderOutput(work / "fit", work_fit); !s.ok()) return Error{s.message()};
    pack_keeps_off.push_back(work / "canvas");
    pack_keeps_off.push_back(work / "fit");
  }
  if (Status s = CheckOutputPath(options.out, pack_keeps_off); !s.ok()) return Error{s.message()};
  std::vector<fs::path> relit_keeps_off = pack_keeps_off;
  relit_keeps_off.emplace_back(options.out);
  const FolderOutput relit_output = RelitFolder(kCommand, relit_keeps_off);
  if (!options.held_out_out.empty()) {
    if (Status s = CheckFolderOutput(options.held_out_out, relit_output); !s.ok())
      return Error{s.message()};
    if (Status s = CheckOutputPath(options.out, {options.held_out_out}); !s.ok())
      return Error{s.message()};
  }

  // 2. The canvas: preprocessed scans, or for an RTI capture without a scan its flat image grid.
  PreprocessedCanvas canvas;
  if (!options.scans.empty()) {
    Result<std::vector<Scan>> exposures = ReadScans(options.scans, options.read);
    if (!exposures.ok()) return exposures.error();
    Result<PreprocessResult> r =
        Preprocess(std::move(exposures).value(), options.preprocess, progress);
    if (!r.ok()) return r.error();
    result.preprocessed = std::move(r).value();
    canvas = CanvasFromPreprocess(*result.preprocessed);
  } else if (photos.is_rti) {
    auto rti = RtiCanvasFor(result.photos, options.rti, progress);
    if (!rti.ok()) return rti.error();
    canvas = rti->canvas;
    result.rti = std::move(rti).value();
  } else {
    return Error{"a scan is required with a calibration file (" + options.photos +
                 "); only an RTI capture (.lp) can be packed on a flat canvas without one"};
  }

  // 3. Fit.
  auto checked =
      FitAndCheck(canvas, result.photos, result.rti, held, fit_options, options, progress);
  if (!checked.ok()) return checked.error();
  result.photo_check = std::move(checked->check);
  ReflectanceFitResult* fit = &checked->fit;
  result.fit = fit->report;

  // 4. Pack, with provenance.
  auto provenance = RunProvenance(options, photos, fit_options, fit->report, result.rti);
  if (!provenance.ok()) return provenance.error();
  if (!options.work.empty()) {
    const std::vector<std::string> photo_inputs = {options.photos};
    if (result.preprocessed) {
      Status written =
          WriteDirectoryAtomically(work / "canvas", work_canvas, [&](const fs::path& dir) {
            return WritePreprocessOutputs(dir, *result.preprocessed, options.preprocess,
                                          options.scans);
          });
      if (!written.ok()) return Error{written.message()};
    }
    Status written = WriteDirectoryAtomically(work / "fit", work_fit, [&](const fs::path& dir) {
      return WriteReflectanceOutputs(dir, *fit, fit_options, photo_inputs);
    });
    if (!written.ok()) return Error{written.message()};
  }
  auto pack = AssemblePack(std::move(canvas), fit->maps, std::move(provenance).value());
  if (!pack.ok()) return pack.error();
  if (Status s = WritePack(options.out, *pack, options.pack); !s.ok()) return Error{s.message()};

  // 5. Held-out photos relit from the pack as written (what a user of the pack gets).
  if (held) {
    auto read = ReadPack(options.out);
    if (!read.ok()) return read.error();
    std::vector<Grid<Vec3f>> relit;
    auto score = EvaluateHeldOut(read->field, read->normals, read->maps, read->canvas_from_scan,
                                 *held, {}, 1.0, &relit);
    if (!score.ok()) return score.error();
    result.held_out = *score;
    if (Status s = WriteRelitFolder(options.held_out_out, relit_output, *held, relit); !s.ok())
      return Error{s.message()};
  }
  auto summary = InspectPack(options.out);
  if (!summary.ok()) return summary.error();
  result.pack = *summary;
  return result;
}

}  // namespace digitize
