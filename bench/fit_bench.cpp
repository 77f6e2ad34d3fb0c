// End-to-end benchmark of `digitize fit` (docs/benchmarks.md): a synthetic painting of ~1 megatexel
// photographed under 64 point lights (8-bit sRGB PNGs written to disk and read back, as a user has
// them), fitted on its true canvas. Reports, side by side, the time of each part and the
// relighting error on held-out lights and views (PSNR against the noise-free truth renders):
//   - the whole fit: photo decoding + samples + rays + fit + writing the maps, by today's path
//     (camera work and view rays per camera position, rays the horizon bounds prove free not
//     traced) and by the per-photo path before it (share_view_rays = false), in the same run,
//     with whether their maps are bit-identical;
//   - samples with and without skipping the rays that cannot be blocked (ray counts);
//   - fit time per texel, fast path vs ceres::Solve, on the same crop of the canvas (ceres::Solve
//     on the full canvas would take minutes), with the held-out PSNR of each on that crop.
// Writes docs/bench_fit.csv (one row per configuration) for bench/plot_fit.gp.
//
//   fit_bench [--long-side=1155] [--lights=64] [--pixels-per-texel=1.13] [--crop=128]
//             [--csv-dir=docs] [--keep=DIR (new or empty)] [--quick=1]
// --load-only=DIR: only the photo loading of a set kept by --keep (profiling the decoder).
// --quick=1: the whole fit by today's path only (no CSV), for profiling one change.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "bench_support.h"
#include "digitize/photo_set.h"
#include "digitize/reflectance_fit.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/photo_sim.h"
#include "digitize_synth/scan_sim.h"

namespace {

using namespace digitize;
using bench::Arg;
using bench::Clock;
using bench::Since;

struct Row {
  std::string config;
  size_t texels = 0, photos = 0, samples_kept = 0, rays = 0, rays_skipped = 0, rays_traced = 0;
  double seconds_load = 0, seconds_samples = 0, seconds_fit = 0, seconds_write = 0,
         seconds_total = 0;
  double us_per_texel_fit = 0, psnr_db = 0, rmse = 0;
  std::string brief;
};

Row Describe(const std::string& config, const ReflectanceFitResult& r, size_t photos,
             const HeldOutScore& score) {
  Row row;
  row.config = config;
  row.texels = r.report.fit.texels;
  row.photos = photos;
  const SampleStats& s = r.report.samples;
  row.samples_kept = s.kept;
  row.rays = s.view_rays.rays + s.light_rays.rays;
  row.rays_skipped = s.view_rays.skipped + s.light_rays.skipped;
  row.rays_traced = s.view_rays.traced + s.light_rays.traced;
  row.seconds_samples = r.report.seconds_samples;
  row.seconds_fit = r.report.seconds_fit;
  row.seconds_total = r.report.seconds_total;
  row.us_per_texel_fit =
      1e6 * r.report.seconds_fit / static_cast<double>(std::max<size_t>(1, row.texels));
  row.psnr_db = score.psnr_db;
  row.rmse = score.rmse;
  row.brief = r.report.Brief();
  return row;
}

// The crop [x0, x0 + n) x [y0, y0 + n) of a canvas as a canvas of its own: texel centres keep
// their place in space, so canvas_from_scan moves with the crop's origin.
struct Crop {
  HeightField field;
  Grid<Vec3f> normals;
  RigidTransform canvas_from_scan;
};
Crop MakeCrop(const HeightField& f, const Grid<Vec3f>& normals, const RigidTransform& cfs, int x0,
              int y0, int n) {
  Crop c;
  c.field.pitch_mm = f.pitch_mm;
  c.field.height_mm = Grid<float>(n, n);
  c.field.state = Grid<TexelState>(n, n);
  c.normals = Grid<Vec3f>(n, n);
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      c.field.height_mm(x, y) = f.height_mm(x0 + x, y0 + y);
      c.field.state(x, y) = f.state(x0 + x, y0 + y);
      c.normals(x, y) = normals(x0 + x, y0 + y);
    }
  // Crop frame = canvas frame shifted by the crop's lower-left corner.
  const Eigen::Vector2d corner =
      f.TexelCentreMm(x0, y0 + n - 1) - Eigen::Vector2d::Constant(0.5 * f.pitch_mm);
  RigidTransform shift;
  shift.translation = {-corner.x(), -corner.y(), 0.0};
  c.canvas_from_scan = shift * cfs;
  return c;
}

}  // namespace

