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

#include <array>
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

inline constexpr std::array<const char*, 4> kFrameSideNames = {"left", "right", "bottom", "top"};

// The frame around the canvas as the ray tests see it: one box per side, from gap_mm outside the
// canvas outline outwards by width_mm, and from below the canvas plane up to raise_mm. A raised
// moulding shadows the canvas edge under a grazing light and hides it from an oblique camera;
// without it those photo pixels would be fitted as paint. Sides (canvas frame, W x H the grid's
// extent): 0 left (X < 0), 1 right (X > W), 2 bottom (Y < 0), 3 top (Y > H). A side whose raise_mm
// is <= 0 has no box. Measured from the scan by the canvas stage (canvas.h); all zero for an RTI
// capture. A box is a plain step at the outline: a bevel or a lip is approximated by its top.
struct FrameBoxes {
  std::array<float, 4> raise_mm{};  // box top above the canvas plane, mm
  std::array<float, 4> width_mm{};  // box width outwards, mm
  std::array<float, 4> gap_mm{};    // from the canvas outline to the box, mm (> 0 where the frame
                                    // hid a strip of canvas from the scanner)
  bool any() const {
    return std::any_of(raise_mm.begin(), raise_mm.end(), [](float r) { return r > 0.0f; });
  }
  float max_raise_mm() const {
    return std::max(0.0f, *std::max_element(raise_mm.begin(), raise_mm.end()));
  }
  // Finite, raise_mm <= 1000, width_mm and gap_mm in [0, 1000] on every side (mm).
  Status Validate() const {
    for (int side = 0; side < 4; ++side) {
      const float r = raise_mm[side], w = width_mm[side], g = gap_mm[side];
      const auto in_range = [](float v) { return std::isfinite(v) && v >= 0.0f && v <= 1000.0f; };
      if (!(std::isfinite(r) && r <= 1000.0f && in_range(w) && in_range(g)))
        return Error{std::string("frame ") + kFrameSideNames[side] +
                     ": raise_mm must be finite and <= 1000, width_mm and gap_mm in [0, 1000], "
                     "got " +
                     FormatNumber(r) + ", " + FormatNumber(w) + " and " + FormatNumber(g)};
    }
    return Status::Ok();
  }
};

// The part of a larger canvas a grid holds: texels [x0, x0 + width) x [y0, y0 + height) of a
// full_width x full_height canvas (a tile and its halo, tile_jobs.h). Texel centres, the canvas
// outline and the frame stay the full canvas's, computed from whole texel indices, so a ray of
// the part is the same ray, bit for bit, as the full canvas's. full_width = 0: the whole canvas.
struct TexelWindow {
  int x0 = 0, y0 = 0;
  int full_width = 0, full_height = 0;
  // The full canvas's highest height: where rays start above the relief (camera rays) and the
  // first bound of the tracer's skipping are the full canvas's, not the window's.
  float full_max_height_mm = 0;
};

struct HeightField {
  Grid<float> height_mm;   // never NaN/Inf; 0 where kOutside
  Grid<TexelState> state;  // same size as height_mm
  double pitch_mm = 0.0;   // texel spacing along X and Y
  FrameBoxes frame;        // none by default
  TexelWindow window;      // the whole canvas by default

  int width() const { return height_mm.width; }
  int height() const { return height_mm.height; }
  int full_width() const { return window.full_width > 0 ? window.full_width : width(); }
  int full_height() const { return window.full_width > 0 ? window.full_height : height(); }
  Eigen::Vector2d extent_mm() const { return {full_width() * pitch_mm, full_height() * pitch_mm}; }
  // Canvas-frame XY of a texel centre (see the header comment for the row flip). x + x0 is a
  // whole number: exact, so a window's centres are the full canvas's.
  Eigen::Vector2d TexelCentreMm(double x, double y) const {
    return {(x + window.x0 + 0.5) * pitch_mm, (full_height() - (y + window.y0) - 0.5) * pitch_mm};
  }
  // Inverse of TexelCentreMm (continuous texel coordinates of this grid).
  Eigen::Vector2d TexelFromMm(double X, double Y) const {
    return {X / pitch_mm - 0.5 - window.x0, full_height() - Y / pitch_mm - 0.5 - window.y0};
  }
};

}  // namespace digitize
