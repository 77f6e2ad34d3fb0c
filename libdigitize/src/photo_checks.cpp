// What a photo set must satisfy before its pixels are used: cameras, lights and options in range,
// each image inside its capture folder and listed once, and every camera seeing the canvas at a
// usable scale.
#include <cmath>
#include <filesystem>
#include <map>
#include <string>
#include <tuple>

#include "digitize/output_dir.h"
#include "digitize/photo_set.h"
#include "photo_set_internal.h"

namespace digitize {

using namespace photo_detail;
namespace fs = std::filesystem;

namespace {

// A rotation built in code (after snapping) must be orthonormal to about float precision.
constexpr double kRotationTolerance = 1e-6;

}  // namespace

Status Camera::Validate(const std::string& what) const {
  const auto bad = [&](const std::string& field, const std::string& problem) {
    return Error{what + "." + field + " " + problem};
  };
  if (width <= 0 || width > kMaxImageSide)
    return bad("width", "must be in 1.." + std::to_string(kMaxImageSide) + " px, got " +
                            std::to_string(width));
  if (height <= 0 || height > kMaxImageSide)
    return bad("height", "must be in 1.." + std::to_string(kMaxImageSide) + " px, got " +
                             std::to_string(height));
  if (model == CameraModel::kPinhole) {
    if (!(std::isfinite(fx) && fx > 0))
      return bad("fx", "must be > 0 px, got " + FormatNumber(fx, kShownDigits));
    if (!(std::isfinite(fy) && fy > 0))
      return bad("fy", "must be > 0 px, got " + FormatNumber(fy, kShownDigits));
    // The field of view over the whole image, whatever the principal point: a focal length off
    // by orders of magnitude (in mm instead of px, or a stray exponent) shows here first.
    const auto fov_deg = [](int size, double f) {
      return 2.0 * std::atan(size / (2.0 * f)) * 180.0 / M_PI;
    };
    for (const auto& [key, size, f, way] :
         {std::tuple{"fx", width, fx, "horizontal"}, std::tuple{"fy", height, fy, "vertical"}}) {
      const double fov = fov_deg(size, f);
      if (!(fov >= kMinFieldOfViewDeg && fov <= kMaxFieldOfViewDeg)) {
        return bad(key, FormatNumber(f, kShownDigits) + " px gives a " + way +
                            " field of view of " + FormatNumber(fov, kShownDigits) + " deg over " +
                            std::to_string(size) + " px; a camera has " +
                            FormatNumber(kMinFieldOfViewDeg, kShownDigits) + " to " +
                            FormatNumber(kMaxFieldOfViewDeg, kShownDigits) + " deg");
      }
    }
  } else {
    if (!(std::isfinite(pixel_pitch_mm) && pixel_pitch_mm > 0)) {
      return bad("pixel_pitch_mm",
                 "must be > 0 mm, got " + FormatNumber(pixel_pitch_mm, kShownDigits));
    }
  }
  if (!std::isfinite(cx)) return bad("cx", "is not finite");
  if (!std::isfinite(cy)) return bad("cy", "is not finite");
  // Shifted lenses move the principal point, but not by more than the image's own size.
  for (const auto& [key, c, size] : {std::tuple{"cx", cx, width}, std::tuple{"cy", cy, height}}) {
    const double margin = kMaxPrincipalPointOffset * size;
    if (!(c >= -margin && c <= size + margin)) {
      return bad(key, FormatNumber(c, kShownDigits) + " px is further outside the " +
                          std::to_string(size) + "-px image than " +
                          FormatNumber(kMaxPrincipalPointOffset, kShownDigits) +
                          " image size (allowed " + FormatNumber(-margin, kShownDigits) + " to " +
                          FormatNumber(size + margin, kShownDigits) + ")");
    }
  }
  const Mat3d& R = camera_from_scan.rotation;
  if (!R.allFinite()) return bad("camera_from_scan.rotation", "is not finite");
  const double det = R.determinant();
  const double off = (R.transpose() * R - Mat3d::Identity()).norm();
  if (!(det > 0) || off > kRotationTolerance) {
    return bad("camera_from_scan.rotation", "is not a rotation (det " +
                                                FormatNumber(det, kShownDigits) + ", |R^T R - I| " +
                                                FormatNumber(off, kShownDigits) + ")");
  }
  if (!camera_from_scan.translation.allFinite()) {
    return bad("camera_from_scan.translation_mm", "is not finite");
  }
  return Status::Ok();
}

Status Light::Validate(const std::string& what) const {
  const auto rgb_ok = [](const Vec3f& v) {
    return v.allFinite() && v.minCoeff() >= 0 && v.maxCoeff() > 0;
  };
  const auto show = [](const Vec3f& v) {
    return "[" + FormatNumber(v.x(), kShownDigits) + ", " + FormatNumber(v.y(), kShownDigits) +
           ", " + FormatNumber(v.z(), kShownDigits) + "]";
  };
  if (type == LightType::kPoint) {
    if (!position_mm.allFinite()) return Error{what + ".position_mm is not finite"};
    if (!rgb_ok(intensity)) {
      return Error{what + ".intensity must be >= 0 and not all zero, got " + show(intensity)};
    }
  } else {
    if (!direction.allFinite() || std::abs(direction.norm() - 1.0) > 1e-6) {
      return Error{what + ".direction must be a unit vector, got |d| = " +
                   FormatNumber(direction.norm(), kShownDigits)};
    }
    if (!rgb_ok(irradiance)) {
      return Error{what + ".irradiance must be >= 0 and not all zero, got " + show(irradiance)};
    }
  }
  return Status::Ok();
}

Status PhotoSetOptions::Validate() const {
  if (!(saturation_encoded > 0 && saturation_encoded <= 1)) {
    return Error{"saturation_encoded must be in (0, 1] (fraction of the maximum code), got " +
                 FormatNumber(saturation_encoded, kShownDigits)};
  }
  if (!(float_saturation_level > 0)) {
    return Error{"float_saturation_level must be > 0 (linear value; inf = never), got " +
                 FormatNumber(float_saturation_level, kShownDigits)};
  }
  if (!(max_non_finite_fraction >= 0 && max_non_finite_fraction <= 1)) {
    return Error{"max_non_finite_fraction must be in [0, 1], got " +
                 FormatNumber(max_non_finite_fraction, kShownDigits)};
  }
  if (max_pixels_per_image == 0) return Error{"max_pixels_per_image must be > 0"};
  if (!(rti_pixel_pitch_mm == 0 ||
        (rti_pixel_pitch_mm >= kMinRtiPitchMm && rti_pixel_pitch_mm <= kMaxRtiPitchMm))) {
    return Error{"rti_pixel_pitch_mm must be " + FormatNumber(kMinRtiPitchMm, kShownDigits) +
                 " to " + FormatNumber(kMaxRtiPitchMm, kShownDigits) +
                 " mm (or 0: from the images), got " +
                 FormatNumber(rti_pixel_pitch_mm, kShownDigits)};
  }
  if (!(std::isfinite(rti_camera_distance_mm) && rti_camera_distance_mm > 0)) {
    return Error{"rti_camera_distance_mm must be > 0 mm, got " +
                 FormatNumber(rti_camera_distance_mm, kShownDigits)};
  }
  return Status::Ok();
}

Status photo_detail::CheckImageInsideFolder(const fs::path& image, const fs::path& dir,
                                            const std::string& entry, const std::string& written,
                                            const PhotoSetOptions& options) {
  if (options.allow_outside_paths) return Status::Ok();
  const fs::path base = ResolvePath(dir.empty() ? fs::path(".") : dir);
  const fs::path resolved = ResolvePath(image);
  if (resolved != base && IsWithinFolder(resolved, base)) return Status::Ok();
  return Error{entry + ": image \"" + written + "\" lies outside the capture folder " +
               base.string() + " (it resolves to " + resolved.string() +
               "); refused unless allowed (--allow-outside-paths)"};
}

// One image listed twice would weigh as two measurements of one light and view. Paths are compared
// once resolved and lexically normalised ("a/../x.png" is "x.png"); the same file under two names
// (a copy, a link) is not looked for: that would mean reading every image's bytes for a mistake
// that a path comparison already catches in the cases met (a line pasted twice, an edited index).
Status photo_detail::CheckDistinctImages(const PhotoSet& set) {
  std::map<fs::path, const Photo*> seen;
  for (const Photo& photo : set.photos) {
    const auto [it, added] = seen.emplace(photo.path.lexically_normal(), &photo);
    if (!added) {
      return Error{photo.entry + ": " + photo.path.string() + " is the same image as " +
                   it->second->entry + " (each image may be listed once)"};
    }
  }
  return Status::Ok();
}

Status CheckCameraSeesCanvas(const Camera& camera, const RigidTransform& canvas_from_scan,
                             const Eigen::Vector2d& extent_mm, const std::string& what) {
  const RigidTransform scan_from_canvas = canvas_from_scan.Inverse();
  const Vec3d centre_scan = scan_from_canvas.Apply(Vec3d(extent_mm.x() / 2, extent_mm.y() / 2, 0));
  const double depth = camera.camera_from_scan.Apply(centre_scan).z();
  if (!(depth > 0)) {
    return Error{what + ": the canvas centre is behind the camera (depth " +
                 FormatNumber(depth, kShownDigits) + " mm)"};
  }
  // The side of the canvas the camera is on: towards-camera direction in the canvas frame.
  const double side = canvas_from_scan.ApplyToDirection(camera.DirectionToCamera(centre_scan)).z();
  if (!(side > 0)) {
    return Error{what +
                 ": the camera is behind the canvas (it looks at the canvas's back; "
                 "direction to the camera has canvas Z " +
                 FormatNumber(side, kShownDigits) + ")"};
  }
  constexpr int kLattice = 9;
  for (int j = 0; j < kLattice; ++j) {
    for (int i = 0; i < kLattice; ++i) {
      const Vec3d p = scan_from_canvas.Apply(
          Vec3d(extent_mm.x() * i / (kLattice - 1), extent_mm.y() * j / (kLattice - 1), 0));
      if (camera.InFront(p) && camera.InImage(camera.Project(p))) return Status::Ok();
    }
  }
  // A camera close to the canvas (a tiled photo set, a part of a photo) may see a patch between
  // the lattice's points: it sees the canvas when its image centre's ray meets the rectangle.
  Vec3d o, d;
  camera.Ray(0.5 * (camera.width - 1), 0.5 * (camera.height - 1), o, d);
  o = canvas_from_scan.Apply(o);
  d = canvas_from_scan.rotation * d;
  if (d.z() < 0 && o.z() > 0) {
    const Vec3d hit = o + (o.z() / -d.z()) * d;
    if (hit.x() >= 0 && hit.y() >= 0 && hit.x() <= extent_mm.x() && hit.y() <= extent_mm.y())
      return Status::Ok();
  }
  const Eigen::Vector2d c = camera.Project(centre_scan);
  return Error{what + ": the camera sees none of the canvas (its centre projects to pixel (" +
               FormatNumber(c.x(), kShownDigits) + ", " + FormatNumber(c.y(), kShownDigits) +
               "), the image is " + Size(camera.width, camera.height) + ")"};
}

Status CheckCanvasFootprint(const Camera& camera, const RigidTransform& canvas_from_scan,
                            const Eigen::Vector2d& extent_mm, double pitch_mm,
                            const std::string& what) {
  const RigidTransform scan_from_canvas = canvas_from_scan.Inverse();
  const Vec3d centre = scan_from_canvas.Apply(Vec3d(extent_mm.x() / 2, extent_mm.y() / 2, 0));
  const Vec3d p = camera.camera_from_scan.Apply(centre);
  // Derivative of the projection along a canvas axis at the centre, px per mm: analytic, so that
  // absurd scales (1e-300) come out as what they are rather than as rounding noise.
  const auto px_per_mm = [&](const Vec3d& axis_canvas) {
    const Vec3d d = camera.camera_from_scan.rotation * (scan_from_canvas.rotation * axis_canvas);
    Eigen::Vector2d j;
    if (camera.model == CameraModel::kOrthographic) {
      j = Eigen::Vector2d(d.x(), d.y()) / camera.pixel_pitch_mm;
    } else {
      j = Eigen::Vector2d(camera.fx * (d.x() * p.z() - p.x() * d.z()),
                          camera.fy * (d.y() * p.z() - p.y() * d.z())) /
          (p.z() * p.z());
    }
    return j.norm();
  };
  const double sx = px_per_mm(Vec3d::UnitX()), sy = px_per_mm(Vec3d::UnitY());
  const double wide = sx * extent_mm.x(), tall = sy * extent_mm.y();
  if (!(wide >= kMinCanvasFootprintPx && tall >= kMinCanvasFootprintPx)) {
    return Error{what + ": the canvas spans only " + FormatNumber(wide, kShownDigits) + " x " +
                 FormatNumber(tall, kShownDigits) + " px in this photo (at least " +
                 FormatNumber(kMinCanvasFootprintPx, kShownDigits) +
                 " px along each axis): its focal length, pixel pitch or distance is off"};
  }
  for (const auto& [axis, s] : {std::pair{"X", sx}, std::pair{"Y", sy}}) {
    const double px_per_texel = s * pitch_mm;
    if (!(px_per_texel >= 1.0 / kMaxTexelsPerPixel)) {
      return Error{what + ": one pixel of this photo spans " +
                   FormatNumber(1.0 / px_per_texel, kShownDigits) + " texels along the canvas's " +
                   axis + " (at most " + FormatNumber(kMaxTexelsPerPixel, kShownDigits) +
                   "): too coarse for a canvas of pitch " + FormatNumber(pitch_mm, kShownDigits) +
                   " mm"};
    }
    if (!(px_per_texel <= kMaxPixelsPerTexel)) {
      return Error{what + ": one texel of the canvas (pitch " +
                   FormatNumber(pitch_mm, kShownDigits) + " mm) spans " +
                   FormatNumber(px_per_texel, kShownDigits) +
                   " pixels of this photo along the canvas's " + axis + " (at most " +
                   FormatNumber(kMaxPixelsPerTexel, kShownDigits) +
                   "): its focal length, pixel pitch or distance is off"};
    }
  }
  return Status::Ok();
}

Status CheckCamerasSeeCanvas(const PhotoSet& set, const RigidTransform& canvas_from_scan,
                             const HeightField& canvas) {
  const Eigen::Vector2d extent = canvas.extent_mm();
  for (const Photo& photo : set.photos) {
    if (Status s = CheckCameraSeesCanvas(photo.camera, canvas_from_scan, extent, photo.entry); !s) {
      return s;
    }
    if (Status s = CheckCanvasFootprint(photo.camera, canvas_from_scan, extent, canvas.pitch_mm,
                                        photo.entry);
        !s) {
      return s;
    }
  }
  return Status::Ok();
}

}  // namespace digitize
