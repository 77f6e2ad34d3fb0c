// What the viewer derives from packs before anything goes to the GPU: Renderer::AddPainting's
// GL-free half (the checks, the painting's extent, height range and box peaks) and the gallery's
// set-up for a list of packs (which hang, which are refused). Split from the renderer so that the
// load path (pack file -> LoadPackForViewer -> PreparePainting -> MakeGallery) runs without GL:
// in tests and in the fuzz target tests/fuzz/fuzz_viewer_load.cpp.
//
// Layer: viewer (libdigitize only, no GL).
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "digitize/core.h"
#include "digitize/pack.h"
#include "digitize/relief.h"
#include "digitize_viewer/gallery.h"

namespace digitize::viewer {

struct PaintingSetup {
  int texels_w = 0, texels_h = 0;
  double pitch_mm = 0, width_mm = 0, height_mm = 0;  // canvas extent, canvas frame
  double delta0_mm = 0;                              // the bump plane
  double min_height_mm = 0;                          // lowest texel
  double max_height_mm = 0;                          // top of the boxes: H, or the highest texel
                                                     // when a pack's H is below it
  std::vector<ReliefBox> boxes;
  std::vector<Vec3d> box_tops;  // per box: (u_max, v_max)'s texel centre at h_max, canvas frame
};

// Errors name the pack (`name`): fewer than 2 x 2 texels, or a pack that does not Validate
// (pack.h: sizes, finite values, the physical bounds on pitch, extent, heights and placement).
// Every value of a result is finite.
Result<PaintingSetup> PreparePainting(const Pack& pack, const std::string& name);

// For each texel, the texel whose reflectance it is shaded with: itself when it is inside the
// canvas and was fitted, else the nearest such texel (4-connected, breadth first). The bump
// plane and the mesh cover the whole grid rectangle, so texels outside the mask's jagged outline,
// or fitted from too few samples (zero maps), would otherwise be relit black: a black outline
// round every scanned canvas. SIZE_MAX everywhere when no texel was fitted.
std::vector<size_t> ShadingSource(const Pack& pack);

// The gallery for `packs` (name, pack), in order: each prepared; those refused are listed (one
// error each, naming the pack) and the others hung side by side (MakeGallery), without a gap.
struct GalleryScene {
  Gallery gallery;
  std::vector<size_t> hung;         // index into packs of each gallery.world_from_canvas
  std::vector<std::string> failed;  // one message per refused pack
};
// `streamed_sizes` (W, H mm): paintings streamed from tiled packs (pyramid_stream.h), hung after
// the packs, in order: gallery.world_from_canvas[hung.size() + j] is streamed painting j's.
GalleryScene HangPaintings(const std::vector<std::pair<std::string, Pack>>& packs,
                           const GalleryOptions& options = {},
                           const std::vector<Eigen::Vector2d>& streamed_sizes = {});

}  // namespace digitize::viewer
