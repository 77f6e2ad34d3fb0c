#include "digitize_synth/reflectance_truth.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace digitize::synth {
namespace {

double Median(std::vector<double>& v) {
  if (v.empty()) return 0;  // no such texels: the flags (is_measured, has_lobe) say so
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

double SpecularAlbedo(const Vec3f& rho_s, float k) {
  return static_cast<double>(rho_s.mean()) * 2.0 * 3.14159265358979323846 / (k + 2.0);
}

}  // namespace

std::vector<RegionReflectanceError> MeasureReflectanceAccuracy(
    const ReflectanceMaps& fitted, const HeightField& fitted_canvas,
    const RigidTransform& fitted_canvas_from_scan, const SyntheticPhotoSet& truth,
    const Painting& painting) {
  const size_t n_materials = truth.materials.size();
  std::vector<std::vector<double>> rho_d(n_materials), albedo(n_materials), logk(n_materials),
      lobe(n_materials), f0(n_materials), log_alpha(n_materials);
  std::vector<size_t> count(n_materials, 0), diffuse(n_materials, 0), ggx(n_materials, 0);
  const RigidTransform true_from_fitted =
      truth.canvas_from_scan * fitted_canvas_from_scan.Inverse();
  const HeightField& true_field = painting.truth;
  for (int y = 0; y < fitted.height(); ++y) {
    for (int x = 0; x < fitted.width(); ++x) {
      if (fitted_canvas.state(x, y) == TexelState::kOutside) continue;
      const TexelFitStatus status = fitted.status(x, y);
      if (status == TexelFitStatus::kTooFewSamples) continue;
      const Eigen::Vector2d xy = fitted_canvas.TexelCentreMm(x, y);
      const Vec3d p = true_from_fitted.Apply({xy.x(), xy.y(), fitted_canvas.height_mm(x, y)});
      const Eigen::Vector2d t = true_field.TexelFromMm(p.x(), p.y());
      const int tx = static_cast<int>(std::lround(t.x())),
                ty = static_cast<int>(std::lround(t.y()));
      if (!true_field.height_mm.Contains(tx, ty)) continue;
      const size_t m = truth.material_index(tx, ty);
      if (m >= n_materials) continue;
      ++count[m];
      if (status == TexelFitStatus::kDiffuseOnly) ++diffuse[m];
      const bool fitted_ggx =
          fitted.model(x, y) == ReflectanceModel::kGgx && status != TexelFitStatus::kDiffuseOnly;
      if (fitted_ggx) ++ggx[m];
      if (truth.materials[m].is_measured) continue;
      const LafortuneParams f = fitted.At(x, y), g = truth.truth.At(tx, ty);
      rho_d[m].push_back((f.rho_d - g.rho_d).norm() / std::max(0.01f, g.rho_d.norm()));
      if (truth.materials[m].is_ggx) {
        if (fitted_ggx) {
          const GgxParams fg = fitted.GgxAt(x, y), tg = truth.materials[m].ggx;
          f0[m].push_back(std::abs(fg.f0.mean() - tg.f0.mean()));
          log_alpha[m].push_back(std::abs(std::log10(fg.alpha / tg.alpha)));
        }
        continue;
      }
      if (fitted_ggx) continue;  // Lafortune truth, GGX fit: only the PSNR compares them
      albedo[m].push_back(std::abs(SpecularAlbedo(f.rho_s, f.k) - SpecularAlbedo(g.rho_s, g.k)));
      if (g.rho_s.maxCoeff() > 0) {
        logk[m].push_back(std::abs(std::log10(std::max(f.k, 1e-3f) / g.k)));
        lobe[m].push_back(std::max(std::abs(f.cx - g.cx), std::abs(f.cy - g.cy)));
      }
    }
  }
  std::vector<RegionReflectanceError> out;
  for (size_t m = 0; m < n_materials; ++m) {
    if (count[m] == 0) continue;
    RegionReflectanceError e;
    e.material = static_cast<int>(m);
    e.name = truth.materials[m].name;
    e.is_measured = truth.materials[m].is_measured;
    e.texels = count[m];
    e.has_lobe = !logk[m].empty();
    e.rho_d_rel_median = Median(rho_d[m]);
    e.spec_albedo_abs_median = Median(albedo[m]);
    e.log10_k_abs_median = Median(logk[m]);
    e.lobe_abs_median = Median(lobe[m]);
    e.diffuse_only_share = static_cast<double>(diffuse[m]) / static_cast<double>(count[m]);
    e.is_ggx = truth.materials[m].is_ggx;
    e.ggx_share = static_cast<double>(ggx[m]) / static_cast<double>(count[m]);
    e.f0_abs_median = Median(f0[m]);
    e.log10_alpha_abs_median = Median(log_alpha[m]);
    out.push_back(e);
  }
  return out;
}

std::string FormatReflectanceAccuracy(const std::vector<RegionReflectanceError>& regions) {
  std::string out;
  char b[256];
  for (const RegionReflectanceError& e : regions) {
    if (e.is_measured) {
      std::snprintf(b, sizeof b, "  %-22s %8zu texels  (measured 3-lobe: no one-lobe truth)\n",
                    e.name.c_str(), e.texels);
    } else if (e.is_ggx) {
      std::snprintf(b, sizeof b,
                    "  %-22s %8zu texels  rho_d %5.1f %%  GGX-fitted %5.1f %%: F0 +-%.4f  "
                    "|log10 alpha| %.3f  diffuse-only %4.1f %%\n",
                    e.name.c_str(), e.texels, 100.0 * e.rho_d_rel_median, 100.0 * e.ggx_share,
                    e.f0_abs_median, e.log10_alpha_abs_median, 100.0 * e.diffuse_only_share);
    } else {
      char lobe[64] = "|log10 k| n/a (no lobe)";  // matte paint: no true k or direction
      if (e.has_lobe)
        std::snprintf(lobe, sizeof lobe, "|log10 k| %.3f  |dc| %.3f", e.log10_k_abs_median,
                      e.lobe_abs_median);
      std::snprintf(b, sizeof b,
                    "  %-22s %8zu texels  rho_d %5.1f %%  spec. albedo +-%.4f  %s  diffuse-only "
                    "%4.1f %%\n",
                    e.name.c_str(), e.texels, 100.0 * e.rho_d_rel_median, e.spec_albedo_abs_median,
                    lobe, 100.0 * e.diffuse_only_share);
    }
    out += b;
  }
  return out;
}

}  // namespace digitize::synth
