// The gallery's layout and the viewer's pack loading (gallery.h): no GL here, so that the load
// path links into the fuzz target (tests/fuzz/fuzz_viewer_load.cpp) without a GL library.
#include <algorithm>
#include <cmath>

#include "digitize_viewer/gallery.h"

namespace digitize::viewer {
namespace {
constexpr double kPi = 3.14159265358979323846;
}

Status GalleryOptions::Validate() const {
  for (double v : {min_room_width_mm, room_depth_mm, room_height_mm, centre_height_mm, gap_mm,
                   frame_mm, light_distance_mm})
    if (!(v > 0 && std::isfinite(v))) return Error{"gallery: every length must be > 0"};
  return Status::Ok();
}

Gallery MakeGallery(const std::vector<Eigen::Vector2d>& sizes_mm, const GalleryOptions& o) {
  const Status valid = o.Validate();
  DIGITIZE_CHECK(valid.ok(), valid.message());
  Gallery g;
  double total = o.gap_mm;
  for (const auto& s : sizes_mm) total += s.x() + 2 * o.frame_mm + o.gap_mm;
  g.width_mm = std::max(o.min_room_width_mm, total);
  g.depth_mm = o.room_depth_mm;
  g.height_mm = o.room_height_mm;
  const double W = g.width_mm, D = g.depth_mm, H = g.height_mm, t = 100;  // wall thickness
  // Darkish walls as in museums: the paintings, lit to paper white, stand out.
  const Vec3f wall(0.28f, 0.30f, 0.34f), floor(0.30f, 0.22f, 0.16f), ceiling(0.6f, 0.6f, 0.6f);
  g.boxes = {
      {Vec3d(-t, -t, -t), Vec3d(W + t, D + t, 0), floor},
      {Vec3d(-t, -t, H), Vec3d(W + t, D + t, H + t), ceiling},
      {Vec3d(-t, D, 0), Vec3d(W + t, D + t, H), wall},  // back wall
      {Vec3d(-t, -t, 0), Vec3d(W + t, 0, H), wall},     // front wall (behind the start)
      {Vec3d(-t, 0, 0), Vec3d(0, D, H), wall},          // left
      {Vec3d(W, 0, 0), Vec3d(W + t, D, H), wall},       // right
  };
  // Canvas X -> world X, canvas Y -> world Z, canvas Z -> world -Y.
  Mat3d r;
  r << 1, 0, 0, 0, 0, -1, 0, 1, 0;
  double x = (W - (total - o.gap_mm)) / 2 + o.gap_mm / 2;  // centre the row
  const double wall_y = D - 2;                             // canvases 2 mm in front of the wall
  const Vec3f gold(0.55f, 0.42f, 0.2f);
  for (const auto& s : sizes_mm) {
    const double x0 = x + o.frame_mm, z0 = o.centre_height_mm - s.y() / 2;
    RigidTransform t_wc;
    t_wc.rotation = r;
    t_wc.translation = Vec3d(x0, wall_y, z0);
    g.world_from_canvas.push_back(t_wc);
    const double f = o.frame_mm, depth = 40;
    const double x1 = x0 + s.x(), z1 = z0 + s.y(), y0 = wall_y - depth;
    g.boxes.push_back({Vec3d(x0 - f, y0, z0 - f), Vec3d(x1 + f, wall_y, z0), gold});  // bottom
    g.boxes.push_back({Vec3d(x0 - f, y0, z1), Vec3d(x1 + f, wall_y, z1 + f), gold});  // top
    g.boxes.push_back({Vec3d(x0 - f, y0, z0), Vec3d(x0, wall_y, z1), gold});          // left
    g.boxes.push_back({Vec3d(x1, y0, z0), Vec3d(x1 + f, wall_y, z1), gold});          // right
    const Vec3d centre(x0 + s.x() / 2, wall_y, o.centre_height_mm);
    Light light;
    light.type = LightType::kPoint;
    const double a = 30 * kPi / 180;
    light.position_mm = centre + o.light_distance_mm * Vec3d(0, -std::cos(a), std::sin(a));
    // White Lambertian at the centre reads 1: I cos(theta) / (pi d^2) = 1.
    const double d = o.light_distance_mm;
    light.intensity = Vec3f::Constant(float(kPi * d * d / std::cos(a)));
    g.lights.push_back(light);
    x += s.x() + 2 * o.frame_mm + o.gap_mm;
  }
  g.start.eye_mm = Vec3d(W / 2, std::max(600.0, D - 2200), 1600);
  g.start.target_mm = Vec3d(W / 2, D, o.centre_height_mm);
  g.start.up = Vec3d::UnitZ();
  g.start.fov_y_deg = 45;
  g.start.near_mm = 10;
  g.start.far_mm = 4 * (W + D + H);
  return g;
}

Result<Pack> LoadPackForViewer(const std::filesystem::path& path) { return ReadPack(path); }

}  // namespace digitize::viewer
