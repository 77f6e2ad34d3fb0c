// Per-texel normals (paper section 5): the area-weighted mean of the normals of the 8 triangles
// that the texel forms with its 8-neighbourhood. Canvas frame, unit length, n_z > 0.
#pragma once

#include "digitize/height_field.h"

namespace digitize {

// Triangles touching a texel without height (kOutside / kUnfilled) or the grid border are left
// out; a texel with none left gets (0, 0, 1). Never NaN.
Grid<Vec3f> ComputeNormals(const HeightField& field);

}  // namespace digitize
