// What the `digitize` commands share: flags several of them take, and how results and failures
// are printed (commands.h). No command file depends on another.
#include <cstdio>

#include "commands.h"
#include "digitize/image_io.h"
#include "digitize/pack_tiled.h"

namespace digitize::cli {

int Fail(const std::string& command, const std::string& message) {
  std::fprintf(stderr, "digitize %s: error: %s\n", command.c_str(), message.c_str());
  return 1;
}

void Warn(const std::string& command, const std::string& message) {
  std::fprintf(stderr, "digitize %s: warning: %s\n", command.c_str(), message.c_str());
}

void PrintRtiPitch(const std::string& command, const PhotoSet& set) {
  if (!set.is_rti) return;
  if (set.rti_pitch_assumed)
    std::fprintf(stderr, "digitize %s: warning: RTI pixel pitch %g mm %s; give --rti-pitch-mm\n",
                 command.c_str(), set.rti_pitch_mm, set.rti_pitch_source.c_str());
  else
    std::printf("RTI pixel pitch: %g mm, %s\n", set.rti_pitch_mm, set.rti_pitch_source.c_str());
}

void PrintPackSummaryLine(const std::string& path, const PackSummary& s) {
  std::printf("%s: %dx%d texels (%.1f x %.1f mm), %zu boxes, %s, %.2f bytes/texel (%llu bytes)\n",
              EscapeForTerminal(path).c_str(), s.width, s.height, s.width * s.pitch_mm,
              s.height * s.pitch_mm, s.box_count, ToString(s.encoding), s.BytesPerTexel(),
              static_cast<unsigned long long>(s.file_bytes));
}

void AddPackWriteFlags(CLI::App* c, PackWriteOptions& o, bool& quantised) {
  c->add_flag("--quantised", quantised,
              "Drop low mantissa bits per channel group (smaller; stated error, docs/formats.md)")
      ->group("Pack");
  c->add_option("--height-bits", o.quantisation.height_bits,
                "Quantised: mantissa bits of height (0-10)")
      ->capture_default_str()
      ->group("Pack");
  c->add_option("--normal-bits", o.quantisation.normal_bits, "Quantised: mantissa bits of nx, ny")
      ->capture_default_str()
      ->group("Pack");
  c->add_option("--rho-bits", o.quantisation.rho_bits, "Quantised: mantissa bits of rho_d, rho_s")
      ->capture_default_str()
      ->group("Pack");
  c->add_option("--lobe-bits", o.quantisation.lobe_bits, "Quantised: mantissa bits of cx, cy, k")
      ->capture_default_str()
      ->group("Pack");
  c->add_option("--pack-tile-size", o.tile_size,
                "Write a tiled, multi-resolution pack (version 3): N x N tiles, every level "
                "prefiltered down to 1 x 1, streamed with bounded memory (N a power of two in "
                "64-4096; 256 suits a streaming viewer). 0: one grid (version 2)")
      ->capture_default_str()
      ->check([](const std::string& text) -> std::string {
        const int n = std::atoi(text.c_str());
        if (n == 0) return {};
        const Status s = CheckPackTileSize(n);
        return s.ok() ? std::string() : s.message();
      })
      ->group("Pack");
}

void AddPhotoSetFlags(CLI::App* c, PhotoSetOptions& o) {
  c->add_option("--rti-pitch-mm", o.rti_pixel_pitch_mm,
                "RTI captures: canvas mm per image pixel (default: the images' resolution tag, "
                "else 1 mm with a warning)")
      ->group("Photos");
  c->add_flag("--allow-outside-paths", o.allow_outside_paths,
              "Read images the calibration / .lp names outside its folder (.., absolute paths, "
              "symbolic links); refused by default: a shared capture must not open other files")
      ->group("Photos");
}

CLI::Option* AddFitFlags(CLI::App* c, ReflectanceFitOptions& o, PhotoSetOptions& photo) {
  c->add_option("--noise-sigma", o.fit.noise_sigma,
                "Radiance noise per channel (linear units, 1 = white): diffuse-only test, outliers")
      ->capture_default_str()
      ->group("Fit");
  c->add_option("--min-samples", o.fit.min_samples,
                "Usable samples a texel needs for a lobe fit (fewer: diffuse-only fallback)")
      ->capture_default_str()
      ->group("Fit");
  c->add_option("--k-max", o.fit.k_max, "Largest lobe exponent k")
      ->capture_default_str()
      ->group("Fit");
  c->add_option(
       "--max-specular-albedo", o.fit.max_specular_albedo,
       "Energy bound of the lobe: rho_s 2 pi / (k + 2) <= this (raise for uncalibrated lights)")
      ->capture_default_str()
      ->group("Fit");
  CLI::Option* dark_ratio =
      c->add_option("--dark-outlier-ratio", o.dark_outlier_ratio,
                    "Samples below this share of the diffuse floor are unmodelled shadows (<= 0: "
                    "keep all; RTI captures: off unless given)")
          ->capture_default_str()
          ->group("Fit");
  c->add_option("--min-cos", o.samples.min_cos,
                "n.v and n.l must exceed this (0 = anything above the horizon)")
      ->capture_default_str()
      ->group("Samples");
  c->add_flag("!--no-shadow-rays", o.samples.shadow_rays,
              "Do not reject samples whose light the relief blocks")
      ->group("Samples");
  c->add_flag("!--no-visibility-rays", o.samples.visibility_rays,
              "Do not reject samples whose texel the relief hides from the camera")
      ->group("Samples");
  c->add_flag("!--no-skip", o.samples.trace.skip_unblockable,
              "Trace every ray (no skipping of rays that cannot be blocked; for comparison)")
      ->group("Samples");
  c->add_option("--saturation", photo.saturation_encoded,
                "Encoded level (0..1) at or above which an 8/16-bit channel is saturated")
      ->capture_default_str()
      ->group("Photos");
  c->add_option("--tile-texels", o.tile_texels,
                "Texels sampled and fitted at a time (memory: ~ tile x photos x 48 bytes)")
      ->capture_default_str()
      ->group("Performance");
  return dark_ratio;
}

void PrintPhotoCheck(const std::string& command, const std::optional<PhotoResidualReport>& check) {
  if (!check) return;
  for (const std::string& w : check->Warnings()) Warn(command, w);
  std::printf("photo check: %s\n", check->Brief().c_str());
}

void AddPhotoCheckAndRelitFlags(CLI::App* c, bool& check_photos, std::string& held_out_out) {
  c->add_flag("--no-photo-check{false}", check_photos,
              "Skip the check after the fit that warns of photos brighter/darker than the fit or "
              "shifted from it (wrong light intensity, misregistered camera)");
  c->add_option("--held-out-out", held_out_out,
                "Folder for the relit held-out photos (same file-name stems; sRGB PNG for sRGB "
                "photos, linear EXR for linear ones)")
      ->transform(FolderPath());
}

void AddRtiCanvasFlags(CLI::App* c, RtiCanvasOptions& o) {
  c->add_flag("--rti-flat{false}", o.normals,
              "RTI captures: fit on the flat canvas with normals straight up (no photometric "
              "stereo, no height; the paper's RTI path)")
      ->group("RTI");
  c->add_flag("--rti-no-height{false}", o.height,
              "RTI captures: keep the photometric-stereo normals but no height field (no relief, "
              "no cast shadows)")
      ->group("RTI");
  c->add_flag("--rti-no-intensities{false}", o.stereo.estimate_intensities,
              "RTI captures: take every light at the same intensity instead of estimating each "
              "image's from the capture (for calibrated domes)")
      ->group("RTI");
}

ScanReadOptions ScanReadOptionsOf(ScanReadOptions read, const std::string& mask,
                                  const std::vector<int>& grid) {
  read.mask = mask;
  if (grid.size() == 2) {
    read.grid_width = grid[0];
    read.grid_height = grid[1];
  }
  return read;
}

void SetFitMethod(ReflectanceFitOptions& options, const std::string& method, int threads) {
  options.fit.method = method == "ceres" ? BrdfFitMethod::kCeresReference : BrdfFitMethod::kFast;
  options.fit.num_threads = threads;
  options.samples.trace.num_threads = threads;
}

void AddPreprocessFlags(CLI::App* c, PreprocessOptions& o) {
  c->add_option("--spike-mm", o.sanitize.spike_mm,
                "A sample farther than this (mm) from all its neighbours is an outlier")
      ->capture_default_str()
      ->group("Clean-up");
  c->add_option("--max-coordinate-mm", o.sanitize.max_abs_coordinate_mm,
                "Coordinates beyond this (mm) are sensor garbage")
      ->capture_default_str()
      ->group("Clean-up");
  c->add_option("--disagree-mm", o.merge.disagree_mm,
                "Exposures differing by more than this (mm) at a pixel are counted as disagreeing")
      ->capture_default_str()
      ->group("Clean-up");
  c->add_option("--stop-gradient-mm", o.canvas.stop_gradient_mm,
                "Sobel magnitude (mm of height per pixel) that stops the canvas region growing")
      ->capture_default_str()
      ->group("Canvas");
  c->add_option(
       "--stop-slope", o.canvas.stop_slope,
       "Surface slope (height / in-plane distance) that also stops the growing: frame walls")
      ->capture_default_str()
      ->group("Canvas");
  c->add_option("--refine-step-mm", o.canvas.refine_step_mm,
                "Height step (mm) the canvas boundary refinement will not cross")
      ->capture_default_str()
      ->group("Canvas");
  c->add_option("--refine-px", o.canvas.refine_px,
                "How far (pixels) the boundary refinement may reach")
      ->capture_default_str()
      ->group("Canvas");
  c->add_option("--erode-px", o.canvas.erode_px, "Erosion (pixels) before the second plane fit")
      ->capture_default_str()
      ->group("Canvas");
  c->add_option("--trim-sigmas", o.canvas.trim_sigmas,
                "Robust plane fit: points this many MADs above the plane are relief, left out")
      ->capture_default_str()
      ->group("Canvas");
  c->add_option("--seed-x", o.canvas.seed_x,
                "Region-growing seed column (pixels; -1 = scan centre)")
      ->capture_default_str()
      ->group("Canvas");
  c->add_option("--seed-y", o.canvas.seed_y, "Region-growing seed row (pixels; -1 = scan centre)")
      ->capture_default_str()
      ->group("Canvas");
  c->add_option("--pitch-mm", o.resample.pitch_mm,
                "Output texel spacing (mm); 0 = the scan's median sample spacing")
      ->capture_default_str()
      ->group("Resampling");
  c->add_option("--max-hole-area-mm2", o.resample.max_hole_area_mm2,
                "Holes up to this area (mm^2) are filled; larger ones are marked unfilled")
      ->capture_default_str()
      ->group("Resampling");
  c->add_option("--max-edge-factor", o.resample.max_edge_factor,
                "Scan triangles with an edge longer than this many pitches are not interpolated")
      ->capture_default_str()
      ->group("Resampling");
  c->add_option("--delta0", o.relief.delta0_fraction,
                "Bump-plane height as a fraction of the max canvas height (0..1)")
      ->capture_default_str()
      ->group("Relief");
  c->add_option("--min-area-mm2", o.relief.min_component_area_mm2,
                "Relief components smaller than this (mm^2) are removed as specks")
      ->capture_default_str()
      ->group("Relief");
  c->add_option("--cell-px", o.relief.cell_px, "Box cell size n (texels): n x n cells become boxes")
      ->capture_default_str()
      ->group("Relief");
  c->add_option("--cover-px", o.relief.cover_px,
                "Boxes cover the relief grown by this many texels (0 = exactly the relief)")
      ->capture_default_str()
      ->group("Relief");
  c->add_option(
       "--min-relief-mm", o.relief.min_relief_mm,
       "A canvas whose highest point is not above this (mm; at least 8 sigma of the noise) "
       "has no relief boxes")
      ->capture_default_str()
      ->group("Relief");
  c->add_flag("!--no-noise-margin", o.noise_margin_from_scan,
              "Classify relief exactly at delta0 instead of delta0 - 2 sigma(noise)")
      ->group("Relief");
}

}  // namespace digitize::cli
