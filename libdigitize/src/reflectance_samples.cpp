#include "digitize/reflectance_samples.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <mutex>
#include <optional>
#include <vector>

#include "camera_rays.h"
#include "digitize/tangent_frame.h"
#include "shadow_horizon.h"

namespace digitize {
namespace {

// keep[] values of GatherSamples: not kept, kept, kept but interpolated.
constexpr uint8_t kKeepDirect = 1, kKeepInterpolated = 2;
// Texels per block of the pass that counts what each texel keeps over the photo-major flags.
constexpr size_t kTexelBlock = 256;

std::string Count(size_t n) {
  char b[32];
  if (n >= 10'000'000)
    std::snprintf(b, sizeof b, "%.1f M", static_cast<double>(n) / 1e6);
  else if (n >= 10'000)
    std::snprintf(b, sizeof b, "%.1f k", static_cast<double>(n) / 1e3);
  else
    std::snprintf(b, sizeof b, "%zu", n);
  return b;
}

// Bilinear colour at pixel coordinates (centres at integers), with the flags of the pixels that
// carry weight. Coordinates are within [-0.5, size - 0.5] (Camera::InImage): clamp to the border.
struct PixelSample {
  Vec3f rgb = Vec3f::Zero();
  uint8_t flags = 0;
  bool seen = false;          // pixels of a pixel map see the texel: visible, no ray needed
  bool stepped_over = false;  // no pixel sees it: bilinear, marked (see Footprint)
};

PixelSample Bilinear(const Photo& photo, double u, double v) {
  const int w = photo.rgb.width, h = photo.rgb.height;
  u = std::clamp(u, 0.0, static_cast<double>(w - 1));
  v = std::clamp(v, 0.0, static_cast<double>(h - 1));
  const int x0 = std::min(static_cast<int>(u), std::max(w - 2, 0));
  const int y0 = std::min(static_cast<int>(v), std::max(h - 2, 0));
  const int x1 = std::min(x0 + 1, w - 1), y1 = std::min(y0 + 1, h - 1);
  const float fx = static_cast<float>(u - x0), fy = static_cast<float>(v - y0);
  const float w00 = (1 - fx) * (1 - fy), w10 = fx * (1 - fy), w01 = (1 - fx) * fy, w11 = fx * fy;
  PixelSample s;
  s.rgb = w00 * photo.rgb(x0, y0) + w10 * photo.rgb(x1, y0) + w01 * photo.rgb(x0, y1) +
          w11 * photo.rgb(x1, y1);
  if (!photo.flags.empty()) {
    if (w00 > 0) s.flags |= photo.flags(x0, y0);
    if (w10 > 0) s.flags |= photo.flags(x1, y0);
    if (w01 > 0) s.flags |= photo.flags(x0, y1);
    if (w11 > 0) s.flags |= photo.flags(x1, y1);
  }
  return s;
}

// The texel's footprint in the photo: the parallelogram px + J [-1/2, 1/2)^2, J the Jacobian of
// texel coordinates -> pixels at the texel centre. The sample is the mean of the pixels whose
// centres fall inside it, i.e. of the pixels whose own nearest texel is this one: the image model
// of the renderers (the generator and RenderRelit shade a pixel by the texel its centre hits) and,
// for a real camera that integrates over a pixel, the texel's own area. A bilinear sample at the
// centre instead blends the neighbours' pixels in at ~1 pixel per texel, so a texel on a boundary
// between two paints is fitted to a mixture whose weights differ from photo to photo (measured on
// the GGX painting of reflectance_fit_ggx_test, noise-free: held-out 29.8 -> 32.5 dB pooled,
// texels 2 from a boundary 37.1 -> 39.3 dB). Texels smaller than a pixel (no centre inside) fall
// back to the bilinear sample; footprints over kMaxFootprintSide pixels a side are sampled on a
// sparser lattice, so a sample never costs more than ~kMaxFootprintSide^2 reads.

//
// With a pixel map (`owner`: the texel each pixel sees) the sample is instead the mean of the
// pixels around the footprint that see this texel, `texel`: relief parallax moves a pixel or two
// between neighbouring cells (a 0.5 mm stroke seen at 30 degrees shifts its hits by 0.3 mm), the
// frame hides whole cells, and the renderers assign pixels by what their rays hit. The window is
// the footprint's bounding box and kParallaxMarginPx more.
constexpr int kMaxFootprintSide = 8;
constexpr double kParallaxMarginPx = 1.0;

// Which pixels a texel's sample averages: what depends on the camera alone, so that photos of one
// camera position share it (Camera::SameView). `pixels` (y * width + x, in the order summed)
// are appended to the caller's list; none: the bilinear value at `px`.
struct FootprintPixels {
  Eigen::Vector2d px = Eigen::Vector2d::Zero();
  uint32_t first = 0, count = 0;  // in the caller's pixel list
  bool seen = false, stepped_over = false;
};

FootprintPixels Footprint(int w, int h, const Eigen::Vector2d& px, const Eigen::Matrix2d& j,
                          const Grid<uint32_t>* owner, uint32_t texel,
                          std::vector<uint32_t>& pixels) {
  FootprintPixels f;
  f.px = px;
  f.first = static_cast<uint32_t>(pixels.size());
  const double det = j.determinant();
  if (!(std::abs(det) > 1e-12) || !std::isfinite(det)) return f;
  const Eigen::Matrix2d inv = j.inverse();
  const double margin = owner ? kParallaxMarginPx : 0.0;
  const double ex = 0.5 * (std::abs(j(0, 0)) + std::abs(j(0, 1))) + margin;
  const double ey = 0.5 * (std::abs(j(1, 0)) + std::abs(j(1, 1))) + margin;
  const int x0 = std::max(0, static_cast<int>(std::ceil(px.x() - ex)));
  const int x1 = std::min(w - 1, static_cast<int>(std::floor(px.x() + ex)));
  const int y0 = std::max(0, static_cast<int>(std::ceil(px.y() - ey)));
  const int y1 = std::min(h - 1, static_cast<int>(std::floor(px.y() + ey)));
  const int step = 1 + std::max(x1 - x0, y1 - y0) / kMaxFootprintSide;
  int in_cell = 0;
  for (int y = y0; y <= y1; y += step)
    for (int x = x0; x <= x1; x += step) {
      const Eigen::Vector2d o = inv * Eigen::Vector2d(x - px.x(), y - px.y());
      const bool inside = o.x() >= -0.5 && o.x() < 0.5 && o.y() >= -0.5 && o.y() < 0.5;
      in_cell += inside;
      if (owner ? (*owner)(x, y) != texel : !inside) continue;
      pixels.push_back(static_cast<uint32_t>(y) * static_cast<uint32_t>(w) +
                       static_cast<uint32_t>(x));
    }
  f.count = static_cast<uint32_t>(pixels.size()) - f.first;
  // No pixel sees the texel: its cell's pixels see a neighbour (relief parallax, a steep wall
  // foreshortened to less than a pixel; or it is hidden, which the view ray decides), or no
  // pixel centre falls in its cell although the photo resolves the grid (an oblique view steps
  // over it). The bilinear value is then its neighbours' paint as much as its own: such a
  // sample is marked, and dropped where the texel has enough others
  // (SampleOptions::min_direct_samples). A photo coarser than the grid keeps it unmarked.
  if (f.count == 0) f.stepped_over = owner && (in_cell > 0 || std::abs(det) >= 1.0);
  f.seen = f.count > 0 && owner != nullptr;
  return f;
}

// Whether a photo's sample is unusable (non-finite, saturated, black), counted in `stats`.
bool RejectPixel(const PixelSample& pixel, const SampleOptions& options, SampleStats& stats) {
  if ((pixel.flags & kPixelNonFinite) || !IsValid(pixel.rgb)) {
    ++stats.non_finite;
    return true;
  }
  if (pixel.flags & kPixelSaturated) {
    ++stats.saturated;
    return true;
  }
  if (options.reject_black && pixel.rgb.maxCoeff() <= options.black_level) {
    ++stats.black;
    return true;
  }
  return false;
}

// One photo's sample over the pixels of `f`.
PixelSample Average(const Photo& photo, const FootprintPixels& f,
                    const std::vector<uint32_t>& pixels) {
  if (f.count == 0) {
    PixelSample b = Bilinear(photo, f.px.x(), f.px.y());
    b.stepped_over = f.stepped_over;
    return b;
  }
  PixelSample s;
  for (uint32_t k = f.first; k < f.first + f.count; ++k) {
    s.rgb += photo.rgb.data[pixels[k]];
    if (!photo.flags.empty()) s.flags |= photo.flags.data[pixels[k]];
  }
  s.rgb /= static_cast<float>(f.count);
  s.seen = f.seen;
  return s;
}

// Per texel: surface point (canvas and scan frames) and tangent frame, shared by every photo;
// and what each photo's light tests read, in float (TileLight).
struct TexelGeometry {
  Vec3d p_canvas, p_scan;
  TangentFrame frame;
  Eigen::Matrix3f local_from_scan;  // the tangent frame's rows times the canvas rotation
  Vec3f p_centred;                  // p_scan - the canvas's centre
};

// A photo's light at the texels of a tile, in float: the light test runs for every photo and
// texel (64 M times for 1 Mtexel x 64 photos); in double, with a root, a division and two
// rotations each, the gather took 0.25 s more of its 2.1 s on fit_bench (measured). Positions are
// relative to the canvas's centre, so float keeps them to ~1e-7 of the canvas's size: directions
// and irradiance agree with Light::DirectionTo and IrradianceAt to float rounding, which is what
// a BrdfSample stores.
class TileLight {
 public:
  TileLight(const Light& light, const Vec3d& centre)
      : point_(light.type == LightType::kPoint),
        position_((point_ ? light.position_mm - centre : light.direction).cast<float>()),
        power_(point_ ? light.intensity : light.irradiance) {}
  struct At {
    Vec3f direction;   // scan frame, unit, towards the light
    Vec3f irradiance;  // at normal incidence
    float distance;    // to the light; infinite for a directional one
  };
  At Of(const Vec3f& p_centred) const {
    if (!point_) return {position_, power_, std::numeric_limits<float>::infinity()};
    const Vec3f d = position_ - p_centred;
    const float d2 = d.squaredNorm();
    if (!(d2 > 0.0f)) return {Vec3f::Zero(), Vec3f::Zero(), 0.0f};  // on the light: no light
    const float inv = 1.0f / std::sqrt(d2);
    return {d * inv, power_ * (inv * inv), d2 * inv};
  }

 private:
  bool point_;
  Vec3f position_;  // point: relative to the canvas's centre; directional: the direction
  Vec3f power_;     // point: intensity; directional: irradiance
};

// What one camera position makes of a texel, shared by the photos taken from it: the camera's
// own rejections, the view direction, the footprint's pixels, and whether the relief hides it.
struct ViewTexel {
  enum Reject : uint8_t { kNone, kBehindCamera, kOutsideImage, kFacingAway };
  Reject reject = kNone;
  bool hidden = false;
  Vec3f view_local = Vec3f::Zero(), view_canvas = Vec3f::Zero();
  FootprintPixels footprint;
};

// GatherSamples with SampleOptions::share_view_rays: per camera position (Camera::SameView) the
// camera's tests, footprints and view rays once, then per photo of it the light's tests, the
// pixel averages and the shadow rays. Rays the horizon proves free are not traced. Fills slots /
// keep exactly as the per-photo path does (reflectance_fit_test compares them).
void GatherPerView(const SampleScene& scene, std::span<const uint32_t> texels,
                   const SampleOptions& options, const std::vector<TexelGeometry>& geometry,
                   const Vec3d& canvas_centre, std::vector<BrdfSample>& slots,
                   std::vector<uint8_t>& keep, SampleStats& stats, bool parallel) {
  const std::vector<Photo>& photos = scene.photos->photos;
  const size_t n_texels = texels.size(), n_photos = photos.size();
  const RigidTransform scan_from_canvas = scene.canvas_from_scan.Inverse();
  const Mat3d& canvas_rot = scene.canvas_from_scan.rotation;
  const Eigen::Matrix3f canvas_rot_f = canvas_rot.cast<float>();
  const double pitch = scene.canvas->pitch_mm;
  const Vec3d texel_step_x = scan_from_canvas.rotation * Vec3d(pitch, 0, 0);
  const Vec3d texel_step_y = scan_from_canvas.rotation * Vec3d(0, -pitch, 0);
  std::optional<HorizonBounds> horizon;
  if (options.horizon_sectors > 0 && options.trace.skip_unblockable &&
      (options.shadow_rays || options.visibility_rays))
    horizon.emplace(*scene.canvas, texels, options.horizon_sectors);
  const auto free = [&](size_t t, const Vec3f& d) { return horizon && horizon->ProvenFree(t, d); };
  const auto for_each = [&](size_t n, const auto& body) {
    if (parallel)
      tbb::parallel_for(size_t{0}, n, body);
    else
      for (size_t i = 0; i < n; ++i) body(i);
  };

  std::vector<std::vector<size_t>> views;  // photo indices per camera position, in set order
  for (size_t i = 0; i < n_photos; ++i) {
    size_t k = 0;
    while (k < views.size() && !photos[views[k][0]].camera.SameView(photos[i].camera)) ++k;
    if (k == views.size()) views.emplace_back();
    views[k].push_back(i);
  }
  // Footprint pixels per chunk of texels, so that chunks fill them in parallel.
  constexpr size_t kChunk = 1024;
  std::vector<std::vector<uint32_t>> chunk_pixels((n_texels + kChunk - 1) / kChunk);
  std::vector<ViewTexel> view(n_texels);
  std::mutex stats_mutex;
  for (const std::vector<size_t>& of_view : views) {
    const Camera& camera = photos[of_view[0]].camera;
    const Grid<uint32_t>* owner =
        scene.pixel_texels ? &scene.pixel_texels->maps[scene.pixel_texels->of_photo[of_view[0]]]
                           : nullptr;
    for_each(chunk_pixels.size(), [&](size_t c) {
      std::vector<uint32_t>& pixels = chunk_pixels[c];
      pixels.clear();
      for (size_t t = c * kChunk; t < std::min(n_texels, (c + 1) * kChunk); ++t) {
        ViewTexel& vt = view[t];
        vt = ViewTexel{};
        const TexelGeometry& g = geometry[t];
        if (!camera.InFront(g.p_scan)) {
          vt.reject = ViewTexel::kBehindCamera;
          continue;
        }
        const Eigen::Vector2d px = camera.Project(g.p_scan);
        if (!camera.InImage(px)) {
          vt.reject = ViewTexel::kOutsideImage;
          continue;
        }
        const Vec3d v_canvas = canvas_rot * camera.DirectionToCamera(g.p_scan);
        const Vec3d v_local = g.frame.ToLocal(v_canvas);
        if (!(v_local.z() > options.min_cos)) {
          vt.reject = ViewTexel::kFacingAway;
          continue;
        }
        vt.view_local = v_local.cast<float>();
        vt.view_canvas = v_canvas.cast<float>();
        Eigen::Matrix2d jacobian;
        jacobian.col(0) = camera.Project(g.p_scan + texel_step_x) - px;
        jacobian.col(1) = camera.Project(g.p_scan + texel_step_y) - px;
        vt.footprint =
            Footprint(camera.width, camera.height, px, jacobian, owner, texels[t], pixels);
      }
    });
    if (options.visibility_rays) {
      // One ray per texel the camera sees and no pixel map vouches for, for all its photos.
      const Vec3d centre = camera.CentreInScan();
      std::vector<uint32_t> ray_of;
      std::vector<Vec3f> origins, directions;
      std::vector<float> far;
      size_t proven = 0;
      for (size_t t = 0; t < n_texels; ++t) {
        const ViewTexel& vt = view[t];
        if (vt.reject != ViewTexel::kNone || vt.footprint.seen) continue;
        if (free(t, vt.view_canvas)) {
          ++proven;
          continue;
        }
        ray_of.push_back(static_cast<uint32_t>(t));
        origins.push_back(geometry[t].p_canvas.cast<float>());
        directions.push_back(vt.view_canvas);
        far.push_back(camera.model == CameraModel::kPinhole
                          ? static_cast<float>((centre - geometry[t].p_scan).norm())
                          : std::numeric_limits<float>::infinity());
      }
      std::vector<uint8_t> blocked(ray_of.size(), 0);
      scene.tracer->Occluded(origins, directions, far, blocked, options.trace, &stats.view_rays);
      for (size_t j = 0; j < ray_of.size(); ++j) view[ray_of[j]].hidden = blocked[j];
      stats.view_rays.rays += proven;
      stats.view_rays.skipped += proven;
    }

    for_each(of_view.size(), [&](size_t v) {
      const size_t i = of_view[v];
      const Photo& photo = photos[i];
      const TileLight light(photo.light, canvas_centre);
      SampleStats local;
      local.candidates = n_texels;
      std::vector<uint32_t> ray_of;  // texel of each shadow ray
      std::vector<uint8_t> ray_keep;
      std::vector<Vec3f> origins, directions;
      std::vector<float> far;
      size_t proven = 0;
      for (size_t t = 0; t < n_texels; ++t) {
        const ViewTexel& vt = view[t];
        switch (vt.reject) {
          case ViewTexel::kBehindCamera:
            ++local.behind_camera;
            continue;
          case ViewTexel::kOutsideImage:
            ++local.outside_image;
            continue;
          case ViewTexel::kFacingAway:
            ++local.facing_away;
            continue;
          case ViewTexel::kNone:
            break;
        }
        const TexelGeometry& g = geometry[t];
        const TileLight::At light_at = light.Of(g.p_centred);
        const Vec3f l_local = g.local_from_scan * light_at.direction;
        if (!(l_local.z() > options.min_cos)) {
          ++local.light_below_horizon;
          continue;
        }
        const PixelSample pixel = Average(photo, vt.footprint, chunk_pixels[t / kChunk]);
        if (RejectPixel(pixel, options, local)) continue;
        if (vt.hidden) {
          ++local.hidden;
          continue;
        }
        BrdfSample& s = slots[i * n_texels + t];
        s.view_dir = vt.view_local;
        s.light_dir = l_local;
        s.radiance = pixel.rgb;
        s.irradiance = light_at.irradiance * l_local.z();
        const uint8_t kept = pixel.stepped_over ? kKeepInterpolated : kKeepDirect;
        if (options.shadow_rays) {
          const Vec3f l = canvas_rot_f * light_at.direction;
          if (!free(t, l)) {
            ray_of.push_back(static_cast<uint32_t>(t));
            ray_keep.push_back(kept);
            origins.push_back(g.p_canvas.cast<float>());
            directions.push_back(l);
            far.push_back(light_at.distance);
            continue;
          }
          ++proven;
        }
        keep[i * n_texels + t] = kept;
        ++local.kept;
      }
      std::vector<uint8_t> blocked(ray_of.size(), 0);
      scene.tracer->Occluded(origins, directions, far, blocked, options.trace, &local.light_rays);
      for (size_t j = 0; j < ray_of.size(); ++j) {
        if (blocked[j]) {
          ++local.shadowed;
        } else {
          keep[i * n_texels + ray_of[j]] = ray_keep[j];
          ++local.kept;
        }
      }
      local.light_rays.rays += proven;
      local.light_rays.skipped += proven;
      std::lock_guard lock(stats_mutex);
      stats += local;
    });
  }
}

}  // namespace

PixelTexelMaps MapPixelsToTexels(const PhotoSet& photos, const HeightField& canvas,
                                 const RigidTransform& canvas_from_scan,
                                 const HeightFieldTracer& tracer) {
  PixelTexelMaps out;
  std::vector<const Camera*> views;
  for (const Photo& photo : photos.photos) {
    size_t k = 0;
    while (k < views.size() && !views[k]->SameView(photo.camera)) ++k;
    if (k == views.size()) views.push_back(&photo.camera);
    out.of_photo.push_back(static_cast<uint32_t>(k));
  }
  const int w = canvas.width(), h = canvas.height();
  const double start_z = CameraRayStartZ(tracer, canvas);
  for (const Camera* camera : views) {
    Grid<uint32_t> map(camera->width, camera->height, kNoTexel);
    tbb::parallel_for(
        tbb::blocked_range<int>(0, camera->height, 8), [&](const tbb::blocked_range<int>& rows) {
          const int n = camera->width;
          std::vector<Vec3f> origins(n), directions(n);
          std::vector<SurfaceHit> hits(n);
          TraceOptions trace;
          trace.num_threads = 1;  // rows are the parallel unit
          for (int v = rows.begin(); v < rows.end(); ++v) {
            CameraRowRays(*camera, canvas_from_scan, start_z, v, origins, directions);
            tracer.Intersect(origins, directions, hits, trace);
            uint32_t* row = map.Row(v);
            for (int u = 0; u < n; ++u) {
              if (!hits[u].hit) continue;
              const int x = std::clamp(static_cast<int>(std::lround(hits[u].texel_x)), 0, w - 1);
              const int y = std::clamp(static_cast<int>(std::lround(hits[u].texel_y)), 0, h - 1);
              if (canvas.state(x, y) == TexelState::kOutside) continue;
              row[u] =
                  static_cast<uint32_t>(y) * static_cast<uint32_t>(w) + static_cast<uint32_t>(x);
            }
          }
        });
    out.rays += static_cast<size_t>(camera->width) * static_cast<size_t>(camera->height);
    out.maps.push_back(std::move(map));
  }
  return out;
}

Status SampleOptions::Validate() const {
  if (!(std::isfinite(min_cos) && min_cos >= 0 && min_cos < 1))
    return Error{"min_cos must be in [0, 1), got " + FormatNumber(min_cos)};
  if (!(std::isfinite(black_level) && black_level >= 0 && black_level < 1))
    return Error{"black_level must be in [0, 1) (linear), got " + FormatNumber(black_level)};
  if (min_direct_samples < 0)
    return Error{"min_direct_samples must be >= 0, got " + std::to_string(min_direct_samples)};
  if (horizon_sectors < 0 || horizon_sectors > kMaxHorizonSectors)
    return Error{"horizon_sectors must be in [0, 32] (0: off), got " +
                 std::to_string(horizon_sectors)};
  return Status::Ok();
}

SampleStats& SampleStats::operator+=(const SampleStats& o) {
  texels += o.texels;
  candidates += o.candidates;
  behind_camera += o.behind_camera;
  outside_image += o.outside_image;
  facing_away += o.facing_away;
  light_below_horizon += o.light_below_horizon;
  non_finite += o.non_finite;
  saturated += o.saturated;
  black += o.black;
  hidden += o.hidden;
  shadowed += o.shadowed;
  stepped_over += o.stepped_over;
  kept += o.kept;
  view_rays += o.view_rays;
  light_rays += o.light_rays;
  return *this;
}

std::string SampleStats::Brief() const {
  std::string out = Count(candidates) + " candidates, " + Count(kept) + " kept";
  char b[64];
  std::snprintf(
      b, sizeof b, " (%.1f %%)",
      candidates ? 100.0 * static_cast<double>(kept) / static_cast<double>(candidates) : 0.0);
  out += b;
  std::string rejected;
  for (const auto& [n, what] :
       {std::pair{behind_camera, "behind camera"}, std::pair{outside_image, "outside image"},
        std::pair{facing_away, "facing away"},
        std::pair{light_below_horizon, "light below horizon"}, std::pair{non_finite, "NaN/Inf"},
        std::pair{saturated, "saturated"}, std::pair{black, "black"}, std::pair{hidden, "hidden"},
        std::pair{shadowed, "shadowed"}, std::pair{stepped_over, "stepped over"}}) {
    if (n == 0) continue;
    rejected += (rejected.empty() ? "" : ", ") + Count(n) + " " + what;
  }
  if (!rejected.empty()) out += "; rejected: " + rejected;
  const size_t rays = view_rays.rays + light_rays.rays;
  const size_t skipped = view_rays.skipped + light_rays.skipped;
  std::snprintf(b, sizeof b, "; rays: %s, %.1f %% skipped", Count(rays).c_str(),
                rays ? 100.0 * static_cast<double>(skipped) / static_cast<double>(rays) : 0.0);
  return out + b;
}

Status ValidateSampleScene(const SampleScene& scene) {
  DIGITIZE_CHECK(scene.canvas && scene.normals && scene.photos && scene.tracer,
                 "SampleScene with a null member");
  const HeightField& canvas = *scene.canvas;
  if (canvas.width() < 2 || canvas.height() < 2)
    return Error{"the canvas is " + std::to_string(canvas.width()) + "x" +
                 std::to_string(canvas.height()) + " texels; at least 2x2 are needed"};
  if (scene.normals->width != canvas.width() || scene.normals->height != canvas.height())
    return Error{"normals are " + std::to_string(scene.normals->width) + "x" +
                 std::to_string(scene.normals->height) + ", the canvas " +
                 std::to_string(canvas.width()) + "x" + std::to_string(canvas.height())};
  for (int y = 0; y < canvas.height(); ++y)
    for (int x = 0; x < canvas.width(); ++x)
      if (!IsValid((*scene.normals)(x, y)) || (*scene.normals)(x, y).norm() < 0.5f)
        return Error{"normal of texel (" + std::to_string(x) + ", " + std::to_string(y) +
                     ") is not a unit vector"};
  if (scene.tracer->width() != canvas.width() || scene.tracer->height() != canvas.height())
    return Error{"the tracer was built from another canvas"};
  if (scene.photos->photos.empty()) return Error{scene.photos->source.string() + ": no photos"};
  for (const Photo& p : scene.photos->photos) {
    if (!p.loaded()) return Error{p.entry + ": " + p.path.string() + ": pixels not loaded"};
    if (p.rgb.width != p.camera.width || p.rgb.height != p.camera.height)
      return Error{p.entry + ": " + p.path.string() + ": image is " + std::to_string(p.rgb.width) +
                   "x" + std::to_string(p.rgb.height) + ", its camera " +
                   std::to_string(p.camera.width) + "x" + std::to_string(p.camera.height)};
  }
  if (const PixelTexelMaps* m = scene.pixel_texels) {
    DIGITIZE_CHECK(m->of_photo.size() == scene.photos->photos.size(),
                   "pixel maps for another photo set");
    for (size_t i = 0; i < m->of_photo.size(); ++i) {
      const Camera& c = scene.photos->photos[i].camera;
      DIGITIZE_CHECK(m->of_photo[i] < m->maps.size() && m->maps[m->of_photo[i]].width == c.width &&
                         m->maps[m->of_photo[i]].height == c.height,
                     "pixel map of photo " + std::to_string(i) + " does not fit its camera");
    }
  }
  if (scene.cameras_checked) return Status::Ok();
  return CheckCamerasSeeCanvas(*scene.photos, scene.canvas_from_scan, canvas);
}

void GatherSampleSlots(const SampleScene& scene, std::span<const uint32_t> texels,
                       const SampleOptions& options, SampleStats& stats, bool parallel,
                       SampleBuffers& b) {
  const HeightField& canvas = *scene.canvas;
  const Grid<Vec3f>& normals = *scene.normals;
  const std::vector<Photo>& photos = scene.photos->photos;
  const size_t n_texels = texels.size(), n_photos = photos.size();
  const RigidTransform scan_from_canvas = scene.canvas_from_scan.Inverse();
  const Mat3d& canvas_rot = scene.canvas_from_scan.rotation;
  const Eigen::Matrix3f canvas_rot_f = canvas_rot.cast<float>();
  const int width = canvas.width();
  // One texel along the canvas's +x and +y texel axes (y grows downwards: -Y in mm), scan frame.
  const Vec3d texel_step_x = scan_from_canvas.rotation * Vec3d(canvas.pitch_mm, 0, 0);
  const Vec3d texel_step_y = scan_from_canvas.rotation * Vec3d(0, -canvas.pitch_mm, 0);

  // The canvas's centre, not the tile's: a texel's sample must not depend on the tiling.
  const Vec3d canvas_centre =
      scan_from_canvas.Apply(Vec3d(canvas.extent_mm().x() / 2, canvas.extent_mm().y() / 2, 0));
  std::vector<TexelGeometry> geometry(n_texels);
  for (size_t t = 0; t < n_texels; ++t) {
    const int x = static_cast<int>(texels[t] % static_cast<uint32_t>(width));
    const int y = static_cast<int>(texels[t] / static_cast<uint32_t>(width));
    DIGITIZE_CHECK(canvas.height_mm.Contains(x, y) && canvas.state(x, y) != TexelState::kOutside,
                   "GatherSamples: texel outside the canvas");
    const Eigen::Vector2d xy = canvas.TexelCentreMm(x, y);
    geometry[t].p_canvas = {xy.x(), xy.y(), canvas.height_mm(x, y)};
    TexelGeometry& g = geometry[t];
    g.p_scan = scan_from_canvas.Apply(g.p_canvas);
    g.frame = MakeTangentFrame(normals(x, y).cast<double>());
    Mat3d local;
    local.row(0) = g.frame.x.transpose() * canvas_rot;
    local.row(1) = g.frame.y.transpose() * canvas_rot;
    local.row(2) = g.frame.z.transpose() * canvas_rot;
    g.local_from_scan = local.cast<float>();
    g.p_centred = (g.p_scan - canvas_centre).cast<float>();
  }

  // slot (i, t) holds photo i's sample of texel t when keep[i * n_texels + t]: photo-major, so
  // each photo's task writes one contiguous run (texel-major made every write a cache miss).
  b.texels = n_texels;
  b.photos = n_photos;
  // Slots are written before they are read (keep says which): only grow them, never clear.
  if (b.slots.size() < n_texels * n_photos) b.slots.resize(n_texels * n_photos);
  b.keep.assign(n_texels * n_photos, 0);
  std::vector<BrdfSample>& slots = b.slots;
  std::vector<uint8_t>& keep = b.keep;
  std::mutex stats_mutex;
  stats.texels += n_texels;

  const auto per_photo = [&](size_t i) {
    const Photo& photo = photos[i];
    const Camera& camera = photo.camera;
    const TileLight light(photo.light, canvas_centre);
    const bool pinhole = camera.model == CameraModel::kPinhole;
    const Vec3d camera_centre_scan = camera.CentreInScan();
    const Grid<uint32_t>* owner =
        scene.pixel_texels ? &scene.pixel_texels->maps[scene.pixel_texels->of_photo[i]] : nullptr;
    SampleStats local;
    local.candidates = n_texels;
    std::vector<uint32_t> candidate;    // texel index t of samples waiting for rays
    std::vector<uint8_t> seen;          // the pixel map says it is visible: no view ray
    std::vector<uint8_t> stepped_over;  // an interpolated sample (PixelSample::stepped_over)
    std::vector<Vec3f> origins, view_dirs, light_dirs;
    std::vector<float> view_far, light_far;
    std::vector<uint32_t> pixel_list;
    candidate.reserve(n_texels);
    for (size_t t = 0; t < n_texels; ++t) {
      const TexelGeometry& g = geometry[t];
      if (!camera.InFront(g.p_scan)) {
        ++local.behind_camera;
        continue;
      }
      const Eigen::Vector2d px = camera.Project(g.p_scan);
      if (!camera.InImage(px)) {
        ++local.outside_image;
        continue;
      }
      const Vec3d v_canvas = canvas_rot * camera.DirectionToCamera(g.p_scan);
      const Vec3d v_local = g.frame.ToLocal(v_canvas);
      if (!(v_local.z() > options.min_cos)) {
        ++local.facing_away;
        continue;
      }
      const TileLight::At light_at = light.Of(g.p_centred);
      const Vec3f l_local = g.local_from_scan * light_at.direction;
      if (!(l_local.z() > options.min_cos)) {
        ++local.light_below_horizon;
        continue;
      }
      Eigen::Matrix2d jacobian;
      jacobian.col(0) = camera.Project(g.p_scan + texel_step_x) - px;
      jacobian.col(1) = camera.Project(g.p_scan + texel_step_y) - px;
      pixel_list.clear();
      const PixelSample pixel = Average(
          photo, Footprint(camera.width, camera.height, px, jacobian, owner, texels[t], pixel_list),
          pixel_list);
      if (RejectPixel(pixel, options, local)) continue;
      BrdfSample& s = slots[i * n_texels + t];
      s.view_dir = v_local.cast<float>();
      s.light_dir = l_local;
      s.radiance = pixel.rgb;
      s.irradiance = light_at.irradiance * l_local.z();
      candidate.push_back(static_cast<uint32_t>(t));
      seen.push_back(pixel.seen);
      stepped_over.push_back(pixel.stepped_over);
      origins.push_back(g.p_canvas.cast<float>());
      view_dirs.push_back(v_canvas.cast<float>());
      light_dirs.push_back(canvas_rot_f * light_at.direction);
      view_far.push_back(pinhole ? static_cast<float>((camera_centre_scan - g.p_scan).norm())
                                 : std::numeric_limits<float>::infinity());
      light_far.push_back(light_at.distance);
    }
    std::vector<uint8_t> hidden(candidate.size(), 0), shadowed(candidate.size(), 0);
    if (options.visibility_rays) {
      // Only the candidates no pixel map vouches for (all of them without maps).
      std::vector<Vec3f> ray_origins, ray_dirs;
      std::vector<float> ray_far;
      std::vector<uint32_t> ray_of;
      for (size_t c = 0; c < candidate.size(); ++c) {
        if (seen[c]) continue;
        ray_origins.push_back(origins[c]);
        ray_dirs.push_back(view_dirs[c]);
        ray_far.push_back(view_far[c]);
        ray_of.push_back(static_cast<uint32_t>(c));
      }
      std::vector<uint8_t> blocked(ray_of.size(), 0);
      scene.tracer->Occluded(ray_origins, ray_dirs, ray_far, blocked, options.trace,
                             &local.view_rays);
      for (size_t j = 0; j < ray_of.size(); ++j) hidden[ray_of[j]] = blocked[j];
    }
    if (options.shadow_rays) {
      // Only the visible candidates need a shadow ray: compact them first.
      size_t m = 0;
      for (size_t c = 0; c < candidate.size(); ++c) {
        if (hidden[c]) continue;
        origins[m] = origins[c];
        light_dirs[m] = light_dirs[c];
        light_far[m] = light_far[c];
        ++m;
      }
      std::vector<uint8_t> blocked(m, 0);
      scene.tracer->Occluded(std::span(origins.data(), m), std::span(light_dirs.data(), m),
                             std::span(light_far.data(), m), blocked, options.trace,
                             &local.light_rays);
      for (size_t c = 0, j = 0; c < candidate.size(); ++c)
        if (!hidden[c]) shadowed[c] = blocked[j++];
    }
    for (size_t c = 0; c < candidate.size(); ++c) {
      if (hidden[c]) {
        ++local.hidden;
      } else if (shadowed[c]) {
        ++local.shadowed;
      } else {
        keep[i * n_texels + candidate[c]] = stepped_over[c] ? kKeepInterpolated : kKeepDirect;
        ++local.kept;
      }
    }
    std::lock_guard lock(stats_mutex);
    stats += local;
  };
  if (!options.share_view_rays) {
    if (parallel)
      tbb::parallel_for(size_t{0}, n_photos, per_photo);
    else
      for (size_t i = 0; i < n_photos; ++i) per_photo(i);
  } else {
    GatherPerView(scene, texels, options, geometry, canvas_centre, slots, keep, stats, parallel);
  }
  // parallel_for added each photo's `local` (whose texels field is 0) under the mutex.

  // What each texel keeps, in parallel over blocks of texels; within a block every photo's keep
  // flags are read as one contiguous run.
  const size_t n_blocks = (n_texels + kTexelBlock - 1) / kTexelBlock;
  b.count.assign(n_texels, 0);
  b.least.assign(n_texels, kKeepDirect);
  std::vector<size_t> block_dropped(n_blocks, 0);
  const auto per_block = [&](size_t k) {
    const size_t t0 = k * kTexelBlock, n = std::min(kTexelBlock, n_texels - t0);
    std::array<uint32_t, kTexelBlock> direct{}, interpolated{};
    for (size_t i = 0; i < n_photos; ++i) {
      const uint8_t* flags = keep.data() + i * n_texels + t0;
      for (size_t j = 0; j < n; ++j) {
        direct[j] += flags[j] == kKeepDirect;
        interpolated[j] += flags[j] == kKeepInterpolated;
      }
    }
    // Interpolated samples only where the texel would otherwise have too few (a photo set from
    // one camera position steps over the same texels in every photo).
    for (size_t j = 0; j < n; ++j) {
      const bool enough = direct[j] >= static_cast<size_t>(options.min_direct_samples);
      b.least[t0 + j] = enough ? kKeepDirect : kKeepInterpolated;
      b.count[t0 + j] = direct[j] + (enough ? 0 : interpolated[j]);
      if (enough) block_dropped[k] += interpolated[j];
    }
  };
  if (parallel)
    tbb::parallel_for(size_t{0}, n_blocks, per_block);
  else
    for (size_t k = 0; k < n_blocks; ++k) per_block(k);
  size_t dropped = 0;
  for (const size_t d : block_dropped) dropped += d;
  stats.stepped_over += dropped;
  stats.kept -= dropped;
}

void SampleBuffers::AppendTexels(size_t first, size_t n, BrdfSamples& out) const {
  DIGITIZE_CHECK(first <= texels && n <= texels - first,
                 "SampleBuffers::AppendTexels: texels out of range");
  size_t total = out.samples.size();
  std::vector<size_t> cursor(n);
  for (size_t j = 0; j < n; ++j) {
    cursor[j] = total;
    total += count[first + j];
    out.texel_begin.push_back(total);
  }
  out.samples.resize(total);
  for (size_t i = 0; i < photos; ++i) {
    const uint8_t* flags = keep.data() + i * texels + first;
    const BrdfSample* from = slots.data() + i * texels + first;
    for (size_t j = 0; j < n; ++j)
      if (flags[j] && flags[j] <= least[first + j]) out.samples[cursor[j]++] = from[j];
  }
}

void GatherSamples(const SampleScene& scene, std::span<const uint32_t> texels,
                   const SampleOptions& options, BrdfSamples& out, SampleStats& stats,
                   bool parallel, SampleBuffers* buffers) {
  SampleBuffers local_buffers;
  SampleBuffers& b = buffers ? *buffers : local_buffers;
  GatherSampleSlots(scene, texels, options, stats, parallel, b);
  b.AppendTexels(0, b.texels, out);
}

}  // namespace digitize
