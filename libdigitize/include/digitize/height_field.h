// The canvas-frame height field: the product of preprocessing and the input of every later stage.
//
// Canvas frame (mm): X and Y span the canvas plane, Z is its normal pointing towards the scanner,
// so relief has positive height. The origin is the lower-left corner of the canvas's bounding
// rectangle in that plane; height 0 is the robust canvas plane (the plane through the bulk of the
// canvas surface, relief excluded).
//
// Texel grid: row 0 is the TOP of the canvas (the image convention, so height maps look like the
// scan). Texel (x, y) has its centre at X = (x + 0.5) * pitch_mm, Y = (height - y - 0.5) *
// pitch_mm.
#pragma once

#include <cstdint>

#include "digitize/core.h"

namespace digitize {

// What a texel holds. Stored in the mask image with these values.
enum class TexelState : uint8_t {
  kOutside = 0,   // not canvas (frame, wall, beyond the canvas outline)
  kMeasured = 1,  // interpolated from valid scan samples
  kFilled = 2,    // inside a small hole, filled by inpainting (reported)
  kUnfilled = 3,  // inside a hole too large to fill: height is inpainted for continuity only
};

inline bool HasHeight(TexelState s) {
  return s == TexelState::kMeasured || s == TexelState::kFilled;
}

struct HeightField {
  Grid<float> height_mm;   // never NaN/Inf; 0 where kOutside
  Grid<TexelState> state;  // same size as height_mm
  double pitch_mm = 0.0;   // texel spacing along X and Y

  int width() const { return height_mm.width; }
  int height() const { return height_mm.height; }
  // Canvas-frame XY of a texel centre (see the header comment for the row flip).
  Eigen::Vector2d TexelCentreMm(double x, double y) const {
    return {(x + 0.5) * pitch_mm, (height_mm.height - y - 0.5) * pitch_mm};
  }
  // Inverse of TexelCentreMm (continuous texel coordinates).
  Eigen::Vector2d TexelFromMm(double X, double Y) const {
    return {X / pitch_mm - 0.5, height_mm.height - Y / pitch_mm - 0.5};
  }
};

}  // namespace digitize
