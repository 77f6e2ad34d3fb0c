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

}  // namespace digitize::viewer
