#include <cstdio>
#include <memory>

#include "commands.h"
#include "digitize/output_dir.h"
#include "digitize/preprocess.h"
#include "digitize/scan_io.h"
#include "progress_bar.h"

namespace digitize::cli {

Result<std::vector<Scan>> ReadScans(const PreprocessArgs& args) {
  ScanReadOptions read = args.read;
  read.mask = args.mask;
  if (args.grid.size() == 2) {
    read.grid_width = args.grid[0];
    read.grid_height = args.grid[1];
  }
  if (Status s = read.Validate(); !s.ok()) return Error{s.message()};
  std::vector<Scan> exposures;
  for (const std::string& path : args.scans) {
    Result<Scan> scan = ReadScan(path, read);
    if (!scan.ok()) return scan.error();
    exposures.push_back(std::move(scan).value());
  }
  return exposures;
}

int RunPreprocess(const PreprocessArgs& args) {
  const std::string cmd = "preprocess";
  if (Status s = args.options.Validate(); !s.ok()) return Fail(cmd, s.message());
  FolderOutput output{cmd, "canvas", {args.scans.begin(), args.scans.end()}};
  if (!args.mask.empty()) output.inputs.emplace_back(args.mask);
  if (Status s = CheckFolderOutput(args.out, output); !s.ok()) return Fail(cmd, s.message());
  Result<std::vector<Scan>> exposures = ReadScans(args);
  if (!exposures.ok()) return Fail(cmd, exposures.error().message);
  ProgressBar bar("preprocess");
  Result<PreprocessResult> result = Preprocess(std::move(exposures).value(), args.options, bar.Callback());
  bar.Finish();
  if (!result.ok()) return Fail(cmd, result.error().message);

  Status written =
      WriteDirectoryAtomically(args.out, output, [&](const std::filesystem::path& dir) {
        return WritePreprocessOutputs(dir, *result, args.options, args.scans);
      });
  if (!written.ok()) return Fail(cmd, written.message());
  for (const StepReport& step : result->steps) std::printf("%6.3fs  %s\n", step.seconds, step.line.c_str());
  std::printf("total %.3f s; outputs in %s/ (height.exr, normals.exr, mask.png, boxes.json, "
              "transform.json, report.json)\n",
              result->total_seconds, args.out.c_str());
  return 0;
}

void AddPreprocessFlags(CLI::App* c, PreprocessOptions& o) {
  c->add_option("--spike-mm", o.sanitize.spike_mm,
                "A sample farther than this (mm) from all its neighbours is an outlier")
      ->capture_default_str()->group("Clean-up");
  c->add_option("--max-coordinate-mm", o.sanitize.max_abs_coordinate_mm,
                "Coordinates beyond this (mm) are sensor garbage")
      ->capture_default_str()->group("Clean-up");
  c->add_option("--disagree-mm", o.merge.disagree_mm,
                "Exposures differing by more than this (mm) at a pixel are counted as disagreeing")
      ->capture_default_str()->group("Clean-up");
  c->add_option("--stop-gradient-mm", o.canvas.stop_gradient_mm,
                "Sobel magnitude (mm of height per pixel) that stops the canvas region growing")
      ->capture_default_str()->group("Canvas");
  c->add_option("--stop-slope", o.canvas.stop_slope,
                "Surface slope (height / in-plane distance) that also stops the growing: frame walls")
      ->capture_default_str()->group("Canvas");
  c->add_option("--refine-step-mm", o.canvas.refine_step_mm,
                "Height step (mm) the canvas boundary refinement will not cross")
      ->capture_default_str()->group("Canvas");
  c->add_option("--refine-px", o.canvas.refine_px, "How far (pixels) the boundary refinement may reach")
      ->capture_default_str()->group("Canvas");
  c->add_option("--erode-px", o.canvas.erode_px, "Erosion (pixels) before the second plane fit")
      ->capture_default_str()->group("Canvas");
  c->add_option("--trim-sigmas", o.canvas.trim_sigmas,
                "Robust plane fit: points this many MADs above the plane are relief, left out")
      ->capture_default_str()->group("Canvas");
  c->add_option("--seed-x", o.canvas.seed_x, "Region-growing seed column (pixels; -1 = scan centre)")
      ->capture_default_str()->group("Canvas");
  c->add_option("--seed-y", o.canvas.seed_y, "Region-growing seed row (pixels; -1 = scan centre)")
      ->capture_default_str()->group("Canvas");
  c->add_option("--pitch-mm", o.resample.pitch_mm,
                "Output texel spacing (mm); 0 = the scan's median sample spacing")
      ->capture_default_str()->group("Resampling");
  c->add_option("--max-hole-area-mm2", o.resample.max_hole_area_mm2,
                "Holes up to this area (mm^2) are filled; larger ones are marked unfilled")
      ->capture_default_str()->group("Resampling");
  c->add_option("--max-edge-factor", o.resample.max_edge_factor,
                "Scan triangles with an edge longer than this many pitches are not interpolated")
      ->capture_default_str()->group("Resampling");
  c->add_option("--delta0", o.relief.delta0_fraction,
                "Bump-plane height as a fraction of the max canvas height (0..1)")
      ->capture_default_str()->group("Relief");
  c->add_option("--min-area-mm2", o.relief.min_component_area_mm2,
                "Relief components smaller than this (mm^2) are removed as specks")
      ->capture_default_str()->group("Relief");
  c->add_option("--cell-px", o.relief.cell_px, "Box cell size n (texels): n x n cells become boxes")
      ->capture_default_str()->group("Relief");
  c->add_option("--cover-px", o.relief.cover_px,
                "Boxes cover the relief grown by this many texels (0 = exactly the relief)")
      ->capture_default_str()->group("Relief");
  c->add_option("--min-relief-mm", o.relief.min_relief_mm,
                "A canvas whose highest point is not above this (mm; at least 8 sigma of the noise) "
                "has no relief boxes")
      ->capture_default_str()->group("Relief");
  c->add_flag("!--no-noise-margin", o.noise_margin_from_scan,
              "Classify relief exactly at delta0 instead of delta0 - 2 sigma(noise)")
      ->group("Relief");
}

void AddPreprocessCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<PreprocessArgs>();
  CLI::App* c = app.add_subcommand(
      "preprocess",
      "Scan of a framed painting -> canvas height field (EXR, mm), normals, mask, relief boxes, "
      "transform and report.\nSeveral scans = several exposures of one pose, merged.");
  c->add_option("scans", args->scans,
                "Scan file(s): float EXR/TIFF (XYZ mm, or depth with --pixel-pitch-mm), 16-bit "
                "PNG/TIFF (with --height-scale-mm), PLY point grid")
      ->required()->check(CLI::ExistingFile);
  c->add_option("-o,--out", args->out,
                "Output folder: new, empty, or an earlier canvas output (replaced only on success)")
      ->required()
      ->transform(FolderPath());
  c->add_option("--mask", args->mask, "Mask image, same size as the scan; 0 = missing sample")
      ->check(CLI::ExistingFile)->group("Input");
  c->add_option("--pixel-pitch-mm", args->read.pixel_pitch_mm,
                "Sample spacing (mm) of depth-only inputs")->group("Input");
  c->add_option("--height-scale-mm", args->read.height_scale_mm,
                "mm per count for 16-bit depth images")->group("Input");
  c->add_option("--height-offset-mm", args->read.height_offset_mm,
                "Added to 16-bit depth after scaling (mm)")->group("Input");
  c->add_option("--grid", args->grid, "WIDTH HEIGHT of a PLY point grid without a 'comment grid' line")
      ->expected(2)->group("Input");
  AddPreprocessFlags(c, args->options);
  c->callback([args, &exit_code] { exit_code = RunPreprocess(*args); });
}

}  // namespace digitize::cli
