#include "digitize/reflectance_fit.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <set>

#include "digitize/image_io.h"
#include "digitize/relight.h"
#include "options_json.h"
#include "select_kth.h"

namespace digitize {
namespace {

using Clock = std::chrono::steady_clock;
double Since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// Texels per task of the fit loop: large enough to amortise a fitter's scratch, small enough to
// balance (as FitBrdf's).
constexpr size_t kFitGrain = 64;

std::string Format(const char* fmt, auto... args) {
  char buffer[512];
  std::snprintf(buffer, sizeof(buffer), fmt, args...);
  return buffer;
}

// The samples of `in` far below the diffuse floor `floor_of` gives each (see the header) are
// left out: when there are any, `out` gets the others. Returns how many. Counted first, so the
// common texel with none is not copied.
template <typename FloorOf>
size_t LeaveOutDark(std::span<const BrdfSample> in, double ratio, double min_gap,
                    const FloorOf& floor_of, std::vector<BrdfSample>& out) {
  const auto dark = [&](const BrdfSample& s) {
    const double floor = floor_of(s);
    const double seen = s.radiance.sum();
    return seen < ratio * floor && floor - seen > min_gap;
  };
  size_t n = 0;
  for (const BrdfSample& s : in) n += dark(s);
  if (n == 0) return 0;
  out.clear();
  for (const BrdfSample& s : in)
    if (!dark(s)) out.push_back(s);
  return n;
}

// After a fit: the samples far below the fitted diffuse floor E rho_d of `params`.
size_t RemoveDarkOutliers(std::span<const BrdfSample> in, const LafortuneParams& params,
                          const ReflectanceFitOptions& o, std::vector<BrdfSample>& out) {
  const double min_gap = o.dark_outlier_sigmas * o.fit.noise_sigma * std::sqrt(3.0);
  return LeaveOutDark(
      in, o.dark_outlier_fit_ratio, min_gap,
      [&](const BrdfSample& s) -> double { return s.irradiance.cwiseProduct(params.rho_d).sum(); },
      out);
}

// Before any fit: the diffuse floor of a texel is estimated as the median apparent reflectance
// q = sum_c radiance / sum_c E over its samples (the lobe only raises q, and a shadow drops it to
// ~0, so the median sits at or a little above rho_d whenever most samples are lit). Samples far
// below that floor are left out (LeaveOutDark); `q` is scratch.
size_t PrefilterDarkOutliers(std::span<const BrdfSample> in, const ReflectanceFitOptions& o,
                             std::vector<double>& q, std::vector<BrdfSample>& out) {
  const double min_gap = o.dark_outlier_sigmas * o.fit.noise_sigma * std::sqrt(3.0);
  const size_t n = in.size();
  q.resize(3 * n);
  size_t m = 0;
  for (const BrdfSample& s : in) {
    const double irradiance = s.irradiance.sum();
    if (irradiance > 0) q[m++] = s.radiance.sum() / irradiance;
  }
  const double floor_q = m >= 3 ? SelectKth(q.data(), q.data() + n, q.data() + 2 * n, m, m / 2) : 0;
  return LeaveOutDark(
      in, o.dark_outlier_ratio, min_gap,
      [&](const BrdfSample& s) { return floor_q * s.irradiance.sum(); }, out);
}

// Which photos can give samples at all, and how many distinct (light, view) pairs they hold (see
// the header). Judged at the canvas centre: lights and cameras are far from the canvas compared
// with its relief, and the count only has to tell one pair from several.
void CountPhotoDirections(const PhotoSet& set, const HeightField& canvas,
                          const RigidTransform& canvas_from_scan, ReflectanceFitReport& report) {
  const RigidTransform scan_from_canvas = canvas_from_scan.Inverse();
  const Vec3d centre =
      scan_from_canvas.Apply(Vec3d(canvas.extent_mm().x() / 2, canvas.extent_mm().y() / 2, 0));
  const double same = std::cos(kSameDirectionDeg * M_PI / 180.0);
  std::vector<std::pair<Vec3d, Vec3d>> distinct;  // (light, view), canvas frame
  report.photos = set.photos.size();
  for (const Photo& photo : set.photos) {
    const Light& light = photo.light;
    const bool below = light.type == LightType::kPoint
                           ? canvas_from_scan.Apply(light.position_mm).z() <= 0
                           : canvas_from_scan.ApplyToDirection(light.direction).z() <= 0;
    if (below) {
      report.light_below_canvas.push_back(photo.entry);
      continue;
    }
    const Vec3d l = canvas_from_scan.ApplyToDirection(light.DirectionTo(centre));
    const Vec3d v = canvas_from_scan.ApplyToDirection(photo.camera.DirectionToCamera(centre));
    const bool seen = std::any_of(distinct.begin(), distinct.end(), [&](const auto& d) {
      return d.first.dot(l) >= same && d.second.dot(v) >= same;
    });
    if (!seen) distinct.emplace_back(l, v);
  }
  report.distinct_directions = static_cast<int>(distinct.size());
}

}  // namespace

std::vector<std::string> ReflectanceFitReport::Warnings() const {
  std::vector<std::string> out;
  if (!light_below_canvas.empty()) {
    std::string list;
    for (size_t i = 0; i < light_below_canvas.size() && i < 3; ++i)
      list += (i ? "; " : "") + light_below_canvas[i];
    if (light_below_canvas.size() > 3) list += "; ...";
    out.push_back(std::to_string(light_below_canvas.size()) + " of " + std::to_string(photos) +
                  " photos have their light at or below the canvas plane, so they add no sample (" +
                  list + ")");
  }
  return out;
}

Status ReflectanceFitOptions::Validate() const {
  if (Status s = samples.Validate(); !s.ok()) return Error{"samples: " + s.message()};
  if (Status s = fit.Validate(); !s.ok()) return Error{"fit: " + s.message()};
  if (tile_texels < 1 || tile_texels > (1 << 24))
    return Error{"tile_texels must be in [1, 16777216], got " + std::to_string(tile_texels)};
  if (!std::isfinite(dark_outlier_ratio) || dark_outlier_ratio >= 1)
    return Error{"dark_outlier_ratio must be < 1 (<= 0 disables), got " +
                 FormatNumber(dark_outlier_ratio)};
  if (!(std::isfinite(dark_outlier_sigmas) && dark_outlier_sigmas >= 0))
    return Error{"dark_outlier_sigmas must be >= 0, got " + FormatNumber(dark_outlier_sigmas)};
  if (!(std::isfinite(dark_outlier_fit_ratio) && dark_outlier_fit_ratio >= 0 &&
        dark_outlier_fit_ratio < 1))
    return Error{"dark_outlier_fit_ratio must be in [0, 1), got " +
                 FormatNumber(dark_outlier_fit_ratio)};
  if (!(std::isfinite(jpeg_sigma_codes) && jpeg_sigma_codes >= 0))
    return Error{"jpeg_sigma_codes must be finite and >= 0 (codes), got " +
                 FormatNumber(jpeg_sigma_codes)};
  if (dark_outlier_rounds < 0 || dark_outlier_rounds > 10)
    return Error{"dark_outlier_rounds must be in [0, 10], got " +
                 std::to_string(dark_outlier_rounds)};
  return Status::Ok();
}

std::string ReflectanceFitReport::Brief() const {
  const double mtexels = static_cast<double>(fit.texels) / 1e6;
  std::string photos;
  if (samples.texels > 0) photos = Format(" x %zu photos", samples.candidates / samples.texels);
  BrdfFitSummary s = fit;
  s.seconds = seconds_total;
  return Format("%.3g M texels%s: ", mtexels, photos.c_str()) + s.BriefReport() +
         Format(" (samples %.2f s, fit %.2f s)", seconds_samples, seconds_fit);
}

namespace {

// Whether every probed channel of `photo` decodes from a code of 0..code_max.
bool OnCodes(const Photo& photo, int code_max) {
  const bool srgb = photo.encoding == ColourEncoding::kSrgb;
  const size_t n = photo.rgb.size();
  const size_t stride = std::max<size_t>(1, n / 2048);
  for (size_t i = 0; i < n; i += stride) {
    for (int c = 0; c < 3; ++c) {
      const double v = std::clamp(static_cast<double>(photo.rgb.data[i][c]), 0.0, 1.0);
      const double encoded = !srgb            ? v
                             : v <= 0.0031308 ? 12.92 * v
                                              : 1.055 * std::pow(v, 1.0 / 2.4) - 0.055;
      const float code = static_cast<float>(std::round(encoded * code_max) / code_max);
      const float decoded = srgb ? SrgbToLinear(code) : code;
      if (std::abs(decoded - photo.rgb.data[i][c]) > 1e-6f + 1e-5f * std::abs(decoded))
        return false;
    }
  }
  return true;
}

}  // namespace

PhotoQuantisation DetectPhotoQuantisation(const PhotoSet& photos) {
  PhotoQuantisation q;
  bool any16 = false, any8 = false, srgb8 = true, srgb16 = true;
  for (const Photo& p : photos.photos) {
    if (!p.loaded()) continue;
    std::string ext = p.path.extension().string();
    for (char& ch : ext) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    if (ext == ".jpg" || ext == ".jpeg") q.lossy = true;
    const bool srgb = p.encoding == ColourEncoding::kSrgb;
    if (OnCodes(p, 255)) {
      any8 = true;
      srgb8 = srgb8 && srgb;
    } else if (OnCodes(p, 65535)) {
      any16 = true;
      srgb16 = srgb16 && srgb;
    }
  }
  if (any8) {
    q.code_max = 255;
    q.srgb = srgb8;
  } else if (any16) {
    q.code_max = 65535;
    q.srgb = srgb16;
  }
  return q;
}

namespace {

// Samples and fits the texels of `region` into `result` (maps of the region's size); `report`
// already holds the photo set's part.
Status FitRegion(const SampleScene& scene, const ReflectanceFitOptions& options,
                 const BrdfFitOptions& fit_options, const TexelRect& region,
                 ReflectanceFitResult& result, SampleBuffers& buffers,
                 const std::function<void(size_t)>& fitted_texels) {
  const HeightField& canvas = *scene.canvas;
  ReflectanceFitReport& report = result.report;
  std::vector<uint32_t> texels;
  texels.reserve(region.texels());
  for (int y = region.y; y < region.y + region.height; ++y) {
    for (int x = region.x; x < region.x + region.width; ++x) {
      if (canvas.state(x, y) == TexelState::kOutside)
        ++report.texels_outside;
      else
        texels.push_back(static_cast<uint32_t>(y) * static_cast<uint32_t>(canvas.width()) +
                         static_cast<uint32_t>(x));
    }
  }

  ReflectanceMaps& maps = result.maps;
  maps = ReflectanceMaps::Zeros(region.width, region.height);
  BrdfFitSummary& summary = report.fit;
  summary.method = options.fit.method;
  double rms_sum = 0, iteration_sum = 0;
  size_t lobe_texels = 0;
  const size_t tile = static_cast<size_t>(options.tile_texels);
  tbb::task_arena arena(fit_options.num_threads > 0 ? fit_options.num_threads
                                                    : tbb::task_arena::automatic);
  for (size_t begin = 0; begin < texels.size(); begin += tile) {
    const std::span<const uint32_t> part(texels.data() + begin,
                                         std::min(tile, texels.size() - begin));
    auto t0 = Clock::now();
    GatherSampleSlots(scene, part, options.samples, report.samples, true, buffers);
    report.seconds_samples += Since(t0);

    // Each texel's samples are taken from the photo-major slots once, in the fit's own parallel
    // loop: filtered on the way in (PrefilterDarkOutliers), fitted, and refitted without the
    // samples its fit shows dark (RemoveDarkOutliers). As separate passes over the tile's samples
    // (a texel-major copy, filter, fit, refit) they were a fifth of samples + fit, the serial
    // filter most of it.
    t0 = Clock::now();
    std::vector<TexelFit> fit(part.size());
    std::vector<size_t> removed(part.size(), 0), given(part.size(), 0);
    const auto fit_block = [&](const tbb::blocked_range<size_t>& r) {
      BrdfTexelFitter fitter(fit_options);
      BrdfSamples gathered;
      buffers.AppendTexels(r.begin(), r.size(), gathered);
      std::vector<BrdfSample> kept, current;
      std::vector<double> q;
      for (size_t t = r.begin(); t != r.end(); ++t) {
        std::span<const BrdfSample> in = gathered.Texel(t - r.begin());
        if (options.dark_outlier_ratio > 0)
          if (const size_t n = PrefilterDarkOutliers(in, options, q, current); n > 0) {
            removed[t] += n;
            in = current;
          }
        given[t] = in.size();
        fit[t] = fitter.Fit(in);
        if (!(options.dark_outlier_ratio > 0)) continue;
        for (int round = 0; round < options.dark_outlier_rounds; ++round) {
          const size_t n = RemoveDarkOutliers(in, fit[t].params, options, kept);
          if (n == 0) break;
          removed[t] += n;
          current.swap(kept);
          in = current;
          fit[t] = fitter.Fit(in);
        }
      }
    };
    arena.execute([&] {
      tbb::parallel_for(tbb::blocked_range<size_t>(0, part.size(), kFitGrain), fit_block);
    });
    report.seconds_fit += Since(t0);

    for (size_t t = 0; t < part.size(); ++t) {
      const int x = static_cast<int>(part[t] % static_cast<uint32_t>(canvas.width())) - region.x;
      const int y = static_cast<int>(part[t] / static_cast<uint32_t>(canvas.width())) - region.y;
      const TexelFit& f = fit[t];
      if (f.model == ReflectanceModel::kGgx)
        maps.SetGgx(x, y, f.ggx);
      else
        maps.Set(x, y, f.params);
      maps.status(x, y) = f.status;
      if (f.status != TexelFitStatus::kDiffuseOnly && f.status != TexelFitStatus::kTooFewSamples &&
          f.status != TexelFitStatus::kFailed)
        ++summary.lobes_by_model[static_cast<size_t>(f.model)];
      maps.fit_error(x, y) = f.rms_error;
      ++summary.count_by_status[static_cast<size_t>(f.status)];
      rms_sum += f.rms_error;
      summary.samples_total += given[t];
      summary.samples_used += static_cast<size_t>(f.samples_used);
      summary.samples_saturated += static_cast<size_t>(f.samples_saturated);
      if (f.iterations > 0) {
        iteration_sum += f.iterations;
        ++lobe_texels;
      }
      if (removed[t] > 0) {
        report.dark_outliers += removed[t];
        ++report.texels_refitted;
      }
    }
    summary.texels += part.size();
    fitted_texels(part.size());
  }
  summary.mean_rms_error = summary.texels ? rms_sum / static_cast<double>(summary.texels) : 0.0;
  summary.mean_iterations = lobe_texels ? iteration_sum / static_cast<double>(lobe_texels) : 0.0;
  summary.seconds = report.seconds_fit;
  // Texels with no photo at all never reached FitBrdf's own check: check the whole maps once.
  const Status valid = maps.Validate();
  DIGITIZE_CHECK(valid.ok(), "FitReflectance produced invalid maps: " + valid.message());
  return Status::Ok();
}

}  // namespace

Status FitReflectanceRegions(const HeightField& canvas, const Grid<Vec3f>& normals,
                             const RigidTransform& canvas_from_scan, const PhotoSet& photos,
                             const ReflectanceFitOptions& options,
                             std::span<const TexelRect> regions, const RegionFitted& done,
                             const ProgressCallback& progress, const PhotoSet* whole_set) {
  auto start = Clock::now();
  if (Status s = options.Validate(); !s.ok()) return Error{"fit options: " + s.message()};
  ReportProgress(progress, "fit", 0.0);
  auto t0 = Clock::now();
  auto built = HeightFieldTracer::Build(canvas);
  if (!built.ok()) return Error{"canvas: " + built.error().message};
  const HeightFieldTracer& tracer = *built;
  size_t all_texels = 0;
  for (size_t r = 0; r < regions.size(); ++r) {
    const TexelRect& g = regions[r];
    if (g.width <= 0 || g.height <= 0 || g.x < 0 || g.y < 0 || g.x + g.width > canvas.width() ||
        g.y + g.height > canvas.height())
      return Error{Format("region %zu (%d, %d, %d x %d) is not inside the %d x %d canvas", r, g.x,
                          g.y, g.width, g.height, canvas.width(), canvas.height())};
    all_texels += g.texels();
  }

  // The photo set's part of every region's report; the first region's also carries the time of
  // what all regions share (the tracer, the pixel maps).
  ReflectanceFitReport shared;
  shared.seconds_tracer = Since(t0);

  SampleScene scene{&canvas, &normals, canvas_from_scan, &photos, &tracer};
  const PhotoSet& set = whole_set ? *whole_set : photos;
  if (whole_set) {
    if (Status s = CheckCamerasSeeCanvas(set, canvas_from_scan, canvas); !s.ok())
      return Error{s.message()};
    scene.cameras_checked = true;
  }
  if (Status s = ValidateSampleScene(scene); !s.ok()) return Error{s.message()};
  PixelTexelMaps pixel_maps;
  if (options.pixel_texel_maps) {
    t0 = Clock::now();
    pixel_maps = MapPixelsToTexels(photos, canvas, canvas_from_scan, tracer);
    scene.pixel_texels = &pixel_maps;
    shared.seconds_samples += Since(t0);
  }
  CountPhotoDirections(set, canvas, canvas_from_scan, shared);
  const int needed = std::max(options.fit.min_samples, kMinDistinctPhotoDirections);
  if (shared.distinct_directions < needed) {
    const int n = shared.distinct_directions;
    const size_t below = shared.light_below_canvas.size();
    return Error{set.source.string() + ": only " + std::to_string(n) + " distinct (light, view) " +
                 (n == 1 ? "pair" : "pairs") + " with the light above the canvas, in " +
                 std::to_string(shared.photos) + (shared.photos == 1 ? " photo" : " photos") +
                 (below ? " (" + std::to_string(below) + " lit from at or below the canvas)" : "") +
                 "; the fit needs at least " + std::to_string(needed) + " (min_samples " +
                 std::to_string(options.fit.min_samples) +
                 "): with fewer, every texel would be \"too few samples\", none told diffuse "
                 "from glossy"};
  }

  BrdfFitOptions fit_options = options.fit;
  if (options.quantisation_from_photos) {
    shared.quantisation = DetectPhotoQuantisation(photos);
    fit_options.photo_code_max = shared.quantisation.code_max;
    fit_options.photo_codes_srgb = shared.quantisation.srgb;
    fit_options.photo_compression_sigma_codes =
        shared.quantisation.lossy ? options.jpeg_sigma_codes : 0.0;
  } else {
    shared.quantisation = {options.fit.photo_code_max, options.fit.photo_codes_srgb,
                           options.fit.photo_compression_sigma_codes > 0};
  }

  SampleBuffers buffers;
  size_t texels_done = 0;
  const auto fitted_texels = [&](size_t n) {
    texels_done += n;
    ReportProgress(progress, "fit",
                   static_cast<double>(texels_done) / static_cast<double>(all_texels));
  };
  for (size_t r = 0; r < regions.size(); ++r) {
    ReflectanceFitResult result;
    result.report = shared;
    if (r > 0) {
      result.report.seconds_tracer = 0;
      result.report.seconds_samples = 0;
      start = Clock::now();
    }
    if (Status s =
            FitRegion(scene, options, fit_options, regions[r], result, buffers, fitted_texels);
        !s.ok())
      return s;
    // kOutside texels count towards progress too (they are skipped, not fitted).
    texels_done += result.report.texels_outside;
    result.report.seconds_total = Since(start);
    if (Status s = done(r, std::move(result)); !s.ok()) return s;
  }
  ReportProgress(progress, "fit", 1.0);
  return Status::Ok();
}

Result<ReflectanceFitResult> FitReflectance(const HeightField& canvas, const Grid<Vec3f>& normals,
                                            const RigidTransform& canvas_from_scan,
                                            const PhotoSet& photos,
                                            const ReflectanceFitOptions& options,
                                            const ProgressCallback& progress) {
  const TexelRect whole{0, 0, canvas.width(), canvas.height()};
  ReflectanceFitResult fitted;
  const Status s = FitReflectanceRegions(
      canvas, normals, canvas_from_scan, photos, options, std::span(&whole, 1),
      [&](size_t, ReflectanceFitResult&& result) {
        fitted = std::move(result);
        return Status::Ok();
      },
      progress);
  if (!s.ok()) return Error{s.message()};
  return fitted;
}

nlohmann::json ToJson(const ReflectanceFitOptions& options) {
  const BrdfFitOptions& f = options.fit;
  return {{"method", f.method == BrdfFitMethod::kFast ? "fast" : "ceres"},
          {"noise_sigma", f.noise_sigma},
          {"min_samples", f.min_samples},
          {"k_min", f.k_min},
          {"k_max", f.k_max},
          {"max_specular_albedo", f.max_specular_albedo},
          {"diffuse_chi2_sigmas", f.diffuse_chi2_sigmas},
          {"fit_lafortune", f.fit_lafortune},
          {"fit_ggx", f.fit_ggx},
          {"ggx_alpha_min", f.ggx_alpha_min},
          {"ggx_alpha_max", f.ggx_alpha_max},
          {"model_penalty_per_parameter", f.model_penalty_per_parameter},
          {"quantisation_from_photos", options.quantisation_from_photos},
          {"jpeg_sigma_codes", options.jpeg_sigma_codes},
          {"min_cos", options.samples.min_cos},
          {"shadow_rays", options.samples.shadow_rays},
          {"visibility_rays", options.samples.visibility_rays},
          {"skip_unblockable", options.samples.trace.skip_unblockable},
          {"share_view_rays", options.samples.share_view_rays},
          {"horizon_sectors", options.samples.horizon_sectors},
          {"dark_outlier_ratio", options.dark_outlier_ratio},
          {"dark_outlier_sigmas", options.dark_outlier_sigmas}};
}

std::string ReflectanceReportJson(const ReflectanceFitResult& result,
                                  const ReflectanceFitOptions& options,
                                  const std::vector<std::string>& inputs) {
  using nlohmann::json;
  const ReflectanceFitReport& r = result.report;
  const SampleStats& s = r.samples;
  json status = json::object();
  for (int i = 0; i < kTexelFitStatusCount; ++i)
    status[ToString(static_cast<TexelFitStatus>(i))] = r.fit.count_by_status[i];
  auto rays = [](const TraceStats& t) {
    return json{
        {"rays", t.rays}, {"skipped", t.skipped}, {"traced", t.traced}, {"blocked", t.blocked}};
  };
  json doc = {{"format", "digitize.fit_report"},
              {"version", 1},
              {"tool_version", DIGITIZE_VERSION},
              {"simd_level", DIGITIZE_SIMD_LEVEL},  // float rounding differs between levels
              {"inputs", inputs},
              {"model",
               {{"name", "lafortune-1-lobe"},
                {"formula",
                 "f_r = rho_d + rho_s * max(0, cx vx lx + cy vy ly + cz vz lz)^k, per RGB channel"},
                {"gauge", "cz = 1, |cx| <= 1, |cy| <= 1"},
                {"frame", "texel tangent frame: z = normal, x = canvas X made perpendicular to it"},
                {"units", "rho_d, rho_s in 1/sr; radiance = f_r * (n.l) * E"},
                {"per_texel",
                 "model.png: 0 = lafortune-1-lobe (above), 100 = ggx: f_r = rho_d + GGX/Schlick/"
                 "Smith specular (ggx.h), F0 in rho_s, alpha in lobe k, lobe (0, 0, 1, alpha)"}}},
              {"brief", r.Brief()},
              {"warnings", r.Warnings()},
              {"photos",
               {{"count", r.photos},
                {"distinct_directions", r.distinct_directions},
                {"light_below_canvas", r.light_below_canvas.size()},
                {"light_below_canvas_entries", r.light_below_canvas}}},
              {"size_texels", {result.maps.width(), result.maps.height()}},
              {"texels_fitted", r.fit.texels},
              {"texels_outside", r.texels_outside},
              {"status", status},
              {"lobes_by_model",
               {{ToString(ReflectanceModel::kLafortune), r.fit.lobes_by_model[0]},
                {ToString(ReflectanceModel::kGgx), r.fit.lobes_by_model[1]}}},
              {"photo_quantisation",
               {{"code_max", r.quantisation.code_max},
                {"srgb", r.quantisation.srgb},
                {"lossy", r.quantisation.lossy}}},
              {"samples",
               {{"candidates", s.candidates},
                {"kept", s.kept},
                {"rejected",
                 {{"behind_camera", s.behind_camera},
                  {"outside_image", s.outside_image},
                  {"facing_away", s.facing_away},
                  {"light_below_horizon", s.light_below_horizon},
                  {"non_finite", s.non_finite},
                  {"saturated", s.saturated},
                  {"black", s.black},
                  {"hidden", s.hidden},
                  {"shadowed", s.shadowed},
                  {"dark_outliers", r.dark_outliers}}},
                {"view_rays", rays(s.view_rays)},
                {"light_rays", rays(s.light_rays)}}},
              {"texels_refitted", r.texels_refitted},
              {"mean_rms_error", r.fit.mean_rms_error},
              {"mean_iterations", r.fit.mean_iterations},
              {"seconds",
               {{"tracer", r.seconds_tracer},
                {"samples", r.seconds_samples},
                {"fit", r.seconds_fit},
                {"total", r.seconds_total}}},
              {"options", ToJson(options)}};
  return doc.dump(2) + "\n";
}

Status WriteReflectanceOutputs(const std::filesystem::path& dir, const ReflectanceFitResult& result,
                               const ReflectanceFitOptions& options,
                               const std::vector<std::string>& inputs) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return Error{dir.string() + ": cannot create the output folder: " + ec.message()};
  const ReflectanceMaps& m = result.maps;
  const ImageMetadata meta = {
      {"digitize:model", "lafortune-1-lobe (gauge cz = 1) or ggx, per texel (model.png)"},
      {"digitize:frame", "texel tangent frame (docs/formats.md)"},
      {"digitize:version", DIGITIZE_VERSION}};
  auto with = [&](const char* quantity) {
    ImageMetadata q = meta;
    q["digitize:quantity"] = quantity;
    return q;
  };
  if (Status s = WriteFloatExr(dir / "rho_d.exr", m.rho_d, {"R", "G", "B"}, with("rho_d (1/sr)"));
      !s.ok())
    return s;
  if (Status s = WriteFloatExr(dir / "rho_s.exr", m.rho_s, {"R", "G", "B"}, with("rho_s (1/sr)"));
      !s.ok())
    return s;
  if (Status s = WriteFloatExr(dir / "lobe.exr", m.lobe, {"cx", "cy", "cz", "k"},
                               with("lobe (cx, cy, cz = 1, k)"));
      !s.ok())
    return s;
  if (Status s = WriteFloatExr(dir / "fit_error.exr", m.fit_error, "Y",
                               with("fit RMS error (radiance units)"));
      !s.ok())
    return s;
  Grid<uint8_t> status(m.width(), m.height());
  for (size_t i = 0; i < status.size(); ++i)
    status.data[i] = static_cast<uint8_t>(static_cast<int>(m.status.data[i]) * 40);
  if (Status s = WritePng8(dir / "fit_status.png", status); !s.ok()) return s;
  Grid<uint8_t> model(m.width(), m.height());
  for (size_t i = 0; i < model.size(); ++i)
    model.data[i] = static_cast<uint8_t>(static_cast<int>(m.model.data[i]) * 100);
  if (Status s = WritePng8(dir / "model.png", model); !s.ok()) return s;
  return WriteTextFile(dir / "report.json", ReflectanceReportJson(result, options, inputs));
}

