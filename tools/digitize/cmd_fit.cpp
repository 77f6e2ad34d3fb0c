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
  args->dark_ratio_option = AddFitFlags(c, args->fit.fit, args->fit.photo);
  AddPhotoSetFlags(c, args->fit.photo);
  AddRtiCanvasFlags(c, args->fit.rti);
  c->add_option("--threads", args->threads, "Worker threads (0 = all cores)")
      ->capture_default_str()
      ->group("Performance");
  c->callback([args, &exit_code] { exit_code = RunFit(*args); });
}

}  // namespace digitize::cli
