#include "height_mesh.h"

#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Tools/Decimater/DecimaterT.hh>
#include <OpenMesh/Tools/Decimater/ModQuadricT.hh>
#include <algorithm>

namespace digitize::viewer {
namespace {
using Mesh = OpenMesh::TriMesh_ArrayKernelT<>;
}

HeightMesh BuildHeightMesh(const HeightField& field, size_t max_triangles) {
  const int w = field.width(), h = field.height();
  const double p = field.pitch_mm;
  // Grid of (w + 2) x (h + 2) vertices: the outline, the texel centres, the outline.
  const int gw = w + 2, gh = h + 2;
  auto coord = [](int i, int n, double pitch) {  // i in [0, n + 1] -> mm from the first edge
    if (i == 0) return 0.0;
    if (i == n + 1) return n * pitch;
    return (i - 0.5) * pitch;
  };
  HeightMesh out;
  out.positions.reserve(size_t(gw) * gh * 3);
  for (int j = 0; j < gh; ++j) {
    const int ty = std::clamp(j - 1, 0, h - 1);
    const double y_mm = h * p - coord(j, h, p);  // row 0 is the top of the canvas
    for (int i = 0; i < gw; ++i) {
      const int tx = std::clamp(i - 1, 0, w - 1);
      out.positions.push_back(float(coord(i, w, p)));
      out.positions.push_back(float(y_mm));
      out.positions.push_back(field.height_mm(tx, ty));
    }
  }
  for (int j = 0; j + 1 < gh; ++j) {
    for (int i = 0; i + 1 < gw; ++i) {
      const uint32_t a = j * gw + i, b = a + 1, c = a + gw, d = c + 1;  // c, d one row down
      // Rows go down in Y: (a, c, b) is counter-clockwise seen from +Z.
      out.indices.insert(out.indices.end(), {a, c, b, b, c, d});
    }
  }
  if (max_triangles == 0 || out.triangles() <= max_triangles) return out;

  Mesh mesh;
  std::vector<Mesh::VertexHandle> vh(out.positions.size() / 3);
  for (size_t v = 0; v < vh.size(); ++v)
    vh[v] = mesh.add_vertex(
        Mesh::Point(out.positions[3 * v], out.positions[3 * v + 1], out.positions[3 * v + 2]));
  for (size_t t = 0; t < out.triangles(); ++t)
    mesh.add_face(vh[out.indices[3 * t]], vh[out.indices[3 * t + 1]], vh[out.indices[3 * t + 2]]);
  mesh.request_vertex_status();
  mesh.request_edge_status();
  mesh.request_face_status();
  for (auto v : mesh.vertices())
    if (mesh.is_boundary(v)) mesh.status(v).set_locked(true);  // keep the canvas rectangle
  OpenMesh::Decimater::DecimaterT<Mesh> decimater(mesh);
  OpenMesh::Decimater::ModQuadricT<Mesh>::Handle quadric;
  decimater.add(quadric);
  decimater.module(quadric).unset_max_err();
  decimater.initialize();
  decimater.decimate_to_faces(0, max_triangles);
  mesh.garbage_collection();

  HeightMesh simple;
  simple.positions.reserve(mesh.n_vertices() * 3);
  for (auto v : mesh.vertices()) {
    const auto& q = mesh.point(v);
    simple.positions.insert(simple.positions.end(), {q[0], q[1], q[2]});
  }
  for (auto f : mesh.faces())
    for (auto v : mesh.fv_range(f)) simple.indices.push_back(uint32_t(v.idx()));
  return simple;
}

}  // namespace digitize::viewer
