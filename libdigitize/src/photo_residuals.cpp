#include "digitize/photo_residuals.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "digitize/height_field_tracer.h"
#include "digitize/relight.h"

namespace digitize {
namespace {

using Clock = std::chrono::steady_clock;

// Rec. 709 luminance of linear RGB.
double Luminance(const Vec3f& c) { return 0.2126 * c.x() + 0.7152 * c.y() + 0.0722 * c.z(); }

std::string Fixed(double v, int decimals) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.*f", decimals, v);
  return buffer;
}

// Photo pixels per canvas mm at the canvas centre (geometric mean of the scales along the
// canvas's X and Y, one texel apart); 0 when the centre is not seen.
double PixelsPerMm(const Camera& camera, const RigidTransform& canvas_from_scan,
                   const HeightField& canvas) {
  const RigidTransform scan_from_canvas = canvas_from_scan.Inverse();
  const double step = canvas.pitch_mm;
  const Vec3d centre(canvas.width() * step / 2, canvas.height() * step / 2, 0.0);
  const Vec3d p0 = scan_from_canvas.Apply(centre);
  const Vec3d px = scan_from_canvas.Apply(centre + Vec3d(step, 0, 0));
  const Vec3d py = scan_from_canvas.Apply(centre + Vec3d(0, step, 0));
  if (!(step > 0) || !camera.InFront(p0) || !camera.InFront(px) || !camera.InFront(py)) return 0;
  const Eigen::Vector2d c = camera.Project(p0);
  const double sx = (camera.Project(px) - c).norm() / step;
  const double sy = (camera.Project(py) - c).norm() / step;
  const double s = std::sqrt(sx * sy);
  return std::isfinite(s) ? s : 0.0;
}

struct Shift {
  double x = 0, y = 0, response = 0;
  bool measured = false;
};

// Shift of `photo`'s content relative to `relit` by phase correlation of their luminance over the
// bounding box of `use` (pixels outside `use` take the image's mean over `use`).
Shift MeasureShift(const Grid<Vec3f>& relit, const Grid<Vec3f>& photo, const Grid<uint8_t>& use,
                   int max_side_px) {
  int x0 = use.width, y0 = use.height, x1 = -1, y1 = -1;
  for (int y = 0; y < use.height; ++y)
    for (int x = 0; x < use.width; ++x)
      if (use(x, y)) {
        x0 = std::min(x0, x), x1 = std::max(x1, x);
        y0 = std::min(y0, y), y1 = std::max(y1, y);
      }
  Shift shift;
  const int factor =
      std::max(1, (std::max(x1 - x0 + 1, y1 - y0 + 1) + max_side_px - 1) / max_side_px);
  // Whole blocks of `factor` pixels only, so that the averaging below is an exact decimation.
  const int w = (x1 - x0 + 1) / factor * factor, h = (y1 - y0 + 1) / factor * factor;
  if (w / factor < 8 || h / factor < 8) return shift;
  double mean_a = 0, mean_b = 0;
  size_t n = 0;
  for (int y = y0; y < y0 + h; ++y)
    for (int x = x0; x < x0 + w; ++x)
      if (use(x, y)) {
        mean_a += Luminance(relit(x, y));
        mean_b += Luminance(photo(x, y));
        ++n;
      }
  if (n == 0) return shift;
  mean_a /= static_cast<double>(n), mean_b /= static_cast<double>(n);
  cv::Mat a(h, w, CV_32F), b(h, w, CV_32F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const bool in = use(x0 + x, y0 + y) != 0;
      a.at<float>(y, x) = static_cast<float>(in ? Luminance(relit(x0 + x, y0 + y)) : mean_a);
      b.at<float>(y, x) = static_cast<float>(in ? Luminance(photo(x0 + x, y0 + y)) : mean_b);
    }
  if (factor > 1) {
    cv::resize(a, a, cv::Size(w / factor, h / factor), 0, 0, cv::INTER_AREA);
    cv::resize(b, b, cv::Size(w / factor, h / factor), 0, 0, cv::INTER_AREA);
  }
  cv::Mat window;
  cv::createHanningWindow(window, a.size(), CV_32F);
  double response = 0;
  const cv::Point2d s = cv::phaseCorrelate(a, b, window, &response);
  if (!std::isfinite(s.x) || !std::isfinite(s.y) || !std::isfinite(response)) return shift;
  shift.x = s.x * factor;
  shift.y = s.y * factor;
  shift.response = std::clamp(response, 0.0, 1.0);
  shift.measured = true;
  return shift;
}

// The relit image moved by (sx, sy) px (its content then sits where the photo's does), and the
// pixels it still covers entirely (a mask pixel whose bilinear footprint leaves the canvas drops).
void Register(const Grid<Vec3f>& rgb, const Grid<uint8_t>& mask, double sx, double sy,
              Grid<Vec3f>& out_rgb, Grid<uint8_t>& out_mask) {
  static_assert(sizeof(Vec3f) == 3 * sizeof(float), "Vec3f must be packed RGB floats");
  const cv::Matx23d move(1, 0, sx, 0, 1, sy);
  const cv::Size size(rgb.width, rgb.height);
  out_rgb = Grid<Vec3f>(rgb.width, rgb.height, Vec3f::Zero());
  const cv::Mat src(size, CV_32FC3, const_cast<Vec3f*>(rgb.data.data()));
  cv::Mat dst(size, CV_32FC3, out_rgb.data.data());
  cv::warpAffine(src, dst, move, size, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar::all(0));
  cv::Mat m(size, CV_32F), warped;
  for (int y = 0; y < rgb.height; ++y)
    for (int x = 0; x < rgb.width; ++x) m.at<float>(y, x) = mask(x, y) ? 1.0f : 0.0f;
  cv::warpAffine(m, warped, move, size, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar::all(0));
  out_mask = Grid<uint8_t>(rgb.width, rgb.height, 0);
  for (int y = 0; y < rgb.height; ++y)
    for (int x = 0; x < rgb.width; ++x) out_mask(x, y) = warped.at<float>(y, x) > 0.999f ? 1 : 0;
}

struct Gain {
  double gain = 1.0;
  size_t pixels = 0;  // well-exposed pixels with some light in the photo
  bool measured = false;
};

Gain MeasureGain(const Grid<Vec3f>& relit, const Grid<Vec3f>& photo, const Grid<uint8_t>& use,
                 const PhotoResidualOptions& options) {
  std::vector<double> ratios;
  std::vector<std::pair<double, double>> pairs;  // (predicted, observed) luminance
  size_t lit = 0;
  for (size_t p = 0; p < use.size(); ++p) {
    if (!use.data[p]) continue;
    const double predicted = Luminance(relit.data[p]), observed = Luminance(photo.data[p]);
    if (!(predicted >= options.min_luminance) || !std::isfinite(observed)) continue;
    ratios.push_back(observed / predicted);
    pairs.emplace_back(predicted, observed);
    if (observed > 0) ++lit;
  }
  Gain gain;
  gain.pixels = lit;
  if (lit < options.min_pixels) return gain;
  const auto mid = ratios.begin() + static_cast<std::ptrdiff_t>(ratios.size() / 2);
  std::nth_element(ratios.begin(), mid, ratios.end());
  const double median = *mid;
  if (!(median > 0) || !std::isfinite(median)) return gain;
  double po = 0, pp = 0;
  size_t inliers = 0;
  for (const auto& [predicted, observed] : pairs)
    if (std::abs(observed / predicted / median - 1.0) <= options.gain_inlier_band) {
      po += predicted * observed;
      pp += predicted * predicted;
      ++inliers;
    }
  const double refined = inliers >= options.min_pixels && pp > 0 ? po / pp : median;
  if (!(refined > 0) || !std::isfinite(refined)) return gain;
  gain.gain = refined;
  gain.measured = true;
  return gain;
}

// RMS (linear, all channels) of photo - gain * relit over `use`; 0 when nothing is used.
double RmsAfterGain(const Grid<Vec3f>& relit, const Grid<Vec3f>& photo, const Grid<uint8_t>& use,
                    double gain) {
  double sse = 0;
  size_t n = 0;
  for (size_t p = 0; p < use.size(); ++p) {
    if (!use.data[p]) continue;
    sse += (photo.data[p].cast<double>() - gain * relit.data[p].cast<double>()).squaredNorm();
    ++n;
  }
  return n ? std::sqrt(sse / (3.0 * static_cast<double>(n))) : 0.0;
}

std::string Name(const PhotoResidual& r) { return r.path + " (" + r.entry + ")"; }

}  // namespace

