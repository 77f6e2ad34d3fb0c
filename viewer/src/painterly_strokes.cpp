#include "digitize_viewer/painterly_strokes.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace digitize::viewer {
namespace {

uint32_t Hash(uint32_t a, uint32_t b, uint32_t c, uint32_t d) {
  uint32_t h = 2166136261u;
  for (uint32_t v : {a, b, c, d}) {
    h ^= v + 0x9e3779b9u + (h << 6) + (h >> 2);
    h *= 16777619u;
  }
  h ^= h >> 15;
  h *= 0x2c1b3c6du;
  h ^= h >> 12;
  return h;
}
double Unit(uint32_t h) { return double(h & 0xffffff) / double(0x1000000); }

struct Walk {
  const StrokeFace& face;
  const Camera cam;
  Vec3d eye, forward;
  double f_px, margin_px, near_mm;
  const StrokeSelectOptions& o;
  std::vector<StrokeAnchor>& out;

  double Depth(const Vec3d& p) const { return (p - eye).dot(forward); }
  Vec3d At(double a, double b) const { return face.origin + a * face.u + b * face.v; }
  // The finest level anchors at depth z need.
  double Needed(double z) const {
    return std::log2(f_px * o.root_mm / (std::max(z, 1e-3) * o.spacing_px));
  }
  // The anchor of cell (i, j) at `level`, introduced there: jittered inside the cell.
  Eigen::Vector2d Anchor(int64_t i, int64_t j, int level) const {
    const uint32_t h = Hash(face.id, uint32_t(i), uint32_t(j), uint32_t(level));
    const double size = o.root_mm / std::exp2(level);
    return Eigen::Vector2d((double(i) + 0.15 + 0.7 * Unit(h)) * size,
                           (double(j) + 0.15 + 0.7 * Unit(Hash(h, 1, 2, 3))) * size);
  }
  bool Visible(const Vec3d& p) const {
    if (cam.camera_from_scan.Apply(p).z() < near_mm) return false;
    const Eigen::Vector2d px = cam.Project(p);
    return px.x() > -margin_px && px.y() > -margin_px && px.x() < cam.width + margin_px &&
           px.y() < cam.height + margin_px;
  }
  void Emit(const Eigen::Vector2d& ab, int level, uint32_t id) {
    if (ab.x() > face.u_len || ab.y() > face.v_len || out.size() >= o.max_anchors) return;
    const Vec3d p = At(ab.x(), ab.y());
    if (!Visible(p)) return;
    const double z = Depth(p);
    // In from when its parent level is fully in (l* = level - 1), whole at l* = level.
    const double w = std::clamp(Needed(z) - level + 1, 0.0, 1.0);
    if (!(w > 0)) return;
    out.push_back({p.cast<float>(), float(w), float(z), id});
  }
  // Cell (i, j) of `level`, whose anchor (introduced at `intro`, already emitted) is `anchor`.
  void Visit(int64_t i, int64_t j, int level, const Eigen::Vector2d& anchor) {
    const double size = o.root_mm / std::exp2(level);
    const double a0 = i * size, b0 = j * size;
    if (a0 >= face.u_len || b0 >= face.v_len) return;
    const double a1 = std::min(a0 + size, face.u_len), b1 = std::min(b0 + size, face.v_len);
    // The cell's corners: its nearest depth sets how fine it must go; all outside one plane of
    // the view frustum (widened by the margin) culls it. Camera frame, as half-spaces valid for
    // any z: u >= -m <=> fx x + (cx + m) z >= 0, and so on.
    std::array<Vec3d, 4> c = {At(a0, b0), At(a1, b0), At(a0, b1), At(a1, b1)};
    double zmin = 1e300;
    std::array<int, 5> outside = {0, 0, 0, 0, 0};
    const double m = margin_px;
    for (const Vec3d& p : c) {
      zmin = std::min(zmin, Depth(p));
      const Vec3d q = cam.camera_from_scan.Apply(p);
      outside[0] += cam.fx * q.x() + (cam.cx + m) * q.z() < 0;
      outside[1] += (cam.width + m - cam.cx) * q.z() - cam.fx * q.x() < 0;
      outside[2] += cam.fy * q.y() + (cam.cy + m) * q.z() < 0;
      outside[3] += (cam.height + m - cam.cy) * q.z() - cam.fy * q.y() < 0;
      outside[4] += q.z() < near_mm;
    }
    for (int k : outside)
      if (k == 4) return;
    // Nothing nearer than the near plane is drawn: a cell reaching behind the camera is refined
    // as if it ended there (else a cell straddling the eye would refine to max_level).
    if (level >= o.max_level || Needed(std::max(zmin, near_mm)) <= level) return;
    for (int k = 0; k < 4; ++k) {
      const int64_t ci = 2 * i + (k & 1), cj = 2 * j + (k >> 1);
      const double cs = size / 2;
      const bool holds = anchor.x() >= ci * cs && anchor.x() < (ci + 1) * cs &&
                         anchor.y() >= cj * cs && anchor.y() < (cj + 1) * cs;
      Eigen::Vector2d child = anchor;  // the parent's anchor stays: nested levels
      if (!holds) {
        child = Anchor(ci, cj, level + 1);
        Emit(child, level + 1, Hash(face.id, uint32_t(ci), uint32_t(cj), uint32_t(level + 1)));
      }
      Visit(ci, cj, level + 1, child);
    }
  }
};

}  // namespace

