// The contract of the viewer's load path on ANY file (docs/architecture.md, "Fuzzing"): a pack
// file -> LoadPackForViewer -> PreparePainting -> the gallery (HangPaintings), everything the
// viewer does before GL. Checked on every input by tests/fuzz/fuzz_viewer_load.cpp and on every
// corpus file by tests/fuzz_corpus_test.cpp:
//   - no crash, no exception, no sanitizer report;
//   - a file that does not load: an error naming it;
//   - a pack that loads (so `digitize verify` could accept it) and has at least 2 x 2 texels is
//     never refused by the viewer's set-up, and hangs in a gallery whose every number is finite,
//     whose start camera validates (what Renderer::Render checks) and whose room stays bounded;
//     a smaller one is refused with an error naming it.
// Returns "" when the contract holds, else what is broken.
#pragma once

#include <cmath>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "digitize_viewer/gallery.h"
#include "digitize_viewer/painting_setup.h"
#include "parser_contract.h"

namespace digitize::fuzz {

// The largest room one painting can need: its 100 m (kMaxPackExtentMm) plus frames and gaps.
constexpr double kMaxGalleryWidthMm = 2 * kMaxPackExtentMm;

inline std::string CheckViewerLoadFile(const std::filesystem::path& path) {
  Result<Pack> pack = viewer::LoadPackForViewer(path);
  if (!pack.ok()) return ErrorNamesSource(pack.error().message, path);
  const std::string name = path.string();
  const Result<viewer::PaintingSetup> setup = viewer::PreparePainting(*pack, name);
  const bool hangable = pack->width() >= 2 && pack->height() >= 2;
  if (!setup.ok()) {
    if (hangable) return "a pack that loads is refused by the viewer: " + setup.error().message;
    return ErrorNamesSource(setup.error().message, path);
  }
  if (!hangable) return "PreparePainting accepts a pack under 2 x 2 texels";
  const viewer::PaintingSetup& p = *setup;
  for (double v :
       {p.pitch_mm, p.width_mm, p.height_mm, p.delta0_mm, p.min_height_mm, p.max_height_mm})
    if (!std::isfinite(v)) return "PreparePainting gives a non-finite extent or height";
  if (!(p.width_mm > 0 && p.height_mm > 0 && p.min_height_mm <= p.max_height_mm))
    return "PreparePainting gives an empty extent or an inverted height range";
  if (p.box_tops.size() != p.boxes.size()) return "one box top per box expected";
  for (const Vec3d& top : p.box_tops)
    if (!top.allFinite()) return "a box top is not finite";

  const std::vector<std::pair<std::string, Pack>> packs = {{name, std::move(pack).value()}};
  const viewer::GalleryScene scene = viewer::HangPaintings(packs);
  if (!scene.failed.empty()) return "HangPaintings refuses what PreparePainting accepts";
  if (scene.hung.size() != 1 || scene.gallery.world_from_canvas.size() != 1)
    return "HangPaintings does not hang the one painting";
  const viewer::Gallery& g = scene.gallery;
  if (Status s = g.start.Validate(); !s.ok()) return "the start camera is invalid: " + s.message();
  if (!(g.width_mm <= kMaxGalleryWidthMm)) return "the room is wider than any painting needs";
  for (const RigidTransform& t : g.world_from_canvas)
    if (!t.rotation.allFinite() || !t.translation.allFinite()) return "a placement is not finite";
  for (const Light& l : g.lights)
    if (!l.position_mm.allFinite() || !l.intensity.allFinite()) return "a light is not finite";
  for (const viewer::SceneBox& b : g.room.boxes)
    if (!b.min_mm.allFinite() || !b.max_mm.allFinite()) return "a wall or frame is not finite";
  for (const viewer::SpotCone& c : g.room.spots)
    if (!c.axis.allFinite() || !std::isfinite(c.inner_deg) || !std::isfinite(c.outer_deg) ||
        !(c.inner_deg < c.outer_deg))
      return "a picture light's cone is not finite";
  for (const Vec3d& c : g.centres_mm)
    if (!c.allFinite()) return "a painting centre is not finite";
  return "";
}

}  // namespace digitize::fuzz