Status PhotoResidualOptions::Validate() const {
  auto bad = [](const char* what, const std::string& rule, double got) {
    return Error{std::string(what) + " must be " + rule + ", got " + FormatNumber(got)};
  };
  if (!(std::isfinite(min_luminance) && min_luminance > 0))
    return bad("min_luminance", "> 0", min_luminance);
  if (!(gain_inlier_band > 0 && gain_inlier_band <= 1))
    return bad("gain_inlier_band", "in (0, 1]", gain_inlier_band);
  if (min_pixels < 1) return bad("min_pixels", ">= 1", static_cast<double>(min_pixels));
  if (!(std::isfinite(max_abs_log_gain) && max_abs_log_gain > 0))
    return bad("max_abs_log_gain", "> 0", max_abs_log_gain);
  if (!(std::isfinite(max_shift_px) && max_shift_px > 0))
    return bad("max_shift_px", "> 0", max_shift_px);
  if (!(min_shift_response >= 0 && min_shift_response <= 1))
    return bad("min_shift_response", "in [0, 1]", min_shift_response);
  if (!(min_shift_improvement >= 0 && min_shift_improvement < 1))
    return bad("min_shift_improvement", "in [0, 1)", min_shift_improvement);
  if (max_correlation_side_px < 16)
    return bad("max_correlation_side_px", ">= 16", max_correlation_side_px);
  if (num_threads < 0) return bad("num_threads", ">= 0", num_threads);
  return Status::Ok();
}

