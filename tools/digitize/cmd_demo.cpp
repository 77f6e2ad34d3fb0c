// `digitize demo`: the whole pipeline on a synthetic painting, judged against its ground truth.
#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "commands.h"
#include "digitize/output_dir.h"
#include "digitize_synth/ground_truth.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/photo_sim.h"
#include "digitize_synth/reflectance_truth.h"
#include "digitize_synth/rti_sim.h"
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
  bool no_rti = false;
  int rti_lights = 48;
};

// A pack as the demo reports it: read back from the file, relit on the held-out photos.
struct PackReport {
  std::string name;
  PackSummary summary;
  HeldOutScore score;
};

// The RTI part of the demo: a small capture of its own painting (image pixel = texel), run
// through RunPipeline as `digitize run --photos fit.lp --held-out held_out.lp` would, once on
// the photometric-stereo canvas and once on the flat one.
struct RtiReport {
  std::string capture_brief, canvas_brief;
  double normals_median_deg = 0, normals_p90_deg = 0;
  double sloped_median_deg = 0, sloped_flat_median_deg = 0, sloped_share = 0;
  double height_rms_mm = 0, relief_rms_mm = 0;
  HeldOutScore with_normals, flat;
  size_t fitted = 0, held_out = 0;
  double seconds = 0;
};

// Every 4th image of the capture's dirs.lp goes to held_out.lp, the others to fit.lp (same
// folder, same lines: the reader's frame and file names stay as WriteSyntheticRti wrote them).
Status SplitLp(const std::filesystem::path& dir, size_t& fitted, size_t& held) {
  std::ifstream in(dir / "dirs.lp");
  std::string line;
  if (!std::getline(in, line)) return Error{(dir / "dirs.lp").string() + ": cannot read"};
  std::vector<std::string> fit_lines, held_lines;
  for (size_t i = 0; std::getline(in, line); ++i) {
    if (line.empty()) continue;
    (i % 4 == 3 ? held_lines : fit_lines).push_back(line);
  }
  for (const auto& [name, lines] :
       {std::pair{"fit.lp", &fit_lines}, {"held_out.lp", &held_lines}}) {
    std::ofstream out(dir / name);
    out << lines->size() << "\n";
    for (const std::string& l : *lines) out << l << "\n";
    if (!out.flush()) return Error{(dir / name).string() + ": cannot write"};
  }
  fitted = fit_lines.size();
  held = held_lines.size();
  return Status::Ok();
}

// RMS of a - b after removing the best plane: integrated heights are defined up to a constant,
// and a tiny common tilt of the normals integrates to a plane that says nothing about relief.
double DetrendedRms(const Grid<float>& a, const Grid<float>& b) {
  Eigen::MatrixXd A(static_cast<Eigen::Index>(a.size()), 3);
  Eigen::VectorXd r(static_cast<Eigen::Index>(a.size()));
  for (int y = 0; y < a.height; ++y)
    for (int x = 0; x < a.width; ++x) {
      const auto i = static_cast<Eigen::Index>(a.Index(x, y));
      A.row(i) << 1.0, x, y;
      r[i] = static_cast<double>(a(x, y)) - b(x, y);
    }
  const Eigen::Vector3d c = A.colPivHouseholderQr().solve(r);
  return std::sqrt((r - A * c).squaredNorm() / static_cast<double>(r.size()));
}

double Rms(const Grid<float>& a) {
  double mean = 0, s = 0;
  for (float v : a.data) mean += v;
  mean /= static_cast<double>(a.size());
  for (float v : a.data) s += (v - mean) * (v - mean);
  return std::sqrt(s / static_cast<double>(a.size()));
}

