// `digitize demo`: the whole pipeline on a synthetic painting, judged against its ground truth.
#include <algorithm>
#include <cstdio>
#include <memory>
#include <optional>

#include "commands.h"
#include "digitize/output_dir.h"
#include "digitize_synth/ground_truth.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/photo_sim.h"
#include "digitize_synth/reflectance_truth.h"
#include "digitize_synth/scan_sim.h"
#include "digitize_synth/synth_io.h"
#include "digitize_viewer/gallery.h"
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
  synth::PhotoSimOptions photos;
  bool measured = false;
  bool no_fit = false;
  ReflectanceFitOptions fit;
  std::string fit_method = "fast";  // as `fit --method`
  PackWriteOptions quantised;       // the second, smaller pack (encoding set to kQuantised)
};

// A pack as the demo reports it: read back from the file, relit on the held-out photos.
struct PackReport {
  std::string name;
  PackSummary summary;
  HeldOutScore score;
};

int RunDemo(const DemoArgs& args) {
  const std::string cmd = "demo";
  synth::ScanSimOptions scan_options;
  scan_options.width_px = scan_options.height_px = args.scan_px;
  scan_options.noise_mm = args.noise_mm;
  scan_options.seed = args.seed;
  synth::PaintingOptions painting_options;
  painting_options.resolution_px =
      args.resolution > 0
          ? args.resolution
          : synth::MatchedResolution(painting_options, synth::FrameOptions{}, scan_options);
  painting_options.seed = args.seed;
  if (Status s = painting_options.Validate(); !s.ok()) return Fail(cmd, s.message());
  if (Status s = scan_options.Validate(); !s.ok()) return Fail(cmd, s.message());
  if (Status s = args.options.Validate(); !s.ok()) return Fail(cmd, s.message());
  synth::PhotoSimOptions photo_options = args.photos;
  photo_options.seed = args.seed;
  if (Status s = photo_options.Validate(); !s.ok()) return Fail(cmd, s.message());
  ReflectanceFitOptions fit_options = args.fit;
  fit_options.fit.method =
      args.fit_method == "ceres" ? BrdfFitMethod::kCeresReference : BrdfFitMethod::kFast;
  // The fit's noise level is the photos' (linear units; 8-bit quantisation adds ~0.001).
  fit_options.fit.noise_sigma = std::max(photo_options.noise_sigma, 0.001);
  if (Status s = fit_options.Validate(); !s.ok()) return Fail(cmd, s.message());
  const std::filesystem::path out = args.out;
  const FolderOutput output{cmd, "demo", {}};
  if (Status s = CheckFolderOutput(out, output); !s.ok()) return Fail(cmd, s.message());

  std::printf(
      "digitize demo: a synthetic %.0f x %.0f mm painting (%d texels on the long side), "
      "framed, scanned at %dx%d with %.3f mm noise, %.0f deg tilt, holes and outliers\n",
      painting_options.width_mm, painting_options.height_mm, painting_options.resolution_px,
      args.scan_px, args.scan_px, args.noise_mm, scan_options.tilt_deg);
  std::fflush(stdout);  // before the progress bars on stderr
  PreprocessResult result;
  synth::Painting painting;
  synth::SyntheticScan scan;
  std::unique_ptr<synth::Scene> scene;
  {
    ProgressBar bar("synth");
    bar.Update("painting", 0.0);
    painting = synth::MakePainting(painting_options);
    bar.Update("scan", 0.5);
    scene = std::make_unique<synth::Scene>(painting, synth::FrameOptions{});
    scan = synth::SimulateScan(*scene, scan_options);
  }
  {
    ProgressBar bar("preprocess");
    Result<PreprocessResult> r = Preprocess(scan.exposures, args.options, bar.Callback());
    bar.Finish();
    if (!r.ok()) return Fail(cmd, r.error().message);
    result = std::move(r).value();
  }
  for (const StepReport& step : result.steps)
    std::printf("%6.3fs  %s\n", step.seconds, step.line.c_str());
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

  // Photos of the same painting under known lights, in the scan's frame (as a calibrated rig
  // would give them), then the fit on the PREPROCESSED canvas, judged on held-out photos.
  std::optional<synth::SyntheticPhotoSet> photos;
  std::optional<ReflectanceFitResult> fit;
  if (!args.no_fit) {
    std::printf(
        "\nphotos: %d light(s) x %d camera(s), %s, noise %.4f; held out: %d light(s) x 2 "
        "views\n",
        photo_options.lights, photo_options.cameras, synth::ToString(photo_options.encoding),
        photo_options.noise_sigma, photo_options.held_out_lights);
    std::fflush(stdout);
    {
      ProgressBar bar("photos");
      photos = synth::SimulatePhotoSet(*scene, scan.canvas_from_scan, photo_options,
                                       synth::DefaultPaintMaterials(args.measured), bar.Callback());
    }
    {
      ProgressBar bar("fit");
      Result<ReflectanceFitResult> r =
          FitReflectance(result.field, result.normals, result.canvas.canvas_from_scan, photos->fit,
                         fit_options, bar.Callback());
      bar.Finish();
      if (!r.ok()) return Fail(cmd, r.error().message);
      fit = std::move(r).value();
    }
    std::printf("samples: %s\n", fit->report.samples.Brief().c_str());
    if (fit->report.dark_outliers > 0)
      std::printf("unmodelled (frame) shadows: %zu dark samples removed, %zu texels refitted\n",
                  fit->report.dark_outliers, fit->report.texels_refitted);
    std::printf("fit: %s\n", fit->report.Brief().c_str());
    auto score =
        EvaluateHeldOut(result.field, result.normals, fit->maps, result.canvas.canvas_from_scan,
                        photos->held_out, photos->held_out_mask);
    if (!score.ok()) return Fail(cmd, score.error().message);
    std::printf(
        "\nrelighting against ground truth (held-out lights and views, frame shadows "
        "masked, clipped to white = 1):\n  %s\n  (end to end: the canvas from the noisy "
        "scan, its own texel grid, 8-bit noisy photos at ~1 px per texel; the fit alone "
        "on noise-free photos at 2 px per texel reaches >= 40 dB: docs/benchmarks.md)\n",
        score->Brief().c_str());
    std::printf("parameter errors by paint region (median over texels):\n%s",
                synth::FormatReflectanceAccuracy(
                    synth::MeasureReflectanceAccuracy(
                        fit->maps, result.field, result.canvas.canvas_from_scan, *photos, painting))
                    .c_str());
  }

  std::vector<PackReport> packs;
  Status gallery = Error{"no fit (--no-fit)"};
  Status written = WriteDirectoryAtomically(out, output, [&](const std::filesystem::path& dir) {
    if (Status s = synth::WriteSyntheticScan(dir / "scan", painting, scan); !s.ok()) return s;
    if (Status s = WritePreprocessOutputs(dir / "canvas", result, args.options,
                                          {"(synthetic, in memory)"});
        !s.ok())
      return s;
    if (!fit) return Status::Ok();
    if (Status s = synth::WriteSyntheticPhotoSet(dir / "photos", *photos); !s.ok()) return s;
    if (Status s =
            WriteReflectanceOutputs(dir / "fit", *fit, fit_options, {"(synthetic, in memory)"});
        !s.ok())
      return s;
    // The packs, made from the folders just written (as `digitize pack` does), then judged from
    // the files: what a museum keeps is what is measured.
    PackWriteOptions quantised = args.quantised;
    quantised.encoding = PackEncoding::kQuantised;
    for (const auto& [name, options] :
         {std::pair<std::string, PackWriteOptions>{"painting.pack.exr", {}},
          {"painting.q.pack.exr", quantised}}) {
      auto summary = PackFromFolders(dir / "canvas", dir / "fit", dir / name, options);
      if (!summary.ok()) return Status(summary.error());
      auto read = ReadPack(dir / name);
      if (!read.ok()) return Status(read.error());
      auto score = EvaluateHeldOut(read->field, read->normals, read->maps, read->canvas_from_scan,
                                   photos->held_out, photos->held_out_mask);
      if (!score.ok()) return Status(score.error());
      packs.push_back({name, *summary, *score});
    }
    // The demo ends in the gallery: the pack just written, read back as the viewer
    // reads it and hung in the virtual room, rendered headless (EGL surfaceless). No GL here is
    // a warning, not a failure: the digitization itself is done.
    const std::filesystem::path pack_path = dir / "painting.pack.exr";
    auto pack = viewer::LoadPackForViewer(pack_path);
    gallery = pack.ok() ? viewer::RenderGalleryScreenshots(
                              {{(out / "painting.pack.exr").string(), std::move(*pack)}},
                              dir / "gallery.png")
                        : Status(pack.error());
    return Status::Ok();
  });
  if (!written.ok()) return Fail(cmd, written.message());
  if (!packs.empty()) {
    std::printf("\ntexture packs, read back and relit on the held-out photos:\n");
    for (const PackReport& p : packs)
      std::printf("  %-20s %6.2f bytes/texel (%d before compression), %s encoding: %s\n",
                  p.name.c_str(), p.summary.BytesPerTexel(), p.summary.raw_bytes_per_texel,
                  ToString(p.summary.encoding), p.score.Brief().c_str());
  }
  std::printf(
      "\noutputs: %s/scan/ (synthetic scan + ground truth), %s/canvas/ (height.exr, "
      "normals.exr, mask.png, boxes.json, transform.json, report.json)\n",
      args.out.c_str(), args.out.c_str());
  if (fit)
    std::printf(
        "         %s/photos/ (calib.json, images, held_out/, truth/), %s/fit/ (rho_d.exr, "
        "rho_s.exr, lobe.exr, fit_error.exr, fit_status.png, report.json)\n"
        "         %s/painting.pack.exr, %s/painting.q.pack.exr (texture packs: `digitize "
        "inspect`, `digitize verify`)\n",
        args.out.c_str(), args.out.c_str(), args.out.c_str(), args.out.c_str());
  if (fit) {
    const std::filesystem::path pack_path = out / "painting.pack.exr";
    if (gallery.ok())
      std::printf(
          "gallery:  %s (%s in the virtual gallery, hybrid + adaptive; walk in it with "
          "digitize-viewer %s)\n",
          (out / "gallery.png").c_str(), pack_path.c_str(), pack_path.c_str());
    else
      std::printf("gallery screenshot skipped: %s\n", gallery.message().c_str());
  }
  return 0;
}

}  // namespace

void AddDemoCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<DemoArgs>();
  CLI::App* c = app.add_subcommand(
      "demo",
      "Run the whole pipeline on a synthetic painting generated on the fly and print its accuracy "
      "against the ground truth");
  c->add_option("-o,--out", args->out,
                "Output folder: new, empty, or an earlier demo output (replaced only on success)")
      ->capture_default_str()
      ->transform(FolderPath());
  c->add_option("--resolution", args->resolution,
                "Painting texels along the long side (0 = matched to the scan's sampling)")
      ->capture_default_str();
  c->add_option("--scan-px", args->scan_px, "Scan grid size (square)")->capture_default_str();
  c->add_option("--noise-mm", args->noise_mm, "Scan noise sigma (mm)")->capture_default_str();
  c->add_option("--seed", args->seed, "Random seed")->capture_default_str();
  AddPreprocessFlags(c, args->options);
  c->add_option("--lights", args->photos.lights, "Point lights of the photo set (dome)")
      ->capture_default_str()
      ->group("Photos");
  c->add_option("--cameras", args->photos.cameras, "Cameras of the photo set (arc over the canvas)")
      ->capture_default_str()
      ->group("Photos");
  c->add_option("--photo-noise", args->photos.noise_sigma,
                "Photo noise sigma (linear units, white = 1)")
      ->capture_default_str()
      ->group("Photos");
  c->add_flag("--measured", args->measured,
              "Paint one region with a measured 3-lobe paint (not in the fitted model)")
      ->group("Photos");
  c->add_flag("--no-fit", args->no_fit, "Stop after preprocessing")->group("Photos");
  c->add_option("--fit-method", args->fit_method,
                "fast (variable projection) or ceres (ceres::Solve reference)")
      ->check(CLI::IsMember({"fast", "ceres"}, CLI::ignore_case))
      ->capture_default_str()
      ->group("Fit");
  c->callback([args, &exit_code] { exit_code = RunDemo(*args); });
}

}  // namespace digitize::cli
