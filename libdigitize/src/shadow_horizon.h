// Horizon bounds of canvas texels: per texel and azimuth sector, an UPPER bound on the slope
// (tan of the elevation) of everything the surface of height_field_tracer.h (the triangulated
// texel grid, its outline ring and the frame's boxes) holds in that sector as seen from the
// texel's vertex. A ray leaving the texel's vertex whose slope exceeds the bound of its sector
// cannot meet the surface (for any tfar): the sample gatherer skips its shadow and visibility
// rays without calling the tracer, and traces the rest as before, so results do not change.
// Private to the samples layer (reflectance_samples.cpp).
//
// Why it is an upper bound. Over a quad of the grid the surface is planar per triangle, so its
// height is at most the quad's highest corner; a ray of slope s is at height h + d s at
// horizontal distance d, so a quad at distance >= d_min with corners <= z_max blocks nothing
// when s > (z_max - h) / d_min. The four quads that have the vertex as a corner (d_min = 0)
// have the bound sqrt(2) (z_max - h) / pitch: a point of such a quad at distance d is a convex
// combination of corners whose weights other than the vertex's own sum to <= sqrt(2) d / pitch,
// for either diagonal. Far quads are taken in blocks of 2^l x 2^l (sliding maxima), block
// size growing with distance; beyond kHorizonReachTexels the canvas's highest point bounds
// everything, and outside the rectangle of texel centres (the outline ring, the frame) the
// highest of the canvas and the frame, at the rectangle's distance within the sector.
//
// The tracer lifts each ray by its origin offset (1e-3 pitch), which covers Embree's float
// rounding; the test below keeps a relative margin on top.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "digitize/core.h"
#include "digitize/height_field.h"

namespace digitize {

// Rings of blocks of 2^l quads up to this Chebyshev distance (texels); beyond it the canvas's
// highest point bounds the horizon: at 128 texels a 2.5 mm impasto on a 0.35 mm pitch subtends
// 3 degrees, below the lowest light of a dome.
inline constexpr int kHorizonReachTexels = 128;
inline constexpr int kMaxHorizonSectors = 32;

class HorizonBounds {
 public:
  // For the texels of `texels` (indices y * width + x), `sectors` in [1, kMaxHorizonSectors]
  // azimuth sectors of equal width from the canvas +X axis, counter-clockwise.
  HorizonBounds(const HeightField& canvas, std::span<const uint32_t> texels, int sectors);

  // True when a ray from texel t's vertex along `d` (canvas frame, unit) provably meets nothing.
  // Rays level or downwards are never proven free.
  bool ProvenFree(size_t t, const Vec3f& d) const {
    if (!(d.z() > 0.0f)) return false;
    if (d.x() == 0.0f && d.y() == 0.0f) return true;  // straight up: above everything
    // d.z > b |d_xy|, squared (both sides >= 0). First with the texel's highest bound over all
    // sectors: most rays clear it, and the sector (a division) is then not needed; where they
    // clear it, they clear their own sector's, so the answer is the same.
    const float z2 = d.z() * d.z(), xy2 = d.x() * d.x() + d.y() * d.y();
    const float highest = highest_[t] * (1 + kRelMargin) + kAbsMargin;
    if (z2 > highest * highest * xy2) return true;
    const float b =
        bound_[t * static_cast<size_t>(sectors_) + Sector(d.x(), d.y())] * (1 + kRelMargin) +
        kAbsMargin;
    return z2 > b * b * xy2;
  }

 private:
  // Sectors are uniform in the "diamond angle" a(d) in [0, 4) (one division instead of atan2):
  // monotonic in the azimuth, 0 on +X, 1 on +Y, 2 on -X, 3 on -Y.
  int Sector(float dx, float dy) const {
    const float a = dy >= 0 ? (dx >= 0 ? dy / (dx + dy) : 1 - dx / (dy - dx))
                            : (dx < 0 ? 2 - dy / (-dx - dy) : 3 + dx / (dx - dy));
    return std::min(sectors_ - 1, static_cast<int>(a * sector_scale_));
  }
  static constexpr float kRelMargin = 1e-4f, kAbsMargin = 1e-6f;
  int sectors_;
  float sector_scale_;          // sectors / 4
  std::vector<float> bound_;    // texel-major: sectors_ slopes (tan) per texel
  std::vector<float> highest_;  // per texel, the largest of its sectors' bounds
};

}  // namespace digitize