namespace {

// One map file, whole or a window of it.
using ReadMapFile = std::function<Result<FloatImage>(const std::filesystem::path&)>;

// Reads one map; checks size and channel names (OpenEXR may reorder channels: map by name).
Result<std::vector<float>> ReadChannels(const std::filesystem::path& path,
                                        const std::vector<std::string>& names, int& width,
                                        int& height, const ReadMapFile& read) {
  auto image = read(path);
  if (!image.ok()) return image.error();
  if (image->channels != static_cast<int>(names.size()))
    return Error{path.string() + ": " + std::to_string(image->channels) + " channels, expected " +
                 std::to_string(names.size())};
  if (width > 0 && (image->width != width || image->height != height))
    return Error{path.string() + ": " + std::to_string(image->width) + "x" +
                 std::to_string(image->height) + ", the other maps are " + std::to_string(width) +
                 "x" + std::to_string(height)};
  width = image->width;
  height = image->height;
  std::vector<int> order(names.size());
  for (size_t c = 0; c < names.size(); ++c) {
    const auto it = std::find(image->channel_names.begin(), image->channel_names.end(), names[c]);
    order[c] = it == image->channel_names.end()
                   ? static_cast<int>(c)
                   : static_cast<int>(it - image->channel_names.begin());
  }
  const size_t n = static_cast<size_t>(width) * static_cast<size_t>(height);
  std::vector<float> out(n * names.size());
  for (size_t i = 0; i < n; ++i)
    for (size_t c = 0; c < names.size(); ++c)
      out[i * names.size() + c] = image->pixels[i * names.size() + static_cast<size_t>(order[c])];
  return out;
}

// The maps of a fit folder, each file read by `read` (the whole file or one window of it).
Result<ReflectanceMaps> ReadMaps(const std::filesystem::path& dir, const ReadMapFile& read) {
  int w = 0, h = 0;
  auto rho_d = ReadChannels(dir / "rho_d.exr", {"R", "G", "B"}, w, h, read);
  if (!rho_d.ok()) return rho_d.error();
  auto rho_s = ReadChannels(dir / "rho_s.exr", {"R", "G", "B"}, w, h, read);
  if (!rho_s.ok()) return rho_s.error();
  auto lobe = ReadChannels(dir / "lobe.exr", {"cx", "cy", "cz", "k"}, w, h, read);
  if (!lobe.ok()) return lobe.error();
  auto error = ReadChannels(dir / "fit_error.exr", {"Y"}, w, h, read);
  if (!error.ok()) return error.error();
  auto status = read(dir / "fit_status.png");
  if (!status.ok()) return status.error();
  if (status->width != w || status->height != h || status->channels != 1)
    return Error{(dir / "fit_status.png").string() + ": not a 1-channel " + std::to_string(w) +
                 "x" + std::to_string(h) + " image"};
  ReflectanceMaps m = ReflectanceMaps::Zeros(w, h);
  for (size_t i = 0; i < m.rho_d.size(); ++i) {
    m.rho_d.data[i] = {(*rho_d)[3 * i], (*rho_d)[3 * i + 1], (*rho_d)[3 * i + 2]};
    m.rho_s.data[i] = {(*rho_s)[3 * i], (*rho_s)[3 * i + 1], (*rho_s)[3 * i + 2]};
    m.lobe.data[i] = {(*lobe)[4 * i], (*lobe)[4 * i + 1], (*lobe)[4 * i + 2], (*lobe)[4 * i + 3]};
    m.fit_error.data[i] = (*error)[i];
    const int code = static_cast<int>(std::lround(status->pixels[i] * 255.0f));
    if (code % 40 != 0 || code / 40 >= kTexelFitStatusCount)
      return Error{(dir / "fit_status.png").string() + ": value " + std::to_string(code) +
                   " is not a fit status"};
    m.status.data[i] = static_cast<TexelFitStatus>(code / 40);
  }
  // model.png: absent in outputs written before GGX texels existed (all Lafortune then).
  if (std::filesystem::exists(dir / "model.png")) {
    auto model = read(dir / "model.png");
    if (!model.ok()) return model.error();
    if (model->width != w || model->height != h || model->channels != 1)
      return Error{(dir / "model.png").string() + ": not a 1-channel " + std::to_string(w) + "x" +
                   std::to_string(h) + " image"};
    for (size_t i = 0; i < m.model.size(); ++i) {
      const int code = static_cast<int>(std::lround(model->pixels[i] * 255.0f));
      if (code % 100 != 0 || code / 100 >= kReflectanceModelCount)
        return Error{(dir / "model.png").string() + ": value " + std::to_string(code) +
                     " is not a reflectance model"};
      m.model.data[i] = static_cast<ReflectanceModel>(code / 100);
    }
  }
  if (Status s = m.Validate(); !s.ok()) return Error{dir.string() + ": " + s.message()};
  return m;
}

}  // namespace

