// Relighting renders by ray tracing the height field (see relight.h for the contract).
//
// One TBB task per row band; each row is one Intersect call (camera rays) and one Occluded call
// (shadow rays of the pixels that face both camera and light), both on the calling thread.
#include "digitize/relight.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "camera_rays.h"
#include "digitize/lafortune.h"
#include "digitize/tangent_frame.h"

namespace digitize {
namespace {

template <class T>
bool SameSize(const Grid<T>& g, int w, int h) {
  return g.width == w && g.height == h;
}

std::string Size(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

// Bilinear interpolation of the normals at continuous texel coordinates (clamped to the grid:
// the outline half-texel takes the border texels' normals), renormalised; +Z when degenerate.
Vec3d BilinearNormal(const Grid<Vec3f>& normals, double tx, double ty) {
  tx = std::clamp(tx, 0.0, normals.width - 1.0);
  ty = std::clamp(ty, 0.0, normals.height - 1.0);
  // The tracer needs >= 2 x 2 texels, so the 2 x 2 neighbourhood always exists.
  const int x0 = std::min(static_cast<int>(tx), normals.width - 2);
  const int y0 = std::min(static_cast<int>(ty), normals.height - 2);
  const int x1 = x0 + 1, y1 = y0 + 1;
  const double fx = tx - x0, fy = ty - y0;
  const Vec3d n =
      (1 - fy) * ((1 - fx) * normals(x0, y0).cast<double>() + fx * normals(x1, y0).cast<double>()) +
      fy * ((1 - fx) * normals(x0, y1).cast<double>() + fx * normals(x1, y1).cast<double>());
  const double len = n.norm();
  if (!(std::isfinite(len) && len > 1e-12)) return Vec3d::UnitZ();
  return n / len;
}

}  // namespace

Status RelightOptions::Validate() const {
  if (num_threads < 0)
    return Error{"num_threads must be >= 0 (0 = all cores), got " + std::to_string(num_threads)};
  return Status::Ok();
}

RelitImage RenderRelit(const HeightFieldTracer& tracer, const HeightField& canvas,
                       const Grid<Vec3f>& normals, const ReflectanceMaps& maps,
                       const RigidTransform& canvas_from_scan, const Camera& camera,
                       const Light& light, const RelightOptions& options) {
  const int w = canvas.width(), h = canvas.height();
  DIGITIZE_CHECK(
      tracer.width() == w && tracer.height() == h && tracer.pitch_mm() == canvas.pitch_mm,
      "RenderRelit: the tracer (" + Size(tracer.width(), tracer.height()) +
          ") was not built from this canvas (" + Size(w, h) + ")");
  DIGITIZE_CHECK(SameSize(canvas.state, w, h), "RenderRelit: canvas state is " +
                                                   Size(canvas.state.width, canvas.state.height) +
                                                   ", heights " + Size(w, h));
  DIGITIZE_CHECK(
      SameSize(normals, w, h),
      "RenderRelit: normals are " + Size(normals.width, normals.height) + ", canvas " + Size(w, h));
  DIGITIZE_CHECK(
      SameSize(maps.rho_d, w, h) && SameSize(maps.rho_s, w, h) && SameSize(maps.lobe, w, h),
      "RenderRelit: reflectance maps are " + Size(maps.width(), maps.height()) +
          " (or differ among themselves), canvas " + Size(w, h));
  DIGITIZE_CHECK(camera.width >= 0 && camera.height >= 0, "RenderRelit: negative camera size");
  if (Status s = options.Validate(); !s.ok()) DIGITIZE_CHECK(false, "RenderRelit: " + s.message());

  RelitImage out;
  out.rgb = Grid<Vec3f>(camera.width, camera.height);
  out.mask = Grid<uint8_t>(camera.width, camera.height, 0);
  if (out.rgb.empty()) return out;

  const RigidTransform scan_from_canvas = canvas_from_scan.Inverse();
  const Mat3d& canvas_rotation = canvas_from_scan.rotation;
  const bool point_light = light.type == LightType::kPoint;
  const Vec3d light_in_canvas = canvas_from_scan.Apply(light.position_mm);
  std::atomic<size_t> shadowed_total{0};
  const double start_z = CameraRayStartZ(tracer, canvas);

  auto render_rows = [&](const tbb::blocked_range<int>& rows) {
    const int n = camera.width;
    std::vector<Vec3f> origins(n), directions(n);
    std::vector<SurfaceHit> hits(n);
    // Shadow rays of this row: pixel, origin, direction, tfar; the unshadowed radiance.
    std::vector<int> lit_pixel;
    std::vector<Vec3f> shadow_origins, shadow_directions, lit_radiance;
    std::vector<float> shadow_tfar;
    std::vector<uint8_t> blocked;
    TraceOptions trace;
    trace.num_threads = 1;  // rows are the parallel unit
    size_t shadowed = 0;
    for (int v = rows.begin(); v < rows.end(); ++v) {
      CameraRowRays(camera, canvas_from_scan, start_z, v, origins, directions);
      tracer.Intersect(origins, directions, hits, trace);
      lit_pixel.clear();
      shadow_origins.clear();
      shadow_directions.clear();
      shadow_tfar.clear();
      lit_radiance.clear();
      Vec3f* rgb = out.rgb.Row(v);
      uint8_t* mask = out.mask.Row(v);
      for (int u = 0; u < n; ++u) {
        const SurfaceHit& hit = hits[u];
        if (!hit.hit) continue;
        // Nearest texel: reflectance is per texel (no interpolation of k across decades).
        const int ix = std::clamp(static_cast<int>(std::lround(hit.texel_x)), 0, w - 1);
        const int iy = std::clamp(static_cast<int>(std::lround(hit.texel_y)), 0, h - 1);
        if (canvas.state(ix, iy) == TexelState::kOutside) continue;
        mask[u] = 1;
        const Vec3d p_canvas =
            origins[u].cast<double>() + static_cast<double>(hit.t) * directions[u].cast<double>();
        const Vec3d p_scan = scan_from_canvas.Apply(p_canvas);
        const TangentFrame frame =
            MakeTangentFrame(BilinearNormal(normals, hit.texel_x, hit.texel_y));
        const Vec3d v_canvas = canvas_rotation * camera.DirectionToCamera(p_scan);
        const Vec3d l_canvas = canvas_rotation * light.DirectionTo(p_scan);
        const Vec3f v_local = frame.ToLocal(v_canvas).cast<float>();
        const Vec3f l_local = frame.ToLocal(l_canvas).cast<float>();
        if (!(v_local.z() > 0.0f && l_local.z() > 0.0f)) continue;  // radiance 0
        const Vec3f f = maps.Evaluate(ix, iy, v_local, l_local);
        const Vec3f radiance = (f * l_local.z()).cwiseProduct(light.IrradianceAt(p_scan));
        if (!options.shadows) {
          rgb[u] = radiance;
          continue;
        }
        lit_pixel.push_back(u);
        lit_radiance.push_back(radiance);
        shadow_origins.push_back(p_canvas.cast<float>());
        shadow_directions.push_back(l_canvas.cast<float>());
        shadow_tfar.push_back(point_light ? static_cast<float>((light_in_canvas - p_canvas).norm())
                                          : std::numeric_limits<float>::infinity());
      }
      if (lit_pixel.empty()) continue;
      blocked.resize(lit_pixel.size());
      tracer.Occluded(shadow_origins, shadow_directions, shadow_tfar, blocked, trace);
      for (size_t i = 0; i < lit_pixel.size(); ++i) {
        if (blocked[i]) {
          ++shadowed;
        } else {
          rgb[lit_pixel[i]] = lit_radiance[i];
        }
      }
    }
    shadowed_total.fetch_add(shadowed, std::memory_order_relaxed);
  };
  auto run = [&] { tbb::parallel_for(tbb::blocked_range<int>(0, camera.height, 4), render_rows); };
  if (options.num_threads > 0) {
    tbb::task_arena arena(options.num_threads);
    arena.execute(run);
  } else {
    run();
  }
  out.shadowed_pixels = shadowed_total.load();

  for (const Vec3f& c : out.rgb.data)
    DIGITIZE_CHECK(c.allFinite(), "RenderRelit: non-finite radiance about to leave the stage");
  return out;
}

ImageComparison CompareImages(const Grid<Vec3f>& test, const Grid<Vec3f>& reference,
                              const Grid<uint8_t>& mask, double peak) {
  DIGITIZE_CHECK(
      SameSize(reference, test.width, test.height) && SameSize(mask, test.width, test.height),
      "CompareImages: sizes differ (test " + Size(test.width, test.height) + ", reference " +
          Size(reference.width, reference.height) + ", mask " + Size(mask.width, mask.height) +
          ")");
  DIGITIZE_CHECK(std::isfinite(peak) && peak > 0,
                 "CompareImages: peak must be finite and > 0, got " + FormatNumber(peak));
  ImageComparison c;
  double sum = 0;  // squared differences over all channels
  for (size_t i = 0; i < test.size(); ++i) {
    if (!mask.data[i] || !test.data[i].allFinite() || !reference.data[i].allFinite()) continue;
    sum += (test.data[i].cast<double>() - reference.data[i].cast<double>()).squaredNorm();
    ++c.pixels;
  }
  if (c.pixels == 0) return c;  // nothing compared: psnr 0, rmse 0
  const double mse = sum / (3.0 * static_cast<double>(c.pixels));
  c.rmse = std::sqrt(mse);
  c.psnr_db =
      mse > 0 ? 10.0 * std::log10(peak * peak / mse) : std::numeric_limits<double>::infinity();
  return c;
}

}  // namespace digitize