int main(int argc, char** argv) {
  const int long_side = std::stoi(Arg(argc, argv, "long-side", "1155"));
  const int lights = std::stoi(Arg(argc, argv, "lights", "64"));
  const int crop_n = std::stoi(Arg(argc, argv, "crop", "128"));
  const double ppt = std::stod(Arg(argc, argv, "pixels-per-texel", "1.13"));
  const std::filesystem::path csv_dir = Arg(argc, argv, "csv-dir", "");
  const std::string csv_name = Arg(argc, argv, "csv-name", "bench_fit.csv");
  const std::string keep = Arg(argc, argv, "keep", "");
  const bool quick = Arg(argc, argv, "quick", "0") != "0";
  if (const std::string only = Arg(argc, argv, "load-only", ""); !only.empty()) {
    for (int run = 0; run < 3; ++run) {
      const auto t = Clock::now();
      auto set = ReadCalibration(std::filesystem::path(only) / "calib.json");
      if (!set.ok()) {
        std::fprintf(stderr, "%s\n", set.error().message.c_str());
        return 1;
      }
      std::printf("load %zu photos: %.2f s\n", set->photos.size(), Since(t));
    }
    return 0;
  }

  // --keep names a user's folder: written into only when new or empty, never cleared (checked
  // before the render). The default is this bench's own scratch folder, cleared from a last run.
  if (std::error_code ec;
      !keep.empty() && std::filesystem::exists(keep, ec) && !std::filesystem::is_empty(keep, ec)) {
    std::fprintf(stderr, "fit_bench: --keep=%s exists and is not empty; give a new folder\n",
                 keep.c_str());
    return 2;
  }
  const bench::Photographed photographed = bench::PhotographPainting(long_side, lights, ppt);
  const synth::Painting& painting = photographed.painting;
  const synth::SyntheticPhotoSet& truth = photographed.photos;
  const synth::PhotoSimOptions& so = photographed.options;
  const double seconds_render = photographed.seconds_render;
  const size_t texels = painting.truth.height_mm.size();
  std::printf("painting %dx%d = %.2f M texels, %zu photos %dx%d (%s), rendered in %.1f s\n",
              painting.truth.width(), painting.truth.height(), texels / 1e6,
              truth.fit.photos.size(), truth.fit.photos[0].camera.width,
              truth.fit.photos[0].camera.height, synth::ToString(so.encoding), seconds_render);

  // The photos as a user has them: files on disk, decoded by the fit.
  const std::filesystem::path dir =
      keep.empty() ? std::filesystem::temp_directory_path() / "digitize_fit_bench"
                   : std::filesystem::path(keep);
  if (keep.empty()) std::filesystem::remove_all(dir);
  if (Status s = synth::WriteSyntheticPhotoSet(dir, truth); !s.ok()) {
    std::fprintf(stderr, "%s\n", s.message().c_str());
    return 1;
  }
  std::vector<Row> rows;
  const HeightField& canvas = painting.truth;
  const Grid<Vec3f>& normals = painting.normals;

  // 1. The whole fit, as `digitize fit` runs it.
  auto t0 = Clock::now();
  auto set = ReadCalibration(dir / "calib.json");
  if (!set.ok()) {
    std::fprintf(stderr, "%s\n", set.error().message.c_str());
    return 1;
  }
  const double seconds_load = Since(t0);
  ReflectanceFitOptions options;
  options.fit.noise_sigma = so.noise_sigma;
  const std::clock_t cpu0 = std::clock();
  auto fast = FitReflectance(canvas, normals, {}, *set, options);
  if (!fast.ok()) return 1;
  const double cpu_fit = static_cast<double>(std::clock() - cpu0) / CLOCKS_PER_SEC;
  t0 = Clock::now();
  (void)WriteReflectanceOutputs(dir / "fit", *fast, options, {"bench"});
  const double seconds_write = Since(t0);
  auto score =
      EvaluateHeldOut(canvas, normals, fast->maps, {}, truth.held_out, truth.held_out_mask);
  Row whole = Describe("whole fit: fast, skip", *fast, set->photos.size(), *score);
  whole.seconds_load = seconds_load;
  whole.seconds_write = seconds_write;
  whole.seconds_total = seconds_load + fast->report.seconds_total + seconds_write;
  rows.push_back(whole);
  if (quick) {
    std::printf(
        "whole fit: load %.2f s, samples %.2f s, fit %.2f s, write %.2f s, total %.2f s; "
        "held-out PSNR %.4f dB\nsamples + fit: %.2f s wall, %.2f s CPU (%.2f cores busy); "
        "%zu dark outliers, %zu texels refitted\n%s\n",
        whole.seconds_load, whole.seconds_samples, whole.seconds_fit, whole.seconds_write,
        whole.seconds_total, whole.psnr_db, fast->report.seconds_total, cpu_fit,
        cpu_fit / fast->report.seconds_total, fast->report.dark_outliers,
        fast->report.texels_refitted, whole.brief.c_str());
    if (keep.empty()) std::filesystem::remove_all(dir);
    return 0;
  }
  // 1b. The per-photo path (before issue 14 part 5): same photos, same writing cost.
  ReflectanceFitOptions per_photo = options;
  per_photo.samples.share_view_rays = false;
  auto before = FitReflectance(canvas, normals, {}, *set, per_photo);
  if (!before.ok()) return 1;
  Row old = Describe(
      "whole fit: per-photo path", *before, set->photos.size(),
      *EvaluateHeldOut(canvas, normals, before->maps, {}, truth.held_out, truth.held_out_mask));
  old.seconds_load = seconds_load;
  old.seconds_write = seconds_write;
  old.seconds_total = seconds_load + before->report.seconds_total + seconds_write;
  rows.push_back(old);
  const auto same = [](const auto& a, const auto& b) {
    return a.data.size() == b.data.size() &&
           std::memcmp(a.data.data(), b.data.data(), a.data.size() * sizeof(a.data[0])) == 0;
  };
  const ReflectanceMaps &mn = fast->maps, &mo = before->maps;
  const bool identical = same(mn.rho_d, mo.rho_d) && same(mn.rho_s, mo.rho_s) &&
                         same(mn.lobe, mo.lobe) && same(mn.fit_error, mo.fit_error) &&
                         same(mn.status, mo.status) && same(mn.model, mo.model);

  // 2. The same without skipping rays.
  ReflectanceFitOptions no_skip = options;
  no_skip.samples.trace.skip_unblockable = false;
  auto traced = FitReflectance(canvas, normals, {}, *set, no_skip);
  rows.push_back(Describe(
      "fast, no skip", *traced, set->photos.size(),
      *EvaluateHeldOut(canvas, normals, traced->maps, {}, truth.held_out, truth.held_out_mask)));
  // 3. No shadow or visibility rays at all: what the rays buy in accuracy.
  ReflectanceFitOptions no_rays = options;
  no_rays.samples.shadow_rays = no_rays.samples.visibility_rays = false;
  auto blind = FitReflectance(canvas, normals, {}, *set, no_rays);
  rows.push_back(Describe(
      "fast, no rays", *blind, set->photos.size(),
      *EvaluateHeldOut(canvas, normals, blind->maps, {}, truth.held_out, truth.held_out_mask)));

  // 4. Fast vs ceres::Solve on a crop (held-out PSNR on the crop's pixels).
  const int n = std::min({crop_n, canvas.width(), canvas.height()});
  const Crop crop = MakeCrop(canvas, normals, RigidTransform{}, (canvas.width() - n) / 2,
                             (canvas.height() - n) / 2, n);
  for (const auto& [name, method] :
       {std::pair{"crop: fast", BrdfFitMethod::kFast},
        std::pair{"crop: ceres::Solve", BrdfFitMethod::kCeresReference}}) {
    ReflectanceFitOptions o = options;
    o.fit.method = method;
    auto r = FitReflectance(crop.field, crop.normals, crop.canvas_from_scan, *set, o);
    auto s = EvaluateHeldOut(crop.field, crop.normals, r->maps, crop.canvas_from_scan,
                             truth.held_out, truth.held_out_mask);
    rows.push_back(Describe(name, *r, set->photos.size(), *s));
  }

  std::printf("\n%-26s %9s %8s %8s %8s %8s %8s %8s %10s %8s %8s\n", "config", "texels", "load s",
              "samp. s", "fit s", "total s", "us/texel", "rays M", "skipped %", "PSNR dB", "RMSE");
  for (const Row& r : rows)
    std::printf("%-26s %9zu %8.2f %8.2f %8.2f %8.2f %8.2f %8.1f %10.1f %8.2f %8.4f\n",
                r.config.c_str(), r.texels, r.seconds_load, r.seconds_samples, r.seconds_fit,
                r.seconds_total, r.us_per_texel_fit, r.rays / 1e6,
                r.rays ? 100.0 * r.rays_skipped / r.rays : 0.0, r.psnr_db, r.rmse);
  const Row& f = rows[4];
  const Row& c = rows[5];
  std::printf(
      "\nfast vs ceres::Solve on the crop: %.1fx faster per texel (%.2f vs %.2f us), PSNR "
      "%.2f vs %.2f dB\n",
      c.us_per_texel_fit / f.us_per_texel_fit, f.us_per_texel_fit, c.us_per_texel_fit, f.psnr_db,
      c.psnr_db);
  std::printf(
      "shared views + horizons vs the per-photo path: samples %.2f s vs %.2f s (%.2fx), fit %.2f "
      "vs %.2f s, total %.2f vs %.2f s (%.2fx); PSNR %.4f vs %.4f dB; maps %s\n",
      rows[0].seconds_samples, rows[1].seconds_samples,
      rows[1].seconds_samples / rows[0].seconds_samples, rows[0].seconds_fit, rows[1].seconds_fit,
      rows[0].seconds_total, rows[1].seconds_total, rows[1].seconds_total / rows[0].seconds_total,
      rows[0].psnr_db, rows[1].psnr_db, identical ? "bit-identical" : "DIFFER");
  std::printf("ray skipping: samples %.2f s vs %.2f s without (%.1fx)\n", rows[0].seconds_samples,
              rows[2].seconds_samples, rows[2].seconds_samples / rows[0].seconds_samples);
  std::printf("whole fit: %s\n", rows[0].brief.c_str());

  if (!csv_dir.empty()) {
    std::ofstream csv(csv_dir / csv_name);
    csv << "config,texels,photos,samples_kept,rays,rays_skipped,rays_traced,seconds_load,"
           "seconds_samples,seconds_fit,seconds_write,seconds_total,us_per_texel_fit,psnr_db,"
           "rmse\n";
    for (const Row& r : rows)
      csv << '"' << r.config << "\"," << r.texels << "," << r.photos << "," << r.samples_kept << ","
          << r.rays << "," << r.rays_skipped << "," << r.rays_traced << "," << r.seconds_load << ","
          << r.seconds_samples << "," << r.seconds_fit << "," << r.seconds_write << ","
          << r.seconds_total << "," << r.us_per_texel_fit << "," << r.psnr_db << "," << r.rmse
          << "\n";
    std::printf("wrote %s\n", (csv_dir / csv_name).c_str());
  }
  if (keep.empty()) std::filesystem::remove_all(dir);
  return 0;
}
