// `digitize run`: scan(s) + photos -> pack in one go (preprocess, fit and pack in memory; the
// intermediate folders only with --work).
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>

#include "commands.h"
#include "digitize/output_dir.h"
#include "digitize/relight.h"
#include "progress_bar.h"

namespace digitize::cli {
namespace {

struct RunArgs {
  PreprocessArgs preprocess;
  FitArgs fit;
  std::string out, work;
  PackWriteOptions pack;
  bool quantised = false;
};

std::string OptionsOf(const std::string& report_json) {
  const auto doc = nlohmann::json::parse(report_json, nullptr, false);
  return doc.is_object() && doc.contains("options") ? doc["options"].dump() : "{}";
}

int Run(RunArgs args) {
  const std::string cmd = "run";
  FitArgs& fa = args.fit;
  fa.options.fit.method = fa.method == "ceres" ? BrdfFitMethod::kCeresReference : BrdfFitMethod::kFast;
  fa.options.fit.num_threads = fa.threads;
  fa.options.samples.trace.num_threads = fa.threads;
  args.pack.encoding = args.quantised ? PackEncoding::kQuantised : PackEncoding::kHalf;
  if (Status s = args.pack.Validate(); !s.ok()) return Fail(cmd, s.message());
  if (Status s = fa.photo.Validate(); !s.ok()) return Fail(cmd, s.message());
  if (Status s = fa.options.Validate(); !s.ok()) return Fail(cmd, s.message());
  if (Status s = args.preprocess.options.Validate(); !s.ok()) return Fail(cmd, s.message());

  // 1. Photos first: a bad calibration fails before minutes of preprocessing.
  ProgressBar bar("run");
  Result<PhotoSet> set = ReadPhotoSetFile(fa.photos, fa.photo, bar.Callback());
  if (!set.ok()) return Fail(cmd, set.error().message);
  if (set->is_rti && (fa.dark_ratio_option == nullptr || fa.dark_ratio_option->count() == 0)) {
    fa.options.dark_outlier_ratio = 0;  // uncalibrated RTI lights: see `digitize fit`
    fa.options.dark_outlier_fit_ratio = 0;
  }
  std::optional<PhotoSet> held;
  if (!fa.held_out.empty()) {
    Result<PhotoSet> h = ReadPhotoSetFile(fa.held_out, fa.photo, bar.Callback());
    if (!h.ok()) return Fail(cmd, h.error().message);
    held = std::move(h).value();
  }

  // Every file read is an input no output may touch; --work holds only its own canvas/ and fit/.
  std::vector<std::filesystem::path> inputs(args.preprocess.scans.begin(),
                                            args.preprocess.scans.end());
  if (!args.preprocess.mask.empty()) inputs.emplace_back(args.preprocess.mask);
  inputs.emplace_back(fa.photos);
  for (const Photo& p : set->photos) inputs.push_back(p.path);
  if (held) {
    inputs.emplace_back(fa.held_out);
    for (const Photo& p : held->photos) inputs.push_back(p.path);
  }
  const std::filesystem::path work(args.work);
  const FolderOutput work_canvas{cmd, "canvas", inputs}, work_fit{cmd, "fit", inputs};
  std::vector<std::filesystem::path> pack_keeps_off = inputs;
  if (!args.work.empty()) {
    if (Status s = CheckFolderOutput(work / "canvas", work_canvas); !s.ok())
      return Fail(cmd, s.message());
    if (Status s = CheckFolderOutput(work / "fit", work_fit); !s.ok())
      return Fail(cmd, s.message());
    pack_keeps_off.push_back(work / "canvas");
    pack_keeps_off.push_back(work / "fit");
  }
  if (Status s = CheckOutputPath(args.out, pack_keeps_off); !s.ok()) return Fail(cmd, s.message());

  // 2. The canvas: preprocessed scans, or for an RTI capture without a scan its flat image grid.
  PreprocessedCanvas canvas;
  std::optional<PreprocessResult> preprocessed;
  std::string preprocess_options = "{}";
  if (!args.preprocess.scans.empty()) {
    Result<std::vector<Scan>> exposures = ReadScans(args.preprocess);
    if (!exposures.ok()) return Fail(cmd, exposures.error().message);
    Result<PreprocessResult> r =
        Preprocess(std::move(exposures).value(), args.preprocess.options, bar.Callback());
    if (!r.ok()) return Fail(cmd, r.error().message);
    preprocessed = std::move(r).value();
    canvas.field = preprocessed->field;
    canvas.normals = preprocessed->normals;
    canvas.canvas_from_scan = preprocessed->canvas.canvas_from_scan;
    canvas.delta0_mm = preprocessed->relief.delta0_mm;
    canvas.max_height_mm = preprocessed->relief.max_height_mm;
    canvas.cell_px = preprocessed->relief.cell_px > 0 ? preprocessed->relief.cell_px : 16;
    canvas.boxes = preprocessed->relief.boxes;
    preprocess_options = OptionsOf(
        PreprocessReportJson(*preprocessed, args.preprocess.options, args.preprocess.scans));
  } else if (set->is_rti) {
    auto flat = FlatCanvasForRti(*set);
    if (!flat.ok()) return Fail(cmd, flat.error().message);
    canvas.field = std::move(flat).value();
    canvas.normals = Grid<Vec3f>(canvas.field.width(), canvas.field.height(), Vec3f::UnitZ());
  } else {
    return Fail(cmd, "a scan is required with a calibration file (" + fa.photos +
                     "); only an RTI capture (.lp) can be packed on a flat canvas without one");
  }

  // 3. Fit.
  Result<ReflectanceFitResult> fit = FitReflectance(canvas.field, canvas.normals,
                                                    canvas.canvas_from_scan, *set, fa.options,
                                                    bar.Callback());
  if (!fit.ok()) {
    bar.Finish();
    return Fail(cmd, fit.error().message);
  }

  // 4. Pack, with provenance: every input file hashed, every stage's options.
  std::vector<std::string> photo_inputs = {fa.photos};
  PackProvenance provenance = NewProvenance();
  std::vector<std::filesystem::path> files(args.preprocess.scans.begin(), args.preprocess.scans.end());
  files.emplace_back(fa.photos);
  for (const Photo& p : set->photos) files.push_back(p.path);
  // Named relative to the calibration file, as its image paths are: not where they lay here.
  if (Status s = AddProvenanceInputs(provenance, files,
                                     std::filesystem::absolute(fa.photos).parent_path());
      !s.ok())
    return Fail(cmd, s.message());
  provenance.fit_brief = fit->report.Brief();
  nlohmann::json options = {
      {"preprocess", nlohmann::json::parse(preprocess_options, nullptr, false)},
      {"fit", nlohmann::json::parse(OptionsOf(ReflectanceReportJson(*fit, fa.options, photo_inputs)),
                                    nullptr, false)},
      {"pack", nlohmann::json::parse(PackOptionsJson(args.pack))}};
  if (set->is_rti)  // the pack's physical size rests on it: the provenance says where it came from
    options["fit"]["rti_pitch"] = {{"mm", set->rti_pitch_mm},
                                   {"source", set->rti_pitch_source},
                                   {"assumed", set->rti_pitch_assumed}};
  provenance.options_json = options.dump();

  if (!args.work.empty()) {
    if (preprocessed) {
      Status written = WriteDirectoryAtomically(
          work / "canvas", work_canvas, [&](const std::filesystem::path& dir) {
            return WritePreprocessOutputs(dir, *preprocessed, args.preprocess.options,
                                          args.preprocess.scans);
          });
      if (!written.ok()) return Fail(cmd, written.message());
    }
    Status written =
        WriteDirectoryAtomically(work / "fit", work_fit, [&](const std::filesystem::path& dir) {
          return WriteReflectanceOutputs(dir, *fit, fa.options, photo_inputs);
        });
    if (!written.ok()) return Fail(cmd, written.message());
  }
  auto pack = AssemblePack(std::move(canvas), fit->maps, std::move(provenance));
  if (!pack.ok()) return Fail(cmd, pack.error().message);
  if (Status s = WritePack(args.out, *pack, args.pack); !s.ok()) return Fail(cmd, s.message());

  // 5. Held-out photos relit from the pack as written (what a user of the pack gets).
  std::optional<HeldOutScore> score;
  if (held) {
    auto read = ReadPack(args.out);
    if (!read.ok()) return Fail(cmd, read.error().message);
    auto s = EvaluateHeldOut(read->field, read->normals, read->maps, read->canvas_from_scan, *held);
    if (!s.ok()) return Fail(cmd, s.error().message);
    score = *s;
  }
  bar.Finish();
  for (const std::string& w : fit->report.Warnings()) Warn(cmd, w);
  if (preprocessed)
    for (const StepReport& step : preprocessed->steps)
      std::printf("%6.3fs  %s\n", step.seconds, step.line.c_str());
  std::printf("photos: %s\n", set->summary.Brief().c_str());
  PrintRtiPitch(cmd, *set);
  std::printf("samples: %s\n", fit->report.samples.Brief().c_str());
  std::printf("fit: %s\n", fit->report.Brief().c_str());
  if (score) std::printf("from the pack: %s\n", score->Brief().c_str());
  auto summary = InspectPack(args.out);
  if (!summary.ok()) return Fail(cmd, summary.error().message);
  std::printf("pack: ");
  PrintPackSummaryLine(args.out, *summary);
  return 0;
}

}  // namespace

void AddRunCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<RunArgs>();
  CLI::App* c = app.add_subcommand(
      "run",
      "Scan(s) + registered photos -> texture pack in one go (preprocess, fit, pack). An RTI "
      "capture (.lp) without a scan is packed on a flat canvas.");
  c->add_option("scans", args->preprocess.scans, "Scan file(s), as for `digitize preprocess`")
      ->check(CLI::ExistingFile);
  c->add_option("--photos", args->fit.photos, "Calibration JSON or RTI .lp file")
      ->required()->check(CLI::ExistingFile);
  c->add_option("-o,--out", args->out, "Pack file to write (replaced only on success)")->required();
  c->add_option(
       "--work", args->work,
       "Also write the canvas/ and fit/ folders here (for inspection or re-packing; only those two "
       "subfolders are replaced, each when new, empty or an earlier output of its kind)")
      ->transform(FolderPath());
  c->add_option("--held-out", args->fit.held_out,
                "Calibration JSON of photos NOT fitted: relight them from the written pack, print PSNR")
      ->check(CLI::ExistingFile);
  c->add_option("--pixel-pitch-mm", args->preprocess.read.pixel_pitch_mm,
                "Sample spacing (mm) of depth-only scans")->group("Input");
  c->add_option("--height-scale-mm", args->preprocess.read.height_scale_mm,
                "mm per count for 16-bit depth images")->group("Input");
  c->add_option("--height-offset-mm", args->preprocess.read.height_offset_mm,
                "Added to 16-bit depth after scaling (mm)")
      ->group("Input");
  c->add_option("--mask", args->preprocess.mask, "Scan mask image; 0 = missing sample")
      ->check(CLI::ExistingFile)->group("Input");
  c->add_option("--grid", args->preprocess.grid, "WIDTH HEIGHT of a PLY point grid")
      ->expected(2)->group("Input");
  AddPreprocessFlags(c, args->preprocess.options);
  c->add_option("--method", args->fit.method, "fast (variable projection) or ceres (reference)")
      ->check(CLI::IsMember({"fast", "ceres"}))->capture_default_str()->group("Fit");
  c->add_option("--noise-sigma", args->fit.options.fit.noise_sigma,
                "Radiance noise per channel (linear units, 1 = white)")
      ->capture_default_str()->group("Fit");
  args->fit.dark_ratio_option =
      c->add_option("--dark-outlier-ratio", args->fit.options.dark_outlier_ratio,
                    "Samples below this share of the diffuse floor are unmodelled shadows")
          ->capture_default_str()->group("Fit");
  c->add_option("--rti-pitch-mm", args->fit.photo.rti_pixel_pitch_mm,
                "RTI captures: canvas mm per image pixel (default: the images' resolution tag, "
                "else 1 mm with a warning)")
      ->group("Photos");
  c->add_flag("--allow-outside-paths", args->fit.photo.allow_outside_paths,
              "Read images the calibration / .lp names outside its folder (.., absolute paths, "
              "symbolic links); refused by default: a shared capture must not open other files")
      ->group("Photos");
  c->add_option("--threads", args->fit.threads, "Worker threads (0 = all cores)")
      ->capture_default_str()->group("Performance");
  AddPackWriteFlags(c, args->pack, args->quantised);
  c->callback([args, &exit_code] { exit_code = Run(*args); });
}

}  // namespace digitize::cli