std::vector<StrokeFace> BoxFaces(const std::vector<SceneBox>& boxes, uint32_t first_id) {
  std::vector<StrokeFace> faces;
  uint32_t id = first_id;
  for (const SceneBox& b : boxes) {
    const Vec3d lo = b.min_mm, hi = b.max_mm, e = hi - lo;
    for (int axis = 0; axis < 3; ++axis)
      for (int side = 0; side < 2; ++side) {
        const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
        StrokeFace f;
        f.origin = lo;
        f.origin[axis] = side ? hi[axis] : lo[axis];
        f.u = Vec3d::Unit(a1);
        f.v = Vec3d::Unit(a2);
        f.u_len = e[a1];
        f.v_len = e[a2];
        // Facing out: u x v = +axis; flip for the low side by swapping u and v.
        if (!side) {
          std::swap(f.u, f.v);
          std::swap(f.u_len, f.v_len);
        }
        f.id = id++;
        if (f.u_len > 0 && f.v_len > 0) faces.push_back(f);
      }
  }
  return faces;
}

std::vector<StrokeAnchor> SelectStrokeAnchors(const std::vector<StrokeFace>& faces,
                                              const ViewCamera& camera,
                                              const StrokeSelectOptions& o) {
  std::vector<StrokeAnchor> out;
  const Camera cam = ToCamera(camera);
  const Vec3d forward = (camera.target_mm - camera.eye_mm).normalized();
  for (const StrokeFace& face : faces) {
    const Vec3d n = face.u.cross(face.v);
    if (n.dot(camera.eye_mm - face.origin) <= 0) continue;  // seen from behind
    Walk walk{
        face, cam, camera.eye_mm, forward, cam.fy, 2 * o.spacing_px, std::max(camera.near_mm, 1e-3),
        o,    out};
    const int64_t ni = int64_t(std::ceil(face.u_len / o.root_mm));
    const int64_t nj = int64_t(std::ceil(face.v_len / o.root_mm));
    for (int64_t i = 0; i < ni; ++i)
      for (int64_t j = 0; j < nj; ++j) {
        const Eigen::Vector2d a = walk.Anchor(i, j, 0);
        walk.Emit(a, 0, Hash(face.id, uint32_t(i), uint32_t(j), 0));
        walk.Visit(i, j, 0, a);
      }
  }
  std::sort(out.begin(), out.end(),
            [](const StrokeAnchor& a, const StrokeAnchor& b) { return a.depth_mm > b.depth_mm; });
  return out;
}

}  // namespace digitize::viewer
