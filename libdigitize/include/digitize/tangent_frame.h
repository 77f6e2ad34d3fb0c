// The per-texel tangent frame every BRDF direction is expressed in (samples, fit, relighting,
// generator, viewer): z = the texel's unit normal n (canvas frame); x = the canvas X axis made
// perpendicular to n (Gram-Schmidt), so on a flat canvas the frame IS the canvas frame and the
// Lafortune lobe's cx follows the canvas's horizontal axis; y = z x x (right-handed).
// Degenerate normal (|n x X| tiny: a vertical wall facing +-X, never a canvas texel in practice):
// x is built from the canvas Y axis instead. A zero or non-finite n gives the canvas frame.
#pragma once

#include <cmath>

#include "digitize/core.h"

namespace digitize {

struct TangentFrame {
  Vec3d x = Vec3d::UnitX(), y = Vec3d::UnitY(), z = Vec3d::UnitZ();  // orthonormal, canvas frame

  // Canvas-frame direction -> tangent-frame components.
  Vec3d ToLocal(const Vec3d& d) const { return {x.dot(d), y.dot(d), z.dot(d)}; }
  Vec3d ToCanvas(const Vec3d& d) const { return x * d.x() + y * d.y() + z * d.z(); }
};

inline TangentFrame MakeTangentFrame(const Vec3d& normal) {
  TangentFrame f;
  const double len = normal.norm();
  if (!(std::isfinite(len) && len > 1e-12)) return f;
  f.z = normal / len;
  Vec3d axis = Vec3d::UnitX();
  if (f.z.cross(axis).squaredNorm() < 1e-6) axis = Vec3d::UnitY();
  f.x = (axis - f.z * f.z.dot(axis)).normalized();
  f.y = f.z.cross(f.x);
  return f;
}

}  // namespace digitize
