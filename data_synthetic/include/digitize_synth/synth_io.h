// Writing a synthetic scan and its ground truth to disk (the `digitize synth` output; the
// library itself works in memory). Layout of dir (docs/formats.md, "synthetic scan"):
//   scan.exr                 the scan, X Y Z in mm, scan frame, NaN = missing (one exposure), or
//   scan_0.exr, scan_1.exr   ... one per exposure when there are several;
//   truth_height.exr         true canvas heights (mm, channel "Y"), canvas frame, row 0 = top;
//   truth_normals.exr        true unit normals (channels X, Y, Z), canvas frame;
//   truth_regions.png        paint region id per texel (8-bit);
//   truth_mask_scan.png      per scan pixel: 255 = the ray hits the canvas, 0 = not;
//   truth_hit_scan.png       per scan pixel: what the ray hits (0 none, 1 canvas, 2 frame, 3 wall);
//   truth.json               canvas_from_scan (4x4 and rotation + translation), canvas and scan
//                            sizes, pitch, every option and seed (format
//                            "digitize.synthetic_truth").
#pragma once

#include <filesystem>
#include <string>

#include "digitize/core.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/scan_sim.h"

namespace digitize::synth {

// The truth.json text (also useful to print).
std::string SyntheticTruthJson(const Painting& painting, const SyntheticScan& scan);

// Creates dir if needed and writes every file atomically (digitize/image_io.h). Returns the first
// error, naming the file; files already written stay (each one complete).
Status WriteSyntheticScan(const std::filesystem::path& dir, const Painting& painting,
                          const SyntheticScan& scan);

}  // namespace digitize::synth
