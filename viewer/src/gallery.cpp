#include "digitize_viewer/gallery.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>

#include "digitize/image_io.h"
#include "digitize_viewer/gl_context.h"

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

Result<Pack> LoadPackForViewer(const std::filesystem::path& path) {
#if DIGITIZE_VIEWER_HAVE_READ_PACK
  return ReadPack(path);
#else
  return Error{path.string() + ": this build has no pack reader (libdigitize/src/pack.cpp)"};
#endif
}

Result<std::vector<ViewCamera>> ReadCameraPath(const std::filesystem::path& path) {
  const std::string name = path.string();
  std::ifstream in(path);
  if (!in) return Error{name + ": cannot open"};
  nlohmann::json j;
  try {
    in >> j;
  } catch (const std::exception& e) {
    return Error{name + ": not JSON (" + e.what() + ")"};
  }
  try {
    if (j.value("format", "") != "digitize.camera_path")
      return Error{name + ": \"format\" must be \"digitize.camera_path\""};
    if (j.value("version", 0) != 1) return Error{name + ": unsupported version (1 expected)"};
    const int w = j.value("width", 640), h = j.value("height", 480);
    const double fov = j.value("fov_y_deg", 50.0);
    if (!j.contains("frames") || !j["frames"].is_array() || j["frames"].empty())
      return Error{name + ": \"frames\" must be a non-empty array"};
    std::vector<ViewCamera> out;
    auto vec = [](const nlohmann::json& a) {
      if (!a.is_array() || a.size() != 3) throw std::runtime_error("3 numbers expected");
      return Vec3d(a[0].get<double>(), a[1].get<double>(), a[2].get<double>());
    };
    for (size_t i = 0; i < j["frames"].size(); ++i) {
      const auto& f = j["frames"][i];
      const std::string where = name + ": frames[" + std::to_string(i) + "]";
      ViewCamera c;
      c.width = w;
      c.height = h;
      c.fov_y_deg = fov;
      c.near_mm = 10;
      c.far_mm = 1e6;
      try {
        c.eye_mm = vec(f.at("eye"));
        c.target_mm = vec(f.at("target"));
        c.up = f.contains("up") ? vec(f["up"]) : Vec3d::UnitZ();
      } catch (const std::exception& e) {
        return Error{where + ": " + e.what()};
      }
      if (Status s = c.Validate(); !s.ok()) return Error{where + ": " + s.message()};
      out.push_back(c);
    }
    return out;
  } catch (const std::exception& e) {
    return Error{name + ": " + e.what()};
  }
}

std::filesystem::path ScreenshotPath(const std::filesystem::path& out_png, size_t index,
                                     size_t count) {
  if (count <= 1) return out_png;
  char suffix[24];  // "_" + up to 20 digits of a size_t + NUL
  std::snprintf(suffix, sizeof(suffix), "_%03zu", index);
  return out_png.parent_path() /
         (out_png.stem().string() + suffix + out_png.extension().string());
}

Status RenderGalleryScreenshots(const std::vector<std::pair<std::string, Pack>>& packs,
                                const std::filesystem::path& out_png,
                                const std::vector<ViewCamera>& path,
                                const GalleryShotOptions& options) {
  auto context = HeadlessContext::Create();
  if (!context) return context.error();
  auto renderer = Renderer::Create();
  if (!renderer) return renderer.error();
  std::vector<Eigen::Vector2d> sizes;
  for (const auto& p : packs) sizes.emplace_back(p.second.width_mm(), p.second.height_mm());
  const Gallery g = MakeGallery(sizes);
  for (size_t i = 0; i < packs.size(); ++i) {
    auto added = (*renderer)->AddPainting(packs[i].second, packs[i].first, g.world_from_canvas[i]);
    if (!added) return added.error();
  }
  (*renderer)->SetSceneBoxes(g.boxes);
  // As every other command: a missing output folder is made (only now, when all is ready).
  if (const std::filesystem::path dir = out_png.parent_path(); !dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) return Error{dir.string() + ": cannot create the screenshot folder: " + ec.message()};
  }
  std::vector<ViewCamera> cameras = path;
  if (cameras.empty()) {
    ViewCamera c = g.start;
    c.width = options.width;
    c.height = options.height;
    cameras.push_back(c);
  }
  for (size_t i = 0; i < cameras.size(); ++i) {
    const RenderedImage img = (*renderer)->Render(cameras[i], g.lights, options.render);
    const std::filesystem::path out = ScreenshotPath(out_png, i, cameras.size());
    if (Status s = WritePngRgb8(out, ToneMap(img.rgb, options.exposure)); !s.ok()) return s;
  }
  return Status::Ok();
}

}  // namespace digitize::viewer
