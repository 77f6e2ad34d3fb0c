// Reflective-sphere light calibration (sphere_calibration.h): OpenCV's HoughCircles for the
// outline, the highlight's centroid for each light.
#include "digitize/sphere_calibration.h"

#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace digitize {

Status SphereDetectOptions::Validate() const {
  if (!(std::isfinite(min_radius_px) && min_radius_px >= 2))
    return Error{"min_radius_px must be >= 2 px, got " + FormatNumber(min_radius_px)};
  if (!(std::isfinite(max_radius_px) && (max_radius_px == 0 || max_radius_px >= min_radius_px)))
    return Error{"max_radius_px must be 0 or >= min_radius_px, got " + FormatNumber(max_radius_px)};
  return Status::Ok();
}

Status SphereLightOptions::Validate() const {
  if (!(std::isfinite(highlight_fraction) && highlight_fraction > 0 && highlight_fraction < 1))
    return Error{"highlight_fraction must be in (0, 1), got " + FormatNumber(highlight_fraction)};
  if (!(std::isfinite(rim_margin) && rim_margin >= 0 && rim_margin < 0.5))
    return Error{"rim_margin must be in [0, 0.5), got " + FormatNumber(rim_margin)};
  if (!(std::isfinite(min_peak) && min_peak >= 0))
    return Error{"min_peak must be >= 0, got " + FormatNumber(min_peak)};
  return Status::Ok();
}

Result<SphereCircle> DetectSphere(const Grid<float>& image, const SphereDetectOptions& options) {
  if (Status s = options.Validate(); !s.ok()) return Error{"sphere detection: " + s.message()};
  if (image.empty()) return Error{"sphere detection: empty image"};
  float lo = image.data[0], hi = image.data[0];
  for (float v : image.data) {
    if (!std::isfinite(v)) return Error{"sphere detection: the image has non-finite pixels"};
    lo = std::min(lo, v), hi = std::max(hi, v);
  }
  if (!(hi > lo)) return Error{"sphere detection: the image is uniform"};
  cv::Mat grey(image.height, image.width, CV_8U);
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x)
      grey.at<uint8_t>(y, x) =
          static_cast<uint8_t>(std::lround(255 * (image(x, y) - lo) / (hi - lo)));
  cv::medianBlur(grey, grey, 5);
  const double max_r =
      options.max_radius_px > 0 ? options.max_radius_px : std::min(image.width, image.height) / 2.0;
  std::vector<cv::Vec3f> circles;
  // Accumulator threshold 20: a clean sphere outline votes with most of its circumference; edge
  // threshold 100 on the 8-bit image (Canny's upper threshold).
  cv::HoughCircles(grey, circles, cv::HOUGH_GRADIENT, 1, std::max(image.width, image.height), 100,
                   20, static_cast<int>(std::floor(options.min_radius_px)),
                   static_cast<int>(std::ceil(max_r)));
  if (circles.empty())
    return Error{"sphere detection: no circle of radius " + FormatNumber(options.min_radius_px) +
                 " .. " + FormatNumber(max_r) + " px found"};
  // Hough's radius is coarse (its accumulator and the median blur leave a few pixels): refine on
  // the image itself. Along 360 rays from the centre, the edge is where the brightness changes
  // most (|I(r - 1) - I(r + 1)|, bilinear, r within 25 % of Hough's); an algebraic (Kasa) circle
  // fit through those edge points, done twice.
  SphereCircle c{circles[0][0], circles[0][1], circles[0][2]};
  auto sample = [&](double x, double y) {
    x = std::clamp(x, 0.0, image.width - 1.0), y = std::clamp(y, 0.0, image.height - 1.0);
    const int x0 = std::min(static_cast<int>(x), image.width - 2 < 0 ? 0 : image.width - 2);
    const int y0 = std::min(static_cast<int>(y), image.height - 2 < 0 ? 0 : image.height - 2);
    const int x1 = std::min(x0 + 1, image.width - 1), y1 = std::min(y0 + 1, image.height - 1);
    const double fx = x - x0, fy = y - y0;
    return (1 - fy) * ((1 - fx) * image(x0, y0) + fx * image(x1, y0)) +
           fy * ((1 - fx) * image(x0, y1) + fx * image(x1, y1));
  };
  for (int round = 0; round < 2; ++round) {
    Eigen::MatrixXd a(360, 3);
    Eigen::VectorXd b(360);
    for (int k = 0; k < 360; ++k) {
      const double t = k * kPi / 180, dx = std::cos(t), dy = std::sin(t);
      double best = -1, best_r = c.radius_px;
      for (double r = 0.75 * c.radius_px; r <= 1.25 * c.radius_px; r += 0.25) {
        const double d = std::abs(sample(c.cx + (r - 1) * dx, c.cy + (r - 1) * dy) -
                                  sample(c.cx + (r + 1) * dx, c.cy + (r + 1) * dy));
        if (d > best) best = d, best_r = r;
      }
      const double x = c.cx + best_r * dx, y = c.cy + best_r * dy;
      a.row(k) << x, y, 1.0;
      b[k] = -(x * x + y * y);
    }
    const Eigen::Vector3d p = a.colPivHouseholderQr().solve(b);
    const double cx = -p[0] / 2, cy = -p[1] / 2, rr = cx * cx + cy * cy - p[2];
    if (!(rr > 0) || !std::isfinite(rr)) break;
    c = SphereCircle{cx, cy, std::sqrt(rr)};
  }
  return c;
}

