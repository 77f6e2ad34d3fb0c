// Accuracy of a reflectance fit against the generator's ground truth: parameter errors reported
// by paint region.
//
// Each fitted texel (status not kTooFewSamples, state not kOutside) is mapped to the painting:
// its centre (X, Y, height) in the FITTED canvas frame goes to the scan frame (fitted
// canvas_from_scan inverse) and into the true canvas frame (truth.canvas_from_scan), then to the
// nearest painting texel, whose material and one-lobe truth it is compared with. Texels of
// measured (3-lobe) materials have no one-lobe truth: only their count is reported and the
// held-out PSNR judges them. GGX materials are compared on the texels fitted with GGX (F0 and
// alpha); Lafortune lobe errors are taken over the texels fitted with Lafortune; rho_d over all.
#pragma once

#include <string>
#include <vector>

#include "digitize/height_field.h"
#include "digitize/reflectance_maps.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/photo_sim.h"

namespace digitize::synth {

struct RegionReflectanceError {
  int material = 0;  // index into SyntheticPhotoSet::materials
  std::string name;
  bool is_measured = false;     // no one-lobe truth: the errors below are 0, only the texel count
  bool has_lobe = false;        // the truth has a lobe (rho_s > 0); else the two lobe errors are 0
  size_t texels = 0;            // compared
  double rho_d_rel_median = 0;  // median over texels of |rho_d - true| / max(|true|, 0.01 1/sr)
                                // (RGB norms; the floor keeps black paint meaningful)
  double spec_albedo_abs_median = 0;  // median |A - A_true|, A = mean_c rho_s,c 2 pi / (k + 2)
  double log10_k_abs_median = 0;      // median |log10 k / k_true|, texels with a true lobe only
  double lobe_abs_median = 0;         // median max(|cx - true|, |cy - true|), same texels
  double diffuse_only_share = 0;      // share of texels fitted diffuse-only
  bool is_ggx = false;                // the truth is GGX
  double ggx_share = 0;               // share of texels fitted with GGX (a lobe)
  double f0_abs_median = 0;           // GGX truth, GGX-fitted texels: median |mean_c F0 - true|
  double log10_alpha_abs_median = 0;  // same texels: median |log10 alpha / alpha_true|
};

std::vector<RegionReflectanceError> MeasureReflectanceAccuracy(
    const ReflectanceMaps& fitted, const HeightField& fitted_canvas,
    const RigidTransform& fitted_canvas_from_scan, const SyntheticPhotoSet& truth,
    const Painting& painting);

// One line per region: "gloss        4321 texels  rho_d 1.2 %  A 0.003  |log k| 0.05  |c| 0.02";
// "|log10 k| n/a (no lobe)" for matte paint.
std::string FormatReflectanceAccuracy(const std::vector<RegionReflectanceError>& regions);

}  // namespace digitize::synth
