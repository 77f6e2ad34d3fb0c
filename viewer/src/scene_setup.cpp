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

}  // namespace digitize::viewer
