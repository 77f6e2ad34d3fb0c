// Test helper: a hand-made pack small enough to reason about texel by texel. Header-only; the
// test that includes it links the pack and brdf layers (ReflectanceMaps::Zeros).
#pragma once

#include "digitize/pack.h"

namespace digitize {

// w x h texels of pitch_mm, flat (height 0, normals +z, all measured), Lambertian: rho_d (1/sr)
// rho_even where x + y is even, rho_odd where it is odd. H = 1 mm, boxes of 16 px, no boxes.
inline Pack FlatCheckerPack(int w, int h, double pitch_mm, float rho_even, float rho_odd) {
  Pack p;
  p.field.pitch_mm = pitch_mm;
  p.field.height_mm = Grid<float>(w, h, 0.0f);
  p.field.state = Grid<TexelState>(w, h, TexelState::kMeasured);
  p.normals = Grid<Vec3f>(w, h, Vec3f(0, 0, 1));
  p.maps = ReflectanceMaps::Zeros(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      p.maps.rho_d(x, y) = Vec3f::Constant((x + y) % 2 ? rho_odd : rho_even);
      p.maps.status(x, y) = TexelFitStatus::kDiffuseOnly;
    }
  p.max_height_mm = 1.0;
  p.cell_px = 16;
  return p;
}

}  // namespace digitize
