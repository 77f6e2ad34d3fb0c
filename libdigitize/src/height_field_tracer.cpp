// Ray queries against the canvas height field: Embree grid primitives plus a max-pyramid that
// proves rays free without tracing them (see height_field_tracer.h for the contract).
//
// The vertex buffer is ours (shared with Embree, no copy): x, y, z per vertex, row-major, (w + 2)
// x (h + 2) vertices: the texel centres plus a ring on the canvas outline that repeats the border
// texels' heights (as the generator's Scene does), so the surface covers the whole canvas
// rectangle and rays through border texel centres meet it inside a grid, not on its rim. Row 0 of
// the buffer is the outline at the top of the canvas (the largest Y). The texel heights in it are
// level 0 of the max-pyramid; levels 1.. hold the maxima of 2^k x 2^k blocks of texels.
#include "digitize/height_field_tracer.h"

#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

namespace digitize {
namespace {

// Quads per side of one Embree grid primitive (Embree allows up to 32767 vertices per side;
// pieces of 256 give its builder parallel work and match the generator's Scene).
constexpr int kGridCells = 256;
// Rays per rtcOccluded1M / rtcIntersect1M call: amortises the call, fits on the stack (12 KiB).
constexpr size_t kRayBatch = 256;
// Spans up to this many rays run on the calling thread: the sample gatherer calls Occluded from
// many threads with spans of a few hundred rays, where spawning tasks would cost more than it
// saves.
constexpr size_t kInlineRays = 4 * kRayBatch;
// Batches per TBB task on long spans.
constexpr size_t kBatchGrain = 4;
// Refinements of the height bound per ray (each shrinks the reach, then the box, then the bound).
// On a synthetic 2048^2 painting, 1 / 2 / 3 / 4 rounds skip 8.5 / 40.6 / 42.6 / 42.7 % of
// shadow rays towards a light dome.
constexpr int kSkipRounds = 3;
// Slack (texels) around a ray's horizontal footprint before it is rounded out to whole texels.
// Embree decides hits in float relative to the ray origin, to ~1e-7 of the local distances; the
// slack covers that with a wide margin yet stays far below the footprint's start (tnear x cos(e),
// 1e-3 texel by default), so the texels behind the origin stay out of the box.
constexpr double kFootprintSlackTexels = 1e-4;
// Relative slack on a traced ray's cut tfar, for the same reason (a hit just at the reach).
constexpr double kReachSlack = 1e-5;

// floor / ceil of a double within int range.
inline int FloorInt(double v) {
  const int i = static_cast<int>(v);  // truncates towards zero
  return i - (v < i);
}
inline int CeilInt(double v) {
  const int i = static_cast<int>(v);
  return i + (v > i);
}

void ErrorCallback(void* user, RTCError code, const char* message) {
  auto* last = static_cast<std::string*>(user);
  *last = "Embree error " + std::to_string(static_cast<int>(code)) + ": " +
          (message ? message : "(no message)");
}

bool MemoryMonitor(void* user, ssize_t bytes, bool /*post*/) {
  static_cast<std::atomic<int64_t>*>(user)->fetch_add(bytes, std::memory_order_relaxed);
  return true;
}

double OriginOffset(const TraceOptions& options, double pitch_mm) {
  return options.origin_offset_mm < 0 ? 1e-3 * pitch_mm : options.origin_offset_mm;
}

// Runs body(first_batch, end_batch) over `batches` batches: inline for short spans or one thread,
// otherwise in parallel (in an arena of num_threads when given).
template <class Body>
void ForBatches(size_t rays, size_t batches, int num_threads, const Body& body) {
  if (rays <= kInlineRays || num_threads == 1) {
    body(size_t{0}, batches);
    return;
  }
  auto run = [&] {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, batches, kBatchGrain),
                      [&](const tbb::blocked_range<size_t>& r) { body(r.begin(), r.end()); });
  };
  if (num_threads > 1) {
    tbb::task_arena arena(num_threads);
    arena.execute(run);
  } else {
    run();
  }
}

}  // namespace

Status TraceOptions::Validate() const {
  if (std::isnan(origin_offset_mm) || std::isinf(origin_offset_mm))
    return Error{"origin_offset_mm must be finite (< 0 = 1e-3 x pitch), got " +
                 FormatNumber(origin_offset_mm)};
  if (num_threads < 0)
    return Error{"num_threads must be >= 0 (0 = all cores), got " + std::to_string(num_threads)};
  return Status::Ok();
}

