// The framed painting as an Embree scene in the canvas frame (see scan_sim.h for the geometry).
#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <mutex>
#include <string>
#include <vector>

#include "digitize_synth/scan_sim.h"

namespace digitize::synth {
namespace {

// Canvas grid primitives cover at most this many quads per side (Embree's limit is 32767
// vertices; smaller pieces also give the BVH builder parallel work).
constexpr int kGridCells = 256;
constexpr size_t kRayBatch = 256;  // rays per rtcIntersect1M call

// Frame moulding profile: (distance outwards from the canvas edge as a share of width_mm,
// height as a share of raise_mm). First and last points are replaced by the wall depth: the inner
// step and the outer face go down to the wall. Sight edge, a cove, a rounded top, a fall outwards.
constexpr std::array<std::array<double, 2>, 10> kProfile = {{{0.0, 0.0},
                                                             {0.0, 1.0},
                                                             {0.10, 1.0},
                                                             {0.18, 0.86},
                                                             {0.30, 0.82},
                                                             {0.45, 0.90},
                                                             {0.62, 0.98},
                                                             {0.78, 0.93},
                                                             {1.0, 0.70},
                                                             {1.0, 0.0}}};

void ErrorCallback(void* user, RTCError code, const char* message) {
  auto* last = static_cast<std::string*>(user);
  *last = "Embree error " + std::to_string(static_cast<int>(code)) + ": " +
          (message ? message : "(no message)");
}

}  // namespace

Status FrameOptions::Validate() const {
  auto fail = [](const std::string& what) { return Status(Error{"frame options: " + what}); };
  if (!(std::isfinite(raise_mm) && raise_mm > 0 && raise_mm <= 1000))
    return fail("raise_mm must be in (0, 1000], got " + FormatNumber(raise_mm));
  if (!(std::isfinite(width_mm) && width_mm > 0 && width_mm <= 1000))
    return fail("width_mm must be in (0, 1000], got " + FormatNumber(width_mm));
  if (!(std::isfinite(wall_depth_mm) && wall_depth_mm > 0 && wall_depth_mm <= 10000))
    return fail("wall_depth_mm must be in (0, 10000], got " + FormatNumber(wall_depth_mm));
  const char* names[4] = {"left_mm", "right_mm", "bottom_mm", "top_mm"};
  const double sides[4] = {left_mm, right_mm, bottom_mm, top_mm};
  for (int k = 0; k < 4; ++k)
    if (!(std::isfinite(sides[k]) && sides[k] >= 0 && sides[k] <= 1000))
      return fail(std::string(names[k]) + " must be in [0, 1000] (0 = width_mm), got " +
                  FormatNumber(sides[k]));
  double narrowest = width_mm;
  for (int k = 0; k < 4; ++k) narrowest = std::min(narrowest, Width(k));
  if (!(std::isfinite(bevel_width_mm) && bevel_width_mm >= 0 && bevel_width_mm < narrowest))
    return fail("bevel_width_mm must be in [0, the narrowest side's width " +
                FormatNumber(narrowest) + "), got " + FormatNumber(bevel_width_mm));
  if (!(std::isfinite(bevel_height_mm) && bevel_height_mm >= 0 && bevel_height_mm <= raise_mm))
    return fail("bevel_height_mm must be in [0, raise_mm], got " + FormatNumber(bevel_height_mm));
  if (!(std::isfinite(lip_mm) && lip_mm >= 0 && lip_mm <= 1000))
    return fail("lip_mm must be in [0, 1000], got " + FormatNumber(lip_mm));
  if (lip_mm > 0 && !(std::isfinite(lip_gap_mm) && lip_gap_mm > 0 && lip_gap_mm < raise_mm))
    return fail("lip_gap_mm must be in (0, raise_mm), got " + FormatNumber(lip_gap_mm));
  return Status::Ok();
}

Status FrameOptions::ValidateFor(double canvas_width_mm, double canvas_height_mm) const {
  if (Status s = Validate(); !s.ok()) return s;
  if (enabled && !(2 * lip_mm < std::min(canvas_width_mm, canvas_height_mm)))
    return Status(Error{"frame options: lip_mm " + FormatNumber(lip_mm) + " hides the whole " +
                        FormatNumber(canvas_width_mm) + " x " + FormatNumber(canvas_height_mm) +
                        " mm canvas"});
  return Status::Ok();
}

double FrameOptions::Width(int side) const {
  const double sides[4] = {left_mm, right_mm, bottom_mm, top_mm};
  return side >= 0 && side < 4 && sides[side] > 0 ? sides[side] : width_mm;
}

FrameBoxes FrameOptions::Boxes() const {
  FrameBoxes boxes;
  if (!enabled) return boxes;
  for (int side = 0; side < 4; ++side) {
    boxes.raise_mm[side] = static_cast<float>(raise_mm);
    boxes.width_mm[side] = static_cast<float>(Width(side));
  }
  return boxes;
}

struct Scene::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  std::string last_error;
  std::vector<Hit> kind_of_geometry;  // by Embree geometry id

  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }

  void Check(const char* what) const {
    RTCError e = rtcGetDeviceError(device);
    DIGITIZE_CHECK(e == RTC_ERROR_NONE, std::string("Scene: ") + what + ": " + last_error);
  }

  void Attach(RTCGeometry geometry, Hit kind) {
    rtcCommitGeometry(geometry);
    unsigned id = rtcAttachGeometry(scene, geometry);
    rtcReleaseGeometry(geometry);
    if (kind_of_geometry.size() <= id) kind_of_geometry.resize(id + 1, Hit::kNone);
    kind_of_geometry[id] = kind;
  }

  void AddTriangles(const std::vector<Eigen::Vector3f>& vertices,
                    const std::vector<std::array<unsigned, 3>>& triangles, Hit kind) {
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), vertices.size()));
    auto* t = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), triangles.size()));
    Check("triangle buffers");
    for (size_t i = 0; i < vertices.size(); ++i)
      for (int k = 0; k < 3; ++k) v[3 * i + k] = vertices[i][k];
    for (size_t i = 0; i < triangles.size(); ++i)
      for (int k = 0; k < 3; ++k) t[3 * i + k] = triangles[i][k];
    Attach(g, kind);
  }

  void AddCanvas(const Painting& painting) {
    const Grid<float>& h = painting.truth.height_mm;
    const int w = h.width, ht = h.height;
    const double pitch = painting.truth.pitch_mm;
    const unsigned stride = static_cast<unsigned>(w + 2);
    const size_t rows = static_cast<size_t>(ht + 2);
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_GRID);
    auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), stride * rows));
    Check("canvas vertex buffer");
    // Vertex (c, r): c = 0 and c = w + 1 lie on the canvas outline, 1..w on the texel centres.
    auto coord = [](int i, int n, double pitch_mm) {
      if (i == 0) return 0.0;
      if (i == n + 1) return n * pitch_mm;
      return (i - 0.5) * pitch_mm;
    };
    tbb::parallel_for(
        tbb::blocked_range<int>(0, ht + 2, 64), [&](const tbb::blocked_range<int>& r) {
          for (int row = r.begin(); row < r.end(); ++row) {
            const float y_mm = static_cast<float>(painting.height_mm - coord(row, ht, pitch));
            const float* src = h.Row(std::clamp(row - 1, 0, ht - 1));
            float* dst = v + 3 * static_cast<size_t>(row) * stride;
            for (int c = 0; c < w + 2; ++c) {
              dst[3 * c + 0] = static_cast<float>(coord(c, w, pitch));
              dst[3 * c + 1] = y_mm;
              dst[3 * c + 2] = src[std::clamp(c - 1, 0, w - 1)];
            }
          }
        });
    const int cells_x = w + 1, cells_y = ht + 1;
    const int tiles_x = (cells_x + kGridCells - 1) / kGridCells;
    const int tiles_y = (cells_y + kGridCells - 1) / kGridCells;
    auto* grids = static_cast<RTCGrid*>(
        rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_GRID, 0, RTC_FORMAT_GRID, sizeof(RTCGrid),
                                static_cast<size_t>(tiles_x) * tiles_y));
    Check("canvas grid buffer");
    for (int ty = 0; ty < tiles_y; ++ty) {
      for (int tx = 0; tx < tiles_x; ++tx) {
        int c0 = tx * kGridCells, r0 = ty * kGridCells;
        RTCGrid& grid = grids[static_cast<size_t>(ty) * tiles_x + tx];
        grid.startVertexID = static_cast<unsigned>(r0) * stride + static_cast<unsigned>(c0);
        grid.stride = stride;
        grid.width = static_cast<unsigned short>(std::min(kGridCells, cells_x - c0) + 1);
        grid.height = static_cast<unsigned short>(std::min(kGridCells, cells_y - r0) + 1);
      }
    }
    Attach(g, Hit::kCanvas);
  }

  // Profile of one side (distance outwards from the canvas outline, height), inner step first.
  static std::vector<std::array<double, 2>> SideProfile(const FrameOptions& frame, double width) {
    std::vector<std::array<double, 2>> out;
    const double bw = frame.bevel_width_mm;
    if (bw > 0 || frame.bevel_height_mm > 0) {
      // The bevel's foot is the canvas outline at the canvas plane (below it: the hidden step).
      out.push_back({0.0, -frame.wall_depth_mm});
      out.push_back({0.0, 0.0});
      out.push_back({bw, frame.bevel_height_mm});
    }
    for (size_t k = 0; k < kProfile.size(); ++k) {
      if (!out.empty() && k == 0) continue;
      const auto& p = kProfile[k];
      const double d = bw + p[0] * (width - bw);
      out.push_back({d, p[1] == 0.0 ? -frame.wall_depth_mm : p[1] * frame.raise_mm});
    }
    return out;
  }

  // A closed loop of rectangles around the canvas, one per profile point, joined by quads.
  void AddFrame(const Painting& painting, const FrameOptions& frame) {
    const double W = painting.width_mm, H = painting.height_mm;
    std::array<std::vector<std::array<double, 2>>, 4> side;  // left, right, bottom, top
    for (int k = 0; k < 4; ++k) side[static_cast<size_t>(k)] = SideProfile(frame, frame.Width(k));
    const size_t points = side[0].size();
    std::vector<Eigen::Vector3f> vertices;
    for (size_t i = 0; i < points; ++i) {
      const double dl = side[0][i][0], dr = side[1][i][0], db = side[2][i][0], dt = side[3][i][0];
      // Every side shares the profile's heights; only the distances differ.
      const float z = static_cast<float>(side[0][i][1]);
      for (const auto& corner : {Eigen::Vector2d(-dl, -db), Eigen::Vector2d(W + dr, -db),
                                 Eigen::Vector2d(W + dr, H + dt), Eigen::Vector2d(-dl, H + dt)})
        vertices.emplace_back(static_cast<float>(corner.x()), static_cast<float>(corner.y()), z);
    }
    std::vector<std::array<unsigned, 3>> triangles;
    for (unsigned i = 0; i + 1 < points; ++i) AddRing(4 * i, 4 * (i + 1), triangles);
    if (frame.lip_mm > 0) {
      // The lip: a plate from the lip's inner outline to the moulding's top (past the bevel),
      // lip_gap_mm .. raise_mm above the canvas plane: top, underside and inner face.
      const double L = frame.lip_mm, o = frame.bevel_width_mm;
      const unsigned base = static_cast<unsigned>(vertices.size());
      for (double z : {frame.lip_gap_mm, frame.raise_mm})
        for (double d : {-L, o})
          for (const auto& corner : {Eigen::Vector2d(-d, -d), Eigen::Vector2d(W + d, -d),
                                     Eigen::Vector2d(W + d, H + d), Eigen::Vector2d(-d, H + d)})
            vertices.emplace_back(static_cast<float>(corner.x()), static_cast<float>(corner.y()),
                                  static_cast<float>(z));
      AddRing(base + 0, base + 4, triangles);   // underside
      AddRing(base + 8, base + 12, triangles);  // top
      AddRing(base + 0, base + 8, triangles);   // inner face
    }
    AddTriangles(vertices, triangles, Hit::kFrame);
  }

  // Quads joining two rectangles of four vertices each (corners in the same order).
  static void AddRing(unsigned a0, unsigned b0, std::vector<std::array<unsigned, 3>>& triangles) {
    for (unsigned k = 0; k < 4; ++k) {
      const unsigned k1 = (k + 1) % 4;
      const unsigned a = a0 + k, b = a0 + k1, c = b0 + k1, d = b0 + k;
      triangles.push_back({a, b, c});
      triangles.push_back({a, c, d});
    }
  }

  // Without a frame: the canvas's sides, from the wall up to the lowest border height (so they
  // never poke above the canvas surface).
  void AddCanvasSides(const Painting& painting, const FrameOptions& frame) {
    const Grid<float>& h = painting.truth.height_mm;
    float top = 0;
    for (int x = 0; x < h.width; ++x) top = std::min({top, h(x, 0), h(x, h.height - 1)});
    for (int y = 0; y < h.height; ++y) top = std::min({top, h(0, y), h(h.width - 1, y)});
    const float W = static_cast<float>(painting.width_mm),
                H = static_cast<float>(painting.height_mm);
    const float bottom = static_cast<float>(-frame.wall_depth_mm);
    std::vector<Eigen::Vector3f> vertices = {{0, 0, bottom}, {W, 0, bottom}, {W, H, bottom},
                                             {0, H, bottom}, {0, 0, top},    {W, 0, top},
                                             {W, H, top},    {0, H, top}};
    std::vector<std::array<unsigned, 3>> triangles;
    for (unsigned k = 0; k < 4; ++k) {
      unsigned k1 = (k + 1) % 4;
      triangles.push_back({k, k1, 4 + k1});
      triangles.push_back({k, 4 + k1, 4 + k});
    }
    AddTriangles(vertices, triangles, Hit::kFrame);
  }

  void AddWall(const Painting& painting, const FrameOptions& frame) {
    // Far larger than any field of view a scan of this scene can have, small enough for float.
    const float reach = static_cast<float>(20 * (painting.width_mm + painting.height_mm) + 1e4);
    const float W = static_cast<float>(painting.width_mm),
                H = static_cast<float>(painting.height_mm);
    const float z = static_cast<float>(-frame.wall_depth_mm);
    std::vector<Eigen::Vector3f> vertices = {{-reach, -reach, z},
                                             {W + reach, -reach, z},
                                             {W + reach, H + reach, z},
                                             {-reach, H + reach, z}};
    AddTriangles(vertices, {{0, 1, 2}, {0, 2, 3}}, Hit::kWall);
  }
};

