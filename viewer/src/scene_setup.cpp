#include "digitize_viewer/scene_setup.h"

#include <algorithm>
#include <cmath>

namespace digitize::viewer {

Light StandardLight(const Pack& pack) {
  const double w = pack.width_mm(), h = pack.height_mm();
  const Vec3d centre(0.5 * w, 0.5 * h, 0);
  Light light;
  light.type = LightType::kPoint;
  light.position_mm = centre + Vec3d(-0.35 * w, 0.25 * h, 0.9 * std::max(w, h));
  const double d = (light.position_mm - centre).norm();
  light.intensity = Vec3f::Constant(float(3.14159265358979323846 * d * d));
  return light;
}

RelitImage RenderReference(const HeightFieldTracer& tracer, const Pack& pack,
                           const ViewCamera& view, const Light& light, bool shadows) {
  RelightOptions options;
  options.shadows = shadows;
  return RenderRelit(tracer, pack.field, pack.normals, pack.maps, RigidTransform{}, ToCamera(view),
                     light, options);
}

ViewCamera Supersampled(const ViewCamera& view, int s) {
  ViewCamera out = view;
  out.width = view.width * s;
  out.height = view.height * s;
  return out;
}

Grid<Vec3f> Downsample(const Grid<Vec3f>& image, int s) {
  Grid<Vec3f> out(image.width / s, image.height / s);
  for (int y = 0; y < out.height; ++y)
    for (int x = 0; x < out.width; ++x) {
      Vec3f sum = Vec3f::Zero();
      for (int dy = 0; dy < s; ++dy)
        for (int dx = 0; dx < s; ++dx) sum += image(x * s + dx, y * s + dy);
      out(x, y) = sum / float(s * s);
    }
  return out;
}

Grid<uint8_t> DownsampleMask(const Grid<uint8_t>& mask, int s) {
  Grid<uint8_t> out(mask.width / s, mask.height / s, 0);
  for (int y = 0; y < out.height; ++y)
    for (int x = 0; x < out.width; ++x) {
      bool all = true;
      for (int dy = 0; dy < s && all; ++dy)
        for (int dx = 0; dx < s && all; ++dx) all = mask(x * s + dx, y * s + dy) != 0;
      out(x, y) = all ? 1 : 0;
    }
  return out;
}

Grid<uint8_t> InteriorMask(const Grid<uint8_t>& mask) {
  Grid<uint8_t> out(mask.width, mask.height, 0);
  for (int y = 1; y + 1 < mask.height; ++y)
    for (int x = 1; x + 1 < mask.width; ++x) {
      bool all = true;
      for (int dy = -1; dy <= 1 && all; ++dy)
        for (int dx = -1; dx <= 1 && all; ++dx) all = mask(x + dx, y + dy) != 0;
      out(x, y) = all ? 1 : 0;
    }
  return out;
}

namespace {

Grid<float> DisplayLuminance(const Grid<Vec3f>& img, double exposure) {
  Grid<float> out(img.width, img.height);
  for (size_t i = 0; i < img.data.size(); ++i) {
    const Vec3f d = DisplayColour(img.data[i], exposure);
    out.data[i] = 0.2126f * d.x() + 0.7152f * d.y() + 0.0722f * d.z();
  }
  return out;
}

}  // namespace

std::vector<ViewCamera> SlowPath(const Pack& pack, int width, int height, int steps) {
  std::vector<ViewCamera> path = {
      MakePaperView(pack.width_mm(), pack.height_mm(), {}, width, height)};
  for (int i = 0; i < steps; ++i) {
    ViewCamera b = path.back();
    const double d = (b.eye_mm - b.target_mm).norm();
    b.eye_mm += Vec3d(0.005 * d, 0.002 * d, -0.01 * d);
    b.target_mm += Vec3d(0.005 * d, 0.002 * d, 0);
    path.push_back(b);
  }
  return path;
}

CoherenceResidual MeasureCoherence(Renderer& renderer, const Pack& pack, const Light& light,
                                   const std::vector<ViewCamera>& path,
                                   const RenderOptions& options) {
  RenderOptions o = options;
  o.technique = Technique::kBump;
  const double plane = pack.delta0_mm;
  CoherenceResidual r;
  double warped = 0, unwarped = 0;
  Grid<float> prev;
  for (size_t k = 0; k < path.size(); ++k) {
    const Grid<float> next = DisplayLuminance(renderer.Render(path[k], {light}, o).rgb, o.exposure);
    if (k > 0) {
      const ViewCamera &a = path[k - 1], &b = path[k];
      const Camera ca = ToCamera(a), cb = ToCamera(b);
      for (int y = 8; y < b.height - 8; ++y)
        for (int x = 8; x < b.width - 8; ++x) {
          Vec3d origin, dir;
          cb.Ray(x, y, origin, dir);
          if (std::abs(dir.z()) < 1e-9) continue;
          const Vec3d p = origin + dir * ((plane - origin.z()) / dir.z());
          if (p.x() < 2 || p.y() < 2 || p.x() > pack.width_mm() - 2 ||
              p.y() > pack.height_mm() - 2 || !ca.InFront(p))
            continue;
          const Eigen::Vector2d q = ca.Project(p);
          const int qx = int(std::floor(q.x())), qy = int(std::floor(q.y()));
          if (qx < 1 || qy < 1 || qx >= a.width - 2 || qy >= a.height - 2) continue;
          const double fx = q.x() - qx, fy = q.y() - qy;  // bilinear: strokes are ~2 px
          const double then = (1 - fy) * ((1 - fx) * prev(qx, qy) + fx * prev(qx + 1, qy)) +
                              fy * ((1 - fx) * prev(qx, qy + 1) + fx * prev(qx + 1, qy + 1));
          warped += std::abs(next(x, y) - then);
          unwarped += std::abs(next(x, y) - prev(x, y));
          ++r.pixels;
        }
    }
    prev = next;
  }
  if (r.pixels > 0) {
    r.warped = warped / double(r.pixels);
    r.unwarped = unwarped / double(r.pixels);
  }
  return r;
}

}  // namespace digitize::viewer
