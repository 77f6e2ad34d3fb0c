// Scans: one structured-light / laser capture as a grid of 3D points, and the clean-up that runs
// before any geometry is estimated from it.
//
// Scan frame (mm): the scanner's own frame. For a pinhole scanner the centre of projection is the
// origin and it looks along +Z, image x along +X, image y (rows, downwards) along +Y. An
// orthographic scanner looks along +Z too. Missing samples are NaN.
#pragma once

#include <string>
#include <vector>

#include "digitize/core.h"

namespace digitize {

struct Scan {
  Grid<Vec3f> xyz_mm;  // per scan pixel, scan frame; NaN = missing
  std::string source;  // where it came from, for messages ("scan_a.exr")
};

struct SanitizeOptions {
  double max_abs_coordinate_mm = 1e6;  // larger |x|,|y|,|z| are sensor garbage (1e30, Inf) -> missing
  double spike_mm = 1.0;  // a sample farther than this from ALL its valid 8-neighbours (along the
                          // viewing axis) is an isolated outlier -> missing
  Status Validate() const;
};

struct SanitizeStats {
  size_t total = 0;         // samples in the grid
  size_t missing = 0;       // NaN on input
  size_t non_finite = 0;    // Inf or beyond max_abs_coordinate_mm, set missing
  size_t spikes = 0;        // isolated outliers, set missing
  size_t valid = 0;         // what is left
};

// Replaces non-finite, absurd and isolated-spike samples by NaN in place. Never fails.
SanitizeStats SanitizeScan(Scan& scan, const SanitizeOptions& options);

struct MergeOptions {
  double disagree_mm = 0.5;  // exposures farther apart than this at a pixel: keep the median
  Status Validate() const;
};

struct MergeStats {
  int exposures = 0;
  size_t filled_from_others = 0;  // pixels missing in some exposure but present in another
  size_t disagreeing = 0;         // pixels where exposures differ by more than disagree_mm
};

// Merges several exposures of ONE pose into one scan: per pixel the median of the valid samples
// (the mean of two). Errors name the offending source when sizes differ or the list is empty.
Result<Scan> MergeExposures(const std::vector<Scan>& exposures, const MergeOptions& options,
                            MergeStats* stats = nullptr);

}  // namespace digitize