struct HeightFieldTracer::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  std::string last_error;
  std::atomic<int64_t> embree_bytes{0};

  int width = 0, height = 0;  // the grid's (a window's) texels
  // The window's place in the full canvas (HeightField::window): texel and outline coordinates
  // are the full canvas's.
  int x0 = 0, y0 = 0, full_width = 0, full_height = 0;
  float window_max_height_mm = 0;
  double pitch_mm = 0, inv_pitch_mm = 0;
  float max_height_mm = 0;
  float frame_raise_mm = 0;  // highest side's raise
  unsigned frame_geometry = RTC_INVALID_GEOMETRY_ID;
  std::vector<float> vertices;  // x, y, z of (w + 2) x (h + 2) vertices, + 1 float for Embree's
                                // 16-byte loads
  std::vector<std::vector<float>> levels;      // levels[k - 1]: maxima of 2^k blocks, k >= 1
  std::vector<int> level_width, level_height;  // for k = 0 (texels) and up

  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }

  Status EmbreeStatus(const char* what) const {
    const RTCError e = rtcGetDeviceError(device);
    if (e == RTC_ERROR_NONE) return Status::Ok();
    return Error{
        std::string("height-field tracer: ") + what + ": " +
        (last_error.empty() ? "Embree error " + std::to_string(static_cast<int>(e)) : last_error)};
  }

  Status AttachFrameBoxes(const FrameBoxes& frame);

  // Height of texel (x, y): vertex (x + 1, y + 1) of the buffer (the outline ring is row and
  // column 0).
  float Height(int x, int y) const {
    return vertices[3 * (static_cast<size_t>(y + 1) * (width + 2) + static_cast<size_t>(x + 1)) +
                    2];
  }

  void BuildPyramid() {
    level_width = {width};
    level_height = {height};
    levels.clear();
    while (level_width.back() > 1 || level_height.back() > 1) {
      const int k = static_cast<int>(level_width.size());  // level being built
      const int pw = level_width.back(), ph = level_height.back();
      const int lw = (pw + 1) / 2, lh = (ph + 1) / 2;
      std::vector<float> level(static_cast<size_t>(lw) * lh);
      const std::vector<float>* prev = k >= 2 ? &levels.back() : nullptr;
      auto at = [&](int x, int y) {
        return prev ? (*prev)[static_cast<size_t>(y) * pw + x] : Height(x, y);
      };
      tbb::parallel_for(tbb::blocked_range<int>(0, lh, 16), [&](const tbb::blocked_range<int>& r) {
        for (int y = r.begin(); y < r.end(); ++y) {
          const int y0 = 2 * y, y1 = std::min(2 * y + 1, ph - 1);
          for (int x = 0; x < lw; ++x) {
            const int x0 = 2 * x, x1 = std::min(2 * x + 1, pw - 1);
            level[static_cast<size_t>(y) * lw + x] =
                std::max(std::max(at(x0, y0), at(x1, y0)), std::max(at(x0, y1), at(x1, y1)));
          }
        }
      });
      levels.push_back(std::move(level));
      level_width.push_back(lw);
      level_height.push_back(lh);
    }
    max_height_mm = levels.empty() ? Height(0, 0) : levels.back()[0];
    if (full_width > 0 && (full_width != width || full_height != height))
      max_height_mm = std::max(max_height_mm, window_max_height_mm);
  }

  // Max height over the texels [x0, x1] x [y0, y1] (inclusive, inside the grid, non-empty), an
  // upper bound from the level whose blocks are at most half the box's longer side (<= 5 x 5
  // blocks read).
  float BoxMax(int x0, int x1, int y0, int y1) const {
    const int span = std::max(x1 - x0, y1 - y0) + 1;
    const int k =
        std::min(std::max(0, static_cast<int>(std::bit_width(static_cast<unsigned>(span))) - 2),
                 static_cast<int>(levels.size()));
    // Two running maxima: halves the dependency chain of max operations.
    float m0 = -std::numeric_limits<float>::infinity(), m1 = m0;
    if (k == 0) {
      for (int y = y0; y <= y1; ++y) {
        const float* row = vertices.data() + 3 * (static_cast<size_t>(y + 1) * (width + 2) + 1) + 2;
        int x = x0;
        for (; x + 1 <= x1; x += 2) {
          m0 = std::max(m0, row[3 * x]);
          m1 = std::max(m1, row[3 * x + 3]);
        }
        if (x <= x1) m0 = std::max(m0, row[3 * x]);
      }
      return std::max(m0, m1);
    }
    const std::vector<float>& level = levels[static_cast<size_t>(k - 1)];
    const int lw = level_width[static_cast<size_t>(k)];
    const int bx0 = x0 >> k, bx1 = x1 >> k;
    for (int by = y0 >> k; by <= (y1 >> k); ++by) {
      const float* row = level.data() + static_cast<size_t>(by) * lw;
      int bx = bx0;
      for (; bx + 1 <= bx1; bx += 2) {
        m0 = std::max(m0, row[bx]);
        m1 = std::max(m1, row[bx + 1]);
      }
      if (bx <= bx1) m0 = std::max(m0, row[bx]);
    }
    return std::max(m0, m1);
  }

  // Vertex range [x0, x1] x [y0, y1] of the quads under the continuous texel box [lo, hi]
  // (rounded out, clamped to the texel grid: the outline ring repeats the border texels). False
  // when the box misses the surface, which spans [-0.5, n - 0.5] texels.
  bool BoxTexels(double lo_x, double hi_x, double lo_y, double hi_y, int& x0, int& x1, int& y0,
                 int& y1) const {
    lo_x -= kFootprintSlackTexels, lo_y -= kFootprintSlackTexels;
    hi_x += kFootprintSlackTexels, hi_y += kFootprintSlackTexels;
    if (hi_x < -0.5 || hi_y < -0.5 || lo_x > width - 0.5 || lo_y > height - 0.5) return false;
    // Clamped before rounding: near-level rays reach far beyond int range. (std::floor is a libm
    // call without SSE4.1; the integer forms below are what the hot path can afford.)
    x0 = std::max(0, FloorInt(std::max(lo_x, -1.0)));
    x1 = std::min(width - 1, CeilInt(std::min(hi_x, static_cast<double>(width))));
    y0 = std::max(0, FloorInt(std::max(lo_y, -1.0)));
    y1 = std::min(height - 1, CeilInt(std::min(hi_y, static_cast<double>(height))));
    return true;
  }

  // The tfar to trace ray (o, d, tfar) with, or a negative value when the ray is proven free
  // (nothing within [tnear, tfar]). `offset`: the origin lift and tnear (mm).
  float CutRay(const Vec3f& o, const Vec3f& d, float tfar, float offset) const {
    if (!(d.z() > 0.0f)) return tfar;    // level or downwards: always traced
    if (!(tfar > offset)) return -1.0f;  // an empty interval: Embree finds nothing either
    // The origin height Embree gets (float), so both sides compare the same numbers; z_start is
    // the ray's height at tnear, where hits begin to count.
    const double lifted_z = static_cast<float>(o.z() + offset);
    const double inv_dz = 1.0 / d.z();
    const double z_start = lifted_z + offset * static_cast<double>(d.z());
    // Beyond t_reach(bound) the ray is higher than `bound`.
    auto t_reach = [&](double bound) { return (bound - lifted_z) * inv_dz; };
    auto cut = [&](double bound) {
      return static_cast<float>(
          std::min<double>(tfar, t_reach(bound) * (1 + kReachSlack) + offset));
    };
    double bound = max_height_mm;
    if (bound <= z_start) return -1.0f;
    // Origin, direction and the footprint's start (at tnear) in continuous texel coordinates
    // (row flip: texel y grows as Y falls). The start lies just in front of the origin, so the
    // texels behind it stay out of the boxes.
    const double tx = o.x() * inv_pitch_mm - 0.5 - x0,
                 ty = full_height - o.y() * inv_pitch_mm - 0.5 - y0;
    const double ddx = d.x() * inv_pitch_mm, ddy = -d.y() * inv_pitch_mm;
    const double sx = tx + offset * ddx, sy = ty + offset * ddy;
    int x0, x1, y0, y1;
    // Every round's box holds the vertices around the start: when one of them is higher than the
    // ray there, no round can skip. Most rays that are not provably free end here, for a few
    // lookups, instead of after every round.
    if (BoxTexels(sx, sx, sy, sy, x0, x1, y0, y1) && BoxMax(x0, x1, y0, y1) > z_start)
      return cut(bound);
    for (int round = 0; round < kSkipRounds; ++round) {
      const double t_end = std::min<double>(tfar, t_reach(bound));
      const double ex = tx + t_end * ddx, ey = ty + t_end * ddy;
      if (!BoxTexels(std::min(sx, ex), std::max(sx, ex), std::min(sy, ey), std::max(sy, ey), x0, x1,
                     y0, y1))
        return -1.0f;  // the footprint misses the surface
      const double refined = BoxMax(x0, x1, y0, y1);
      if (refined <= z_start) return -1.0f;
      if (refined >= bound) break;
      bound = refined;
    }
    return cut(bound);
  }

  // CutRay with the frame boxes: a ray the relief cannot block may still meet a side's box, and
  // only where it leaves the canvas rectangle below the highest raise. Such a ray is traced up
  // to where it rises above every box (Embree finds which box, if any, it meets).
  float CutRayFramed(const Vec3f& o, const Vec3f& d, float tfar, float offset) const {
    const float t = CutRay(o, d, tfar, offset);
    if (frame_raise_mm <= 0.0f || !(d.z() > 0.0f)) return t;  // no frame, or traced as it is
    const double lifted_z = static_cast<float>(o.z() + offset);
    const double t_above = (frame_raise_mm - lifted_z) / d.z();
    if (t_above <= 0.0) return t;  // starts above every box
    // Where the ray's horizontal path leaves [0, W] x [0, H] (0 for an origin outside it).
    const double W = full_width * pitch_mm, H = full_height * pitch_mm;
    const auto exit_along = [](double p, double dp, double hi) {
      if (p < 0.0 || p > hi) return 0.0;
      if (dp > 0.0) return (hi - p) / dp;
      if (dp < 0.0) return -p / dp;
      return std::numeric_limits<double>::infinity();
    };
    const double t_exit = std::min(exit_along(o.x(), d.x(), W), exit_along(o.y(), d.y(), H));
    if (t_exit >= std::min<double>(tfar, t_above)) return t;
    const float t_frame =
        static_cast<float>(std::min<double>(tfar, t_above * (1 + kReachSlack) + offset));
    return std::max(t, t_frame);
  }
};

