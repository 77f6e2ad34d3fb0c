// The painting's reflectance prefiltered for views in which a pixel covers several texels (far
// and grazing views, the gallery): a mip pyramid of what the shading averages over a footprint,
// so a pixel shades the mean surface under it instead of the one texel its ray happens to meet
// (aliasing: the image flickers as the visitor walks, and differs from the antialiased reference
// by the texel-to-texel contrast of the paint). renderer.h says how the shader reads it (levels
// 1.. in one texture per channel; level 0 is the per-texel textures the point shading reads).
//
// Level 0 holds, per texel, the shading inputs premultiplied by weights; a coarser level is the
// area-weighted box mean of the finer one (child texel x covers parent texels [x W / w, (x + 1)
// W / w), so odd sizes lose nothing). Weights: w = 1 where the texel is shaded (ShadingSource
// found it a fitted texel), w_l = w for Lafortune texels, w_g = w for GGX ones, else 0. Dividing a
// premultiplied mean by its weight's mean gives the mean over the texels that have it, so the two
// models' parameters are never averaged together:
//   kDiffuse   (w rho_d, w)
//   kLafortune (w_l rho_s, w_l)
//   kLobe      (w_l cx, w_l cy, w_l cz, w_l k)
//   kGgx       (w_g F0, w_g)
//   kNormal    (w n, w_g alpha^2)      n: the unit texel normal, so |mean n| < 1 measures how much
//                                       the normals under a footprint spread (Toksvig).
// Sizes follow GL's mip chain: level l is max(1, w >> l) x max(1, h >> l), down to 1 x 1.
// Every value is finite; a grid of texels none of which is shaded gives all-zero levels.
//
// Layer: viewer (libdigitize only, no GL).
#pragma once

#include <array>
#include <vector>

#include "digitize/pack.h"

namespace digitize::viewer {

enum ShadingChannel { kDiffuse = 0, kLafortune, kLobe, kGgx, kNormal, kShadingChannels };

struct ShadingLevel {
  int width = 0, height = 0;
  std::array<std::vector<float>, kShadingChannels> rgba;  // row 0 first, 4 floats per texel
};

struct ShadingPyramid {
  std::vector<ShadingLevel> levels;  // level 0 = the pack's grid
};

// `source`: ShadingSource(pack) (painting_setup.h), one entry per texel.
ShadingPyramid BuildShadingPyramid(const Pack& pack, const std::vector<size_t>& source);

// The box mean of `level` at half its size (GL's next mip size), as BuildShadingPyramid's levels.
ShadingLevel HalveShadingLevel(const ShadingLevel& level);

}  // namespace digitize::viewer
