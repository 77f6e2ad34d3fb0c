#include <algorithm>
#include <cstdio>
#include <memory>

#include "commands.h"
#include "digitize/output_dir.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/patch_sim.h"
#include "digitize_synth/photo_sim.h"
#include "digitize_synth/rti_sim.h"
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
  std::vector<double> frame_sides, bevel, offset;
  bool no_frame = false, no_weave = false, no_strokes = false, no_impasto = false,
       no_cracks = false;
  // Photo set (--photos).
  bool photos = false, measured = false;
  std::vector<int> camera_grid;  // --camera-grid C R
  synth::PhotoSimOptions photo;
  std::string photo_encoding = "srgb8";
  // RTI capture (--rti).
  bool rti = false;
  synth::RtiSimOptions rti_options;
  std::string rti_encoding = "srgb8";
  // Overlapping patches (--patches CxR) instead of one scan.
  std::string patches;
  synth::PatchGridOptions grid;
  std::vector<double> tilted_patch;
  bool resolution_given = false;
};

// --patches: the painting scanned as a grid of overlapping patches (patch_sim.h), each patch the
// --scan-size / --model / tilt / noise scan of its part; patches.json (nominal poses) and
// truth_patches.json (true poses) beside them.
int RunSynthPatches(SynthArgs& args) {
  const std::string cmd = "synth";
  int columns = 0, rows = 0;
  char x = 0, extra = 0;
  if (std::sscanf(args.patches.c_str(), "%d%c%d%c", &columns, &x, &rows, &extra) != 3 ||
      (x != 'x' && x != 'X'))
    return Fail(cmd, "--patches must be COLUMNSxROWS (e.g. 3x2), got \"" + args.patches + "\"");
  if (args.photos || args.rti) return Fail(cmd, "--patches cannot be combined with --photos/--rti");
  synth::PatchGridOptions& g = args.grid;
  g.columns = columns, g.rows = rows;
  g.scan = args.scan;
  g.seed = args.painting.seed;
  if (args.tilted_patch.size() == 2)
    g.tilted_patch = static_cast<int>(args.tilted_patch[0]),
    g.tilted_patch_deg = args.tilted_patch[1];
  if (Status s = g.Validate(); !s.ok()) return Fail(cmd, s.message());
  if (!args.resolution_given)
    args.painting.resolution_px = synth::MatchedPatchResolution(args.painting, g);
  if (Status s = args.painting.Validate(); !s.ok()) return Fail(cmd, s.message());
  if (Status s = args.frame.ValidateFor(args.painting.width_mm, args.painting.height_mm); !s.ok())
    return Fail(cmd, s.message());
  const FolderOutput output{cmd, "synth", {}};
  if (Status s = CheckFolderOutput(args.out, output); !s.ok()) return Fail(cmd, s.message());
  ProgressBar bar("synth");
  bar.Update("painting", 0.0);
  const synth::Painting painting = synth::MakePainting(args.painting);
  bar.Update("scene", 0.3);
  const synth::Scene scene(painting, args.frame);
  bar.Update("patches", 0.45);
  const synth::SyntheticPatchScan scan = synth::SimulatePatchScan(scene, g);
  bar.Update("writing", 0.8);
  Status written =
      WriteDirectoryAtomically(args.out, output, [&](const std::filesystem::path& dir) {
        return synth::WriteSyntheticPatchScan(dir, painting, scan);
      });
  bar.Finish();
  if (!written.ok()) return Fail(cmd, written.message());
  std::printf(
      "synthetic painting %.0f x %.0f mm, %dx%d texels; %dx%d patches of %dx%d samples, "
      "%.0f x %.0f mm each, drift up to %.1f mm / %.1f deg -> %s/ (patches.json, "
      "truth_patches.json)\n",
      painting.width_mm, painting.height_mm, painting.truth.width(), painting.truth.height(),
      columns, rows, scan.patches[0].scan.options.width_px, scan.patches[0].scan.options.height_px,
      scan.field_mm.x(), scan.field_mm.y(), g.drift_mm, g.drift_deg, args.out.c_str());
  return 0;
}

