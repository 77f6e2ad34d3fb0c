// Texture pack pyramid (issue 14): the prefilter that makes a coarser level of a pack, so a far
// view of a 1-Gtexel painting still shades right. Layer: pack.
//
// One coarse texel is the 2 x 2 fine texels it covers (a last odd row / column covers 1). Only
// measured or filled texels of the footprint's first such texel's model are averaged; a
// footprint with none is outside. The filter (docs/formats.md, "Pack pyramid"):
//   height: mean; max_height: the footprint's max (conservative relief bounds)
//   rho_d, lobe cx, cy: mean
//   normal: n = mean / |mean|; L = |mean| < 1 measures the normal variance (Toksvig)
//   Lafortune: k' = L k / (L + k (1 - L)) (Toksvig's factor), and rho_s scaled by
//              (k' + 2) / (k + 2) so the lobe's integral (energy) is kept
//   GGX: alpha'^2 = mean(alpha^2) + (1 - L) / L (the variance of the normal's slope), clamped
//        to [kGgxMinAlpha, 1]; rho_s (F0) mean
// Not yet: the tiled file format and reader, the streaming viewer (see the branch's report).
#pragma once
#include "digitize/core.h"
#include "digitize/height_field.h"
#include "digitize/reflectance_maps.h"

namespace digitize {

struct PackLevel {
  HeightField field;          // mean height, state
  Grid<float> max_height_mm;  // highest fine height under each texel
  Grid<Vec3f> normals;        // unit, nz > 0
  ReflectanceMaps maps;       // prefiltered as above; fit_error 0
};

// Level 0 from full-resolution maps (max_height = height). Precondition: same sizes.
PackLevel BaseLevel(const HeightField& field, const Grid<Vec3f>& normals,
                    const ReflectanceMaps& maps);

// The next coarser level: ceil(w / 2) x ceil(h / 2), pitch doubled. An empty level gives an
// empty level. Memory: the input and the output only (a quarter of it).
PackLevel PrefilterLevel(const PackLevel& fine);

}  // namespace digitize