// Renders the capture into dir/rti, runs both pipelines, judges the written pack on the truth.
Result<RtiReport> RunRtiDemo(const std::filesystem::path& dir, const DemoArgs& args) {
  const auto start = std::chrono::steady_clock::now();
  synth::PaintingOptions painting_options;
  // 256 x 192 texels of 0.25 mm: weave, strokes, impasto and cracks at the photos' resolution.
  painting_options.width_mm = 64;
  painting_options.height_mm = 48;
  painting_options.resolution_px = 256;
  painting_options.seed = args.seed;
  synth::RtiSimOptions rti_options;  // 8-bit sRGB, paint gloss, 2 deg jitter, +-15 % intensity
  rti_options.lights = args.rti_lights;
  rti_options.seed = args.seed;
  if (Status s = painting_options.Validate(); !s.ok()) return Error{s.message()};
  if (Status s = rti_options.Validate(); !s.ok()) return Error{s.message()};
  const synth::SyntheticRtiCapture capture =
      synth::SimulateRti(synth::MakePainting(painting_options), rti_options);
  RtiReport report;
  report.capture_brief = capture.Brief();
  const std::filesystem::path rti_dir = dir / "rti";
  if (Status s = synth::WriteSyntheticRti(rti_dir, capture); !s.ok()) return Error{s.message()};
  if (Status s = SplitLp(rti_dir, report.fitted, report.held_out); !s.ok())
    return Error{s.message()};

  PipelineOptions o;
  o.photos = (rti_dir / "fit.lp").string();
  o.held_out = (rti_dir / "held_out.lp").string();
  o.photo.rti_pixel_pitch_mm = capture.pitch_mm;  // the PNGs carry no resolution tag
  o.out = (dir / "rti.pack.exr").string();
  o.held_out_out = (dir / "rti_relit").string();
  PipelineOptions flat = o;
  flat.rti.normals = flat.rti.height = false;
  flat.out = (dir / "rti.flat.pack.exr").string();
  flat.held_out_out.clear();
  Result<PipelineResult> r = RunPipeline(o);
  if (!r.ok()) return r.error();
  Result<PipelineResult> f = RunPipeline(flat);
  if (!f.ok()) return f.error();
  if (!r->held_out || !f->held_out) return Error{"RunPipeline gave no held-out score"};
  report.with_normals = *r->held_out;
  report.flat = *f->held_out;
  if (r->rti) report.canvas_brief = r->rti->Brief();

  // Judged from the file, as the gallery reads it.
  Result<Pack> pack = ReadPack(o.out);
  if (!pack.ok()) return pack.error();
  if (pack->normals.width != capture.normals.width ||
      pack->normals.height != capture.normals.height)
    return Error{o.out + ": grid differs from the capture's"};
  std::vector<double> err;
  err.reserve(capture.normals.size());
  for (size_t i = 0; i < capture.normals.size(); ++i)
    err.push_back(
        AngleDeg(pack->normals.data[i].cast<double>(), capture.normals.data[i].cast<double>()));
  // Straight up (the flat canvas) is nearly right on the flat majority of texels: the texels
  // sloped by more than 3 deg show what the normals add.
  std::vector<double> sloped, sloped_flat;
  for (size_t i = 0; i < capture.normals.size(); ++i) {
    const double slope = AngleDeg(Vec3d::UnitZ(), capture.normals.data[i].cast<double>());
    if (slope <= 3.0) continue;
    sloped.push_back(err[i]);
    sloped_flat.push_back(slope);
  }
  if (!sloped.empty()) {
    std::sort(sloped.begin(), sloped.end());
    std::sort(sloped_flat.begin(), sloped_flat.end());
    report.sloped_median_deg = sloped[sloped.size() / 2];
    report.sloped_flat_median_deg = sloped_flat[sloped_flat.size() / 2];
    report.sloped_share = static_cast<double>(sloped.size()) / capture.normals.size();
  }
  std::sort(err.begin(), err.end());
  report.normals_median_deg = err[err.size() / 2];
  report.normals_p90_deg = err[err.size() * 9 / 10];
  report.height_rms_mm = DetrendedRms(pack->field.height_mm, capture.height_mm);
  report.relief_rms_mm = Rms(capture.height_mm);
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

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
  if (!args.no_fit && !args.no_rti)
    std::printf(
        "  then an RTI capture of a small painting (%d lights, 8-bit, no scan), fitted with and "
        "without photometric-stereo normals\n",
        args.rti_lights);
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
  std::optional<RtiReport> rti;
  Status rti_gallery = Error{"no RTI capture"};
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
    // The RTI capture's pack hangs beside it (after the RTI run below).
    const std::filesystem::path pack_path = dir / "painting.pack.exr";
    auto pack = viewer::LoadPackForViewer(pack_path);
    if (!pack.ok()) {
      gallery = Status(pack.error());
      return Status::Ok();
    }
    std::vector<std::pair<std::string, Pack>> hung = {
        {(out / "painting.pack.exr").string(), std::move(*pack)}};
    auto render_gallery = [&] {
      viewer::GalleryShotOptions shot;
      shot.close_up = dir / "gallery_closeup.png";
      gallery = viewer::RenderGalleryScreenshots(hung, dir / "gallery.png", {}, shot);
    };
    if (args.no_rti) {
      render_gallery();
      return Status::Ok();
    }
    // The RTI path: no scan, the canvas from the capture itself (a minute's work on a museum's
    // dome capture; seconds here). Its pack hangs in the gallery like the scanned one.
    {
      ProgressBar bar("rti");
      bar.Update("capture + 2 runs", 0.0);
      Result<RtiReport> r = RunRtiDemo(dir, args);
      bar.Finish();
      if (!r.ok()) return Status(r.error());
      rti = std::move(r).value();
    }
    auto rti_pack = viewer::LoadPackForViewer(dir / "rti.pack.exr");
    if (!rti_pack.ok()) {
      rti_gallery = Status(rti_pack.error());
      render_gallery();
      return Status::Ok();
    }
    hung.emplace_back((out / "rti.pack.exr").string(), *rti_pack);
    render_gallery();
    // A 64 mm canvas is a speck from the room's start view: the paper's framed face view of it,
    // placed where the gallery hangs it, under the gallery's light.
    const Eigen::Vector2d size_mm(rti_pack->width() * rti_pack->field.pitch_mm,
                                  rti_pack->height() * rti_pack->field.pitch_mm);
    const RigidTransform world_from_canvas = viewer::MakeGallery({size_mm}).world_from_canvas[0];
    viewer::ViewCamera camera = viewer::MakePaperView(size_mm.x(), size_mm.y(), {}, 1280, 720);
    camera.eye_mm = world_from_canvas.Apply(camera.eye_mm);
    camera.target_mm = world_from_canvas.Apply(camera.target_mm);
    camera.up = world_from_canvas.ApplyToDirection(camera.up);
    rti_gallery =
        viewer::RenderGalleryScreenshots({{(out / "rti.pack.exr").string(), std::move(*rti_pack)}},
                                         dir / "rti_gallery.png", {camera});
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
  if (rti) {
    std::printf(
        "\nRTI capture (no scan: normals, height and light intensities from the photos "
        "themselves): %s; %zu fitted, %zu held out (every 4th)\n  canvas: %s\n",
        rti->capture_brief.c_str(), rti->fitted, rti->held_out, rti->canvas_brief.c_str());
    std::printf("  normals median error    %.2f deg   (p90 %.2f deg), the pack's vs the truth\n",
                rti->normals_median_deg, rti->normals_p90_deg);
    std::printf(
        "    on the %.1f %% of texels sloped > 3 deg: median %.2f deg (straight up, as the "
        "flat canvas has them: %.2f deg)\n",
        100 * rti->sloped_share, rti->sloped_median_deg, rti->sloped_flat_median_deg);
    std::printf(
        "  height RMS error        %.4f mm    (%.1f %% of the relief RMS %.4f mm), "
        "after removing a plane\n",
        rti->height_rms_mm, 100 * rti->height_rms_mm / rti->relief_rms_mm, rti->relief_rms_mm);
    std::printf("  held-out PSNR, normals  %.2f dB linear, %.2f dB 8-bit sRGB\n",
                rti->with_normals.psnr_db, rti->with_normals.psnr_srgb8_db);
    std::printf(
        "  held-out PSNR, flat     %.2f dB linear, %.2f dB 8-bit sRGB (normals straight "
        "up): the normals gain %+.2f dB 8-bit sRGB\n",
        rti->flat.psnr_db, rti->flat.psnr_srgb8_db,
        rti->with_normals.psnr_srgb8_db - rti->flat.psnr_srgb8_db);
    std::printf("  (%.1f s for the capture and both runs)\n", rti->seconds);
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
  if (rti)
    std::printf(
        "         %s/rti/ (images, dirs.lp = fit.lp + held_out.lp, truth/), %s/rti_relit/ (the "
        "held-out photos relit from the pack)\n"
        "         %s/rti.pack.exr (photometric-stereo canvas), %s/rti.flat.pack.exr (flat "
        "canvas)\n",
        args.out.c_str(), args.out.c_str(), args.out.c_str(), args.out.c_str());
  if (fit) {
    const std::filesystem::path pack_path = out / "painting.pack.exr";
    if (gallery.ok())
      std::printf(
          "gallery:  %s and %s (%s%s in the virtual gallery, hybrid + adaptive; walk in it "
          "with digitize-viewer %s%s)\n",
          (out / "gallery.png").c_str(), (out / "gallery_closeup.png").c_str(), pack_path.c_str(),
          rti ? " and the RTI pack" : "", pack_path.c_str(),
          rti ? (" " + (out / "rti.pack.exr").string()).c_str() : "");
    else
      std::printf("gallery screenshot skipped: %s\n", gallery.message().c_str());
  }
  if (rti) {
    if (rti_gallery.ok())
      std::printf("rti gallery: %s (%s in the virtual gallery, framed face view)\n",
                  (out / "rti_gallery.png").c_str(), (out / "rti.pack.exr").c_str());
    else
      std::printf("rti gallery screenshot skipped: %s\n", rti_gallery.message().c_str());
  }
  return 0;
}

}  // namespace

void AddDemoCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<DemoArgs>();
  CLI::App* c = app.add_subcommand(
      "demo",
      "Run the whole pipeline on a synthetic painting generated on the fly (scan, photos, fit, "
      "packs, gallery; then a synthetic RTI capture without a scan, fitted on its "
      "photometric-stereo canvas and on the flat one) and print its accuracy against the ground "
      "truth");
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
  c->add_option("--rti-lights", args->rti_lights,
                "Lights of the synthetic RTI capture (every 4th held out)")
      ->capture_default_str()
      ->group("RTI");
  c->add_flag("--no-rti", args->no_rti, "Skip the RTI capture (photometric-stereo canvas)")
      ->group("RTI");
  c->add_option("--fit-method", args->fit_method,
                "fast (variable projection) or ceres (ceres::Solve reference)")
      ->check(CLI::IsMember({"fast", "ceres"}, CLI::ignore_case))
      ->capture_default_str()
      ->group("Fit");
  c->callback([args, &exit_code] { exit_code = RunDemo(*args); });
}

}  // namespace digitize::cli
