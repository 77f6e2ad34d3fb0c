// Per-texel normals from the 8-neighbourhood fan (paper section 5).
//
// The 8 neighbours n_0..n_7 of a texel c, taken counter-clockwise in the canvas frame (X right,
// Y up, so "north" is row y - 1), form the fan triangles (c, n_i, n_{i+1}) that tile the 3x3
// neighbourhood. The sum of their unnormalised cross products (twice their area times their
// normal) is normalised. With offsets in texels (ox, oy) and d_i = h(n_i) - h(c), the cross
// product of a fan triangle divided by the pitch p is, writing j = i + 1,
//   ( oy_i d_j - d_i oy_j,  d_i ox_j - ox_i d_j,  p (ox_i oy_j - oy_i ox_j) )
// and the last bracket is 1 for every fan triangle. When all 8 triangles are present the sum
// collapses to the Sobel operator: (-Sx, -Sy, 8 p) with Sx, Sy the Sobel sums of the d_i. That is
// the fast path; borders and texels next to missing heights take the general path.
//
// Sums are taken in double so that heights up to FLT_MAX do not overflow (their squares would in
// float) and so that a tilted plane gives its normal to float rounding.
#include "digitize/normals.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

namespace digitize {
namespace {

// Counter-clockwise in the canvas frame, starting east. (dx, dy) in grid steps (dy > 0 is down
// the rows); the canvas-frame offset is (dx, -dy).
constexpr int kDx[8] = {1, 1, 0, -1, -1, -1, 0, 1};
constexpr int kDy[8] = {0, -1, -1, -1, 0, 1, 1, 1};

inline bool Usable(TexelState s, float h) { return HasHeight(s) && std::isfinite(h); }

// Normalises (x, y, z) with z > 0 into a unit float vector with n_z > 0. Scaling by the largest
// component first keeps the norm finite whatever the magnitudes.
inline Vec3f Normalise(double x, double y, double z) {
  const double scale = std::max({std::abs(x), std::abs(y), z});
  x /= scale;
  y /= scale;
  z /= scale;
  const double inv = 1.0 / std::sqrt(x * x + y * y + z * z);
  // n_z can underflow to 0 in float for a near-vertical fan (heights ~1e30 at a tiny pitch):
  // keep it positive, as promised; the change in length is far below float rounding.
  const float nz = std::max(static_cast<float>(z * inv), std::numeric_limits<float>::min());
  return {static_cast<float>(x * inv), static_cast<float>(y * inv), nz};
}

// Any texel: only the fan triangles whose three vertices are in the grid and have a height.
Vec3f GeneralNormal(const HeightField& field, int x, int y) {
  const auto& heights = field.height_mm;
  const auto& states = field.state;
  const float hc = heights(x, y);
  if (!Usable(states(x, y), hc)) return {0, 0, 1};
  bool ok[8];
  double d[8];
  for (int i = 0; i < 8; ++i) {
    const int nx = x + kDx[i], ny = y + kDy[i];
    ok[i] = heights.Contains(nx, ny) && Usable(states(nx, ny), heights(nx, ny));
    d[i] = ok[i] ? static_cast<double>(heights(nx, ny)) - hc : 0.0;
  }
  double sx = 0, sy = 0;
  int triangles = 0;
  for (int i = 0; i < 8; ++i) {
    const int j = (i + 1) & 7;
    if (!ok[i] || !ok[j]) continue;
    const double oxi = kDx[i], oyi = -kDy[i], oxj = kDx[j], oyj = -kDy[j];
    sx += oyi * d[j] - d[i] * oyj;
    sy += d[i] * oxj - oxi * d[j];
    ++triangles;
  }
  if (triangles == 0 || !std::isfinite(sx) || !std::isfinite(sy)) return {0, 0, 1};
  return Normalise(sx, sy, triangles * field.pitch_mm);
}

}  // namespace

Grid<Vec3f> ComputeNormals(const HeightField& field) {
  const int w = field.width(), h = field.height();
  DIGITIZE_CHECK(field.state.width == w && field.state.height == h &&
                     field.state.size() == field.height_mm.size(),
                 "ComputeNormals: state and height grids differ in size");
  DIGITIZE_CHECK(
      w == 0 || h == 0 || (std::isfinite(field.pitch_mm) && field.pitch_mm > 0),
      "ComputeNormals: pitch_mm must be finite and > 0, got " + std::to_string(field.pitch_mm));
  if (w == 0 || h == 0) return Grid<Vec3f>(w, h, Vec3f(0, 0, 1));
  Grid<Vec3f> normals;
  // Every texel is written below. Eigen's default constructor leaves the storage untouched, so
  // the (page-faulting) first touch of ~150 MB at 4096 x 3072 happens in the parallel loop
  // instead of in a serial fill.
  normals.width = w;
  normals.height = h;
  normals.data.resize(static_cast<size_t>(w) * static_cast<size_t>(h));
  const double z8 = 8.0 * field.pitch_mm;
  // Below this pitch (8 p)^2 underflows and the fast path's normalisation could divide by 0.
  const bool fast_ok = z8 > 1e-140;

  tbb::parallel_for(tbb::blocked_range<int>(0, h, 8), [&](const tbb::blocked_range<int>& rows) {
    // full[x]: the 3x3 neighbourhood of texel x on this row all has height (fast path).
    std::vector<uint8_t> column(w), full(w);
    for (int y = rows.begin(); y < rows.end(); ++y) {
      Vec3f* out = normals.Row(y);
      if (y == 0 || y == h - 1 || w < 3 || !fast_ok) {
        for (int x = 0; x < w; ++x) out[x] = GeneralNormal(field, x, y);
        continue;
      }
      const float* hn = field.height_mm.Row(y - 1);  // north (canvas +Y)
      const float* hc = field.height_mm.Row(y);
      const float* hs = field.height_mm.Row(y + 1);  // south
      const TexelState* sn = field.state.Row(y - 1);
      const TexelState* sc = field.state.Row(y);
      const TexelState* ss = field.state.Row(y + 1);
      for (int x = 0; x < w; ++x)
        column[x] = HasHeight(sn[x]) & HasHeight(sc[x]) & HasHeight(ss[x]);
      full[0] = full[w - 1] = 0;  // the row ends take the general path
      for (int x = 1; x < w - 1; ++x) full[x] = column[x - 1] & column[x] & column[x + 1];

      // Branch-free Sobel on raw heights (the centre cancels): east minus west, north minus
      // south. Texels that need the general path are recomputed below.
      for (int x = 1; x < w - 1; ++x) {
        const double gx = (static_cast<double>(hn[x + 1]) - hn[x - 1]) +
                          2.0 * (static_cast<double>(hc[x + 1]) - hc[x - 1]) +
                          (static_cast<double>(hs[x + 1]) - hs[x - 1]);
        const double gy = (static_cast<double>(hn[x - 1]) - hs[x - 1]) +
                          2.0 * (static_cast<double>(hn[x]) - hs[x]) +
                          (static_cast<double>(hn[x + 1]) - hs[x + 1]);
        const double inv = 1.0 / std::sqrt(gx * gx + gy * gy + z8 * z8);
        out[x] = Vec3f(static_cast<float>(-gx * inv), static_cast<float>(-gy * inv),
                       static_cast<float>(z8 * inv));
        // A non-finite height anywhere in the 3x3 (hc included, via 0 * hc) poisons this sum.
        const double probe = gx + gy + 0.0 * hc[x];
        full[x] &= static_cast<uint8_t>(probe - probe == 0.0);
      }
      for (int x = 0; x < w; ++x)
        if (!full[x] || !(out[x].z() > 0.0f)) out[x] = GeneralNormal(field, x, y);
    }
  });
  return normals;
}

}  // namespace digitize