Result<PhotoResidualReport> CheckPhotoResiduals(const HeightField& canvas,
                                                const Grid<Vec3f>& normals,
                                                const ReflectanceMaps& maps,
                                                const RigidTransform& canvas_from_scan,
                                                const PhotoSet& photos,
                                                const PhotoResidualOptions& options) {
  const auto start = Clock::now();
  if (Status s = options.Validate(); !s.ok()) return Error{"photo residuals: " + s.message()};
  if (maps.width() != canvas.width() || maps.height() != canvas.height() ||
      normals.width != canvas.width() || normals.height != canvas.height())
    return Error{"photo residuals: reflectance maps " + std::to_string(maps.width()) + "x" +
                 std::to_string(maps.height()) + " and normals " + std::to_string(normals.width) +
                 "x" + std::to_string(normals.height) + " must have the canvas's size " +
                 std::to_string(canvas.width()) + "x" + std::to_string(canvas.height())};
  for (const Photo& photo : photos.photos)
    if (!photo.loaded())
      return Error{photo.entry + ": " + photo.path.string() + ": pixels not loaded"};
  auto tracer = HeightFieldTracer::Build(canvas);
  if (!tracer.ok()) return Error{"canvas: " + tracer.error().message};
  RelightOptions relight;
  relight.shadows = options.shadows;
  relight.num_threads = options.num_threads;

  PhotoResidualReport report;
  report.options = options;
  for (const Photo& photo : photos.photos) {
    PhotoResidual r;
    r.entry = photo.entry;
    r.path = photo.path.string();
    const RelitImage relit = RenderRelit(*tracer, canvas, normals, maps, canvas_from_scan,
                                         photo.camera, photo.light, relight);
    DIGITIZE_CHECK(relit.rgb.width == photo.rgb.width && relit.rgb.height == photo.rgb.height,
                   "relit image and photo sizes differ");
    Grid<uint8_t> use = relit.mask;
    for (size_t p = 0; p < use.size(); ++p)
      if (!photo.flags.empty() && photo.flags.data[p]) use.data[p] = 0;

    Gain gain = MeasureGain(relit.rgb, photo.rgb, use, options);
    if (!gain.measured) r.flags |= kResidualTooFewPixels;
    if (gain.measured) {
      const Shift shift = MeasureShift(relit.rgb, photo.rgb, use, options.max_correlation_side_px);
      if (shift.measured) {
        r.shift_x_px = shift.x;
        r.shift_y_px = shift.y;
        r.shift_px = std::hypot(shift.x, shift.y);
        r.shift_response = shift.response;
        const double px_per_mm = PixelsPerMm(photo.camera, canvas_from_scan, canvas);
        if (px_per_mm > 0) {
          r.shift_mm = r.shift_px / px_per_mm;
          r.shift_texels = r.shift_mm / canvas.pitch_mm;
        }
      }
      if (!shift.measured || shift.response < options.min_shift_response) {
        r.flags |= kResidualShiftWeak;
      } else if (r.shift_px > options.max_shift_px) {
        // Misregistered pixels compare texels with their neighbours, which biases the ratios
        // (2 % at 4 texels): the gain is measured again on the relit image moved onto the photo.
        Grid<Vec3f> moved;
        Grid<uint8_t> moved_use;
        Register(relit.rgb, relit.mask, shift.x, shift.y, moved, moved_use);
        for (size_t p = 0; p < moved_use.size(); ++p)
          if (!photo.flags.empty() && photo.flags.data[p]) moved_use.data[p] = 0;
        const Gain registered = MeasureGain(moved, photo.rgb, moved_use, options);
        // A real misregistration: the relit image moved by the shift matches the photo better.
        // A spurious correlation peak (large flat regions, a part of the canvas in a corner of
        // the photo) does not, and is no warning.
        // Compared over the pixels both cover: a large shift leaves only a corner of the photo,
        // whose RMS says nothing about the rest.
        Grid<uint8_t> both = use;
        size_t common = 0;
        for (size_t p = 0; p < both.size(); ++p) common += both.data[p] &= moved_use.data[p];
        const double before = RmsAfterGain(relit.rgb, photo.rgb, both, gain.gain);
        const double after = RmsAfterGain(moved, photo.rgb, both, registered.gain);
        if (registered.measured && common >= options.min_pixels &&
            after < (1.0 - options.min_shift_improvement) * before) {
          r.flags |= kResidualShifted;
          gain = registered;
        } else {
          r.flags |= kResidualShiftWeak;
        }
      }
    }
    r.gain = gain.gain;
    r.gain_pixels = gain.pixels;
    if (gain.measured && std::abs(std::log(r.gain)) > options.max_abs_log_gain)
      r.flags |= kResidualGainOff;

    // Against the relit image as rendered (what the fit predicts for this photo's declared pose).
    double sse = 0, sse_gain = 0;
    for (size_t p = 0; p < use.size(); ++p) {
      if (!use.data[p]) continue;
      const Vec3f& o = photo.rgb.data[p];
      const Vec3f& e = relit.rgb.data[p];
      sse += (o - e).cast<double>().squaredNorm();
      sse_gain += (o.cast<double>() - r.gain * e.cast<double>()).squaredNorm();
      ++r.pixels;
    }
    if (r.pixels > 0) {
      r.rms = std::sqrt(sse / (3.0 * static_cast<double>(r.pixels)));
      r.rms_after_gain = std::sqrt(sse_gain / (3.0 * static_cast<double>(r.pixels)));
    }
    for (double v : {r.gain, r.shift_x_px, r.shift_y_px, r.shift_px, r.shift_mm, r.shift_texels,
                     r.shift_response, r.rms, r.rms_after_gain})
      DIGITIZE_CHECK(std::isfinite(v), "non-finite photo residual for " + photo.entry);
    report.photos.push_back(std::move(r));
  }
  report.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return report;
}

