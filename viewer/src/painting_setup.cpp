// The viewer's GL-free set-up (painting_setup.h).
#include "digitize_viewer/painting_setup.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

namespace digitize::viewer {

Result<PaintingSetup> PreparePainting(const Pack& pack, const std::string& name) {
  const int w = pack.width(), h = pack.height();
  auto fail = [&](const std::string& what) { return Error{name + ": " + what}; };
  if (w < 2 || h < 2)
    return fail("the pack has " + std::to_string(w) + "x" + std::to_string(h) +
                " texels; at least 2x2 needed");
  // Everything the shaders divide by or place in the room (sizes, pitch, heights, H, delta0,
  // boxes) is checked there, against bounds that keep the gallery finite.
  if (Status s = pack.Validate(); !s.ok()) return fail(s.message());
  PaintingSetup p;
  p.texels_w = w;
  p.texels_h = h;
  p.pitch_mm = pack.field.pitch_mm;
  p.width_mm = pack.width_mm();
  p.height_mm = pack.height_mm();
  p.delta0_mm = pack.delta0_mm;
  float min_h = std::numeric_limits<float>::infinity(), max_h = -min_h;
  for (const float v : pack.field.height_mm.data) {
    min_h = std::min(min_h, v);
    max_h = std::max(max_h, v);
  }
  p.min_height_mm = min_h;
  // A pack whose H is below its highest texel would let the relief poke out of the boxes.
  p.max_height_mm = std::max<double>(pack.max_height_mm, max_h);
  p.boxes = pack.boxes;
  for (const ReliefBox& b : p.boxes) {
    const Eigen::Vector2d xy = pack.field.TexelCentreMm(b.u_max, b.v_max);
    p.box_tops.emplace_back(xy.x(), xy.y(), b.h_max_mm);
  }
  return p;
}

std::vector<size_t> ShadingSource(const Pack& pack) {
  const int w = pack.width(), h = pack.height();
  std::vector<size_t> source(size_t(w) * h, SIZE_MAX), queue;
  for (size_t i = 0; i < source.size(); ++i) {
    if (pack.field.state.data[i] != TexelState::kOutside &&
        pack.maps.status.data[i] != TexelFitStatus::kTooFewSamples) {
      source[i] = i;
      queue.push_back(i);
    }
  }
  for (size_t head = 0; head < queue.size(); ++head) {
    const size_t i = queue[head];
    const int x = int(i % w), y = int(i / w);
    for (const auto& [dx, dy] : {std::pair{1, 0}, {-1, 0}, {0, 1}, {0, -1}}) {
      if (x + dx < 0 || x + dx >= w || y + dy < 0 || y + dy >= h) continue;
      const size_t j = size_t(y + dy) * w + (x + dx);
      if (source[j] != SIZE_MAX) continue;
      source[j] = source[i];
      queue.push_back(j);
    }
  }
  return source;
}

GalleryScene HangPaintings(const std::vector<std::pair<std::string, Pack>>& packs,
                           const GalleryOptions& options,
                           const std::vector<Eigen::Vector2d>& streamed_sizes) {
  GalleryScene scene;
  std::vector<Eigen::Vector2d> sizes;
  for (size_t i = 0; i < packs.size(); ++i) {
    auto setup = PreparePainting(packs[i].second, packs[i].first);
    if (!setup.ok()) {
      scene.failed.push_back(setup.error().message);
      continue;
    }
    scene.hung.push_back(i);
    sizes.emplace_back(setup->width_mm, setup->height_mm);
  }
  sizes.insert(sizes.end(), streamed_sizes.begin(), streamed_sizes.end());
  scene.gallery = MakeGallery(sizes, options);
  return scene;
}

}  // namespace digitize::viewer
