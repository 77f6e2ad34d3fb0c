// An RTI capture's canvas (rti_canvas.h): intensities and normals by photometric stereo, a height
// field by integration, relief boxes.
#include "digitize/rti_canvas.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "digitize/relief.h"

namespace digitize {

namespace {

using Clock = std::chrono::steady_clock;

Vec3d LightDirection(const Light& light) {
  return light.type == LightType::kDirectional ? light.direction.normalized()
                                               : light.position_mm.normalized();
}

void ScaleLight(Light& light, double factor) {
  const float f = static_cast<float>(factor);
  if (light.type == LightType::kDirectional)
    light.irradiance *= f;
  else
    light.intensity *= f;
}

}  // namespace

Status RtiCanvasOptions::Validate() const {
  if (Status s = stereo.Validate(); !s.ok()) return s;
  if (Status s = integration.Validate(); !s.ok()) return s;
  if (Status s = relief.Validate(); !s.ok()) return s;
  if (!(std::isfinite(intensity_kernel_deg) && intensity_kernel_deg > 0))
    return Error{"intensity_kernel_deg must be > 0, got " + FormatNumber(intensity_kernel_deg)};
  if (refine_intensity_rounds < 0 || refine_intensity_rounds > 10)
    return Error{"refine_intensity_rounds must be in [0, 10], got " +
                 std::to_string(refine_intensity_rounds)};
  return Status::Ok();
}

std::string RtiCanvas::Brief() const {
  std::string s;
  if (!stereo_brief.empty()) s += "normals: " + stereo_brief;
  if (!integration_brief.empty()) s += "; height: " + integration_brief;
  char b[96];
  std::snprintf(b, sizeof b, "%srelief: %zu box(es), max height %.3f mm; %.2f s",
                s.empty() ? "" : "; ", canvas.boxes.size(), canvas.max_height_mm, seconds);
  return s + b;
}

Result<RtiCanvas> RtiCanvasFor(PhotoSet& rti, const RtiCanvasOptions& options,
                               const ProgressCallback& progress) {
  const auto start = Clock::now();
  if (Status s = options.Validate(); !s.ok()) return Error{s.message()};
  auto flat = FlatCanvasForRti(rti);
  if (!flat.ok()) return flat.error();
  RtiCanvas out;
  out.canvas.field = std::move(flat).value();
  const int w = out.canvas.field.width(), h = out.canvas.field.height();
  out.canvas.normals = Grid<Vec3f>(w, h, Vec3f::UnitZ());
  out.intensities.assign(rti.photos.size(), 1.0);
  if (!options.normals) {
    out.seconds = std::chrono::duration<double>(Clock::now() - start).count();
    return out;
  }

  std::vector<PhotometricImage> images;
  images.reserve(rti.photos.size());
  for (const Photo& photo : rti.photos) {
    if (!photo.loaded())
      return Error{photo.entry + ": " + photo.path.string() + ": pixels not loaded"};
    if (photo.rgb.width != w || photo.rgb.height != h)
      return Error{photo.entry + ": " + photo.path.string() + ": image is " +
                   std::to_string(photo.rgb.width) + "x" + std::to_string(photo.rgb.height) +
                   ", the capture's canvas " + std::to_string(w) + "x" + std::to_string(h)};
    PhotometricImage image;
    image.rgb = &photo.rgb;
    image.exclude = photo.flags.empty() ? nullptr : &photo.flags;
    image.point_light = photo.light.type == LightType::kPoint;
    image.light = image.point_light ? photo.light.position_mm : photo.light.direction;
    images.push_back(image);
  }
  ReportProgress(progress, "normals", 0.0);
  PhotometricStereoOptions stereo = options.stereo;
  stereo.pitch_mm = rti.rti_pitch_mm > 0 ? rti.rti_pitch_mm : stereo.pitch_mm;
  auto solved = SolvePhotometricStereo(images, stereo);
  if (!solved.ok()) return Error{rti.source.string() + ": normals: " + solved.error().message};
  out.stereo_brief = solved->Brief();
  out.intensities = solved->intensities;
  for (size_t i = 0; i < rti.photos.size(); ++i)
    ScaleLight(rti.photos[i].light, out.intensities[i]);
  out.canvas.normals = solved->normals;

  if (options.height) {
    ReportProgress(progress, "height", 0.5);
    // Pixels whose normal is a placeholder (no usable samples) carry no gradient.
    Grid<uint8_t> mask(w, h, 1);
    for (size_t p = 0; p < mask.size(); ++p)
      mask.data[p] = solved->status.data[p] == PhotometricStatus::kOk ? 1 : 0;
    auto heights =
        IntegrateNormals(solved->normals, stereo.pitch_mm, &mask, nullptr, options.integration);
    if (!heights.ok()) return Error{rti.source.string() + ": height: " + heights.error().message};
    out.integration_brief = heights->Brief();
    out.canvas.field = HeightFieldFromIntegration(*heights, stereo.pitch_mm, &mask);
    const ReliefResult relief = ClassifyRelief(out.canvas.field, options.relief);
    out.canvas.delta0_mm = relief.delta0_mm;
    out.canvas.max_height_mm = relief.max_height_mm;
    out.canvas.cell_px = relief.cell_px > 0 ? relief.cell_px : 16;
    out.canvas.boxes = relief.boxes;
  }
  ReportProgress(progress, "height", 1.0);
  out.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return out;
}

void ScaleRtiIntensities(PhotoSet& rti, std::vector<double>& intensities,
                         const std::vector<double>& factors) {
  DIGITIZE_CHECK(intensities.size() == rti.photos.size() && factors.size() == rti.photos.size(),
                 "one intensity and one factor per photo");
  for (size_t i = 0; i < factors.size(); ++i) {
    if (!(std::isfinite(factors[i]) && factors[i] > 0)) continue;
    ScaleLight(rti.photos[i].light, factors[i]);
    intensities[i] *= factors[i];
  }
}

double PredictRtiIntensity(const PhotoSet& fitted, const std::vector<double>& intensities,
                           const Vec3d& direction, double kernel_deg) {
  const Vec3d d = direction.normalized();
  const double inv_two_s2 = 1.0 / (2.0 * kernel_deg * kernel_deg);
  double sum_w = 0, sum_log = 0;
  // The nearest light counts even where every light lies far outside the kernel.
  double nearest_deg = 1e30, nearest_log = 0;
  for (size_t i = 0; i < fitted.photos.size() && i < intensities.size(); ++i) {
    if (!(intensities[i] > 0)) continue;
    const double deg = AngleDeg(LightDirection(fitted.photos[i].light), d);
    const double log_e = std::log(intensities[i]);
    const double w = std::exp(-deg * deg * inv_two_s2);
    sum_w += w;
    sum_log += w * log_e;
    if (deg < nearest_deg) nearest_deg = deg, nearest_log = log_e;
  }
  if (nearest_deg >= 1e30) return 1.0;
  if (!(sum_w > 1e-12)) return std::exp(nearest_log);
  return std::exp(sum_log / sum_w);
}

void ApplyPredictedIntensities(const PhotoSet& fitted, const std::vector<double>& intensities,
                               double kernel_deg, PhotoSet& other) {
  for (Photo& photo : other.photos)
    ScaleLight(photo.light,
               PredictRtiIntensity(fitted, intensities, LightDirection(photo.light), kernel_deg));
}

}  // namespace digitize