Result<ReflectanceMaps> ReadReflectanceMaps(const std::filesystem::path& dir) {
  return ReadMaps(dir, [](const std::filesystem::path& path) { return ReadImage(path); });
}

Result<ReflectanceMaps> ReadReflectanceMapsWindow(const std::filesystem::path& dir, int x0, int y0,
                                                  int width, int height,
                                                  ImageRegionReader& reader) {
  return ReadMaps(dir, [&](const std::filesystem::path& path) {
    return reader.Read(path, x0, y0, width, height);
  });
}

}  // namespace digitize

namespace digitize {

std::string HeldOutScore::Brief() const {
  char b[200];
  std::snprintf(b, sizeof b,
                "held-out PSNR %.2f dB linear, %.2f dB 8-bit sRGB (RMSE %.4f) over %zu photo(s), "
                "%.3g M px",
                psnr_db, psnr_srgb8_db, rmse, images.size(), static_cast<double>(pixels) / 1e6);
  return b;
}

namespace {

// PSNR of a sum of squared errors over `pixels` RGB pixels; +inf for no error.
double Psnr(double sse, size_t pixels, double peak) {
  if (pixels == 0) return 0;
  const double mse = sse / (3.0 * static_cast<double>(pixels));
  return mse > 0 ? 10.0 * std::log10(peak * peak / mse) : std::numeric_limits<double>::infinity();
}

// Sum over the masked pixels and channels of the squared difference of the 8-bit sRGB codes of
// a / peak and b / peak (both already clipped to [0, peak]).
double SquaredErrorSrgb8(const Grid<Vec3f>& a, const Grid<Vec3f>& b, const Grid<uint8_t>& mask,
                         double peak) {
  const float inv = static_cast<float>(1.0 / peak);
  auto code = [&](float v) { return std::round(255.0f * LinearToSrgb(v * inv)); };
  double sse = 0;
  for (size_t p = 0; p < mask.size(); ++p) {
    if (!mask.data[p] || !a.data[p].allFinite() || !b.data[p].allFinite()) continue;
    for (int c = 0; c < 3; ++c) {
      const double d = code(a.data[p][c]) - code(b.data[p][c]);
      sse += d * d;
    }
  }
  return sse;
}

}  // namespace

Result<HeldOutScore> EvaluateHeldOut(const HeightField& canvas, const Grid<Vec3f>& normals,
                                     const ReflectanceMaps& maps,
                                     const RigidTransform& canvas_from_scan,
                                     const PhotoSet& held_out,
                                     const std::vector<Grid<uint8_t>>& masks, double peak,
                                     std::vector<Grid<Vec3f>>* relit_images) {
  const auto start = Clock::now();
  if (relit_images) relit_images->clear();
  if (!(std::isfinite(peak) && peak > 0))
    return Error{"peak must be > 0, got " + FormatNumber(peak)};
  if (!masks.empty() && masks.size() != held_out.photos.size())
    return Error{"held-out: " + std::to_string(masks.size()) + " masks for " +
                 std::to_string(held_out.photos.size()) + " photos"};
  if (maps.width() != canvas.width() || maps.height() != canvas.height())
    return Error{"reflectance maps are " + std::to_string(maps.width()) + "x" +
                 std::to_string(maps.height()) + ", the canvas " + std::to_string(canvas.width()) +
                 "x" + std::to_string(canvas.height())};
  auto tracer = HeightFieldTracer::Build(canvas);
  if (!tracer.ok()) return Error{"canvas: " + tracer.error().message};
  HeldOutScore score;
  double sse = 0, sse_srgb8 = 0;
  for (size_t i = 0; i < held_out.photos.size(); ++i) {
    const Photo& photo = held_out.photos[i];
    if (!photo.loaded())
      return Error{photo.entry + ": " + photo.path.string() + ": pixels not loaded"};
    const RelitImage relit =
        RenderRelit(*tracer, canvas, normals, maps, canvas_from_scan, photo.camera, photo.light);
    Grid<uint8_t> mask = relit.mask;
    if (!masks.empty()) {
      if (masks[i].width != mask.width || masks[i].height != mask.height)
        return Error{photo.entry + ": mask size differs from the image"};
      for (size_t p = 0; p < mask.size(); ++p) mask.data[p] &= masks[i].data[p] ? 1 : 0;
    }
    if (!photo.flags.empty())
      for (size_t p = 0; p < mask.size(); ++p)
        if (photo.flags.data[p]) mask.data[p] = 0;
    Grid<Vec3f> a = relit.rgb, b = photo.rgb;
    const float top = static_cast<float>(peak);
    for (Vec3f& c : a.data) c = c.cwiseMax(0.0f).cwiseMin(top);
    for (Vec3f& c : b.data) c = c.cwiseMax(0.0f).cwiseMin(top);
    const ImageComparison cmp = CompareImages(a, b, mask, peak);
    const double image_sse_srgb8 = SquaredErrorSrgb8(a, b, mask, peak);
    score.images.push_back(
        {photo.entry, cmp.psnr_db, cmp.rmse, Psnr(image_sse_srgb8, cmp.pixels, 255.0), cmp.pixels});
    sse += cmp.rmse * cmp.rmse * 3.0 * static_cast<double>(cmp.pixels);
    sse_srgb8 += image_sse_srgb8;
    score.pixels += cmp.pixels;
    if (relit_images) relit_images->push_back(relit.rgb);
  }
  if (score.pixels > 0) {
    const double mse = sse / (3.0 * static_cast<double>(score.pixels));
    score.rmse = std::sqrt(mse);
    score.psnr_db = Psnr(sse, score.pixels, peak);
    score.psnr_srgb8_db = Psnr(sse_srgb8, score.pixels, 255.0);
  }
  score.seconds = Since(start);
  return score;
}

}  // namespace digitize