Scene::Scene(const Painting& painting, const FrameOptions& frame)
    : painting_(painting), frame_(frame), impl_(std::make_unique<Impl>()) {
  Status valid = frame.ValidateFor(painting.width_mm, painting.height_mm);
  DIGITIZE_CHECK(valid.ok(), "Scene: " + valid.message());
  DIGITIZE_CHECK(!painting.truth.height_mm.empty(), "Scene: empty painting");
  impl_->device = rtcNewDevice(nullptr);
  DIGITIZE_CHECK(impl_->device != nullptr, "Scene: rtcNewDevice failed");
  rtcSetDeviceErrorFunction(impl_->device, ErrorCallback, &impl_->last_error);
  impl_->scene = rtcNewScene(impl_->device);
  // Watertight intersection: without it a few rays in a million slip between canvas triangles
  // and report the wall in the middle of the canvas.
  rtcSetSceneFlags(impl_->scene, RTC_SCENE_FLAG_ROBUST);
  impl_->Check("rtcNewScene");
  impl_->AddCanvas(painting);
  if (frame.enabled) {
    impl_->AddFrame(painting, frame);
  } else {
    impl_->AddCanvasSides(painting, frame);
  }
  impl_->AddWall(painting, frame);
  rtcCommitScene(impl_->scene);
  impl_->Check("scene build");
}

