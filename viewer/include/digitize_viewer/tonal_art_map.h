// Tonal art maps (seed 004, after Praun et al.): hatching textures for the gallery's `hatching`
// style, one per tone and mip level, built so that the hatching stays coherent as the tone and
// the viewing distance change:
//   - every texture of a tone has the same mean ink (to within what one stroke adds: the last
//     stroke of a texture is the candidate that lands nearest the target);
//   - a stroke of a tone is in every darker tone (same level), and a stroke of a level is in every
//     finer level (same tone): blending two neighbouring tones or mip levels never makes a stroke
//     appear from nothing or vanish in a jump;
//   - strokes keep their width in pixels at every level and their length relative to the
//     texture, so a far surface is not drawn with blurred, fat strokes.
// Built tone by tone (lightest first) and, within a tone, level by level from kFirstStrokeLevel's
// size up to the finest: strokes are added until the level's mean reaches the tone's target; each
// stroke is the best of `candidates` random ones (the one that covers the least ink already
// there, so strokes spread evenly; the last one of a texture the one that lands closest to the
// target) and goes into that texture and every darker tone and finer level. Levels coarser than
// kFirstStrokeLevel are box-filtered from it (seed 004: a stroke cannot keep its width there),
// which keeps their mean and the tone nesting exactly. Textures tile (strokes wrap around).
//
// Layer: viewer (libdigitize only, no GL).
#pragma once

#include <cstdint>
#include <vector>

#include "digitize/core.h"

namespace digitize::viewer {

struct TonalArtMapOptions {
  int size = 128;  // finest level, a power of two >= kFirstStrokeLevel
  std::vector<double> tone_ink = {0.10, 0.22, 0.36, 0.50, 0.65, 0.80};  // mean ink per tone,
                                                                        // increasing, in (0, 1)
  double stroke_width_px = 1.6;                                         // at every level
  double min_length = 0.25, max_length = 0.55;  // relative to the texture side
  double angle_deg = 40;                        // hatching direction (from +x towards +y)
  double angle_jitter_deg = 6;                  // uniform +- about it
  int cross_hatch_from_tone = 3;  // from this tone on, half the new strokes are orthogonal
  int candidates = 100;           // random strokes tried per stroke added
  uint64_t seed = 1;
  Status Validate() const;
};

struct TonalArtMap {
  static constexpr int kFirstStrokeLevel = 16;  // side of the coarsest level that gets strokes
  int tones = 0;
  int levels = 0;  // level 0 = size x size, level k = size / 2^k, down to 1 x 1
  // ink[tone * levels + level]: coverage in [0, 1] per texel (0 white paper, 1 black ink).
  std::vector<Grid<float>> ink;
  // strokes[tone * levels + level]: ids of the strokes drawn in it (levels with strokes only;
  // empty below kFirstStrokeLevel), ascending.
  std::vector<std::vector<uint32_t>> strokes;
  std::vector<double> target;  // the options' tone_ink

  const Grid<float>& At(int tone, int level) const { return ink[tone * levels + level]; }
  const std::vector<uint32_t>& StrokesAt(int tone, int level) const {
    return strokes[tone * levels + level];
  }
  static double Mean(const Grid<float>& g);
};

// Invalid options throw InvariantError (validate first).
TonalArtMap BuildTonalArtMap(const TonalArtMapOptions& options = {});

}  // namespace digitize::viewer