HeightFieldTracer::HeightFieldTracer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
HeightFieldTracer::HeightFieldTracer(HeightFieldTracer&&) noexcept = default;
HeightFieldTracer& HeightFieldTracer::operator=(HeightFieldTracer&&) noexcept = default;
HeightFieldTracer::~HeightFieldTracer() = default;

// The frame boxes as one triangle mesh (12 triangles per box). Corners belong to the left and
// right boxes, which span the bottom and top widths (and gaps) too, and the bottom and top boxes
// reach them, so a grazing ray cannot pass between two boxes. The boxes start one pitch below the
// canvas plane: rays from the canvas start above it.
Status HeightFieldTracer::Impl::AttachFrameBoxes(const FrameBoxes& frame) {
  if (Status s = frame.Validate(); !s.ok()) return Error{"height-field tracer: " + s.message()};
  const float W = static_cast<float>(full_width * pitch_mm);
  const float H = static_cast<float>(full_height * pitch_mm);
  const float z0 = static_cast<float>(-pitch_mm);
  const auto& w = frame.width_mm;
  struct Box {
    float x0, x1, y0, y1, z1;
  };
  std::vector<Box> boxes;
  // A side with a raise but no width still blocks: a thin wall of one pitch.
  const float min_w = static_cast<float>(pitch_mm);
  const auto width_of = [&](int side) { return std::max(w[side], min_w); };
  const auto& gap = frame.gap_mm;
  // Outer edges of the bottom and top boxes (Y), inner edges of the left and right ones (X).
  const float y0 = frame.raise_mm[2] > 0 ? -gap[2] - width_of(2) : 0.0f;
  const float y1 = frame.raise_mm[3] > 0 ? H + gap[3] + width_of(3) : H;
  const auto& r = frame.raise_mm;
  if (r[0] > 0) boxes.push_back({-gap[0] - width_of(0), -gap[0], y0, y1, r[0]});
  if (r[1] > 0) boxes.push_back({W + gap[1], W + gap[1] + width_of(1), y0, y1, r[1]});
  // The bottom and top boxes reach the left and right ones' inner edges (over their gaps).
  const float x0 = r[0] > 0 ? -gap[0] : 0.0f, x1 = r[1] > 0 ? W + gap[1] : W;
  if (r[2] > 0) boxes.push_back({x0, x1, y0, -gap[2], r[2]});
  if (r[3] > 0) boxes.push_back({x0, x1, H + gap[3], y1, r[3]});

  RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(
      g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 8 * boxes.size()));
  auto* triangles = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
      g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), 12 * boxes.size()));
  if (Status s = EmbreeStatus("frame buffers"); !s.ok() || !vertices || !triangles) {
    rtcReleaseGeometry(g);
    return Error{s.ok() ? "height-field tracer: frame buffer allocation failed" : s.message()};
  }
  // Corner i of a box: bit 0 picks x1, bit 1 y1, bit 2 z1; two triangles per face.
  static constexpr unsigned kFaces[6][4] = {{0, 2, 6, 4}, {1, 5, 7, 3}, {0, 4, 5, 1},
                                            {2, 3, 7, 6}, {0, 1, 3, 2}, {4, 6, 7, 5}};
  for (size_t b = 0; b < boxes.size(); ++b) {
    const Box& box = boxes[b];
    for (unsigned i = 0; i < 8; ++i) {
      float* p = vertices + 3 * (8 * b + i);
      p[0] = (i & 1) ? box.x1 : box.x0;
      p[1] = (i & 2) ? box.y1 : box.y0;
      p[2] = (i & 4) ? box.z1 : z0;
    }
    for (int f = 0; f < 6; ++f) {
      unsigned* t = triangles + 3 * (12 * b + 2 * f);
      const unsigned base = static_cast<unsigned>(8 * b);
      const unsigned* q = kFaces[f];
      t[0] = base + q[0], t[1] = base + q[1], t[2] = base + q[2];
      t[3] = base + q[0], t[4] = base + q[2], t[5] = base + q[3];
    }
  }
  rtcCommitGeometry(g);
  frame_geometry = rtcAttachGeometry(scene, g);
  rtcReleaseGeometry(g);
  frame_raise_mm = frame.max_raise_mm();
  return EmbreeStatus("frame geometry");
}