Scene::~Scene() = default;

namespace {

// Fills an Embree ray; a zero or non-finite direction or origin gives an empty ray (tfar < tnear).
void SetRay(RTCRay& ray, const Vec3d& o, const Vec3d& direction, float max_t, unsigned id) {
  Vec3d d = direction;
  const double len = d.norm();
  const bool valid = len > 0 && std::isfinite(len) && o.allFinite();
  if (valid) d /= len;
  ray.org_x = static_cast<float>(o.x());
  ray.org_y = static_cast<float>(o.y());
  ray.org_z = static_cast<float>(o.z());
  ray.dir_x = static_cast<float>(d.x());
  ray.dir_y = static_cast<float>(d.y());
  ray.dir_z = static_cast<float>(d.z());
  ray.tnear = 0.0f;
  ray.tfar = valid ? max_t : -1.0f;
  ray.time = 0.0f;
  ray.mask = 0xFFFFFFFFu;
  ray.id = id;
  ray.flags = 0;
}

}  // namespace

void Scene::Intersect(const std::vector<Vec3d>& origins, const std::vector<Vec3d>& directions,
                      std::vector<RayHit>& hits) const {
  IntersectImpl(origins, directions, nullptr, hits);
}

void Scene::Intersect(const std::vector<Vec3d>& origins, const std::vector<Vec3d>& directions,
                      const std::vector<float>& max_t_mm, std::vector<RayHit>& hits) const {
  DIGITIZE_CHECK(max_t_mm.size() == origins.size(), "Scene::Intersect: size mismatch");
  IntersectImpl(origins, directions, &max_t_mm, hits);
}

