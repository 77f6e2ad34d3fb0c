// Preprocess of one scan too large to hold (a canvas of 16k texels a side: the scan alone is
// 2.4 GB of samples, the whole-canvas steps ~13 bytes a texel more), in bounded memory:
//   1. the canvas frame (plane, outline, frame boxes, mask) from the scan read at a stride;
//   2. the canvas grid cut into tiles with a halo; each tile resampled from its own rectangle
//      of the scan (read through a bounded image cache), its holes found and filled as on the
//      whole canvas (a hole inside the canvas mask is inside the outline whatever tile sees it),
//      its core written into height.exr and mask.png a row of tiles at a time;
//   3. per tile again, its window of heights and states read back (a raw file beside the
//      outputs between the passes, removed after): relief with the canvas's H
//      (TexelWindow::full_max_height_mm) and normals, normals.exr written a row of tiles at a
//      time.
// The same folder as WritePreprocessOutputs writes (canvas_mask_scan.png at the canvas pass's
// stride). Peak memory: the strided scan's canvas pass, one tile's window, and a row of tiles of
// the output maps (docs/benchmarks.md, "Tiles").
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "digitize/preprocess.h"

namespace digitize {

struct TiledPreprocessOptions {
  int tile_texels = 2048;  // a tile's core side, rounded up to a multiple of relief.cell_px
  int halo_texels = 0;     // 0: TiledPreprocessHalo (from the hole and speck areas)
  // Every stride-th scan sample (both ways) goes to the canvas pass; 0: the smallest stride that
  // keeps it to 2^24 samples (~0.5 GB while the canvas is found). 1 = every sample: the frame
  // of the whole preprocess.
  int canvas_stride = 0;
  size_t cache_mb = 512;  // the image cache that reads the scan's and the maps' rectangles
  Status Validate() const;
};

// The halo: holes up to resample.max_hole_area_mm2 and relief specks up to
// relief.min_component_area_mm2 that reach a tile's core lie inside its window when compact
// (twice the diameter of a disc of that area, at least 32 texels), rounded up to whole cells.
int TiledPreprocessHalo(const PreprocessOptions& options, double pitch_mm);

// Reads `scan` (a 3-channel float XYZ EXR or TIFF: the format a rectangle can be read from
// without the rest) and writes the canvas folder's files into `dir` (an existing folder, written
// atomically as a whole by the caller: pipeline.h). The result has no grids: field.window holds
// the canvas's size and H. Equal to Preprocess on the same scan with canvas_stride 1 up to the
// float rounding of the texel transform (tests/preprocess_tiled_test.cpp states the tolerance),
// except for a hole larger than the halo that crosses a tile's edge.
// Errors name the scan: not XYZ, unreadable, no canvas found, a grid too large.
Result<PreprocessResult> PreprocessScanTiled(const std::filesystem::path& scan,
                                             const PreprocessOptions& options,
                                             const TiledPreprocessOptions& tiled,
                                             const std::filesystem::path& dir,
                                             const std::vector<std::string>& inputs,
                                             const ProgressCallback& progress = nullptr);

}  // namespace digitize
