// Reading and writing scans in the formats users have (docs/formats.md, "Scans"):
//   - float EXR / TIFF, 3 channels: X, Y, Z in mm (scan frame);
//   - float EXR / TIFF, 1 channel: depth (Z, mm) on a regular grid of pixel_pitch_mm
//     (orthographic);
//   - 16-bit PNG / TIFF, 1 channel: depth = value * height_scale_mm (+ height_offset_mm), value 0 =
//     missing, on a regular grid of pixel_pitch_mm;
//   - PLY point grids (OpenMesh): vertices in row-major order with "width"/"height" given in a
//     comment line ("comment grid WIDTH HEIGHT") or through ScanReadOptions; NaN = missing.
// An optional mask image (8/16-bit, 0 = missing) marks missing samples in any of them.
#pragma once

#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize/scan_data.h"

namespace digitize {

struct ScanReadOptions {
  double pixel_pitch_mm = 0;    // needed for depth-only inputs (1 channel); 0 = refuse them
  double height_scale_mm = 0;   // needed for 16-bit integer inputs: mm per count; 0 = refuse
  double height_offset_mm = 0;  // added after scaling
  std::filesystem::path mask;   // optional mask image, same size as the scan
  int grid_width = 0, grid_height = 0;   // PLY without a "comment grid" line
  size_t max_samples = size_t{1} << 27;  // refuse larger grids (a corrupt header, not a scan)
  Status Validate() const;
};

// Errors name the file and the problem (missing, unreadable, wrong channel count, wrong size of the
// mask, depth without pitch, ...). The result may still hold NaN/Inf samples: SanitizeScan cleans.
Result<Scan> ReadScan(const std::filesystem::path& path, const ScanReadOptions& options);

// Which channels of an XYZ image hold X, Y and Z: by name when the file names its axes ("X" or
// "layer.X"; OpenEXR stores channels sorted by name), else the stored order (R, G, B).
std::array<int, 3> XyzChannels(const std::vector<std::string>& names);

// Writes a scan as a 3-channel float EXR (X, Y, Z in mm, NaN = missing), atomically.
Status WriteScanExr(const std::filesystem::path& path, const Scan& scan);

}  // namespace digitize
