// The triangle mesh of a height field (Technique::kMesh): one vertex per texel centre plus a ring
// on the canvas outline repeating the border heights (the surface HeightFieldTracer traces), two
// triangles per quad; simplified with OpenMesh's quadric decimater when a budget is given (the
// outline is locked so the canvas keeps its rectangle). Internal to the viewer: OpenMesh stays in
// height_mesh.cpp.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "digitize/height_field.h"

namespace digitize::viewer {

struct HeightMesh {
  std::vector<float> positions;   // x, y, z per vertex, canvas frame, mm
  std::vector<uint32_t> indices;  // 3 per triangle, counter-clockwise seen from +Z
  size_t triangles() const { return indices.size() / 3; }
};

// max_triangles = 0: the full mesh, 2 (w + 1) (h + 1) triangles.
HeightMesh BuildHeightMesh(const HeightField& field, size_t max_triangles);

}  // namespace digitize::viewer
