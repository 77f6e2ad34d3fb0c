// Ray queries against a canvas height field with Embree (the shadow and visibility rays of
// the reflectance samples; relighting renders; later the viewer's ground-truth reference).
//
// Layer: samples (core + height_field.h). Embree stays in height_field_tracer.cpp.
//
// GEOMETRY. The surface is the triangulated texel grid in the CANVAS frame (mm): one vertex per
// texel centre at (TexelCentreMm(x, y), height_mm(x, y)), two triangles per quad of four texel
// centres -- the same surface the generator's Scene traces, and the one normals.h differentiates.
// Like the Scene's canvas, it is extended by half a texel to the canvas outline (a ring of
// vertices at X = 0, X = width x pitch, Y = 0, Y = height x pitch repeating the border texels'
// heights), so it covers the whole canvas rectangle and a ray through a border texel's centre
// meets it inside a quad, not on the rim where a watertight test may let it pass; texel
// coordinates of hits therefore run over [-0.5, width - 0.5] x [-0.5, height - 0.5].
// Every texel takes part (kOutside texels hold height 0, the canvas plane: they block nothing
// above it). Built as Embree grid primitives (RTC_GEOMETRY_TYPE_GRID, pieces of <= 256 x 256
// quads).
//
// FRAME. When the field carries frame boxes (HeightField::frame), they are a second Embree geometry
// (a triangle mesh, 12 triangles per side): they block shadow and visibility rays like the
// relief, and a camera ray (Intersect) that meets a box first reports `frame`, not a canvas hit.
//
// SKIPPING RAYS THAT CANNOT BE BLOCKED. A ray leaving a point at height h upwards (dz > 0) can only
// hit relief higher than h, and only within the horizontal reach r = (H - h) / tan(elevation) where
// H bounds the relief it can meet. Occluded() first bounds H with the global max height, then
// refines it with a max-pyramid (per-block maxima over power-of-two blocks) over the ray's
// horizontal footprint up to min(tfar, reach) -- the bounding box of the segment from tnear to
// distance r along the ray's azimuth, a part of the square of radius r around the origin, rounded
// out to whole texels -- up to 3 rounds; a ray whose bound falls to <= h (+ epsilon: the ray's
// height at tnear) is skipped (not blocked), and a traced ray gets tfar cut to its reach. A ray
// whose footprint starts next to a vertex higher than itself cannot be skipped by any round and
// is traced at once. Rays going down or level (dz <= 0) are always traced (with their own tfar).
// With frame boxes, a ray the relief cannot block is still traced when its horizontal path leaves
// the canvas rectangle below the highest box's top (up to where it rises above it).
// The skip is exact (never skips a ray that Embree would report blocked, up to the epsilon
// below), so results with and without skipping agree; `TraceOptions::skip_unblockable = false`
// turns it off for benchmarks and tests. COST: Embree is fast on this geometry, and the rays
// the rule proves free are cheap for it too: on a 2048^2 painting skipping is 5-20 % slower on one
// texel's lights per call and ~5 % faster on incoherent rays (numbers in docs/architecture.md,
// layer "samples").
//
// Self-intersection: callers pass origins ON the surface; each ray starts at tnear =
// origin_offset_mm (default 1e-3 x pitch) along its direction, after the origin is lifted by the
// same amount along +Z.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

#include "digitize/core.h"
#include "digitize/height_field.h"

namespace digitize {

struct TraceOptions {
  bool skip_unblockable = true;  // skip rays that the max-pyramid proves free
  double origin_offset_mm = -1;  // < 0: 1e-3 x pitch_mm
  int num_threads = 0;           // 0 = all cores (batches run in parallel with TBB); spans of
                                 // up to 1024 rays always run on the calling thread

  // origin_offset_mm finite, num_threads >= 0. Occluded / Intersect throw InvariantError
  // otherwise (options are the caller's code, not user input).
  Status Validate() const;
};

// Counts of one or many Occluded calls (add them up with +=).
struct TraceStats {
  size_t rays = 0;     // requested
  size_t skipped = 0;  // proven unblockable without tracing
  size_t traced = 0;   // given to Embree
  size_t blocked = 0;  // found blocked (all traced)
  TraceStats& operator+=(const TraceStats& o) {
    rays += o.rays, skipped += o.skipped, traced += o.traced, blocked += o.blocked;
    return *this;
  }
};

struct SurfaceHit {
  bool hit = false;    // the ray meets the canvas first
  bool frame = false;  // the ray meets the field's frame boxes first (hit is false)
  float t = 0;         // distance along the (unit) direction, mm
  float texel_x = 0;   // continuous texel coordinates of the hit (texel centres at integers)
  float texel_y = 0;
};

class HeightFieldTracer {
 public:
  // Errors: an empty field, a field smaller than 2 x 2 texels, pitch <= 0, non-finite heights,
  // or an Embree failure (message from Embree). Copies what it needs: `field` may go away.
  static Result<HeightFieldTracer> Build(const HeightField& field);

  HeightFieldTracer(HeightFieldTracer&&) noexcept;
  HeightFieldTracer& operator=(HeightFieldTracer&&) noexcept;
  ~HeightFieldTracer();

  // Occlusion of many rays, canvas frame. origins: points on the surface (mm); directions: unit;
  // tfar: max distance (mm) per ray (+inf for a directional light). blocked[i] = 1 when something
  // lies on ray i within (tnear, tfar), else 0. All spans the same length. Thread-safe; runs in
  // parallel over batches when the span is long. Stats are ADDED to *stats when given.
  void Occluded(std::span<const Vec3f> origins, std::span<const Vec3f> directions,
                std::span<const float> tfar, std::span<uint8_t> blocked,
                const TraceOptions& options = {}, TraceStats* stats = nullptr) const;

  // Closest hits of many rays (camera rays of a relighting render), canvas frame, no skipping.
  void Intersect(std::span<const Vec3f> origins, std::span<const Vec3f> directions,
                 std::span<SurfaceHit> hits, const TraceOptions& options = {}) const;

  float max_height_mm() const;
  // Memory held: the shared vertex buffer, the max-pyramid and Embree's own allocations (its
  // memory monitor), bytes. About 31 bytes per texel (129 MB at 2048^2).
  size_t memory_bytes() const;
  double pitch_mm() const;
  int width() const;
  int height() const;

 private:
  struct Impl;
  explicit HeightFieldTracer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace digitize
