// Camera rays into the canvas frame, a row at a time: what RenderRelit and the pixel maps of the
// samples (MapPixelsToTexels) both trace. Private to the samples layer.
#pragma once

#include <algorithm>
#include <span>

#include "digitize/core.h"
#include "digitize/height_field.h"
#include "digitize/height_field_tracer.h"
#include "digitize/photo_set.h"

namespace digitize {

// Height (canvas frame) at which descending camera rays start: 1 mm above the highest relief and
// frame top. A hit point then carries the float rounding of its coordinates only, not of a
// ~1000 mm ray length (comparable to the shadow rays' origin offset).
inline double CameraRayStartZ(const HeightFieldTracer& tracer, const HeightField& canvas) {
  return std::max<double>(tracer.max_height_mm(), canvas.frame.max_raise_mm()) + 1.0;
}

// The rays through the pixel centres of row v, canvas frame (unit directions).
inline void CameraRowRays(const Camera& camera, const RigidTransform& canvas_from_scan,
                          double start_z, int v, std::span<Vec3f> origins,
                          std::span<Vec3f> directions) {
  for (int u = 0; u < camera.width; ++u) {
    Vec3d o, d;
    camera.Ray(u, v, o, d);
    o = canvas_from_scan.Apply(o);
    d = (canvas_from_scan.rotation * d).normalized();
    if (d.z() < 0 && o.z() > start_z) o += ((o.z() - start_z) / -d.z()) * d;
    origins[u] = o.cast<float>();
    directions[u] = d.cast<float>();
  }
}

}  // namespace digitize
