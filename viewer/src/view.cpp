#include "digitize_viewer/view.h"

#include <algorithm>
#include <cmath>

namespace digitize::viewer {
namespace {
constexpr double kDegToRad = 3.14159265358979323846 / 180.0;
}

Status ViewCamera::Validate() const {
  if (!eye_mm.allFinite() || !target_mm.allFinite() || !up.allFinite())
    return Error{"camera: eye, target and up must be finite"};
  const Vec3d forward = target_mm - eye_mm;
  if (forward.norm() <= 1e-9) return Error{"camera: eye and target coincide"};
  if (up.norm() <= 1e-12 || forward.normalized().cross(up.normalized()).norm() < 1e-6)
    return Error{"camera: up must not be zero or parallel to the view direction"};
  if (!(fov_y_deg > 0 && fov_y_deg < 180))
    return Error{"camera: fov_y_deg must be in (0, 180), got " + FormatNumber(fov_y_deg)};
  if (width <= 0 || height <= 0)
    return Error{"camera: image size must be positive, got " + std::to_string(width) + "x" +
                 std::to_string(height)};
  if (!(near_mm > 0 && far_mm > near_mm && std::isfinite(far_mm)))
    return Error{"camera: need 0 < near_mm < far_mm, got " + FormatNumber(near_mm) + ", " +
                 FormatNumber(far_mm)};
  return Status::Ok();
}

Camera ToCamera(const ViewCamera& view) {
  Camera c;
  c.model = CameraModel::kPinhole;
  c.width = view.width;
  c.height = view.height;
  c.fx = c.fy = 0.5 * view.height / std::tan(0.5 * view.fov_y_deg * kDegToRad);
  c.cx = 0.5 * (view.width - 1);
  c.cy = 0.5 * (view.height - 1);
  const Vec3d forward = (view.target_mm - view.eye_mm).normalized();
  const Vec3d right = forward.cross(view.up).normalized();
  const Vec3d down = forward.cross(right);
  c.camera_from_scan.rotation.row(0) = right.transpose();
  c.camera_from_scan.rotation.row(1) = down.transpose();
  c.camera_from_scan.rotation.row(2) = forward.transpose();
  c.camera_from_scan.translation = -(c.camera_from_scan.rotation * view.eye_mm);
  return c;
}

std::string PaperView::Name() const {
  const char* d = distance == ViewDistance::kClose    ? "close"
                  : distance == ViewDistance::kFramed ? "framed"
                                                      : "far";
  return std::string(d) + (angle == ViewAngle::kFace ? "-face" : "-grazing");
}

std::vector<PaperView> AllPaperViews() {
  std::vector<PaperView> out;
  for (ViewDistance d : {ViewDistance::kClose, ViewDistance::kFramed, ViewDistance::kFar})
    for (ViewAngle a : {ViewAngle::kFace, ViewAngle::kGrazing}) out.push_back({d, a});
  return out;
}

ViewCamera MakePaperView(double canvas_width_mm, double canvas_height_mm, const PaperView& view,
                         int width, int height) {
  ViewCamera cam;
  cam.width = width;
  cam.height = height;
  cam.fov_y_deg = 40;
  const double aspect = double(width) / height;
  const double framed = 0.55 * std::max(canvas_height_mm, canvas_width_mm / aspect) /
                        std::tan(0.5 * cam.fov_y_deg * kDegToRad);
  const double d = view.distance == ViewDistance::kClose    ? framed / 4
                   : view.distance == ViewDistance::kFramed ? framed
                                                            : 4 * framed;
  const Vec3d centre(0.5 * canvas_width_mm, 0.5 * canvas_height_mm, 0);
  const double a = view.angle == ViewAngle::kFace ? 0.0 : kGrazingDeg * kDegToRad;
  cam.target_mm = centre;
  cam.eye_mm = centre + d * Vec3d(0, -std::sin(a), std::cos(a));
  cam.up = view.angle == ViewAngle::kFace ? Vec3d::UnitY() : Vec3d::UnitZ();
  cam.near_mm = std::max(0.1, d * 0.02);
  cam.far_mm = d * 10 + 10 * std::max(canvas_width_mm, canvas_height_mm);
  return cam;
}

}  // namespace digitize::viewer
