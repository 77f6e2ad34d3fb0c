// Scans: the clean-up that runs on a capture (scan_data.h: the Scan, its frame) before any
// geometry is estimated from it, and the merging of exposures of one pose.
#pragma once

#include <vector>

#include "digitize/core.h"
#include "digitize/scan_data.h"

namespace digitize {

struct SanitizeOptions {
  // larger |x|,|y|,|z| are sensor garbage (1e30, Inf) -> missing
  double max_abs_coordinate_mm = 1e6;
  double spike_mm = 1.0;  // a sample farther than this from ALL its valid 8-neighbours (along the
                          // viewing axis) is an isolated outlier -> missing
  Status Validate() const;
};

struct SanitizeStats {
  size_t total = 0;       // samples in the grid
  size_t missing = 0;     // NaN on input
  size_t non_finite = 0;  // Inf or beyond max_abs_coordinate_mm, set missing
  size_t spikes = 0;      // isolated outliers, set missing
  size_t valid = 0;       // what is left
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