Result<HeightFieldTracer> HeightFieldTracer::Build(const HeightField& field) {
  const int w = field.width(), h = field.height();
  const auto& heights = field.height_mm;
  if (heights.empty()) return Error{"height-field tracer: the height field is empty"};
  if (heights.data.size() != static_cast<size_t>(w) * static_cast<size_t>(h))
    return Error{"height-field tracer: height grid of " + std::to_string(w) + "x" +
                 std::to_string(h) + " holds " + std::to_string(heights.data.size()) + " values"};
  if (w < 2 || h < 2)
    return Error{"height-field tracer: the height field must be at least 2x2 texels, got " +
                 std::to_string(w) + "x" + std::to_string(h)};
  if (!(std::isfinite(field.pitch_mm) && field.pitch_mm > 0))
    return Error{"height-field tracer: pitch_mm must be finite and > 0, got " +
                 FormatNumber(field.pitch_mm)};

  auto impl = std::make_unique<Impl>();
  impl->width = w;
  impl->height = h;
  impl->x0 = field.window.x0;
  impl->y0 = field.window.y0;
  impl->full_width = field.full_width();
  impl->full_height = field.full_height();
  impl->window_max_height_mm = field.window.full_max_height_mm;
  impl->pitch_mm = field.pitch_mm;
  impl->inv_pitch_mm = 1.0 / field.pitch_mm;

  // Vertices at the texel centres (TexelCentreMm) plus the outline ring; heights as they are.
  const int vw = w + 2, vh = h + 2;  // vertices per row / column
  const size_t vertex_count = static_cast<size_t>(vw) * static_cast<size_t>(vh);
  impl->vertices.resize(3 * vertex_count + 1);
  std::atomic<bool> all_finite{true};
  float* v = impl->vertices.data();
  const double pitch = field.pitch_mm;
  // Canvas-frame coordinate of vertex i of n + 2 along an axis of a grid whose first texel is
  // texel `first` of the full canvas: first and first + n on its outline. A window's outline
  // sides inside the full canvas lie in its halo, which no ray of its tile reaches.
  auto coord = [pitch](int i, int n, int first) {
    if (i == 0) return first * pitch;
    if (i == n + 1) return (first + n) * pitch;
    return (first + i - 0.5) * pitch;
  };
  const int x0 = field.window.x0, y0 = field.window.y0;
  const double full_h_mm = field.full_height() * pitch;
  tbb::parallel_for(tbb::blocked_range<int>(0, vh, 32), [&](const tbb::blocked_range<int>& r) {
    bool finite = true;
    for (int row = r.begin(); row < r.end(); ++row) {
      const float y_mm = static_cast<float>(full_h_mm - coord(row, h, y0));
      const float* src = heights.Row(std::clamp(row - 1, 0, h - 1));
      float* dst = v + 3 * static_cast<size_t>(row) * vw;
      for (int c = 0; c < vw; ++c) {
        const float z = src[std::clamp(c - 1, 0, w - 1)];
        dst[3 * c + 0] = static_cast<float>(coord(c, w, x0));
        dst[3 * c + 1] = y_mm;
        dst[3 * c + 2] = z;
        finite &= std::isfinite(z);
      }
    }
    if (!finite) all_finite.store(false, std::memory_order_relaxed);
  });
  if (!all_finite.load()) {
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        if (!std::isfinite(heights(x, y)))
          return Error{"height-field tracer: texel (" + std::to_string(x) + ", " +
                       std::to_string(y) + ") has a non-finite height (" +
                       FormatNumber(heights(x, y)) + " mm)"};
  }

  impl->device = rtcNewDevice(nullptr);
  if (!impl->device) return Error{"height-field tracer: rtcNewDevice failed"};
  rtcSetDeviceErrorFunction(impl->device, ErrorCallback, &impl->last_error);
  rtcSetDeviceMemoryMonitorFunction(impl->device, MemoryMonitor, &impl->embree_bytes);
  impl->scene = rtcNewScene(impl->device);
  // Watertight intersection: camera rays through texel centres meet the grid exactly at its
  // vertices, where a non-robust test lets a few rays slip between the triangles.
  // COMPACT: Embree's allocation at 2048^2 falls from 116 to 73 MB, and rays are no slower.
  rtcSetSceneFlags(impl->scene, RTC_SCENE_FLAG_ROBUST | RTC_SCENE_FLAG_COMPACT);
  if (Status s = impl->EmbreeStatus("rtcNewScene"); !s.ok()) return Error{s.message()};

  RTCGeometry g = rtcNewGeometry(impl->device, RTC_GEOMETRY_TYPE_GRID);
  rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, v, 0,
                             3 * sizeof(float), vertex_count);
  const int cells_x = vw - 1, cells_y = vh - 1;
  const int tiles_x = (cells_x + kGridCells - 1) / kGridCells;
  const int tiles_y = (cells_y + kGridCells - 1) / kGridCells;
  auto* grids = static_cast<RTCGrid*>(
      rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_GRID, 0, RTC_FORMAT_GRID, sizeof(RTCGrid),
                              static_cast<size_t>(tiles_x) * static_cast<size_t>(tiles_y)));
  if (Status s = impl->EmbreeStatus("grid buffers"); !s.ok() || !grids) {
    rtcReleaseGeometry(g);
    return Error{s.ok() ? "height-field tracer: grid buffer allocation failed" : s.message()};
  }
  for (int ty = 0; ty < tiles_y; ++ty) {
    for (int tx = 0; tx < tiles_x; ++tx) {
      const int c0 = tx * kGridCells, r0 = ty * kGridCells;
      RTCGrid& grid = grids[static_cast<size_t>(ty) * tiles_x + tx];
      grid.startVertexID =
          static_cast<unsigned>(r0) * static_cast<unsigned>(vw) + static_cast<unsigned>(c0);
      grid.stride = static_cast<unsigned>(vw);
      grid.width = static_cast<unsigned short>(std::min(kGridCells, cells_x - c0) + 1);
      grid.height = static_cast<unsigned short>(std::min(kGridCells, cells_y - r0) + 1);
    }
  }
  rtcCommitGeometry(g);
  rtcAttachGeometry(impl->scene, g);
  rtcReleaseGeometry(g);
  if (field.frame.any()) {
    if (Status s = impl->AttachFrameBoxes(field.frame); !s.ok()) return Error{s.message()};
  }
  rtcCommitScene(impl->scene);
  if (Status s = impl->EmbreeStatus("scene build"); !s.ok()) return Error{s.message()};

  impl->BuildPyramid();
  return HeightFieldTracer(std::move(impl));
}

