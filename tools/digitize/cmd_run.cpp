// `digitize run`: scan(s) + photos -> pack in one go (RunPipeline: preprocess, fit and pack in
// memory; the intermediate folders only with --work).
#include <cstdio>
#include <memory>

#include "commands.h"
#include "progress_bar.h"

namespace digitize::cli {
namespace {

struct RunArgs {
  PipelineOptions pipeline;
  std::string mask;
  std::vector<int> grid;
  std::string method = "fast";
  int threads = 0;
  CLI::Option* dark_ratio_option = nullptr;  // set: the user chose it (RTI default is off)
  bool quantised = false;
};

int Run(RunArgs args) {
  const std::string cmd = "run";
  PipelineOptions& o = args.pipeline;
  SetFitMethod(o.fit, args.method, args.threads);
  o.pack.encoding = args.quantised ? PackEncoding::kQuantised : PackEncoding::kHalf;
  o.read = ScanReadOptionsOf(o.read, args.mask, args.grid);
  o.dark_outlier_ratio_chosen =
      args.dark_ratio_option != nullptr && args.dark_ratio_option->count() > 0;
  ProgressBar bar("run");
  Result<PipelineResult> r = RunPipeline(o, bar.Callback());
  bar.Finish();
  if (!r.ok()) return Fail(cmd, r.error().message);
  for (const std::string& w : r->fit.Warnings()) Warn(cmd, w);
  PrintPhotoCheck(cmd, r->photo_check);
  if (r->preprocessed)
    for (const StepReport& step : r->preprocessed->steps)
      std::printf("%6.3fs  %s\n", step.seconds, step.line.c_str());
  std::printf("photos: %s\n", r->photos.summary.Brief().c_str());
  PrintRtiPitch(cmd, r->photos);
  if (r->rti) std::printf("rti canvas: %s\n", r->rti->Brief().c_str());
  std::printf("samples: %s\n", r->fit.samples.Brief().c_str());
  std::printf("fit: %s\n", r->fit.Brief().c_str());
  if (r->held_out) std::printf("from the pack: %s\n", r->held_out->Brief().c_str());
  std::printf("pack: ");
  PrintPackSummaryLine(o.out, r->pack);
  return 0;
}

}  // namespace

void AddRunCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<RunArgs>();
  CLI::App* c = app.add_subcommand(
      "run",
      "Scan(s) + registered photos -> texture pack in one go (preprocess, fit, pack). An RTI "
      "capture (.lp) without a scan is packed on a flat canvas.");
  c->add_option("scans", args->pipeline.scans, "Scan file(s), as for `digitize preprocess`")
      ->check(CLI::ExistingFile);
  c->add_option("--photos", args->pipeline.photos, "Calibration JSON or RTI .lp file")
      ->required()
      ->check(CLI::ExistingFile);
  c->add_option("-o,--out", args->pipeline.out, "Pack file to write (replaced only on success)")
      ->required();
  c->add_option(
       "--work", args->pipeline.work,
       "Also write the canvas/ and fit/ folders here (for inspection or re-packing; only those two "
       "subfolders are replaced, each when new, empty or an earlier output of its kind)")
      ->transform(FolderPath());
  c->add_option(
       "--held-out", args->pipeline.held_out,
       "Calibration JSON or .lp of photos NOT fitted: relight them from the written pack, print "
       "PSNR (linear and 8-bit sRGB)")
      ->check(CLI::ExistingFile);
  AddPhotoCheckAndRelitFlags(c, args->pipeline.check_photos, args->pipeline.held_out_out);
  c->add_option("--pixel-pitch-mm", args->pipeline.read.pixel_pitch_mm,
                "Sample spacing (mm) of depth-only scans")
      ->group("Input");
  c->add_option("--height-scale-mm", args->pipeline.read.height_scale_mm,
                "mm per count for 16-bit depth images")
      ->group("Input");
  c->add_option("--height-offset-mm", args->pipeline.read.height_offset_mm,
                "Added to 16-bit depth after scaling (mm)")
      ->group("Input");
  c->add_option("--mask", args->mask, "Scan mask image; 0 = missing sample")
      ->check(CLI::ExistingFile)
      ->group("Input");
  c->add_option("--grid", args->grid, "WIDTH HEIGHT of a PLY point grid")
      ->expected(2)
      ->group("Input");
  AddPreprocessFlags(c, args->pipeline.preprocess);
  c->add_option("--method", args->method, "fast (variable projection) or ceres (reference)")
      ->check(CLI::IsMember({"fast", "ceres"}))
      ->capture_default_str()
      ->group("Fit");
  c->add_option("--noise-sigma", args->pipeline.fit.fit.noise_sigma,
                "Radiance noise per channel (linear units, 1 = white)")
      ->capture_default_str()
      ->group("Fit");
  args->dark_ratio_option =
      c->add_option("--dark-outlier-ratio", args->pipeline.fit.dark_outlier_ratio,
                    "Samples below this share of the diffuse floor are unmodelled shadows")
          ->capture_default_str()
          ->group("Fit");
  AddPhotoSetFlags(c, args->pipeline.photo);
  AddRtiCanvasFlags(c, args->pipeline.rti);
  c->add_option("--threads", args->threads, "Worker threads (0 = all cores)")
      ->capture_default_str()
      ->group("Performance");
  AddPackWriteFlags(c, args->pipeline.pack, args->quantised);
  c->callback([args, &exit_code] { exit_code = Run(*args); });
}

}  // namespace digitize::cli
