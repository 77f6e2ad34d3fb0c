// A texture pack built straight from a synthetic painting's ground truth (no scan, no photos, no
// fit): the true height field, its analytic normals, the true per-region reflectance (one-lobe
// maps as SimulatePhotoSet's `truth`) and the relief boxes of ClassifyRelief. What the viewer's
// tests and benchmark render, so that every image error they measure is the renderer's alone.
//
// Layer: data_synthetic (digitize + painting.h + photo_sim.h).
#pragma once

#include <vector>

#include "digitize/pack.h"
#include "digitize/relief.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/photo_sim.h"

namespace digitize::synth {

struct TruthPackOptions {
  ReliefOptions relief;  // delta0 and the box cell size n (cell_px)
  // Region materials (region i gets materials[i % size]); empty: DefaultPaintMaterials(false).
  // Measured materials contribute their diffuse term only (the one-lobe maps cannot hold them).
  std::vector<PaintMaterial> materials;
};

// canvas_from_scan = identity; provenance names the generator. Invalid relief options throw
// (InvariantError): options are the caller's code here. A flat painting gives no boxes.
Pack MakeTruthPack(const Painting& painting, const TruthPackOptions& options = {});

// The one-lobe truth maps alone (status kConverged, or kDiffuseOnly for measured materials).
ReflectanceMaps TruthReflectanceMaps(const Painting& painting,
                                     const std::vector<PaintMaterial>& materials);

}  // namespace digitize::synth