std::string PhotoResidualReport::Brief() const {
  size_t gain_off = 0, shifted = 0, not_judged = 0;
  double worst_gain = 1.0, worst_shift = 0;
  for (const PhotoResidual& r : photos) {
    if (r.flags & kResidualTooFewPixels) ++not_judged;
    if (r.flags & kResidualGainOff) {
      ++gain_off;
      if (std::abs(std::log(r.gain)) > std::abs(std::log(worst_gain))) worst_gain = r.gain;
    }
    if (r.flags & kResidualShifted) {
      ++shifted;
      worst_shift = std::max(worst_shift, r.shift_px);
    }
  }
  std::string s = std::to_string(photos.size()) + " photos checked: " + std::to_string(gain_off) +
                  " with their gain off";
  if (gain_off) s += " (worst " + Fixed(worst_gain, 2) + ")";
  s += ", " + std::to_string(shifted) + " shifted";
  if (shifted) s += " (max " + Fixed(worst_shift, 1) + " px)";
  s += ", " + std::to_string(not_judged) + " not judged; " + Fixed(seconds, 1) + " s";
  return s;
}

std::vector<std::string> PhotoResidualReport::Warnings() const {
  std::vector<std::string> lines;
  for (const PhotoResidual& r : photos) {
    if (r.flags & kResidualTooFewPixels)
      lines.push_back(Name(r) + ": only " + std::to_string(r.gain_pixels) +
                      " well-exposed canvas pixels (at least " +
                      std::to_string(options.min_pixels) +
                      " needed): the photo is black, misses the canvas or is saturated; not "
                      "checked against the fit");
    if (r.flags & kResidualGainOff) {
      const double percent = (r.gain - 1.0) * 100.0;
      lines.push_back(Name(r) + ": the photo is " + Fixed(r.gain, 2) +
                      "x as bright as its relit image (" + (percent >= 0 ? "+" : "") +
                      Fixed(percent, 0) +
                      " %): its light's intensity differs from the calibration (an uncalibrated "
                      "RTI flash, a light that drifted, an exposure change)");
    }
    if (r.flags & kResidualShifted) {
      std::string where = "(" + Fixed(r.shift_x_px, 1) + ", " + Fixed(r.shift_y_px, 1) + ") px";
      if (r.shift_mm > 0)
        where += " (" + Fixed(r.shift_texels, 1) + " texels, " + Fixed(r.shift_mm, 2) + " mm)";
      lines.push_back(Name(r) + ": the photo is shifted by " + where +
                      " from its relit image: its camera pose is off (misregistration)");
    }
  }
  return lines;
}

}  // namespace digitize
