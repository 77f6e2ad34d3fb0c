// `digitize fit`: a canvas folder (or an RTI capture alone) + photos -> a fit folder.
#include <cstdio>
#include <memory>
#include <optional>

#include "commands.h"
#include "digitize/output_dir.h"
#include "progress_bar.h"

namespace digitize::cli {
namespace {

struct FitArgs {
  std::string canvas, photos, held_out, out;
  std::string method = "fast";
  PhotoSetOptions photo;
  ReflectanceFitOptions options;
  int threads = 0;
  CLI::Option* dark_ratio_option = nullptr;  // set: the user chose it (RTI default is off)
};

int RunFit(FitArgs args) {
  const std::string cmd = "fit";
  SetFitMethod(args.options, args.method, args.threads);
  if (Status s = args.photo.Validate(); !s.ok()) return Fail(cmd, s.message());
  if (Status s = args.options.Validate(); !s.ok()) return Fail(cmd, s.message());
  // Before the photos are loaded: an incomplete canvas folder fails in a moment, not a minute.
  if (!args.canvas.empty())
    if (Status s = CheckCanvasFolder(args.canvas); !s.ok()) return Fail(cmd, s.message());

  ProgressBar bar("fit");
  Result<PhotoSet> set = ReadPhotoSetFile(args.photos, args.photo, bar.Callback());
  if (!set.ok()) return Fail(cmd, set.error().message);
  args.options = FitOptionsFor(
      *set, args.options, args.dark_ratio_option != nullptr && args.dark_ratio_option->count() > 0);
  // Held-out photos read before the fit: a bad file fails before minutes of work, and its
  // images are inputs the output must not touch.
  std::optional<PhotoSet> held;
  if (!args.held_out.empty()) {
    Result<PhotoSet> h = ReadPhotoSetFile(args.held_out, args.photo, bar.Callback());
    if (!h.ok()) return Fail(cmd, h.error().message);
    held = std::move(h).value();
  }
  FolderOutput output{cmd, "fit", {args.photos}};
  if (!args.canvas.empty()) output.inputs.emplace_back(args.canvas);
  for (const Photo& p : set->photos) output.inputs.push_back(p.path);
  if (held) {
    output.inputs.emplace_back(args.held_out);
    for (const Photo& p : held->photos) output.inputs.push_back(p.path);
  }
  if (Status s = CheckFolderOutput(args.out, output); !s.ok()) return Fail(cmd, s.message());
  Result<PreprocessedCanvas> canvas = LoadFitCanvas(args.canvas, *set);
  if (!canvas.ok()) return Fail(cmd, canvas.error().message);
  Result<ReflectanceFitResult> result = FitReflectance(
      canvas->field, canvas->normals, canvas->canvas_from_scan, *set, args.options, bar.Callback());
  if (!result.ok()) {
    bar.Finish();
    return Fail(cmd, result.error().message);
  }
  std::optional<HeldOutScore> score;
  if (held) {
    auto s = EvaluateHeldOut(canvas->field, canvas->normals, result->maps,
                             canvas->canvas_from_scan, *held);
    if (!s.ok()) return Fail(cmd, s.error().message);
    score = *s;
  }
  bar.Finish();

  std::vector<std::string> inputs = {args.photos};
  if (!args.canvas.empty()) inputs.insert(inputs.begin(), args.canvas);
  Status written =
      WriteDirectoryAtomically(args.out, output, [&](const std::filesystem::path& dir) {
        return WriteReflectanceOutputs(dir, *result, args.options, inputs);
      });
  if (!written.ok()) return Fail(cmd, written.message());
  for (const std::string& w : result->report.Warnings()) Warn(cmd, w);
  std::printf("photos: %s\n", set->summary.Brief().c_str());
  PrintRtiPitch(cmd, *set);
  std::printf("samples: %s\n", result->report.samples.Brief().c_str());
  if (result->report.dark_outliers > 0)
    std::printf("unmodelled shadows: %zu dark samples removed, %zu texels refitted\n",
                result->report.dark_outliers, result->report.texels_refitted);
  if (score) std::printf("%s\n", score->Brief().c_str());
  std::printf("%s\n", result->report.Brief().c_str());
  std::printf("outputs in %s/ (rho_d.exr, rho_s.exr, lobe.exr, fit_error.exr, fit_status.png, "
              "report.json)\n", args.out.c_str());
  return 0;
}

}  // namespace

void AddFitCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<FitArgs>();
  CLI::App* c = app.add_subcommand(
      "fit",
      "Canvas (a `digitize preprocess` folder) + registered photos -> per-texel Lafortune "
      "reflectance maps (rho_d, rho_s, lobe as float EXR), a fit-error map, a status map and a "
      "report.\nPhotos: a calibration JSON (docs/formats.md) or an RTI capture (.lp; fitted on a "
      "flat canvas when --canvas is left out).");
  c->add_option("--photos", args->photos, "Calibration JSON or RTI .lp file")
      ->required()->check(CLI::ExistingFile);
  c->add_option("--canvas", args->canvas, "Folder written by `digitize preprocess`")
      ->check(CLI::ExistingDirectory);
  c->add_option("-o,--out", args->out,
                "Output folder: new, empty, or an earlier fit output (replaced only on success)")
      ->required()
      ->transform(FolderPath());
  c->add_option("--held-out", args->held_out,
                "Calibration JSON of photos NOT fitted: relight them from the maps and print PSNR")
      ->check(CLI::ExistingFile);
  c->add_option("--method", args->method, "fast (variable projection) or ceres (ceres::Solve reference)")
      ->check(CLI::IsMember({"fast", "ceres"}))->capture_default_str()->group("Fit");
  c->add_option("--noise-sigma", args->options.fit.noise_sigma,
                "Radiance noise per channel (linear units, 1 = white): diffuse-only test, outliers")
      ->capture_default_str()->group("Fit");
  c->add_option("--min-samples", args->options.fit.min_samples,
                "Usable samples a texel needs for a lobe fit (fewer: diffuse-only fallback)")
      ->capture_default_str()->group("Fit");
  c->add_option("--k-max", args->options.fit.k_max, "Largest lobe exponent k")
      ->capture_default_str()->group("Fit");
  c->add_option("--max-specular-albedo", args->options.fit.max_specular_albedo,
                "Energy bound of the lobe: rho_s 2 pi / (k + 2) <= this (raise for uncalibrated lights)")
      ->capture_default_str()->group("Fit");
  args->dark_ratio_option =
      c->add_option("--dark-outlier-ratio", args->options.dark_outlier_ratio,
                    "Samples below this share of the diffuse floor are unmodelled shadows (<= 0: "
                    "keep all; RTI captures: off unless given)")
          ->capture_default_str()->group("Fit");
  c->add_option("--min-cos", args->options.samples.min_cos,
                "n.v and n.l must exceed this (0 = anything above the horizon)")
      ->capture_default_str()->group("Samples");
  c->add_flag("!--no-shadow-rays", args->options.samples.shadow_rays,
              "Do not reject samples whose light the relief blocks")->group("Samples");
  c->add_flag("!--no-visibility-rays", args->options.samples.visibility_rays,
              "Do not reject samples whose texel the relief hides from the camera")->group("Samples");
  c->add_flag("!--no-skip", args->options.samples.trace.skip_unblockable,
              "Trace every ray (no skipping of rays that cannot be blocked; for comparison)")
      ->group("Samples");
  c->add_option("--saturation", args->photo.saturation_encoded,
                "Encoded level (0..1) at or above which an 8/16-bit channel is saturated")
      ->capture_default_str()->group("Photos");
  c->add_option("--rti-pitch-mm", args->photo.rti_pixel_pitch_mm,
                "RTI captures: canvas mm per image pixel (default: the images' resolution tag, "
                "else 1 mm with a warning)")
      ->group("Photos");
  c->add_flag("--allow-outside-paths", args->photo.allow_outside_paths,
              "Read images the calibration / .lp names outside its folder (.., absolute paths, "
              "symbolic links); refused by default: a shared capture must not open other files")
      ->group("Photos");
  c->add_option("--tile-texels", args->options.tile_texels,
                "Texels sampled and fitted at a time (memory: ~ tile x photos x 48 bytes)")
      ->capture_default_str()->group("Performance");
  c->add_option("--threads", args->threads, "Worker threads (0 = all cores)")
      ->capture_default_str()->group("Performance");
  c->callback([args, &exit_code] { exit_code = RunFit(*args); });
}

}  // namespace digitize::cli