int RunSynth(SynthArgs args) {
  const std::string cmd = "synth";
  args.painting.weave = !args.no_weave;
  args.painting.strokes = !args.no_strokes;
  args.painting.impasto = !args.no_impasto;
  args.painting.craquelure = !args.no_cracks;
  args.frame.enabled = !args.no_frame;
  args.scan.model =
      args.model == "pinhole" ? synth::ScannerModel::kPinhole : synth::ScannerModel::kOrthographic;
  if (args.scan_size.size() == 2) {
    args.scan.width_px = args.scan_size[0];
    args.scan.height_px = args.scan_size[1];
  }
  if (!args.patches.empty()) {
    if (args.offset.size() == 2)
      args.scan.offset_mm = Vec3d(args.offset[0], args.offset[1], args.scan.offset_mm.z());
    return RunSynthPatches(args);
  }
  if (args.frame_sides.size() == 4) {
    args.frame.left_mm = args.frame_sides[0], args.frame.right_mm = args.frame_sides[1];
    args.frame.top_mm = args.frame_sides[2], args.frame.bottom_mm = args.frame_sides[3];
  }
  if (args.bevel.size() == 2)
    args.frame.bevel_width_mm = args.bevel[0], args.frame.bevel_height_mm = args.bevel[1];
  if (args.offset.size() == 2)
    args.scan.offset_mm = Vec3d(args.offset[0], args.offset[1], args.scan.offset_mm.z());
  args.scan.seed = args.painting.seed;
  args.photo.seed = args.painting.seed;
  args.rti_options.seed = args.painting.seed;
  args.rti_options.encoding =
      args.rti_encoding == "exr" ? synth::RtiEncoding::kLinearFloat : synth::RtiEncoding::kSrgb8;
  args.photo.encoding = args.photo_encoding == "srgb16" ? synth::PhotoEncoding::kSrgb16
                        : args.photo_encoding == "exr"  ? synth::PhotoEncoding::kLinearExr
                        : args.photo_encoding == "jpeg" ? synth::PhotoEncoding::kJpeg
                                                        : synth::PhotoEncoding::kSrgb8;
  if (args.camera_grid.size() == 2) {
    args.photo.grid_cols = args.camera_grid[0];
    args.photo.grid_rows = args.camera_grid[1];
  }
  std::vector<synth::PaintMaterial> materials;
  if (args.photos) {
    materials = synth::DefaultPaintMaterials(args.measured);
    // Every material on some region (region i gets material i % count).
    args.painting.region_count =
        std::max(args.painting.region_count, static_cast<int>(materials.size()));
  }
  if (Status s = args.painting.Validate(); !s.ok()) return Fail(cmd, s.message());
  if (Status s = args.scan.Validate(); !s.ok()) return Fail(cmd, s.message());
  if (Status s = args.frame.ValidateFor(args.painting.width_mm, args.painting.height_mm); !s.ok())
    return Fail(cmd, s.message());
  if (Status s = args.photo.Validate(); args.photos && !s.ok()) return Fail(cmd, s.message());
  if (Status s = args.rti_options.Validate(); args.rti && !s.ok()) return Fail(cmd, s.message());
  const FolderOutput output{cmd, "synth", {}};
  if (Status s = CheckFolderOutput(args.out, output); !s.ok()) return Fail(cmd, s.message());

  ProgressBar bar("synth");
  // Shares of the bar: the photo set takes most of the time when there is one.
  const double render_share = args.photos ? 0.6 : 0.0;
  const double k = 1.0 - render_share;
  bar.Update("painting", 0.0);
  const synth::Painting painting = synth::MakePainting(args.painting);
  bar.Update("scene", 0.3 * k);
  const synth::Scene scene(painting, args.frame);
  bar.Update("scan", 0.45 * k);
  synth::SyntheticScan scan = synth::SimulateScan(scene, args.scan);
  const size_t exposures = scan.exposures.size();
  synth::SyntheticPhotoSet photos;  // without pixels: each image is written once rendered
  synth::SyntheticRtiCapture rti;
  if (args.rti) {
    bar.Update("rti", 0.6 * k);
    rti = synth::SimulateRti(painting, args.rti_options);
  }
  Status written =
      WriteDirectoryAtomically(args.out, output, [&](const std::filesystem::path& dir) {
        bar.Update("writing", 0.7 * k);
        if (Status s = synth::WriteSyntheticScan(dir, painting, scan); !s.ok()) return s;
        // Written: the photos need its pose only, so its samples and masks (14 bytes a scan
        // sample) go before the render.
        scan.exposures = {};
        scan.canvas_mask_scan = Grid<uint8_t>();
        scan.hit_scan = Grid<uint8_t>();
        if (args.rti) {
          if (Status s = synth::WriteSyntheticRti(dir / "rti", rti); !s.ok()) return s;
        }
        if (!args.photos) return Status::Ok();
        const double from = 0.7 * k;
        return synth::RenderSyntheticPhotoSet(
            dir / "photos", scene, scan.canvas_from_scan, args.photo, materials,
            [&](std::string_view step, double f) { bar.Update(step, from + render_share * f); },
            &photos);
      });
  bar.Finish();
  if (!written.ok()) return Fail(cmd, written.message());
  std::printf(
      "synthetic painting %.0f x %.0f mm, %dx%d texels; scan %dx%d (%zu exposure(s)) -> %s/\n",
      painting.width_mm, painting.height_mm, painting.truth.width(), painting.truth.height(),
      args.scan.width_px, args.scan.height_px, exposures, args.out.c_str());
  if (args.photos) {
    std::printf("photo set: %s -> %s/photos/\n", photos.Brief().c_str(), args.out.c_str());
  }
  if (args.rti) {
    std::printf("RTI capture: %s -> %s/rti/ (pitch %g mm)\n", rti.Brief().c_str(), args.out.c_str(),
                rti.pitch_mm);
  }
  return 0;
}

}  // namespace

void AddSynthCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<SynthArgs>();
  CLI::App* c = app.add_subcommand(
      "synth", "Generate a synthetic framed painting, its scan, and the ground truth beside it");
  c->add_option("-o,--out", args->out,
                "Output folder: new, empty, or an earlier synth output (replaced only on success)")
      ->required()
      ->transform(FolderPath());
  auto& p = args->painting;
  c->add_option("--seed", p.seed, "Random seed (same seed, same data)")->capture_default_str();
  c->add_option("--width-mm", p.width_mm, "Canvas width (mm)")
      ->capture_default_str()
      ->group("Painting");
  c->add_option("--height-mm", p.height_mm, "Canvas height (mm)")
      ->capture_default_str()
      ->group("Painting");
  c->add_option("--resolution", p.resolution_px, "Texels along the longer canvas side (64..16384)")
      ->capture_default_str()
      ->each([args](const std::string&) { args->resolution_given = true; })
      ->group("Painting");
  c->add_option("--impasto-max-mm", p.impasto_max_mm, "Highest impasto (mm)")
      ->capture_default_str()
      ->group("Painting");
  c->add_flag("--no-weave", args->no_weave, "No canvas weave")->group("Painting");
  c->add_flag("--no-strokes", args->no_strokes, "No brush strokes")->group("Painting");
  c->add_flag("--no-impasto", args->no_impasto, "No impasto / knife work")->group("Painting");
  c->add_flag("--no-cracks", args->no_cracks, "No craquelure")->group("Painting");
  c->add_flag("--no-frame", args->no_frame, "No frame and wall: the canvas alone")->group("Frame");
  c->add_option("--frame-raise-mm", args->frame.raise_mm, "Frame height above the canvas (mm)")
      ->capture_default_str()
      ->group("Frame");
  c->add_option("--frame-width-mm", args->frame.width_mm, "Frame width (mm)")
      ->capture_default_str()
      ->group("Frame");
  c->add_option("--frame-sides-mm", args->frame_sides,
                "Per-side frame widths LEFT RIGHT TOP BOTTOM (mm; 0 = --frame-width-mm)")
      ->expected(4)
      ->group("Frame");
  c->add_option("--bevel-mm", args->bevel, "Bevel at the frame's inner edge: WIDTH HEIGHT (mm)")
      ->expected(2)
      ->group("Frame");
  c->add_option("--lip-mm", args->frame.lip_mm, "Frame lip overhanging the canvas edge (mm)")
      ->capture_default_str()
      ->group("Frame");
  c->add_option("--lip-gap-mm", args->frame.lip_gap_mm, "Lip's underside above the canvas (mm)")
      ->capture_default_str()
      ->group("Frame");
  c->add_option("--bow-mm", p.bow_mm, "Canvas bow at its centre (mm; negative sags away)")
      ->capture_default_str()
      ->group("Painting");
  auto& s = args->scan;
  c->add_option("--scan-size", args->scan_size, "Scan grid WIDTH HEIGHT (samples)")
      ->expected(2)
      ->group("Scan");
  c->add_option("--model", args->model, "Scanner model")
      ->check(CLI::IsMember({"ortho", "pinhole"}))
      ->capture_default_str()
      ->group("Scan");
  c->add_option("--tilt-deg", s.tilt_deg, "Canvas tilt against the scanner (degrees)")
      ->capture_default_str()
      ->group("Scan");
  c->add_option("--tilt-axis-deg", s.tilt_axis_deg, "Direction of the tilt axis (degrees)")
      ->capture_default_str()
      ->group("Scan");
  c->add_option("--roll-deg", s.roll_deg, "In-plane rotation (degrees)")
      ->capture_default_str()
      ->group("Scan");
  c->add_option("--distance-mm", s.distance_mm, "Scanner to canvas centre (mm)")
      ->capture_default_str()
      ->group("Scan");
  c->add_option("--margin", s.field_margin, "Field of view beyond canvas + frame (share)")
      ->capture_default_str()
      ->group("Scan");
  c->add_option("--noise-mm", s.noise_mm, "Gaussian noise sigma along the ray (mm)")
      ->capture_default_str()
      ->group("Scan");
  c->add_option("--dropout", s.dropout, "Share of samples lost at random")
      ->capture_default_str()
      ->group("Scan");
  c->add_option("--hole-blobs", s.hole_blobs, "Blob-shaped holes")
      ->capture_default_str()
      ->group("Scan");
  c->add_option("--border-holes", s.border_hole_blobs, "Blob-shaped holes on the canvas outline")
      ->capture_default_str()
      ->group("Scan");
  c->add_option("--offset-mm", args->offset, "Canvas centre off the optical axis: X Y (mm)")
      ->expected(2)
      ->group("Scan");
  c->add_option("--outliers", s.outliers, "Share of outlier samples")
      ->capture_default_str()
      ->group("Scan");
  c->add_option("--exposures", s.exposures, "Exposures of the same pose")
      ->capture_default_str()
      ->group("Scan");
  auto& ph = args->photo;
  CLI::Option* photos =
      c->add_flag("--photos", args->photos,
                  "Also render a photo set of the painting (calibration in the scan frame, "
                  "held-out renders, reflectance truth) into <out>/photos/")
          ->group("Photos");
  c->add_option("--lights", ph.lights, "Point lights on a dome around the canvas (count)")
      ->capture_default_str()
      ->needs(photos)
      ->group("Photos");
  c->add_option("--cameras", ph.cameras,
                "Cameras on an arc through the canvas normal (count; 1 = straight above)")
      ->capture_default_str()
      ->needs(photos)
      ->group("Photos");
  c->add_option("--camera-grid", args->camera_grid,
                "A tiled photo set, as a large painting is photographed: one camera straight above "
                "each of C x R cells of the canvas, each under its own --lights (replaces "
                "--cameras' arc)")
      ->expected(2)
      ->needs(photos)
      ->group("Photos");
  c->add_option("--grid-overlap", ph.grid_overlap,
                "With --camera-grid: each image covers its cell grown by this share of a cell on "
                "every side")
      ->capture_default_str()
      ->needs(photos)
      ->group("Photos");
  c->add_option("--pixels-per-texel", ph.pixels_per_texel,
                "Image sampling of the canvas: pixels per texel at the image centre")
      ->capture_default_str()
      ->needs(photos)
      ->group("Photos");
  c->add_option("--held-out-lights", ph.held_out_lights,
                "Held-out lights (noise-free renders from two views to judge a fit; 0: none)")
      ->capture_default_str()
      ->needs(photos)
      ->group("Photos");
  c->add_option("--photo-encoding", args->photo_encoding,
                "Image files: 8-bit sRGB PNG, 16-bit sRGB PNG, linear float EXR, or 8-bit sRGB "
                "JPEG (quality 95, 4:4:4: a tiled set of a large painting stays a few GB)")
      ->check(CLI::IsMember({"srgb8", "srgb16", "exr", "jpeg"}))
      ->capture_default_str()
      ->needs(photos)
      ->group("Photos");
  c->add_option("--photo-noise", ph.noise_sigma,
                "Gaussian noise sigma of the fitting images (linear radiance; white Lambertian at "
                "normal incidence reads 0.8)")
      ->capture_default_str()
      ->needs(photos)
      ->group("Photos");
  c->add_flag("--measured", args->measured,
              "Add a measured paint (bluepaint, Lafortune 1997) outside the fitted one-lobe family "
              "as a 7th material (off by default)")
      ->needs(photos)
      ->group("Photos");
  auto& rt = args->rti_options;
  CLI::Option* rti =
      c->add_flag("--rti", args->rti,
                  "Also render an RTI capture of the painting (orthographic camera straight down, "
                  "image pixel = texel; dirs.lp with the nominal directions; truth normals, "
                  "heights, albedo, lights) into <out>/rti/")
          ->group("RTI");
  c->add_option("--rti-lights", rt.lights, "Directional lights on a dome (count)")
      ->capture_default_str()
      ->needs(rti)
      ->group("RTI");
  c->add_option("--rti-jitter-deg", rt.direction_jitter_deg,
                "Handheld light: true direction off the .lp's by this sigma (degrees)")
      ->capture_default_str()
      ->needs(rti)
      ->group("RTI");
  c->add_option("--rti-intensity-error", rt.intensity_error,
                "Per-image light intensity uniform in 1 +- this (share)")
      ->capture_default_str()
      ->needs(rti)
      ->group("RTI");
  c->add_option("--rti-light-distance-mm", rt.light_distance_mm,
                "Point lights at this distance from the canvas centre (mm; 0 = directional)")
      ->capture_default_str()
      ->needs(rti)
      ->group("RTI");
  c->add_option("--rti-encoding", args->rti_encoding, "Image files: 8-bit sRGB PNG or linear EXR")
      ->check(CLI::IsMember({"srgb8", "exr"}))
      ->capture_default_str()
      ->needs(rti)
      ->group("RTI");
  auto& g = args->grid;
  CLI::Option* patches =
      c->add_option("--patches", args->patches,
                    "Scan the painting as COLUMNSxROWS overlapping patches (e.g. 3x2): "
                    "patch_R_C.exr, patches.json (nominal rig poses, for `digitize preprocess "
                    "--patches`), truth_patches.json (true poses); --scan-size WIDTH is per patch")
          ->group("Patches");
  c->add_option("--patch-overlap", g.overlap, "Share of a patch shared with its neighbour")
      ->capture_default_str()
      ->needs(patches)
      ->group("Patches");
  c->add_option("--drift-mm", g.drift_mm, "True pose off the nominal by up to this (mm)")
      ->capture_default_str()
      ->needs(patches)
      ->group("Patches");
  c->add_option("--drift-deg", g.drift_deg, "True pose tilted off the nominal by up to this (deg)")
      ->capture_default_str()
      ->needs(patches)
      ->group("Patches");
  c->add_option("--tilted-patch", args->tilted_patch,
                "INDEX DEG: that patch (row-major) scanned with DEG more tilt")
      ->expected(2)
      ->needs(patches)
      ->group("Patches");
  c->callback([args, &exit_code] { exit_code = RunSynth(*args); });
}

}  // namespace digitize::cli
