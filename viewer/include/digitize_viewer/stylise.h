// The gallery's stylised looks (digitize-viewer --style NAME): the realistic render (the packs
// shaded as renderer.h says, the room as scene.frag) redrawn by a screen pass that reads its
// colour and depth, so every style covers room, frames and paintings alike and follows the
// paintings' relief as the depth buffer has it. GL-free parts here (the zoom cycle, the solid
// texture); the pass is in renderer.cpp / style.frag.
//
//   watercolor, binary, collage -- dynamic solid textures (seed 003 after seed 000): a noise
//     cube carved by each surface point's world position, blended over n = 4 octaves whose
//     frequencies follow the camera distance (InfiniteZoom), so texture elements keep their size
//     on screen at any distance and move with the surfaces (object space, not screen space);
//     watercolor: pigment density and paper grain modulate the colour (Bousseau's density model
//     C' = C - (C - C^2)(d - 1)), a wobbled colour lookup and darkened edges; binary: ink where
//     the texture falls below the tone's ink (threshold structure), plus depth outlines;
//     collage: the tone cut into 4 bands, each a paper strip of its own texture and hue, white
//     torn borders between them.
//   hatching -- tonal art maps (seed 004, tonal_art_map.h): 6 tones x 8 mip levels as a texture
//     array; the ink a pixel needs (1 - its display luminance) picks the two nearest tones and
//     blends them; texture coordinates are the world position projected along the surface's
//     dominant axis, scaled by the zoom cycle (the map at 2^k and 2^(k+1) blended by s) so a
//     tile keeps its size on screen, and the map's mip levels keep the strokes' width.
//   painterly -- strokes (seed 002): anchors fixed on the surfaces from a hierarchy that keeps
//     their density on screen (painterly_strokes.h), each drawn as a soft quad with the
//     render's colour at the anchor, oriented along its iso-luminance lines, shortened where the
//     colour along it strays (fidelity), over the render itself.
//
// Layer: viewer (libdigitize only, no GL here).
#pragma once

#include <array>
#include <cstdint>
#include <string_view>
#include <vector>

#include "digitize/core.h"

namespace digitize::viewer {

enum class Style { kRealistic, kWatercolor, kBinary, kCollage, kHatching, kPainterly };
inline constexpr Style kAllStyles[] = {Style::kRealistic, Style::kWatercolor, Style::kBinary,
                                       Style::kCollage,   Style::kHatching,   Style::kPainterly};
// "realistic", "watercolor", "binary", "collage", "hatching", "painterly"
const char* ToString(Style s);
Result<Style> ParseStyle(std::string_view name);

// Seed 003 section 3.1: for a point at distance z_cam (> 0, any unit) from the camera, octave
// i = 1..4 samples the solid texture at 2^(i-1) x / 2^floor(log2 z_cam) (`scale` is the
// denominator) with weight alpha_i(s), s = log2 z_cam - floor(log2 z_cam):
//   alpha_1 = s / 2, alpha_2 = 1/2 - s/6, alpha_3 = 1/3 - s/6, alpha_4 = 1/6 - s/6.
// They sum to 1, alpha_1(0) = alpha_4(1) = 0 and alpha_i(1) = alpha_{i+1}(0): continuous across
// the cycle's end, where every octave becomes the next one. z_cam is clamped to >= 1e-6.
inline constexpr int kZoomOctaves = 4;
struct ZoomCycle {
  double s = 0;      // position in the cycle, [0, 1)
  double scale = 1;  // 2^floor(log2 z_cam)
  std::array<double, kZoomOctaves> weights{};
  // Blending independent octaves shrinks the texture's contrast by sqrt(sum alpha_i^2) (seed 003
  // section 5); the styles scale the blend's deviation from its mean by this to restore it.
  double ContrastGain() const;
};
ZoomCycle InfiniteZoom(double z_cam);

// The noise cube the solid-texture styles carve: size^3 RGBA8 texels, tiling, each channel
// band-limited noise (64 random-phase waves of integer wave numbers per cube, so it tiles) with
// its values equalised to a uniform distribution over [0, 255] (a threshold of t then inks a
// fraction t of the surface). Channels: r pigment (|k| 3-6 waves per cube), g paper grain
// (10-16), b strokes and stipples (5-9), a wobble (1-3).
struct SolidTexture {
  int size = 0;
  std::vector<std::array<uint8_t, 4>> texels;  // x fastest, then y, then z
  static constexpr std::array<std::array<int, 2>, 4> kBands = {{{3, 6}, {10, 16}, {5, 9}, {1, 3}}};
};
// size: a power of two in [8, 256]; invalid sizes throw InvariantError.
SolidTexture BuildSolidTexture(int size = 64, uint64_t seed = 7);

}  // namespace digitize::viewer
