// Holes of the resampled canvas grid (resample.cpp's header comment, step 4) and the texel
// states (step 5). Private to the canvas layer: OpenCV types.
#pragma once

#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

#include "digitize/core.h"
#include "digitize/height_field.h"
#include "digitize/resample.h"

namespace digitize::resample_detail {

// Texels covered by the drawn triangles, the outline, the holes inside it by component.
struct HoleMap {
  cv::Mat covered;  // 255: drawn (measured)
  cv::Mat inside;   // 255: inside the outline
  cv::Mat holes;    // 255: inside and not covered
  cv::Mat labels, comp_stats;
  int ncomp = 0;  // components, label 0 (not a hole) included
};

// The outline (the covered texels, the footprint of mask quads and everything they enclose) and
// its holes. Frees the footprint.
HoleMap FindHoles(const cv::Mat& covered, Grid<uint8_t>* footprint);

// Small holes (kFilled) and large ones (kUnfilled), per component and per texel.
struct HoleSizes {
  std::vector<uint8_t>
      comp_filled;  // per component: 1 = small (all kFilled), 0 = has large-hole texels
  cv::Mat large;    // 255: texel of a large hole (empty: none)
  size_t holes_filled = 0, holes_unfilled = 0;
};

HoleSizes SplitLargeHoles(const HoleMap& map, double pitch, const ResampleOptions& options);

// Every hole of `map` filled in `out` (row-major heights of the grid).
void FillHoles(const HoleMap& map, const HoleSizes& sizes, float* out);

struct StateCounts {
  size_t measured = 0, filled = 0, unfilled = 0, outside = 0;
};

// The texel states of `field` from the holes; outside texels at height 0; never NaN.
StateCounts AssignStates(const HoleMap& map, const cv::Mat& large, HeightField* field);

}  // namespace digitize::resample_detail