namespace digitize {

Status WriteRelitImages(const std::filesystem::path& dir, const PhotoSet& held_out,
                        const std::vector<Grid<Vec3f>>& relit) {
  if (relit.size() != held_out.photos.size())
    return Error{"held-out: " + std::to_string(relit.size()) + " relit images for " +
                 std::to_string(held_out.photos.size()) + " photos"};
  std::set<std::string> stems;
  for (size_t i = 0; i < relit.size(); ++i) {
    const Photo& photo = held_out.photos[i];
    const std::string stem = photo.path.stem().string();
    if (!stems.insert(stem).second)
      return Error{photo.entry + ": " + photo.path.string() + ": a second held-out photo named '" +
                   stem + "': its relit image would overwrite the first one's"};
    const Grid<Vec3f>& image = relit[i];
    if (photo.encoding == ColourEncoding::kLinear) {
      if (Status s = WriteFloatExr(dir / (stem + ".exr"), image, {"R", "G", "B"}); !s.ok())
        return s;
      continue;
    }
    Grid<std::array<uint8_t, 3>> codes(image.width, image.height);
    for (size_t p = 0; p < image.size(); ++p)
      for (int c = 0; c < 3; ++c)
        codes.data[p][c] = static_cast<uint8_t>(
            std::lround(255.0f * LinearToSrgb(std::clamp(image.data[p][c], 0.0f, 1.0f))));
    if (Status s = WritePngRgb8(dir / (stem + ".png"), codes); !s.ok()) return s;
  }
  return Status::Ok();
}

}  // namespace digitize
