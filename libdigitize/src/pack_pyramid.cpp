// Texture pack pyramid: the 2 x 2 prefilter (pack_pyramid.h).
#include "digitize/pack_pyramid.h"

#include <algorithm>
#include <cmath>

#include "digitize/ggx.h"

namespace digitize {

PackLevel BaseLevel(const HeightField& field, const Grid<Vec3f>& normals,
                    const ReflectanceMaps& maps) {
  DIGITIZE_CHECK(normals.width == field.width() && normals.height == field.height() &&
                     maps.width() == field.width() && maps.height() == field.height(),
                 "BaseLevel: maps of different sizes");
  PackLevel level{field, field.height_mm, normals, maps};
  return level;
}

PackLevel PrefilterLevel(const PackLevel& fine) {
  const int fw = fine.field.width(), fh = fine.field.height();
  const int w = (fw + 1) / 2, h = (fh + 1) / 2;
  PackLevel out;
  out.field.height_mm = Grid<float>(w, h, 0.0f);
  out.field.state = Grid<TexelState>(w, h, TexelState::kOutside);
  out.field.pitch_mm = fine.field.pitch_mm * 2;
  out.max_height_mm = Grid<float>(w, h, 0.0f);
  out.normals = Grid<Vec3f>(w, h, Vec3f(0, 0, 1));
  out.maps = ReflectanceMaps::Zeros(w, h);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      bool have = false;
      ReflectanceModel model = ReflectanceModel::kLafortune;
      int n = 0;
      double height = 0, alpha2 = 0;
      float max_height = 0;
      Eigen::Vector3d normal = Eigen::Vector3d::Zero(), rho_d = normal, rho_s = normal;
      double cx = 0, cy = 0, k = 0;
      TexelState state = TexelState::kOutside;
      TexelFitStatus status = fine.maps.status(std::min(2 * x, fw - 1), std::min(2 * y, fh - 1));
      for (int dy = 0; dy < 2; ++dy) {
        for (int dx = 0; dx < 2; ++dx) {
          const int fx = 2 * x + dx, fy = 2 * y + dy;
          if (fx >= fw || fy >= fh) continue;
          const TexelState s = fine.field.state(fx, fy);
          // Unfilled holes are continuity only: averaging them in would invent surface.
          if (s != TexelState::kMeasured && s != TexelState::kFilled) continue;
          if (!have) {
            have = true;
            model = fine.maps.model(fx, fy);
            status = fine.maps.status(fx, fy);
            max_height = fine.max_height_mm(fx, fy);
          }
          if (fine.maps.model(fx, fy) != model) continue;
          // A measured texel anywhere makes the coarse one measured: it is mostly data.
          if (s == TexelState::kMeasured || state == TexelState::kOutside) state = s;
          ++n;
          height += fine.field.height_mm(fx, fy);
          max_height = std::max(max_height, fine.max_height_mm(fx, fy));
          normal += fine.normals(fx, fy).cast<double>();
          rho_d += fine.maps.rho_d(fx, fy).cast<double>();
          rho_s += fine.maps.rho_s(fx, fy).cast<double>();
          const auto& lobe = fine.maps.lobe(fx, fy);
          cx += lobe[0];
          cy += lobe[1];
          k += lobe[3];
          alpha2 += double(lobe[3]) * lobe[3];
        }
      }
      if (n == 0) {
        out.maps.status(x, y) = status;
        continue;
      }
      normal /= n;
      // Clamped away from 0: two opposite normals would otherwise give an infinite variance.
      const double length = std::clamp(normal.norm(), 1e-3, 1.0);
      Eigen::Vector3d unit = normal.norm() > 1e-9 ? normal.normalized() : Eigen::Vector3d(0, 0, 1);
      if (unit.z() <= 0) unit = Eigen::Vector3d(0, 0, 1);
      out.field.height_mm(x, y) = float(height / n);
      out.field.state(x, y) = state;
      out.max_height_mm(x, y) = max_height;
      out.normals(x, y) = unit.cast<float>();
      out.maps.rho_d(x, y) = (rho_d / n).cast<float>();
      out.maps.status(x, y) = status;
      out.maps.model(x, y) = model;
      auto& lobe = out.maps.lobe(x, y);
      if (model == ReflectanceModel::kGgx) {
        const double a2 = alpha2 / n + (1.0 - length) / length;
        lobe = {0.0f, 0.0f, 1.0f, float(std::clamp(std::sqrt(a2), double(kGgxMinAlpha), 1.0))};
        out.maps.rho_s(x, y) = (rho_s / n).cast<float>();
      } else {
        const double k_mean = k / n;
        const double k_filtered = length * k_mean / (length + k_mean * (1.0 - length));
        lobe = {float(cx / n), float(cy / n), 1.0f, float(k_filtered)};
        out.maps.rho_s(x, y) = (rho_s / n * ((k_filtered + 2.0) / (k_mean + 2.0))).cast<float>();
      }
    }
  }
  return out;
}

}  // namespace digitize
