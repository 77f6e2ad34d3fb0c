// Resampling of the canvas part of a scan onto a regular grid in the canvas frame (paper section
// 4.2, end; docs/architecture.md, step 7). The scan's own pixel grid is triangulated (two triangles
// per quad of valid canvas samples, none across a height step) and every triangle is rasterised
// into the canvas grid with linear interpolation; where triangles overlap, the highest wins (a
// height field is seen from above). Texels no triangle covers are holes: small ones are inpainted
// (TexelState::kFilled), larger ones inpainted for continuity but marked kUnfilled.
#pragma once

#include "digitize/canvas.h"
#include "digitize/height_field.h"
#include "digitize/scan.h"

namespace digitize {

struct ResampleOptions {
  double pitch_mm = 0;              // output texel spacing; 0 = the median scan sample spacing
  double max_edge_factor = 4.0;     // triangles with an edge longer than this many pitches (in 3D)
                                    // span a step or a gap and are not drawn
  double max_hole_area_mm2 = 4.0;   // holes up to this area are filled and reported; larger stay
                                    // kUnfilled
  int max_texels_per_side = 16384;  // refuse absurd grids (pitch too small for the canvas)
  // The scan's median sample spacing (mm), which sets the edge limit when it is coarser than the
  // pitch; 0 = measured on the scan given. A tile of a larger scan gives the whole scan's, so its
  // triangles are the whole scan's.
  double scan_spacing_mm = 0;
  bool find_holes = true;  // false: texels no triangle covered are kOutside, no hole is sought
                           // or filled (for callers that read the measured texels only)
  Status Validate() const;
};

struct ResampleStats {
  size_t texels = 0, measured = 0, filled = 0, unfilled = 0, outside = 0;
  size_t holes_filled = 0, holes_unfilled = 0;  // connected hole regions
  size_t triangles_drawn = 0, triangles_skipped = 0;
};

Result<HeightField> ResampleToCanvasGrid(const Scan& scan, const CanvasResult& canvas,
                                         const ResampleOptions& options,
                                         ResampleStats* stats = nullptr);
// The same, consuming the scan: its samples (12 bytes each) are freed as soon as its triangles
// are drawn, before the hole steps allocate theirs (the preprocess's peak at large scans).
Result<HeightField> ResampleToCanvasGrid(Scan&& scan, const CanvasResult& canvas,
                                         const ResampleOptions& options,
                                         ResampleStats* stats = nullptr);

}  // namespace digitize
