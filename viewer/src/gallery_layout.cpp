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
                   frame_mm, light_distance_mm, view_distance_mm})
    if (!(v > 0 && std::isfinite(v))) return Error{"gallery: every length must be > 0"};
  return Status::Ok();
}

namespace {

SceneBox Box(const Vec3d& lo, const Vec3d& hi, const Vec3f& albedo,
             SceneSurface surface = SceneSurface::kPlain) {
  SceneBox b;
  b.min_mm = lo.cwiseMin(hi);
  b.max_mm = lo.cwiseMax(hi);
  b.albedo = albedo;
  b.surface = surface;
  return b;
}

// A moulded frame round the canvas rectangle [x0, x1] x [z0, z1] hung on the wall plane y =
// wall_y: a profile of steps across the moulding (outer band, raised lip, cove, bead, slip), each
// a ring of four boxes standing out of the wall by its depth, so the picture light catches the
// lip and leaves the cove in half shadow as on a carved frame.
void AddFrame(std::vector<SceneBox>& boxes, double x0, double z0, double x1, double z1,
              double wall_y, double width) {
  struct Step {
    double from, to, depth;  // fractions of the width from the sight edge; depth in mm
    Vec3f albedo;
  };
  const Vec3f gilt(0.62f, 0.47f, 0.22f), dark_gilt(0.42f, 0.31f, 0.14f), slip(0.55f, 0.5f, 0.4f);
  const Step steps[] = {
      {0.00, 0.14, 18, slip},       // the slip round the canvas
      {0.14, 0.26, 44, gilt},       // bead
      {0.26, 0.58, 36, dark_gilt},  // cove
      {0.58, 0.82, 52, gilt},       // lip, the frame's top
      {0.82, 1.00, 40, dark_gilt},  // outer band
  };
  for (const Step& st : steps) {
    const double a = st.from * width, b = st.to * width, y = wall_y - st.depth;
    boxes.push_back(Box({x0 - b, y, z0 - b}, {x1 + b, wall_y, z0 - a}, st.albedo));  // bottom
    boxes.push_back(Box({x0 - b, y, z1 + a}, {x1 + b, wall_y, z1 + b}, st.albedo));  // top
    boxes.push_back(Box({x0 - b, y, z0 - a}, {x0 - a, wall_y, z1 + a}, st.albedo));  // left
    boxes.push_back(Box({x1 + a, y, z0 - a}, {x1 + b, wall_y, z1 + a}, st.albedo));  // right
  }
}

}  // namespace

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
  // A museum room: muted deep walls so the lit paintings stand out, a pale ceiling, oak boards.
  const Vec3f wall(0.2f, 0.25f, 0.26f), floor(0.36f, 0.24f, 0.14f), ceiling(0.78f, 0.78f, 0.76f);
  const Vec3f skirting(0.72f, 0.71f, 0.68f), metal(0.05f, 0.05f, 0.055f);
  auto& boxes = g.room.boxes;
  boxes = {
      Box({-t, -t, -t}, {W + t, D + t, 0}, floor, SceneSurface::kFloorboards),
      Box({-t, -t, H}, {W + t, D + t, H + t}, ceiling),
      Box({-t, D, 0}, {W + t, D + t, H}, wall),  // back wall
      Box({-t, -t, 0}, {W + t, 0, H}, wall),     // front wall (behind the start)
      Box({-t, 0, 0}, {0, D, H}, wall),          // left
      Box({W, 0, 0}, {W + t, D, H}, wall),       // right
  };
  const double sk_h = 120, sk_t = 16;  // skirting boards round the four walls
  boxes.push_back(Box({0, D - sk_t, 0}, {W, D, sk_h}, skirting));
  boxes.push_back(Box({0, 0, 0}, {W, sk_t, sk_h}, skirting));
  boxes.push_back(Box({0, 0, 0}, {sk_t, D, sk_h}, skirting));
  boxes.push_back(Box({W - sk_t, 0, 0}, {W, D, sk_h}, skirting));
  g.room.ambient = 0.2;

  // Canvas X -> world X, canvas Y -> world Z, canvas Z -> world -Y.
  Mat3d r;
  r << 1, 0, 0, 0, 0, -1, 0, 1, 0;
  double x = (W - (total - o.gap_mm)) / 2 + o.gap_mm / 2;  // centre the row
  const double wall_y = D - 2;                             // canvases 2 mm in front of the wall
  const double a = 30 * kPi / 180;                         // the lights' elevation
  const double track_y = D - o.light_distance_mm * std::cos(a);
  if (!sizes_mm.empty())  // the lighting track the picture lights hang from, wall to wall
    boxes.push_back(Box({0, track_y - 20, H - 30}, {W, track_y + 20, H}, metal));
  for (const auto& s : sizes_mm) {
    const double x0 = x + o.frame_mm, z0 = o.centre_height_mm - s.y() / 2;
    RigidTransform t_wc;
    t_wc.rotation = r;
    t_wc.translation = Vec3d(x0, wall_y, z0);
    g.world_from_canvas.push_back(t_wc);
    AddFrame(boxes, x0, z0, x0 + s.x(), z0 + s.y(), wall_y, o.frame_mm);
    const Vec3d centre(x0 + s.x() / 2, wall_y, o.centre_height_mm);
    g.centres_mm.push_back(centre);
    g.sizes_mm.push_back(s);
    Light light;
    light.type = LightType::kPoint;
    light.position_mm = centre + o.light_distance_mm * Vec3d(0, -std::cos(a), std::sin(a));
    // White Lambertian at the centre reads 1: I cos(theta) / (pi d^2) = 1.
    const double d = o.light_distance_mm;
    light.intensity = Vec3f::Constant(float(kPi * d * d / std::cos(a)));
    g.lights.push_back(light);
    // Its cone: the frame's corners inside the full-strength angle, a soft pool round it.
    SpotCone spot;
    spot.axis = (centre - light.position_mm).normalized();
    const double half_diag = 0.5 * std::hypot(s.x(), s.y()) + o.frame_mm;
    spot.inner_deg = std::atan2(half_diag, d) * 180 / kPi + 3;
    spot.outer_deg = spot.inner_deg + 8;
    g.room.spots.push_back(spot);
    // The fixture: a stem from the track, a can, its lens (facing down towards the wall).
    const Vec3d& l = light.position_mm;
    boxes.push_back(Box(l + Vec3d(-8, -8, 40), Vec3d(l.x() + 8, l.y() + 8, H - 30), metal));
    boxes.push_back(Box(l + Vec3d(-35, -35, -10), l + Vec3d(35, 35, 60), metal));
    boxes.push_back(Box(l + Vec3d(-25, -25, -14), l + Vec3d(25, 25, -10), Vec3f(3.0f, 2.8f, 2.5f),
                        SceneSurface::kEmissive));
    x += s.x() + 2 * o.frame_mm + o.gap_mm;
  }
  // A visitor at the first painting, a little to its left, looking along the wall between it and
  // the next one (or past it), at eye height: the room's perspective and the next paintings show.
  const Vec3d first = g.centres_mm.empty() ? Vec3d(W / 2, D, o.centre_height_mm) : g.centres_mm[0];
  const Vec3d next =
      g.centres_mm.size() > 1 ? g.centres_mm[1] : first + Vec3d(std::min(1500.0, W / 4), 0, 0);
  const double dist = std::min(o.view_distance_mm, 0.8 * D);
  g.start.eye_mm = Vec3d(std::clamp(first.x() - 0.3 * dist, 300.0, W - 300.0), D - dist, 1600);
  g.start.target_mm = Vec3d(0.5 * (first.x() + next.x()), D, o.centre_height_mm - 80);
  g.start.up = Vec3d::UnitZ();
  g.start.fov_y_deg = 55;
  g.start.near_mm = 10;
  g.start.far_mm = 4 * (W + D + H);
  return g;
}

