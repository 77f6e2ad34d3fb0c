// `digitize preprocess`: scan(s), or a patch list of overlapping scans, -> a canvas folder.
#include <cstdio>
#include <memory>

#include "commands.h"
#include "progress_bar.h"

namespace digitize::cli {

namespace {

struct PreprocessArgs {
  std::vector<std::string> scans;
  std::string patches;
  std::string out;
  ScanReadOptions read;
  std::string mask;
  std::vector<int> grid;
  PreprocessOptions options;
  TiledPreprocessOptions tiled;
  int tile_texels = 0;
};

int RunPreprocess(const PreprocessArgs& args) {
  const std::string cmd = "preprocess";
  if (args.scans.empty() == args.patches.empty())
    return Fail(cmd, "give the scan(s) of one pose, or --patches LIST of overlapping scans");
  PreprocessFolderOptions o;
  o.scans = args.scans;
  o.patches = args.patches;
  o.read = ScanReadOptionsOf(args.read, args.mask, args.grid);
  o.preprocess = args.options;
  if (args.tile_texels > 0) {
    o.tiled = args.tiled;
    o.tiled->tile_texels = args.tile_texels;
  }
  o.out = args.out;
  ProgressBar bar("preprocess");
  Result<PreprocessResult> result = PreprocessToFolder(o, bar.Callback());
  bar.Finish();
  if (!result.ok()) return Fail(cmd, result.error().message);
  for (const StepReport& step : result->steps)
    std::printf("%6.3fs  %s\n", step.seconds, step.line.c_str());
  std::printf(
      "total %.3f s; outputs in %s/ (height.exr, normals.exr, mask.png, boxes.json, "
      "transform.json, report.json%s)\n",
      result->total_seconds, args.out.c_str(), result->registration ? ", registration.json" : "");
  return 0;
}

}  // namespace

void AddPreprocessCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<PreprocessArgs>();
  CLI::App* c = app.add_subcommand(
      "preprocess",
      "Scan of a framed painting -> canvas height field (EXR, mm), normals, mask, relief boxes, "
      "transform and report.\nSeveral scans = several exposures of one pose, merged; "
      "--patches = overlapping scans of one painting, registered and merged.");
  c->add_option("scans", args->scans,
                "Scan file(s): float EXR/TIFF (XYZ mm, or depth with --pixel-pitch-mm), 16-bit "
                "PNG/TIFF (with --height-scale-mm), PLY point grid")
      ->check(CLI::ExistingFile);
  c->add_option("--patches", args->patches,
                "Patch list (JSON, docs/formats.md): overlapping scans with their nominal rig "
                "poses; registered, merged, registration.json written beside the canvas")
      ->check(CLI::ExistingFile);
  c->add_option("-o,--out", args->out,
                "Output folder: new, empty, or an earlier canvas output (replaced only on success)")
      ->required()
      ->transform(FolderPath());
  c->add_option("--mask", args->mask, "Mask image, same size as the scan; 0 = missing sample")
      ->check(CLI::ExistingFile)
      ->group("Input");
  c->add_option("--pixel-pitch-mm", args->read.pixel_pitch_mm,
                "Sample spacing (mm) of depth-only inputs")
      ->group("Input");
  c->add_option("--height-scale-mm", args->read.height_scale_mm,
                "mm per count for 16-bit depth images")
      ->group("Input");
  c->add_option("--height-offset-mm", args->read.height_offset_mm,
                "Added to 16-bit depth after scaling (mm)")
      ->group("Input");
  c->add_option("--grid", args->grid,
                "WIDTH HEIGHT of a PLY point grid without a 'comment grid' line")
      ->expected(2)
      ->group("Input");
  c->add_option("--max-scan-samples", args->read.max_samples,
                "Refuse a scan with more samples than this: a guard against a corrupt header "
                "(about 14 bytes of memory a sample; a 16384 x 12288 scan needs 2e8; "
                "--tile-texels reads a scan a part at a time instead)")
      ->capture_default_str()
      ->check(CLI::Range(size_t{1}, size_t{1} << 32))
      ->group("Input");
  c->add_option("--tile-texels", args->tile_texels,
                "Preprocess in tiles of N texels a side (and a halo) in bounded memory, for a "
                "scan too large to hold: one 3-channel float XYZ EXR/TIFF; 0 = whole (default)")
      ->check(CLI::Range(0, 16384))
      ->group("Large scans");
  c->add_option("--tile-halo", args->tiled.halo_texels,
                "Texels around each tile it also resamples (holes and relief specks that cross "
                "its edge); 0 = from the hole and speck areas")
      ->check(CLI::Range(0, 4096))
      ->group("Large scans");
  c->add_option("--canvas-stride", args->tiled.canvas_stride,
                "With --tile-texels: the canvas (plane, outline, frame) is found on every N-th "
                "scan sample; 0 = so that it reads at most 2^24 samples, 1 = every sample")
      ->check(CLI::Range(0, 64))
      ->group("Large scans");
  AddPreprocessFlags(c, args->options);
  c->callback([args, &exit_code] { exit_code = RunPreprocess(*args); });
}

}  // namespace digitize::cli
