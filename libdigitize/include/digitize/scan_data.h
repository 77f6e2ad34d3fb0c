// The scan as data (core layer): one structured-light / laser capture as a grid of 3D points.
// The readers (scan_io.h) produce it, the clean-up (scan.h) and every later stage take it.
//
// Scan frame (mm): the scanner's own frame. For a pinhole scanner the centre of projection is the
// origin and it looks along +Z, image x along +X, image y (rows, downwards) along +Y. An
// orthographic scanner looks along +Z too. Missing samples are NaN.
#pragma once

#include <string>

#include "digitize/core.h"

namespace digitize {

struct Scan {
  Grid<Vec3f> xyz_mm;  // per scan pixel, scan frame; NaN = missing
  std::string source;  // where it came from, for messages ("scan_a.exr")
};

}  // namespace digitize