void HeightFieldTracer::Occluded(std::span<const Vec3f> origins, std::span<const Vec3f> directions,
                                 std::span<const float> tfar, std::span<uint8_t> blocked,
                                 const TraceOptions& options, TraceStats* stats) const {
  DIGITIZE_CHECK(impl_, "HeightFieldTracer::Occluded on a moved-from tracer");
  const size_t n = origins.size();
  DIGITIZE_CHECK(directions.size() == n && tfar.size() == n && blocked.size() == n,
                 "HeightFieldTracer::Occluded: spans differ in length (" + std::to_string(n) +
                     " origins, " + std::to_string(directions.size()) + " directions, " +
                     std::to_string(tfar.size()) + " tfar, " + std::to_string(blocked.size()) +
                     " blocked)");
  if (Status s = options.Validate(); !s.ok())
    DIGITIZE_CHECK(false, "HeightFieldTracer::Occluded: " + s.message());
  if (n == 0) return;
  const Impl& impl = *impl_;
  const float offset = static_cast<float>(OriginOffset(options, impl.pitch_mm));
  const bool skip = options.skip_unblockable;
  std::atomic<size_t> traced_total{0}, blocked_total{0};

  auto body = [&](size_t first_batch, size_t end_batch) {
    std::array<RTCRay, kRayBatch> rays;
    std::array<uint32_t, kRayBatch> index;
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    size_t traced = 0, hits = 0;
    for (size_t batch = first_batch; batch < end_batch; ++batch) {
      const size_t first = batch * kRayBatch, count = std::min(kRayBatch, n - first);
      unsigned m = 0;
      for (size_t k = 0; k < count; ++k) {
        const size_t i = first + k;
        const Vec3f& o = origins[i];
        const Vec3f& d = directions[i];
        DIGITIZE_CHECK(IsValid(o) && IsValid(d) && !std::isnan(tfar[i]),
                       "HeightFieldTracer::Occluded: ray " + std::to_string(i) +
                           " has a non-finite origin, direction or tfar");
        blocked[i] = 0;
        const float t_max = skip ? impl.CutRayFramed(o, d, tfar[i], offset) : tfar[i];
        if (skip && t_max < 0.0f) continue;
        RTCRay& ray = rays[m];
        ray.org_x = o.x();
        ray.org_y = o.y();
        ray.org_z = o.z() + offset;
        ray.dir_x = d.x();
        ray.dir_y = d.y();
        ray.dir_z = d.z();
        ray.tnear = offset;
        ray.tfar = t_max;
        ray.time = 0.0f;
        ray.mask = 0xFFFFFFFFu;
        ray.id = m;
        ray.flags = 0;
        index[m++] = static_cast<uint32_t>(k);
      }
      if (m == 0) continue;
      rtcOccluded1M(impl.scene, &context, rays.data(), m, sizeof(RTCRay));
      traced += m;
      for (unsigned j = 0; j < m; ++j) {
        // Embree marks an occluded ray by setting its tfar to -inf.
        if (rays[j].tfar < 0.0f) {
          blocked[first + index[j]] = 1;
          ++hits;
        }
      }
    }
    traced_total.fetch_add(traced, std::memory_order_relaxed);
    blocked_total.fetch_add(hits, std::memory_order_relaxed);
  };
  ForBatches(n, (n + kRayBatch - 1) / kRayBatch, options.num_threads, body);

  if (stats) {
    TraceStats s;
    s.rays = n;
    s.traced = traced_total.load();
    s.skipped = n - s.traced;
    s.blocked = blocked_total.load();
    *stats += s;
  }
}

