// The prefiltered reflectance pyramid (shading_pyramid.h).
#include "digitize_viewer/shading_pyramid.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "digitize/ggx.h"

namespace digitize::viewer {
namespace {

// Weights of the parent cells [0, from) that child cell i of `to` covers, as (first index,
// weights): child i spans [i r, (i + 1) r) with r = from / to >= 1, a cell partly covered weighs
// its share.
struct Footprint1d {
  int first = 0;
  std::vector<float> weights;
};

std::vector<Footprint1d> BoxWeights(int from, int to) {
  std::vector<Footprint1d> out(to);
  const double r = double(from) / to;
  for (int i = 0; i < to; ++i) {
    const double a = i * r, b = (i + 1) * r;
    Footprint1d& f = out[i];
    f.first = int(std::floor(a));
    for (int j = f.first; j < from && j < b; ++j) {
      const double overlap = std::min<double>(b, j + 1) - std::max<double>(a, j);
      if (overlap > 0) f.weights.push_back(float(overlap / r));
    }
  }
  return out;
}

}  // namespace

ShadingLevel HalveShadingLevel(const ShadingLevel& level) {
  const int w = level.width, h = level.height;
  ShadingLevel out;
  out.width = std::max(1, w >> 1);
  out.height = std::max(1, h >> 1);
  const std::vector<Footprint1d> fx = BoxWeights(w, out.width), fy = BoxWeights(h, out.height);
  for (int c = 0; c < kShadingChannels; ++c) {
    const std::vector<float>& in = level.rgba[c];
    // Rows first (w -> out.width), then columns (h -> out.height).
    std::vector<float> rows(size_t(out.width) * h * 4, 0.0f);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < out.width; ++x) {
        float* o = &rows[(size_t(y) * out.width + x) * 4];
        for (size_t k = 0; k < fx[x].weights.size(); ++k) {
          const float* s = &in[(size_t(y) * w + fx[x].first + k) * 4];
          for (int q = 0; q < 4; ++q) o[q] += fx[x].weights[k] * s[q];
        }
      }
    std::vector<float>& o = out.rgba[c];
    o.assign(size_t(out.width) * out.height * 4, 0.0f);
    for (int y = 0; y < out.height; ++y)
      for (size_t k = 0; k < fy[y].weights.size(); ++k) {
        const float wk = fy[y].weights[k];
        const float* s = &rows[size_t(fy[y].first + int(k)) * out.width * 4];
        float* d = &o[size_t(y) * out.width * 4];
        for (int i = 0; i < out.width * 4; ++i) d[i] += wk * s[i];
      }
  }
  return out;
}

ShadingPyramid BuildShadingPyramid(const Pack& pack, const std::vector<size_t>& source) {
  const int w = pack.width(), h = pack.height();
  const size_t n = size_t(w) * h;
  ShadingLevel base;
  base.width = w;
  base.height = h;
  for (auto& c : base.rgba) c.assign(4 * n, 0.0f);
  for (size_t i = 0; i < n; ++i) {
    const bool shaded = i < source.size() && source[i] != SIZE_MAX;
    const size_t from = shaded ? source[i] : i;
    const bool ggx = pack.maps.model.data[from] == ReflectanceModel::kGgx;
    const float ws = shaded ? 1.0f : 0.0f, wl = ggx ? 0.0f : ws, wg = ggx ? ws : 0.0f;
    const Vec3f& d = pack.maps.rho_d.data[from];
    const Vec3f& s = pack.maps.rho_s.data[from];
    const auto& c = pack.maps.lobe.data[from];
    Vec3f nn = pack.normals.data[i];
    const float len = nn.norm();
    nn = len > 1e-12f ? Vec3f(nn / len) : Vec3f(0, 0, 1);
    const float alpha = std::clamp(c[3], kGgxMinAlpha, kGgxMaxAlpha);
    float* o[kShadingChannels];
    for (int k = 0; k < kShadingChannels; ++k) o[k] = &base.rgba[k][4 * i];
    for (int k = 0; k < 3; ++k) {
      o[kDiffuse][k] = ws * d[k];
      o[kLafortune][k] = wl * s[k];
      o[kGgx][k] = wg * s[k];
      o[kNormal][k] = ws * nn[k];
    }
    o[kDiffuse][3] = ws;
    o[kLafortune][3] = wl;
    o[kGgx][3] = wg;
    o[kNormal][3] = wg * alpha * alpha;
    for (int k = 0; k < 4; ++k) o[kLobe][k] = wl * c[k];
  }
  ShadingPyramid pyramid;
  pyramid.levels.push_back(std::move(base));
  while (pyramid.levels.back().width > 1 || pyramid.levels.back().height > 1)
    pyramid.levels.push_back(HalveShadingLevel(pyramid.levels.back()));
  return pyramid;
}

}  // namespace digitize::viewer