void Scene::IntersectImpl(const std::vector<Vec3d>& origins, const std::vector<Vec3d>& directions,
                          const std::vector<float>* max_t_mm, std::vector<RayHit>& hits) const {
  DIGITIZE_CHECK(origins.size() == directions.size(), "Scene::Intersect: size mismatch");
  hits.assign(origins.size(), RayHit{});
  const size_t n = origins.size();
  const size_t batches = (n + kRayBatch - 1) / kRayBatch;
  constexpr float kInf = std::numeric_limits<float>::infinity();
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, batches), [&](const tbb::blocked_range<size_t>& r) {
        std::array<RTCRayHit, kRayBatch> rays;
        RTCIntersectContext context;
        rtcInitIntersectContext(&context);
        context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
        for (size_t batch = r.begin(); batch < r.end(); ++batch) {
          const size_t first = batch * kRayBatch, count = std::min(kRayBatch, n - first);
          for (size_t k = 0; k < count; ++k) {
            RTCRayHit& ray = rays[k];
            SetRay(ray.ray, origins[first + k], directions[first + k],
                   max_t_mm ? (*max_t_mm)[first + k] : kInf, static_cast<unsigned>(k));
            ray.hit.geomID = RTC_INVALID_GEOMETRY_ID;
            ray.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
          }
          rtcIntersect1M(impl_->scene, &context, rays.data(), static_cast<unsigned>(count),
                         sizeof(RTCRayHit));
          for (size_t k = 0; k < count; ++k) {
            const RTCRayHit& ray = rays[k];
            RayHit& out = hits[first + k];
            if (ray.hit.geomID == RTC_INVALID_GEOMETRY_ID) continue;
            out.what = impl_->kind_of_geometry[ray.hit.geomID];
            out.t = ray.ray.tfar;
            Vec3d normal(ray.hit.Ng_x, ray.hit.Ng_y, ray.hit.Ng_z);
            Vec3d dir(ray.ray.dir_x, ray.ray.dir_y, ray.ray.dir_z);
            normal.normalize();
            if (normal.dot(dir) > 0) normal = -normal;
            out.normal = normal;
          }
        }
      });
}