void HeightFieldTracer::Intersect(std::span<const Vec3f> origins, std::span<const Vec3f> directions,
                                  std::span<SurfaceHit> hits, const TraceOptions& options) const {
  DIGITIZE_CHECK(impl_, "HeightFieldTracer::Intersect on a moved-from tracer");
  const size_t n = origins.size();
  DIGITIZE_CHECK(directions.size() == n && hits.size() == n,
                 "HeightFieldTracer::Intersect: spans differ in length (" + std::to_string(n) +
                     " origins, " + std::to_string(directions.size()) + " directions, " +
                     std::to_string(hits.size()) + " hits)");
  if (Status s = options.Validate(); !s.ok())
    DIGITIZE_CHECK(false, "HeightFieldTracer::Intersect: " + s.message());
  if (n == 0) return;
  const Impl& impl = *impl_;
  const double inv_pitch = 1.0 / impl.pitch_mm;

  auto body = [&](size_t first_batch, size_t end_batch) {
    std::array<RTCRayHit, kRayBatch> rays;
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;  // camera rays: neighbours go together
    for (size_t batch = first_batch; batch < end_batch; ++batch) {
      const size_t first = batch * kRayBatch, count = std::min(kRayBatch, n - first);
      for (size_t k = 0; k < count; ++k) {
        const Vec3f& o = origins[first + k];
        const Vec3f& d = directions[first + k];
        DIGITIZE_CHECK(IsValid(o) && IsValid(d), "HeightFieldTracer::Intersect: ray " +
                                                     std::to_string(first + k) +
                                                     " has a non-finite origin or direction");
        RTCRayHit& r = rays[k];
        r.ray.org_x = o.x();
        r.ray.org_y = o.y();
        r.ray.org_z = o.z();
        r.ray.dir_x = d.x();
        r.ray.dir_y = d.y();
        r.ray.dir_z = d.z();
        r.ray.tnear = 0.0f;
        r.ray.tfar = std::numeric_limits<float>::infinity();
        r.ray.time = 0.0f;
        r.ray.mask = 0xFFFFFFFFu;
        r.ray.id = static_cast<unsigned>(k);
        r.ray.flags = 0;
        r.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        r.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
      }
      rtcIntersect1M(impl.scene, &context, rays.data(), static_cast<unsigned>(count),
                     sizeof(RTCRayHit));
      for (size_t k = 0; k < count; ++k) {
        const RTCRayHit& r = rays[k];
        SurfaceHit& out = hits[first + k];
        out = SurfaceHit{};
        if (r.hit.geomID == RTC_INVALID_GEOMETRY_ID) continue;
        if (r.hit.geomID == impl.frame_geometry) {
          out.frame = true;  // the frame hides the canvas along this ray
          continue;
        }
        const double t = r.ray.tfar;
        const double X = r.ray.org_x + t * r.ray.dir_x, Y = r.ray.org_y + t * r.ray.dir_y;
        out.hit = true;
        out.t = r.ray.tfar;
        // The full canvas's coordinates rounded to float first, then the window's offset taken
        // off (exact in float): a window's hits are the full canvas's hits, shifted.
        out.texel_x = static_cast<float>(X * inv_pitch - 0.5) - static_cast<float>(impl.x0);
        out.texel_y = static_cast<float>(impl.full_height - Y * inv_pitch - 0.5) -
                      static_cast<float>(impl.y0);
      }
    }
  };
  ForBatches(n, (n + kRayBatch - 1) / kRayBatch, options.num_threads, body);
}

float HeightFieldTracer::max_height_mm() const {
  DIGITIZE_CHECK(impl_, "HeightFieldTracer: moved-from");
  return impl_->max_height_mm;
}
double HeightFieldTracer::pitch_mm() const {
  DIGITIZE_CHECK(impl_, "HeightFieldTracer: moved-from");
  return impl_->pitch_mm;
}
int HeightFieldTracer::width() const {
  DIGITIZE_CHECK(impl_, "HeightFieldTracer: moved-from");
  return impl_->width;
}
int HeightFieldTracer::height() const {
  DIGITIZE_CHECK(impl_, "HeightFieldTracer: moved-from");
  return impl_->height;
}
size_t HeightFieldTracer::memory_bytes() const {
  DIGITIZE_CHECK(impl_, "HeightFieldTracer: moved-from");
  size_t bytes = impl_->vertices.capacity() * sizeof(float);
  for (const auto& level : impl_->levels) bytes += level.capacity() * sizeof(float);
  return bytes + static_cast<size_t>(std::max<int64_t>(0, impl_->embree_bytes.load()));
}

}  // namespace digitize