Result<std::vector<SphereLight>> LightsFromSphere(const std::vector<const Grid<float>*>& images,
                                                  const SphereCircle& circle,
                                                  const SphereLightOptions& options) {
  if (Status s = options.Validate(); !s.ok()) return Error{"sphere lights: " + s.message()};
  if (images.empty()) return Error{"sphere lights: no image"};
  const double r = circle.radius_px;
  for (size_t i = 0; i < images.size(); ++i) {
    if (!images[i] || images[i]->empty())
      return Error{"sphere lights: image " + std::to_string(i) + " is empty"};
    if (images[i]->width != images[0]->width || images[i]->height != images[0]->height)
      return Error{"sphere lights: image " + std::to_string(i) + " differs in size from image 0"};
  }
  const int w = images[0]->width, h = images[0]->height;
  if (!(std::isfinite(r) && r >= 2 && circle.cx - r >= -0.5 && circle.cy - r >= -0.5 &&
        circle.cx + r <= w - 0.5 && circle.cy + r <= h - 0.5))
    return Error{"sphere lights: the circle (" + FormatNumber(circle.cx) + ", " +
                 FormatNumber(circle.cy) + ", r " + FormatNumber(r) + ") does not fit the " +
                 std::to_string(w) + "x" + std::to_string(h) + " image"};
  const double inner = r * (1 - options.rim_margin);
  const int x0 = std::max(0, static_cast<int>(std::floor(circle.cx - r)));
  const int x1 = std::min(w - 1, static_cast<int>(std::ceil(circle.cx + r)));
  const int y0 = std::max(0, static_cast<int>(std::floor(circle.cy - r)));
  const int y1 = std::min(h - 1, static_cast<int>(std::ceil(circle.cy + r)));
  auto inside = [&](int x, int y) { return std::hypot(x - circle.cx, y - circle.cy) <= inner; };
  std::vector<SphereLight> lights(images.size());
  for (size_t i = 0; i < images.size(); ++i) {
    const Grid<float>& im = *images[i];
    float peak = -1;
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x)
        if (inside(x, y) && std::isfinite(im(x, y))) peak = std::max(peak, im(x, y));
    if (!(peak >= options.min_peak)) continue;
    const double threshold = options.highlight_fraction * peak;
    double sw = 0, su = 0, sv = 0;
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) {
        if (!inside(x, y) || !(im(x, y) >= threshold)) continue;
        const double wgt = im(x, y) - threshold + 1e-6 * peak;
        sw += wgt, su += wgt * x, sv += wgt * y;
      }
    if (!(sw > 0)) continue;
    const double u = su / sw, v = sv / sw;
    double nx = (u - circle.cx) / r, ny = -(v - circle.cy) / r;
    const double q = nx * nx + ny * ny;
    if (q > 1) nx /= std::sqrt(q), ny /= std::sqrt(q);
    const Vec3d n(nx, ny, std::sqrt(std::max(0.0, 1 - nx * nx - ny * ny)));
    const Vec3d l = 2 * n.z() * n - Vec3d::UnitZ();
    lights[i].found = true;
    lights[i].direction = l.normalized();
    lights[i].highlight_px = {u, v};
  }
  return lights;
}

}  // namespace digitize
