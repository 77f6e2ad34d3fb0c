#include <cstdio>
#include <memory>

#include "commands.h"
#include "digitize/output_dir.h"
#include "digitize/preprocess.h"
#include "digitize_synth/ground_truth.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/scan_sim.h"
#include "digitize_synth/synth_io.h"
#include "progress_bar.h"

namespace digitize::cli {
namespace {

struct DemoArgs {
  std::string out = "digitize-demo";
  int resolution = 0;  // 0 = matched to the scan's sampling
  int scan_px = 1024;
  uint64_t seed = 1;
  double noise_mm = 0.02;
  PreprocessOptions options;
};

int RunDemo(const DemoArgs& args) {
  const std::string cmd = "demo";
  synth::ScanSimOptions scan_options;
  scan_options.width_px = scan_options.height_px = args.scan_px;
  scan_options.noise_mm = args.noise_mm;
  scan_options.seed = args.seed;
  synth::PaintingOptions painting_options;
  painting_options.resolution_px =
      args.resolution > 0 ? args.resolution
                          : synth::MatchedResolution(painting_options, synth::FrameOptions{}, scan_options);
  painting_options.seed = args.seed;
  if (Status s = painting_options.Validate(); !s.ok()) return Fail(cmd, s.message());
  if (Status s = scan_options.Validate(); !s.ok()) return Fail(cmd, s.message());
  if (Status s = args.options.Validate(); !s.ok()) return Fail(cmd, s.message());

  std::printf("digitize demo: a synthetic %.0f x %.0f mm painting (%d texels on the long side), "
              "framed, scanned at %dx%d with %.3f mm noise, %.0f deg tilt, holes and outliers\n",
              painting_options.width_mm, painting_options.height_mm, painting_options.resolution_px, args.scan_px,
              args.scan_px, args.noise_mm, scan_options.tilt_deg);
  std::fflush(stdout);  // before the progress bars on stderr
  PreprocessResult result;
  synth::Painting painting;
  synth::SyntheticScan scan;
  {
    ProgressBar bar("synth");
    bar.Update("painting", 0.0);
    painting = synth::MakePainting(painting_options);
    bar.Update("scan", 0.5);
    const synth::Scene scene(painting, synth::FrameOptions{});
    scan = synth::SimulateScan(scene, scan_options);
  }
  {
    ProgressBar bar("preprocess");
    Result<PreprocessResult> r = Preprocess(scan.exposures, args.options, bar.Callback());
    bar.Finish();
    if (!r.ok()) return Fail(cmd, r.error().message);
    result = std::move(r).value();
  }
  for (const StepReport& step : result.steps) std::printf("%6.3fs  %s\n", step.seconds, step.line.c_str());
  std::printf("preprocess total %.3f s\n\n", result.total_seconds);

  const synth::PreprocessAccuracy acc = synth::MeasureAccuracy(result, painting, scan);
  std::printf("accuracy against ground truth (target in brackets):\n");
  std::printf("  canvas normal error     %.4f deg   [<= 0.05]\n", acc.normal_error_deg);
  std::printf("  canvas mask IoU         %.5f       [>= 0.995], frame pixels kept %zu [0]\n",
              acc.mask_iou, acc.frame_pixels_kept);
  std::printf("  height RMSE             %.4f mm    [<= %.4f = 2 x noise], offset %.4f mm\n",
              acc.height_rmse_mm, 2 * args.noise_mm, acc.height_offset_mm);
  std::printf("  normals median error    %.3f deg   (p90 %.3f deg)\n", acc.normals_median_deg,
              acc.normals_p90_deg);
  std::printf("  relief above delta0     %zu texels, %zu outside every box [0]\n",
              acc.relief_texels_true, acc.relief_texels_uncovered);

  const std::filesystem::path out = args.out;
  Status written = WriteDirectoryAtomically(out, [&](const std::filesystem::path& dir) {
    if (Status s = synth::WriteSyntheticScan(dir / "scan", painting, scan); !s.ok()) return s;
    return WritePreprocessOutputs(dir / "canvas", result, args.options, {"(synthetic, in memory)"});
  });
  if (!written.ok()) return Fail(cmd, written.message());
  std::printf("\noutputs: %s/scan/ (synthetic scan + ground truth), %s/canvas/ (height.exr, "
              "normals.exr, mask.png, boxes.json, transform.json, report.json)\n",
              args.out.c_str(), args.out.c_str());
  return 0;
}

}  // namespace

void AddDemoCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<DemoArgs>();
  CLI::App* c = app.add_subcommand(
      "demo",
      "Run the whole pipeline on a synthetic painting generated on the fly and print its accuracy "
      "against the ground truth");
  c->add_option("-o,--out", args->out, "Output folder")->capture_default_str();
  c->add_option("--resolution", args->resolution,
                "Painting texels along the long side (0 = matched to the scan's sampling)")
      ->capture_default_str();
  c->add_option("--scan-px", args->scan_px, "Scan grid size (square)")->capture_default_str();
  c->add_option("--noise-mm", args->noise_mm, "Scan noise sigma (mm)")->capture_default_str();
  c->add_option("--seed", args->seed, "Random seed")->capture_default_str();
  AddPreprocessFlags(c, args->options);
  c->callback([args, &exit_code] { exit_code = RunDemo(*args); });
}

}  // namespace digitize::cli