ViewCamera CloseUpView(const Gallery& gallery, size_t index) {
  DIGITIZE_CHECK(index < gallery.centres_mm.size(),
                 "CloseUpView: no painting " + std::to_string(index));
  const Vec3d c = gallery.centres_mm[index];
  const double angle = 35 * kPi / 180, d = 350;
  ViewCamera v;
  v.eye_mm = c + d * Vec3d(-std::sin(angle), -std::cos(angle), 0.12).normalized();
  v.target_mm = c;
  v.up = Vec3d::UnitZ();
  v.fov_y_deg = 45;
  v.near_mm = 5;
  v.far_mm = 4 * (gallery.width_mm + gallery.depth_mm + gallery.height_mm);
  return v;
}

std::vector<ViewCamera> GalleryTour(const Gallery& g, int frames, int width, int height) {
  DIGITIZE_CHECK(frames >= 2, "GalleryTour: at least 2 frames");
  std::vector<ViewCamera> keys = {g.start};
  for (size_t i = 0; i < g.centres_mm.size(); ++i) {
    ViewCamera front = g.start;
    const double d = std::clamp(3 * g.sizes_mm[i].maxCoeff(), 400.0, 1200.0);
    front.eye_mm = g.centres_mm[i] + Vec3d(0, -d, 0.04 * d);
    front.target_mm = g.centres_mm[i];
    keys.push_back(front);
    if (i == 0) {
      ViewCamera near = CloseUpView(g, 0);
      near.fov_y_deg = g.start.fov_y_deg;
      keys.push_back(near);
      keys.push_back(front);  // and back before walking on
    }
  }
  // Each leg's share of the frames: the eye's walk plus the gaze's swing (mm at 1 m).
  std::vector<double> length(keys.size(), 0.0);
  for (size_t k = 1; k < keys.size(); ++k) {
    const Vec3d a = (keys[k - 1].target_mm - keys[k - 1].eye_mm).normalized();
    const Vec3d b = (keys[k].target_mm - keys[k].eye_mm).normalized();
    length[k] =
        length[k - 1] + (keys[k].eye_mm - keys[k - 1].eye_mm).norm() + 1000 * (a - b).norm();
  }
  std::vector<ViewCamera> out;
  const double total = length.back();
  for (int f = 0; f < frames; ++f) {
    const double at = total * f / (frames - 1);
    size_t k = 1;
    while (k + 1 < keys.size() && length[k] < at) ++k;
    ViewCamera c = keys.size() == 1 ? keys[0] : keys[k];
    if (keys.size() > 1 && length[k] > length[k - 1]) {
      const double u = std::clamp((at - length[k - 1]) / (length[k] - length[k - 1]), 0.0, 1.0);
      const double e = u * u * (3 - 2 * u);  // ease in and out: no jolt at a stop
      c.eye_mm = (1 - e) * keys[k - 1].eye_mm + e * keys[k].eye_mm;
      // The gaze turns through the direction, not the target point (which may jump sideways).
      const Vec3d a = (keys[k - 1].target_mm - keys[k - 1].eye_mm).normalized();
      const Vec3d b = (keys[k].target_mm - keys[k].eye_mm).normalized();
      Vec3d d = (1 - e) * a + e * b;
      if (d.norm() < 1e-6) d = b;
      c.target_mm = c.eye_mm + 1000 * d.normalized();
      c.near_mm = std::min(keys[k - 1].near_mm, keys[k].near_mm);
    }
    c.width = width;
    c.height = height;
    c.up = Vec3d::UnitZ();
    c.eye_mm.x() = std::clamp(c.eye_mm.x(), 100.0, g.width_mm - 100);
    c.eye_mm.y() = std::clamp(c.eye_mm.y(), 100.0, g.depth_mm - 100);
    c.eye_mm.z() = std::clamp(c.eye_mm.z(), 100.0, g.height_mm - 100);
    out.push_back(c);
  }
  return out;
}

Result<Pack> LoadPackForViewer(const std::filesystem::path& path) { return ReadPack(path); }

bool IsTiledPack(const std::filesystem::path& path) {
  auto summary = InspectPack(path);
  return summary.ok() && summary->tile_size > 0;
}

}  // namespace digitize::viewer
