// `digitize fit`: a canvas folder (or an RTI capture alone) + photos -> a fit folder.
#include <cstdio>
#include <memory>

#include "commands.h"
#include "progress_bar.h"

namespace digitize::cli {
namespace {

struct FitArgs {
  FitFolderOptions fit;
  std::string method = "fast";
  int threads = 0;
  CLI::Option* dark_ratio_option = nullptr;  // set: the user chose it (RTI default is off)
};

int RunFit(FitArgs args) {
  const std::string cmd = "fit";
  FitFolderOptions& o = args.fit;
  SetFitMethod(o.fit, args.method, args.threads);
  o.dark_outlier_ratio_chosen =
      args.dark_ratio_option != nullptr && args.dark_ratio_option->count() > 0;
  ProgressBar bar("fit");
  Result<FitFolderResult> r = FitToFolder(o, bar.Callback());
  bar.Finish();
  if (!r.ok()) return Fail(cmd, r.error().message);
  const ReflectanceFitReport& report = r->fit;
  for (const std::string& w : report.Warnings()) Warn(cmd, w);
  PrintPhotoCheck(cmd, r->photo_check);
  std::printf("photos: %s\n", r->photos.summary.Brief().c_str());
  PrintRtiPitch(cmd, r->photos);
  if (r->rti) std::printf("rti canvas: %s\n", r->rti->Brief().c_str());
  std::printf("samples: %s\n", report.samples.Brief().c_str());
  if (report.dark_outliers > 0)
    std::printf("unmodelled shadows: %zu dark samples removed, %zu texels refitted\n",
                report.dark_outliers, report.texels_refitted);
  if (r->held_out) std::printf("%s\n", r->held_out->Brief().c_str());
  std::printf("%s\n", report.Brief().c_str());
  std::printf(
      "outputs in %s/ (rho_d.exr, rho_s.exr, lobe.exr, fit_error.exr, fit_status.png, "
      "report.json)\n",
      o.out.c_str());
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
  c->add_option("--photos", args->fit.photos, "Calibration JSON or RTI .lp file")
      ->required()
      ->check(CLI::ExistingFile);
  c->add_option("--canvas", args->fit.canvas, "Folder written by `digitize preprocess`")
      ->check(CLI::ExistingDirectory);
  c->add_option("-o,--out", args->fit.out,
                "Output folder: new, empty, or an earlier fit output (replaced only on success)")
      ->required()
      ->transform(FolderPath());
  c->add_option("--held-out", args->fit.held_out,
                "Calibration JSON or .lp of photos NOT fitted: relight them from the maps and "
                "print PSNR (linear and 8-bit sRGB)")
      ->check(CLI::ExistingFile);
  AddPhotoCheckAndRelitFlags(c, args->fit.check_photos, args->fit.held_out_out);
  c->add_option("--method", args->method,
                "fast (variable projection) or ceres (ceres::Solve reference)")
      ->check(CLI::IsMember({"fast", "ceres"}))
      ->capture_default_str()
      ->group("Fit");
  c->add_option("--noise-sigma", args->fit.fit.fit.noise_sigma,
                "Radiance noise per channel (linear units, 1 = white): diffuse-only test, outliers")
      ->capture_default_str()
      ->group("Fit");
  c->add_option("--min-samples", args->fit.fit.fit.min_samples,
                "Usable samples a texel needs for a lobe fit (fewer: diffuse-only fallback)")
      ->capture_default_str()
      ->group("Fit");
  c->add_option("--k-max", args->fit.fit.fit.k_max, "Largest lobe exponent k")
      ->capture_default_str()
      ->group("Fit");
  c->add_option(
       "--max-specular-albedo", args->fit.fit.fit.max_specular_albedo,
       "Energy bound of the lobe: rho_s 2 pi / (k + 2) <= this (raise for uncalibrated lights)")
      ->capture_default_str()
      ->group("Fit");
  args->dark_ratio_option =
      c->add_option("--dark-outlier-ratio", args->fit.fit.dark_outlier_ratio,
                    "Samples below this share of the diffuse floor are unmodelled shadows (<= 0: "
                    "keep all; RTI captures: off unless given)")
          ->capture_default_str()
          ->group("Fit");
  c->add_option("--min-cos", args->fit.fit.samples.min_cos,
                "n.v and n.l must exceed this (0 = anything above the horizon)")
      ->capture_default_str()
      ->group("Samples");
  c->add_flag("!--no-shadow-rays", args->fit.fit.samples.shadow_rays,
              "Do not reject samples whose light the relief blocks")
      ->group("Samples");
  c->add_flag("!--no-visibility-rays", args->fit.fit.samples.visibility_rays,
              "Do not reject samples whose texel the relief hides from the camera")
      ->group("Samples");
  c->add_flag("!--no-skip", args->fit.fit.samples.trace.skip_unblockable,
              "Trace every ray (no skipping of rays that cannot be blocked; for comparison)")
      ->group("Samples");
  c->add_option("--saturation", args->fit.photo.saturation_encoded,
                "Encoded level (0..1) at or above which an 8/16-bit channel is saturated")
      ->capture_default_str()
      ->group("Photos");
  AddPhotoSetFlags(c, args->fit.photo);
  AddRtiCanvasFlags(c, args->fit.rti);
  c->add_option("--tile-texels", args->fit.fit.tile_texels,
                "Texels sampled and fitted at a time (memory: ~ tile x photos x 48 bytes)")
      ->capture_default_str()
      ->group("Performance");
  c->add_option("--threads", args->threads, "Worker threads (0 = all cores)")
      ->capture_default_str()
      ->group("Performance");
  c->callback([args, &exit_code] { exit_code = RunFit(*args); });
}

}  // namespace digitize::cli