void Scene::Occluded(const std::vector<Vec3d>& origins, const std::vector<Vec3d>& directions,
                     const std::vector<float>& max_t_mm, std::vector<uint8_t>& blocked) const {
  DIGITIZE_CHECK(origins.size() == directions.size() && origins.size() == max_t_mm.size(),
                 "Scene::Occluded: size mismatch");
  const size_t n = origins.size();
  blocked.assign(n, 0);
  const size_t batches = (n + kRayBatch - 1) / kRayBatch;
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, batches), [&](const tbb::blocked_range<size_t>& r) {
        std::array<RTCRay, kRayBatch> rays;
        RTCIntersectContext context;
        rtcInitIntersectContext(&context);
        context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
        for (size_t batch = r.begin(); batch < r.end(); ++batch) {
          const size_t first = batch * kRayBatch, count = std::min(kRayBatch, n - first);
          for (size_t k = 0; k < count; ++k) {
            SetRay(rays[k], origins[first + k], directions[first + k], max_t_mm[first + k],
                   static_cast<unsigned>(k));
          }
          rtcOccluded1M(impl_->scene, &context, rays.data(), static_cast<unsigned>(count),
                        sizeof(RTCRay));
          // Embree marks a blocked ray by setting tfar to -inf; an empty ray keeps its tfar of -1.
          for (size_t k = 0; k < count; ++k) {
            blocked[first + k] = rays[k].tfar == -std::numeric_limits<float>::infinity() ? 1 : 0;
          }
        }
      });
}

}  // namespace digitize::synth
