#include "digitize/reflectance_maps.h"

#include <cmath>
#include <string>

namespace digitize {

const char* ToString(ReflectanceModel model) {
  switch (model) {
    case ReflectanceModel::kLafortune:
      return "lafortune";
    case ReflectanceModel::kGgx:
      return "ggx";
  }
  return "unknown";
}

ReflectanceMaps ReflectanceMaps::Zeros(int width, int height) {
  ReflectanceMaps m;
  m.rho_d = Grid<Vec3f>(width, height);
  m.rho_s = Grid<Vec3f>(width, height);
  m.lobe = Grid<std::array<float, 4>>(width, height, {-1.0f, -1.0f, 1.0f, 1.0f});
  m.fit_error = Grid<float>(width, height, 0.0f);
  m.status = Grid<TexelFitStatus>(width, height, TexelFitStatus::kTooFewSamples);
  m.model = Grid<ReflectanceModel>(width, height, ReflectanceModel::kLafortune);
  return m;
}

Status ReflectanceMaps::Validate() const {
  const int w = width(), h = height();
  auto same = [&](const auto& g) { return g.width == w && g.height == h; };
  if (!same(rho_s) || !same(lobe) || !same(fit_error) || !same(status) || !same(model))
    return Error{"reflectance maps differ in size (rho_d is " + std::to_string(w) + "x" +
                 std::to_string(h) + ")"};
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const std::string where =
          "reflectance maps: texel (" + std::to_string(x) + ", " + std::to_string(y) + "): ";
      if (Status s = At(x, y).Validate(); !s.ok()) return Error{where + s.message()};
      const auto m = static_cast<int>(model(x, y));
      if (m < 0 || m >= kReflectanceModelCount)
        return Error{where + "unknown reflectance model " + std::to_string(m)};
      if (model(x, y) == ReflectanceModel::kGgx) {
        const GgxParams g = GgxAt(x, y);
        if (!(g.f0.minCoeff() >= 0.0f && g.f0.maxCoeff() <= 1.0f))
          return Error{where + "GGX F0 must lie in [0, 1]"};
        if (!(g.alpha >= kGgxMinAlpha && g.alpha <= kGgxMaxAlpha))
          return Error{where + "GGX alpha must lie in [" + FormatNumber(kGgxMinAlpha) + ", " +
                       FormatNumber(kGgxMaxAlpha) + "], got " + FormatNumber(g.alpha)};
      }
      if (!(std::isfinite(fit_error(x, y)) && fit_error(x, y) >= 0))
        return Error{"reflectance maps: texel (" + std::to_string(x) + ", " + std::to_string(y) +
                     "): fit error must be finite and >= 0, got " + FormatNumber(fit_error(x, y))};
    }
  }
  return Status::Ok();
}

}  // namespace digitize
