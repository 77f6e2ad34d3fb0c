#include "digitize_synth/truth_pack.h"

#include <string>

namespace digitize::synth {

ReflectanceMaps TruthReflectanceMaps(const Painting& painting,
                                     const std::vector<PaintMaterial>& materials_in) {
  const std::vector<PaintMaterial> materials =
      materials_in.empty() ? DefaultPaintMaterials(false) : materials_in;
  const int w = painting.truth.width(), h = painting.truth.height();
  ReflectanceMaps maps = ReflectanceMaps::Zeros(w, h);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const PaintMaterial& m = materials[painting.region(x, y) % materials.size()];
      if (m.is_measured) {
        LafortuneParams diffuse;  // the measured diffuse term only, as SimulatePhotoSet's truth
        diffuse.rho_d = m.measured.diffuse_albedo / static_cast<float>(3.14159265358979323846);
        maps.Set(x, y, diffuse);
        maps.status(x, y) = TexelFitStatus::kDiffuseOnly;
      } else if (m.is_ggx) {
        maps.SetGgx(x, y, m.ggx);
        maps.status(x, y) = TexelFitStatus::kConverged;
      } else {
        maps.Set(x, y, m.lafortune);
        maps.status(x, y) = TexelFitStatus::kConverged;
      }
    }
  }
  return maps;
}

Pack MakeTruthPack(const Painting& painting, const TruthPackOptions& options) {
  const Status valid = options.relief.Validate();
  DIGITIZE_CHECK(valid.ok(), "MakeTruthPack: " + valid.message());
  Pack pack;
  pack.field = painting.truth;
  pack.normals = painting.normals;
  pack.maps = TruthReflectanceMaps(painting, options.materials);
  const ReliefResult relief = ClassifyRelief(painting.truth, options.relief);
  pack.delta0_mm = relief.delta0_mm;
  pack.max_height_mm = relief.max_height_mm;
  pack.cell_px = relief.cell_px;
  pack.boxes = relief.boxes;
  pack.provenance.tool_version = std::string("digitize ") + DIGITIZE_VERSION;
  pack.provenance.fit_brief =
      "ground truth (synthetic painting, seed " + std::to_string(painting.options.seed) + ")";
  return pack;
}

}  // namespace digitize::synth
