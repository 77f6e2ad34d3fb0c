#include <cstdio>
#include <memory>

#include "commands.h"
#include "digitize/output_dir.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/scan_sim.h"
#include "digitize_synth/synth_io.h"
#include "progress_bar.h"

namespace digitize::cli {
namespace {

struct SynthArgs {
  std::string out;
  synth::PaintingOptions painting;
  synth::FrameOptions frame;
  synth::ScanSimOptions scan;
  std::string model = "ortho";
  std::vector<int> scan_size;
  bool no_frame = false, no_weave = false, no_strokes = false, no_impasto = false, no_cracks = false;
};

int RunSynth(SynthArgs args) {
  const std::string cmd = "synth";
  args.painting.weave = !args.no_weave;
  args.painting.strokes = !args.no_strokes;
  args.painting.impasto = !args.no_impasto;
  args.painting.craquelure = !args.no_cracks;
  args.frame.enabled = !args.no_frame;
  args.scan.model = args.model == "pinhole" ? synth::ScannerModel::kPinhole
                                            : synth::ScannerModel::kOrthographic;
  if (args.scan_size.size() == 2) {
    args.scan.width_px = args.scan_size[0];
    args.scan.height_px = args.scan_size[1];
  }
  args.scan.seed = args.painting.seed;
  if (Status s = args.painting.Validate(); !s.ok()) return Fail(cmd, s.message());
  if (Status s = args.scan.Validate(); !s.ok()) return Fail(cmd, s.message());

  ProgressBar bar("synth");
  bar.Update("painting", 0.0);
  const synth::Painting painting = synth::MakePainting(args.painting);
  bar.Update("scene", 0.3);
  const synth::Scene scene(painting, args.frame);
  bar.Update("scan", 0.45);
  const synth::SyntheticScan scan = synth::SimulateScan(scene, args.scan);
  bar.Update("writing", 0.7);
  Status written = WriteDirectoryAtomically(args.out, [&](const std::filesystem::path& dir) {
    return synth::WriteSyntheticScan(dir, painting, scan);
  });
  bar.Finish();
  if (!written.ok()) return Fail(cmd, written.message());
  std::printf("synthetic painting %.0f x %.0f mm, %dx%d texels; scan %dx%d (%zu exposure(s)) -> %s/\n",
              painting.width_mm, painting.height_mm, painting.truth.width(), painting.truth.height(),
              args.scan.width_px, args.scan.height_px, scan.exposures.size(), args.out.c_str());
  return 0;
}

}  // namespace

void AddSynthCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<SynthArgs>();
  CLI::App* c = app.add_subcommand(
      "synth", "Generate a synthetic framed painting, its scan, and the ground truth beside it");
  c->add_option("-o,--out", args->out, "Output folder (replaced as a whole, only on success)")->required();
  auto& p = args->painting;
  c->add_option("--seed", p.seed, "Random seed (same seed, same data)")->capture_default_str();
  c->add_option("--width-mm", p.width_mm, "Canvas width (mm)")->capture_default_str()->group("Painting");
  c->add_option("--height-mm", p.height_mm, "Canvas height (mm)")->capture_default_str()->group("Painting");
  c->add_option("--resolution", p.resolution_px, "Texels along the longer canvas side (64..8192)")
      ->capture_default_str()->group("Painting");
  c->add_option("--impasto-max-mm", p.impasto_max_mm, "Highest impasto (mm)")
      ->capture_default_str()->group("Painting");
  c->add_flag("--no-weave", args->no_weave, "No canvas weave")->group("Painting");
  c->add_flag("--no-strokes", args->no_strokes, "No brush strokes")->group("Painting");
  c->add_flag("--no-impasto", args->no_impasto, "No impasto / knife work")->group("Painting");
  c->add_flag("--no-cracks", args->no_cracks, "No craquelure")->group("Painting");
  c->add_flag("--no-frame", args->no_frame, "No frame and wall: the canvas alone")->group("Frame");
  c->add_option("--frame-raise-mm", args->frame.raise_mm, "Frame height above the canvas (mm)")
      ->capture_default_str()->group("Frame");
  c->add_option("--frame-width-mm", args->frame.width_mm, "Frame width (mm)")
      ->capture_default_str()->group("Frame");
  auto& s = args->scan;
  c->add_option("--scan-size", args->scan_size, "Scan grid WIDTH HEIGHT (samples)")->expected(2)->group("Scan");
  c->add_option("--model", args->model, "Scanner model")
      ->check(CLI::IsMember({"ortho", "pinhole"}))->capture_default_str()->group("Scan");
  c->add_option("--tilt-deg", s.tilt_deg, "Canvas tilt against the scanner (degrees)")
      ->capture_default_str()->group("Scan");
  c->add_option("--tilt-axis-deg", s.tilt_axis_deg, "Direction of the tilt axis (degrees)")
      ->capture_default_str()->group("Scan");
  c->add_option("--roll-deg", s.roll_deg, "In-plane rotation (degrees)")->capture_default_str()->group("Scan");
  c->add_option("--distance-mm", s.distance_mm, "Scanner to canvas centre (mm)")
      ->capture_default_str()->group("Scan");
  c->add_option("--margin", s.field_margin, "Field of view beyond canvas + frame (share)")
      ->capture_default_str()->group("Scan");
  c->add_option("--noise-mm", s.noise_mm, "Gaussian noise sigma along the ray (mm)")
      ->capture_default_str()->group("Scan");
  c->add_option("--dropout", s.dropout, "Share of samples lost at random")->capture_default_str()->group("Scan");
  c->add_option("--hole-blobs", s.hole_blobs, "Blob-shaped holes")->capture_default_str()->group("Scan");
  c->add_option("--outliers", s.outliers, "Share of outlier samples")->capture_default_str()->group("Scan");
  c->add_option("--exposures", s.exposures, "Exposures of the same pose")->capture_default_str()->group("Scan");
  c->callback([args, &exit_code] { exit_code = RunSynth(*args); });
}

}  // namespace digitize::cli
