// The painterly style's stroke anchors (seed 002, section 5.2): points fixed on the surfaces
// (object space, so strokes move with them), taken from a hierarchy so that their density on
// screen stays constant as the visitor walks. Each planar face of the scene (walls, frames,
// canvases) carries an implicit quadtree: root cells of root_mm, each cell one anchor jittered
// inside it, and a cell's anchor is also one of its four children's (a point of a level is in
// every finer level, as the paper's hierarchy keeps it). Per frame a cell is refined where its
// anchors would lie further apart on screen than spacing_px; an anchor introduced at level l
// gets weight clamp(l* - l + 1, 0, 1) with l* = log2(f root_mm / (z spacing_px)) at its depth z
// (f: focal length, px; level l* spaces anchors spacing_px apart), so anchors fade in and out
// over a zoom octave instead of popping, and the weighted anchor count per screen area on a
// face-on plane is (1 + 3 phi) / 4^phi / spacing_px^2, phi = l* - floor(l*): within 1 .. 1.27.
//
// Layer: viewer (libdigitize only, no GL).
#pragma once

#include <cstdint>
#include <vector>

#include "digitize/core.h"
#include "digitize_viewer/renderer.h"
#include "digitize_viewer/view.h"

namespace digitize::viewer {

// A planar rectangle origin + a u + b v, a in [0, u_len], b in [0, v_len]; u, v unit and
// orthogonal; its front side faces u x v (anchors on a face seen from behind are not chosen).
struct StrokeFace {
  Vec3d origin = Vec3d::Zero(), u = Vec3d::UnitX(), v = Vec3d::UnitY();
  double u_len = 0, v_len = 0;
  uint32_t id = 0;  // seeds the anchors' jitter
};

// The six faces of each box, facing out. `first_id` numbers them.
std::vector<StrokeFace> BoxFaces(const std::vector<SceneBox>& boxes, uint32_t first_id = 0);

struct StrokeAnchor {
  Vec3f position = Vec3f::Zero();  // world, mm
  float weight = 0;                // (0, 1]: how far it has faded in
  float depth_mm = 0;              // along the view direction
  uint32_t id = 0;                 // stable per anchor (its stroke's own random perturbation)
};

struct StrokeSelectOptions {
  double spacing_px = 9;  // the strokes' spacing on screen
  double root_mm = 1024;  // root cell side
  int max_level = 14;     // finest level (root_mm / 2^14 = 0.06 mm)
  size_t max_anchors = 300000;
};

// The anchors of `faces` in view of `camera` (in front of it, projecting inside the image with
// a margin of 2 spacings, on faces seen from the front), farthest first (the painter's order).
// Occlusion is the renderer's (depth test per stroke). Finite always.
std::vector<StrokeAnchor> SelectStrokeAnchors(const std::vector<StrokeFace>& faces,
                                              const ViewCamera& camera,
                                              const StrokeSelectOptions& options = {});

}  // namespace digitize::viewer
