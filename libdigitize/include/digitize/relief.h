// Relief classification (paper section 4.3): significant relief -> boxes.
#pragma once

#include <vector>

#include "digitize/height_field.h"

namespace digitize {

struct ReliefOptions {
  double delta0_fraction = 0.30;        // bump-plane height as a fraction of the max canvas height
  double min_component_area_mm2 = 0.5;  // connected components of valid relief smaller than
                                        // this are noise specks and removed
  int cell_px = 16;                     // n: cells of n x n texels become boxes
  double noise_margin_mm = 0;   // classify at delta0 - margin so texels whose true height is
                                // just above delta0 are not lost to noise (0 = none)
  int cover_px = 1;             // boxes cover Mv grown by this many texels (0 = Mv exactly), so
                                // relief between texel centres is inside a box too
  double min_relief_mm = 0.02;  // relief floor: a canvas whose highest point is not above this
                                // has no significant relief (no boxes)
  Status Validate() const;
};

struct ReliefBox {
  int x0 = 0, y0 = 0;         // first texel of the cell (column, row)
  int width = 0, height = 0;  // cell size in texels (smaller at the grid's right/bottom edge)
  float h_max_mm = 0;         // highest height inside the cell
  int u_max = 0, v_max = 0;   // texel (column, row) of that highest point
};

struct ReliefResult {
  double max_height_mm = 0;  // H: top of every box
  double delta0_mm = 0;      // bump plane: bottom of every box
  int cell_px = 0;
  Grid<uint8_t> valid;           // Mv after speck removal: 1 = significant relief
  std::vector<ReliefBox> boxes;  // row-major cell order
  size_t components_kept = 0, components_removed = 0;
  size_t texels_above = 0;  // texels in Mv after speck removal
};

// Only texels with HasHeight() take part. A window of a larger canvas (field.window.full_width
// > 0: a tile and its halo) takes H from field.window.full_max_height_mm, so delta0 is the
// canvas's, not the tile's. Returns no boxes when nothing rises above delta0
// (a flat canvas: max height <= min_relief_mm, or all relief in specks); never fails on a valid
// HeightField.
ReliefResult ClassifyRelief(const HeightField& field, const ReliefOptions& options);

}  // namespace digitize
