#include "shadow_horizon.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <string>

namespace digitize {
namespace {

// Blocks of 2^l quads cover the Chebyshev ring (rho_{l-1}, rho_l], rho_l = kInnerTexels 2^l:
// 64 single quads, then 48 blocks per ring, each about a quarter of its distance wide.
constexpr int kInnerTexels = 4;
constexpr int kLevels = 5;  // kInnerTexels << kLevels == kHorizonReachTexels
static_assert(kInnerTexels << kLevels == kHorizonReachTexels);
constexpr float kNoQuad = -1e30f;      // padding: no quad there (outside, bounded apart)
constexpr float kAlwaysTrace = 1e30f;  // a bound no ray clears (finite: no Inf in products)
// Widening of every interval of diamond angles (HorizonBounds::Sector, period 4): the float
// diamond angle of a direction is good to ~1e-7.
constexpr double kAngleSlack = 1e-5;
constexpr double kTwoPi = 2 * M_PI;

// The diamond angle of azimuth `a` (rad, [0, 2 pi)), and back.
double Diamond(double a) {
  const double x = std::cos(a), y = std::sin(a);
  if (y >= 0) return x >= 0 ? y / (x + y) : 1 - x / (y - x);
  return x < 0 ? 2 - y / (-x - y) : 3 + x / (x - y);
}
double Azimuth(double diamond) {
  const double q = std::min(3.0, std::floor(diamond)), f = diamond - q;
  return q * M_PI / 2 + std::atan2(f, 1 - f);
}

struct Entry {
  int delta;    // offset of the block's first quad in the padded level grids
  int level;    // block of 2^level x 2^level quads
  float inv_d;  // 1 / its distance from the vertex (texels); sqrt(2) for the vertex's own quads
  uint32_t sectors;
};

// Sectors [4 k / n, 4 (k + 1) / n] of diamond angle that meet the azimuths [lo, hi] (rad,
// hi - lo < 2 pi).
uint32_t SectorMask(double lo, double hi, int sectors) {
  const double shift = std::floor(lo / kTwoPi) * kTwoPi;
  lo -= shift, hi -= shift;  // lo in [0, 2 pi)
  const double d_lo = Diamond(lo) - kAngleSlack;
  const double d_hi = (hi < kTwoPi ? Diamond(hi) : 4 + Diamond(hi - kTwoPi)) + kAngleSlack;
  const double w = 4.0 / sectors;
  uint32_t mask = 0;
  for (int k = 0; k < sectors; ++k)
    for (double turn : {-4.0, 0.0, 4.0})
      if (k * w + turn <= d_hi && (k + 1) * w + turn >= d_lo) mask |= 1u << k;
  return mask;
}

// Angular interval and distance of the square [x0, x0 + b] x [y0, y0 + b] (texel offsets from the
// vertex; canvas +Y is texel -y), as an Entry.
Entry MakeEntry(int x0, int y0, int b, int level, int stride, int sectors) {
  Entry e;
  e.delta = y0 * stride + x0;
  e.level = level;
  const bool own = x0 <= 0 && x0 + b >= 0 && y0 <= 0 && y0 + b >= 0;  // the vertex is a corner
  const double cx = x0 + 0.5 * b, cy = y0 + 0.5 * b;
  const double centre = std::atan2(-cy, cx);
  double lo = 0, hi = 0;
  for (int c = 0; c < 4; ++c) {
    const double px = x0 + (c & 1) * b, py = y0 + (c >> 1) * b;
    if (px == 0 && py == 0) continue;
    const double a = std::remainder(std::atan2(-py, px) - centre, kTwoPi);
    lo = std::min(lo, a), hi = std::max(hi, a);
  }
  e.sectors = SectorMask(centre + lo, centre + hi, sectors);
  if (own) {
    e.inv_d = static_cast<float>(std::sqrt(2.0));
  } else {
    const double dx = std::max({0.0, static_cast<double>(x0), static_cast<double>(-(x0 + b))});
    const double dy = std::max({0.0, static_cast<double>(y0), static_cast<double>(-(y0 + b))});
    e.inv_d = static_cast<float>(1.0 / std::hypot(dx, dy));
  }
  return e;
}

}  // namespace

HorizonBounds::HorizonBounds(const HeightField& canvas, std::span<const uint32_t> texels,
                             int sectors)
    : sectors_(sectors), sector_scale_(static_cast<float>(sectors) / 4) {
  DIGITIZE_CHECK(sectors >= 1 && sectors <= kMaxHorizonSectors,
                 "HorizonBounds: sectors must be in [1, 32], got " + std::to_string(sectors));
  bound_.assign(texels.size() * static_cast<size_t>(sectors), kAlwaysTrace);
  highest_.assign(texels.size(), 0.0f);
  if (texels.empty()) return;
  const int w = canvas.width(), h = canvas.height();
  const Grid<float>& z = canvas.height_mm;
  const uint32_t uw = static_cast<uint32_t>(w);
  int y_min = h, y_max = 0;
  for (uint32_t t : texels) {
    y_min = std::min(y_min, static_cast<int>(t / uw));
    y_max = std::max(y_max, static_cast<int>(t / uw));
  }
  // Quad (qx, qy) has texels (qx .. qx + 1, qy .. qy + 1) as corners. The padded grids hold the
  // quads any texel of rows [y_min, y_max] reaches: qx + pad, qy - (y_min - pad).
  const int pad = kHorizonReachTexels;
  const int gw = w - 1 + 2 * pad, gh = y_max - y_min + 2 * pad;
  const int qy0 = y_min - pad;
  std::vector<std::vector<float>> level(kLevels + 1);
  level[0].assign(static_cast<size_t>(gw) * gh, kNoQuad);
  tbb::parallel_for(0, gh, [&](int gy) {
    const int qy = qy0 + gy;
    if (qy < 0 || qy > h - 2) return;
    float* row = level[0].data() + static_cast<size_t>(gy) * gw + pad;
    for (int qx = 0; qx <= w - 2; ++qx)
      row[qx] =
          std::max(std::max(z(qx, qy), z(qx + 1, qy)), std::max(z(qx, qy + 1), z(qx + 1, qy + 1)));
  });
  // Sliding maxima: level l at (i, j) is the maximum over the 2^l x 2^l quads from (i, j).
  for (int l = 1; l <= kLevels; ++l) {
    const std::vector<float>& prev = level[l - 1];
    std::vector<float>& next = level[l];
    next.assign(prev.size(), kNoQuad);
    const int s = 1 << (l - 1);
    tbb::parallel_for(0, gh, [&](int gy) {
      const float* a = prev.data() + static_cast<size_t>(gy) * gw;
      const float* b = gy + s < gh ? a + static_cast<size_t>(s) * gw : nullptr;
      float* out = next.data() + static_cast<size_t>(gy) * gw;
      for (int gx = 0; gx < gw; ++gx) {
        float m = a[gx];
        if (gx + s < gw) m = std::max(m, a[gx + s]);
        if (b) {
          m = std::max(m, b[gx]);
          if (gx + s < gw) m = std::max(m, b[gx + s]);
        }
        out[gx] = m;
      }
    });
  }

  // The blocks around a vertex, the same for every texel.
  std::vector<Entry> entries;
  for (int y0 = -kInnerTexels; y0 < kInnerTexels; ++y0)
    for (int x0 = -kInnerTexels; x0 < kInnerTexels; ++x0)
      entries.push_back(MakeEntry(x0, y0, 1, 0, gw, sectors));
  for (int l = 1; l <= kLevels; ++l) {
    const int b = 1 << l, outer = kInnerTexels << l, inner = outer / 2;
    for (int y0 = -outer; y0 < outer; y0 += b)
      for (int x0 = -outer; x0 < outer; x0 += b)
        if (!(x0 >= -inner && x0 + b <= inner && y0 >= -inner && y0 + b <= inner))
          entries.push_back(MakeEntry(x0, y0, b, l, gw, sectors));
  }
  // Per sector and edge of the rectangle of texel centres (outward normals +X, +Y, -X, -Y in the
  // canvas frame): the largest cosine between a direction of the sector and the normal, which
  // turns the edge's distance into the least distance at which the sector's rays cross it.
  std::vector<std::array<double, 4>> edge_cos(static_cast<size_t>(sectors));
  for (int k = 0; k < sectors; ++k) {
    const double a0 = Azimuth(4.0 * k / sectors), a1 = Azimuth(4.0 * (k + 1) / sectors);
    const double centre = 0.5 * (a0 + a1), half = 0.5 * (a1 - a0) + 1e-6;
    for (int e = 0; e < 4; ++e) {
      const double off = std::abs(std::remainder(e * M_PI / 2 - centre, kTwoPi));
      const double c = off <= half ? 1.0 : std::cos(off - half);
      edge_cos[static_cast<size_t>(k)][static_cast<size_t>(e)] = c > 0 ? c + 1e-9 : 0.0;
    }
  }
  const float z_max = *std::max_element(z.data.begin(), z.data.end());
  // Beyond the rectangle: the outline ring repeats border heights; the frame's boxes.
  const float z_outside = std::max(z_max, canvas.frame.any() ? canvas.frame.max_raise_mm() : 0.0f);
  const double inv_pitch = 1.0 / canvas.pitch_mm;

  // The blocks' bounds, for kLanes texels of one row side by side (their blocks are the same
  // offsets from consecutive places, so every read and max is a vector op; one texel at a time
  // this loop was most of the bounds' time), or for one texel alone.
  constexpr int kLanes = 8;
  using Lanes = std::array<std::array<float, kLanes>, kMaxHorizonSectors>;
  const auto block_bounds = [&]<int L>(size_t base, const float* hp, Lanes& best) {
    for (int k = 0; k < sectors; ++k)
      for (int j = 0; j < L; ++j)
        best[static_cast<size_t>(k)][j] = (z_max - hp[j]) / static_cast<float>(kHorizonReachTexels);
    for (const Entry& e : entries) {
      const float* level_at = level[e.level].data() + base + static_cast<size_t>(e.delta);
      std::array<float, kLanes> v;
      for (int j = 0; j < L; ++j) v[j] = (level_at[j] - hp[j]) * e.inv_d;
      for (uint32_t m = e.sectors; m; m &= m - 1) {
        std::array<float, kLanes>& b = best[static_cast<size_t>(std::countr_zero(m))];
        for (int j = 0; j < L; ++j) b[j] = std::max(b[j], v[j]);
      }
    }
  };
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, texels.size(), 256), [&](const tbb::blocked_range<size_t>& r) {
        Lanes best;
        std::array<float, kLanes> hp;
        for (size_t t = r.begin(); t < r.end();) {
          const int x = static_cast<int>(texels[t] % uw);
          const int y = static_cast<int>(texels[t] / uw);
          const size_t base = static_cast<size_t>(y - qy0) * gw + (x + pad);
          // kLanes texels in a row of the canvas (same row, consecutive x), else one.
          int lanes = 1;
          if (t + kLanes <= r.end() && x + kLanes <= w &&
              texels[t + kLanes - 1] == texels[t] + static_cast<uint32_t>(kLanes - 1))
            lanes = kLanes;
          for (int j = 0; j < lanes; ++j) hp[static_cast<size_t>(j)] = z(x + j, y);
          if (lanes == kLanes)
            block_bounds.template operator()<kLanes>(base, hp.data(), best);
          else
            block_bounds.template operator()<1>(base, hp.data(), best);
          for (int j = 0; j < lanes; ++j, ++t) {
            const int xj = x + j;
            const std::array<double, 4> edge = {static_cast<double>(w - 1 - xj),
                                                static_cast<double>(y), static_cast<double>(xj),
                                                static_cast<double>(h - 1 - y)};
            const double rise = z_outside - hp[static_cast<size_t>(j)];
            for (int k = 0; k < sectors; ++k) {
              double slope =
                  std::max(0.0f, best[static_cast<size_t>(k)][static_cast<size_t>(j)]) * inv_pitch;
              if (rise > 0) {
                for (int e = 0; e < 4; ++e) {
                  const double c = edge_cos[static_cast<size_t>(k)][static_cast<size_t>(e)];
                  if (c == 0) continue;
                  if (edge[static_cast<size_t>(e)] == 0) {
                    slope = kAlwaysTrace;
                    break;
                  }
                  slope = std::max(slope, rise * c / edge[static_cast<size_t>(e)] * inv_pitch);
                }
              }
              const float bound = static_cast<float>(std::min<double>(slope, kAlwaysTrace));
              bound_[t * static_cast<size_t>(sectors) + static_cast<size_t>(k)] = bound;
              highest_[t] = std::max(highest_[t], bound);
            }
          }
        }
      });
}

}  // namespace digitize
