// Synthetic photo sets: cameras and lights around the canvas, Embree rendering of the framed
// painting with per-region paint materials, shadows, noise and the encodings (photo_sim.h).
//
// Work plan: per camera, the primary rays are traced once (every light of that camera shares
// them); then every (image, block of rows) of that camera is an independent task: shadow rays,
// shading, noise, encoding. Noise streams are seeded per (image, row), so the result does not
// depend on how TBB schedules the tasks.
#include "digitize_synth/photo_sim.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <mutex>
#include <numbers>
#include <random>
#include <string>

#include "digitize/tangent_frame.h"

namespace digitize::synth {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180;
// pi (3 - sqrt 5): successive lights of the spiral turn by this azimuth, so that any run of them
// spreads evenly around the dome.
constexpr double kGoldenAngleRad = 2.39996322972865332;
constexpr int kRowGrain = 8;          // image rows per task
constexpr int kMaxImageSide = 32768;  // a larger image is a wrong option, not a photo
// Shadow-ray origins are lifted off the surface along the geometric normal by this much: Embree
// hits are accurate to a few float ulps of the coordinates (~1e-4 mm at 500 mm), and 2 um is far
// below any relief the painting has (weave amplitude 30 um), so no self-shadowing acne and no
// light leaking under a ridge.
constexpr double kShadowOffsetMm = 2e-3;

uint64_t SplitMix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// The SplitMix64 sequence as a random bit generator: passes BigCrush, one add and a few mixes
// per draw, no state to seed (a Mersenne Twister spent more time here than the rendering did:
// three normals per pixel).
struct SplitMixEngine {
  using result_type = uint64_t;
  uint64_t state = 0;
  static constexpr result_type min() { return 0; }
  static constexpr result_type max() { return ~uint64_t{0}; }
  result_type operator()() { return SplitMix64(state += 0x9E3779B97F4A7C15ull); }
};

// One noise stream per (image, row): the same numbers whatever thread draws them.
SplitMixEngine RowStream(uint64_t seed, int image, int row) {
  uint64_t s = SplitMix64(seed ^ 0x50484F544F53494Dull);  // "PHOTOSIM": not the scan's streams
  s = SplitMix64(s ^ (static_cast<uint64_t>(image) + 1) * 0x9E3779B97F4A7C15ull);
  s = SplitMix64(s ^ (static_cast<uint64_t>(row) + 1) * 0x165667B19E3779F9ull);
  return SplitMixEngine{s};
}

// ---------------------------------------------------------------------------------------------
// Encodings. The same sRGB EOTF in double as the reader's tables (photo_set.cpp), so the linear
// value of a code here is bit for bit the one digitize::LoadPhoto returns for it.

double SrgbEotf(double c) { return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4); }

struct SrgbCodec {
  int max_code = 0;
  std::vector<float> linear;  // per code
  // bound[c]: the linear value from which code c is nearer than c - 1 (bound[0] = -inf,
  // bound[max + 1] = +inf), i.e. code = round(OETF(x) * max) exactly when
  // bound[code] <= x < bound[code + 1].
  std::vector<double> bound;
  explicit SrgbCodec(int max)
      : max_code(max), linear(static_cast<size_t>(max) + 1), bound(static_cast<size_t>(max) + 2) {
    for (int i = 0; i <= max; ++i) linear[i] = static_cast<float>(SrgbEotf(double(i) / max));
    bound[0] = -std::numeric_limits<double>::infinity();
    for (int i = 1; i <= max; ++i) bound[i] = SrgbEotf((i - 0.5) / max);
    bound[max + 1] = std::numeric_limits<double>::infinity();
  }
  // round(OETF(clamp(x, 0, 1)) * max_code): a float estimate (powf is within ~1e-6 of the
  // OETF, a hundredth of a 16-bit code), then one step each way to the exact code, without
  // branches (they would be mispredicted half the time).
  int Encode(float x) const {
    if (!(x > 0.0f)) return 0;
    if (x >= 1.0f) return max_code;
    const float e = x <= 0.0031308f ? 12.92f * x : 1.055f * std::pow(x, 1.0f / 2.4f) - 0.055f;
    int code = std::clamp(static_cast<int>(e * max_code + 0.5f), 0, max_code);
    const double xd = x;
    code += xd >= bound[code + 1];
    code -= xd < bound[code];
    return code;
  }
};

const SrgbCodec& Codec(PhotoEncoding e) {
  static const SrgbCodec codec8(255), codec16(65535);
  return e == PhotoEncoding::kSrgb16 ? codec16 : codec8;
}

// ---------------------------------------------------------------------------------------------
// Placement.

// camera_from_canvas of a camera at `eye` looking at `target`: z along the view, x right, y down,
// with image rows running down the canvas (-Y) as in the texel grid, so the top view shows the
// painting upright.
RigidTransform LookAt(const Vec3d& eye, const Vec3d& target) {
  const Vec3d z = (target - eye).normalized();
  Vec3d x = Vec3d(0, -1, 0).cross(z);
  if (x.squaredNorm() < 1e-12) x = Vec3d::UnitX();  // looking along Y: never for our arcs
  x.normalize();
  const Vec3d y = z.cross(x);
  RigidTransform t;
  t.rotation.row(0) = x.transpose();
  t.rotation.row(1) = y.transpose();
  t.rotation.row(2) = z.transpose();
  t.translation = -(t.rotation * eye);
  return t;
}

// A camera of the set, in both frames.
struct View {
  Camera camera;                      // as stored: scan frame
  RigidTransform camera_from_canvas;  // rendering: canvas frame
  Vec3d eye_canvas = Vec3d::Zero();
};

// The canvas rectangle [x0, x1] x [y0, y1] (mm, canvas frame, Z = 0) a camera must hold.
struct ViewRect {
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  Vec3d Centre() const { return {0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0}; }
};

// The canvas grown by view_margin of its size (the arc's cameras), or the grid cell (c, r) grown
// by grid_overlap of the cell's size.
ViewRect CanvasView(const Painting& p, const PhotoSimOptions& o) {
  const double mx = o.view_margin * p.width_mm, my = o.view_margin * p.height_mm;
  return {-mx, -my, p.width_mm + mx, p.height_mm + my};
}
ViewRect CellView(const Painting& p, const PhotoSimOptions& o, int c, int r) {
  const double cw = p.width_mm / o.grid_cols, ch = p.height_mm / o.grid_rows;
  const double mx = o.grid_overlap * cw, my = o.grid_overlap * ch;
  // Row 0 at the top (largest Y), as the texel grid and the images.
  const double top = p.height_mm - r * ch;
  return {c * cw - mx, top - ch - my, (c + 1) * cw + mx, top + my};
}

View MakeView(const Painting& painting, const PhotoSimOptions& o, const Vec3d& eye,
              const ViewRect& rect, const RigidTransform& canvas_from_scan) {
  View view;
  view.eye_canvas = eye;
  view.camera_from_canvas = LookAt(eye, rect.Centre());
  Camera& cam = view.camera;
  cam.model = CameraModel::kPinhole;
  // One texel at the canvas centre spans pixels_per_texel pixels when seen from the top.
  const double f = o.pixels_per_texel * o.camera_distance_mm / painting.truth.pitch_mm;
  cam.fx = cam.fy = f;
  // The rectangle must be in the image.
  double half_u = 0, half_v = 0;
  for (double X : {rect.x0, rect.x1}) {
    for (double Y : {rect.y0, rect.y1}) {
      const Vec3d p = view.camera_from_canvas.Apply(Vec3d(X, Y, 0));
      DIGITIZE_CHECK(p.z() > 1e-6,
                     "SimulatePhotoSet: the canvas (with its margin) reaches behind "
                     "a camera; increase camera_distance_mm or reduce the arc");
      half_u = std::max(half_u, std::abs(f * p.x() / p.z()));
      half_v = std::max(half_v, std::abs(f * p.y() / p.z()));
    }
  }
  const double w = std::ceil(2 * half_u), h = std::ceil(2 * half_v);
  DIGITIZE_CHECK(w <= kMaxImageSide && h <= kMaxImageSide,
                 "SimulatePhotoSet: images of " + FormatNumber(w) + " x " + FormatNumber(h) +
                     " px; lower pixels_per_texel or the painting's resolution");
  cam.width = std::max(1, static_cast<int>(w));
  cam.height = std::max(1, static_cast<int>(h));
  cam.cx = 0.5 * (cam.width - 1);
  cam.cy = 0.5 * (cam.height - 1);
  cam.camera_from_scan = view.camera_from_canvas * canvas_from_scan;
  return view;
}

// The light at spiral position s (0 .. n-1 are the fitting lights) around `centre`, canvas frame.
Vec3d SpiralLight(const Vec3d& centre, const PhotoSimOptions& o, double s, int n) {
  const double sin_lo = std::sin(o.light_min_elevation_deg * kDeg);
  const double sin_hi = std::sin(o.light_max_elevation_deg * kDeg);
  // Equal steps in sin(elevation): equal dome area per light.
  const double u = (s + 0.5) / n;
  const double sin_el = std::clamp(sin_lo + u * (sin_hi - sin_lo), -1.0, 1.0);
  const double cos_el = std::sqrt(std::max(0.0, 1 - sin_el * sin_el));
  const double az = s * kGoldenAngleRad;
  return centre + o.light_distance_mm * Vec3d(cos_el * std::cos(az), cos_el * std::sin(az), sin_el);
}

// Held-out light j of m: between fitting lights (half-integer spiral positions, evenly spread)
// when there are at least as many fitting lights, else evenly along the spiral.
double HeldOutSpiralPosition(int j, int m, int n) {
  if (n >= m) return std::floor((j + 0.5) * n / m) + 0.5;  // <= n - 0.5: still on the dome
  return (j + 0.5) * n / m - 0.5;
}

// ---------------------------------------------------------------------------------------------
// Rendering.

// What a camera pixel sees, with everything that does not depend on the light (traced and
// computed once per camera, then shared by all its lights).
struct PixelHit {
  Vec3f p = Vec3f::Zero();      // hit, canvas frame (mm)
  Vec3f n_geo = Vec3f::Zero();  // geometric normal, facing the camera
  // Canvas: the tangent frame of the interpolated analytic normal (frame_z = that normal) and
  // the view direction in it.
  Vec3f frame_x = Vec3f::Zero(), frame_y = Vec3f::Zero(), frame_z = Vec3f::Zero();
  Vec3f v_local = Vec3f::Zero();
  uint8_t material = 0;
  bool faces_camera = false;  // canvas: n.v > 0 (else it renders black)
  Scene::Hit what = Scene::Hit::kNone;
};

// Embree's grid primitive is not watertight where a ray passes exactly through a grid vertex:
// the ray slips through the canvas and reports the wall (or the frame's inner face from behind).
// A centred top view at 1 pixel per texel puts pixel centres exactly on texel centres (the
// vertices), so this happens there at ~1e-4 of the pixels. Such a hit lies under the canvas
// sheet inside its outline, where nothing can be seen from the front; those rays are traced
// again with the direction moved by a thousandth of a pixel (up to kRetraces times).
constexpr int kRetraces = 3;
constexpr double kRetraceStepPx = 1e-3;

void RetraceSlips(const Scene& scene, const View& view, const Mat3d& canvas_from_camera,
                  float min_height_mm, const std::vector<Vec3d>& origins, std::vector<Vec3d>& dirs,
                  std::vector<Scene::RayHit>& hits) {
  const Painting& painting = scene.painting();
  constexpr double kTolMm = 1e-3;
  auto slipped = [&](size_t i) {
    const Scene::RayHit& h = hits[i];
    if (h.what != Scene::Hit::kWall && h.what != Scene::Hit::kFrame) return false;
    const Vec3d p = origins[i] + h.t * dirs[i].normalized();
    return p.x() > -kTolMm && p.y() > -kTolMm && p.x() < painting.width_mm + kTolMm &&
           p.y() < painting.height_mm + kTolMm && p.z() < min_height_mm - kTolMm;
  };
  const double step = kRetraceStepPx / view.camera.fx;
  for (int attempt = 1; attempt <= kRetraces; ++attempt) {
    std::vector<size_t> again;
    for (size_t i = 0; i < hits.size(); ++i) {
      if (slipped(i)) again.push_back(i);
    }
    if (again.empty()) return;
    std::vector<Vec3d> o, d;
    for (size_t i : again) {
      dirs[i] = dirs[i].normalized() + canvas_from_camera * Vec3d(step, 0.7 * step, 0.0);
      o.push_back(origins[i]);
      d.push_back(dirs[i]);
    }
    std::vector<Scene::RayHit> h;
    scene.Intersect(o, d, h);
    for (size_t k = 0; k < again.size(); ++k) hits[again[k]] = h[k];
  }
}

Grid<PixelHit> TracePrimary(const Scene& scene, const View& view,
                            const Grid<uint8_t>& material_index) {
  const Painting& painting = scene.painting();
  const float min_height_mm =
      *std::min_element(painting.truth.height_mm.data.begin(), painting.truth.height_mm.data.end());
  const HeightField& truth = painting.truth;
  const Grid<Vec3f>& normals = painting.normals;
  const int w = view.camera.width, h = view.camera.height;
  const Camera& cam = view.camera;
  const Mat3d canvas_from_camera = view.camera_from_canvas.rotation.transpose();
  Grid<PixelHit> hits(w, h, PixelHit{});
  tbb::parallel_for(
      tbb::blocked_range<int>(0, h, kRowGrain), [&](const tbb::blocked_range<int>& r) {
        std::vector<Vec3d> origins(static_cast<size_t>(w), view.eye_canvas),
            dirs(static_cast<size_t>(w));
        std::vector<Scene::RayHit> row_hits;
        for (int y = r.begin(); y < r.end(); ++y) {
          for (int x = 0; x < w; ++x) {
            dirs[x] = canvas_from_camera * Vec3d((x - cam.cx) / cam.fx, (y - cam.cy) / cam.fy, 1.0);
          }
          scene.Intersect(origins, dirs, row_hits);
          RetraceSlips(scene, view, canvas_from_camera, min_height_mm, origins, dirs, row_hits);
          for (int x = 0; x < w; ++x) {
            const Scene::RayHit& rh = row_hits[x];
            PixelHit& out = hits(x, y);
            out.what = rh.what;
            if (rh.what == Scene::Hit::kNone) continue;
            const Vec3d p = view.eye_canvas + rh.t * dirs[x].normalized();
            out.p = p.cast<float>();
            out.n_geo = rh.normal.cast<float>();
            if (rh.what != Scene::Hit::kCanvas) continue;
            // Nearest texel for the material; bilinear analytic normal for the shading.
            const Eigen::Vector2d t = truth.TexelFromMm(p.x(), p.y());
            const double tx = std::clamp(t.x(), 0.0, truth.width() - 1.0);
            const double ty = std::clamp(t.y(), 0.0, truth.height() - 1.0);
            const int nx = static_cast<int>(std::lround(tx)),
                      ny = static_cast<int>(std::lround(ty));
            out.material = material_index(nx, ny);
            const int x0 = std::min(static_cast<int>(tx), std::max(0, truth.width() - 2));
            const int y0 = std::min(static_cast<int>(ty), std::max(0, truth.height() - 2));
            const int x1 = std::min(x0 + 1, truth.width() - 1),
                      y1 = std::min(y0 + 1, truth.height() - 1);
            const float fx = static_cast<float>(tx - x0), fy = static_cast<float>(ty - y0);
            Vec3f n = (1 - fy) * ((1 - fx) * normals(x0, y0) + fx * normals(x1, y0)) +
                      fy * ((1 - fx) * normals(x0, y1) + fx * normals(x1, y1));
            const TangentFrame frame = MakeTangentFrame(n.cast<double>());
            const Vec3d v = (view.eye_canvas - p).normalized();
            out.frame_x = frame.x.cast<float>();
            out.frame_y = frame.y.cast<float>();
            out.frame_z = frame.z.cast<float>();
            out.v_local = frame.ToLocal(v).cast<float>();
            out.faces_camera = out.v_local.z() > 0;
          }
        }
      });
  return hits;
}

// One image to render: which camera view, which light, where the result goes.
struct Job {
  int view = 0;
  Vec3d light_canvas = Vec3d::Zero();
  bool held_out = false;
  int index = 0;  // into fit.photos or held_out.photos
};

struct Shading {
  const std::vector<PaintMaterial>* materials = nullptr;
  float frame_brdf = 0;  // frame_albedo / pi
  float intensity = 0;   // grey point light, linear units x mm^2 x sr
};

// Radiance of a pixel (unshadowed); also whether the surface faces the light (n.l > 0) and the
// camera, for the shadow statistics. Float: hit points are float already, and the light's
// direction to ~1e-7 changes a k = 500 lobe by ~5e-5 of its value.
Vec3f Shade(const PixelHit& hit, const Vec3f& light, const Shading& s, bool* lit_side) {
  *lit_side = false;
  if (hit.what == Scene::Hit::kNone) return Vec3f::Zero();
  const Vec3f to_light = light - hit.p;
  const float d2 = to_light.squaredNorm();
  const Vec3f l = to_light / std::sqrt(d2);
  const float irradiance = s.intensity / d2;
  if (hit.what != Scene::Hit::kCanvas) {
    const float cos_l = hit.n_geo.dot(l);
    if (!(cos_l > 0)) return Vec3f::Zero();
    *lit_side = true;
    return Vec3f::Constant(s.frame_brdf * cos_l * irradiance);
  }
  const float cos_l = hit.frame_z.dot(l);
  if (!hit.faces_camera || !(cos_l > 0)) return Vec3f::Zero();
  *lit_side = true;
  const Vec3f l_local(hit.frame_x.dot(l), hit.frame_y.dot(l), cos_l);
  return (*s.materials)[hit.material].Evaluate(hit.v_local, l_local) * (cos_l * irradiance);
}

struct RenderCounts {
  std::atomic<size_t> saturated{0}, canvas_lit{0}, shadowed{0};
};

}  // namespace

// ---------------------------------------------------------------------------------------------

Vec3f PaintMaterial::Evaluate(const Vec3f& v, const Vec3f& l) const {
  if (is_measured) return EvaluateMeasuredLafortune(measured, v, l);
  return is_ggx ? EvaluateGgx(ggx, v, l) : EvaluateLafortune(lafortune, v, l);
}

std::vector<PaintMaterial> GgxPaintMaterials() {
  // name, diffuse albedo (RGB; BRDF = albedo / pi), F0 (RGB), alpha. Dielectric paints and
  // varnishes reflect F0 ~ 0.04 (refractive index 1.5) in grey; the metal has no diffuse term.
  struct Spec {
    const char* name;
    Vec3f albedo, f0;
    float alpha;
  };
  const Vec3f dielectric = Vec3f::Constant(0.04f);
  const Spec specs[] = {
      {"ggx varnish a0.05 (dark umber)", {0.09f, 0.065f, 0.05f}, dielectric, 0.05f},
      {"ggx satin a0.15 (vermilion)", {0.50f, 0.13f, 0.08f}, dielectric, 0.15f},
      {"ggx green earth a0.3", {0.16f, 0.30f, 0.17f}, dielectric, 0.3f},
      {"ggx yellow ochre a0.6", {0.62f, 0.50f, 0.28f}, dielectric, 0.6f},
      {"ggx gold leaf a0.2 (metal)", {0.0f, 0.0f, 0.0f}, {1.0f, 0.78f, 0.34f}, 0.2f},
      {"lambertian (lead white)", {0.80f, 0.77f, 0.68f}, Vec3f::Zero(), 0.0f},
      {"ggx glaze a0.02 (madder)", {0.25f, 0.04f, 0.06f}, dielectric, 0.02f},
  };
  std::vector<PaintMaterial> out;
  for (const Spec& s : specs) {
    PaintMaterial m;
    m.name = s.name;
    if (s.alpha > 0.0f) {
      m.is_ggx = true;
      m.ggx.rho_d = s.albedo / static_cast<float>(kPi);
      m.ggx.f0 = s.f0;
      m.ggx.alpha = s.alpha;
      // The one-lobe stand-in (unused by the renderer): the diffuse term.
      m.lafortune.rho_d = m.ggx.rho_d;
    } else {
      m.lafortune.rho_d = s.albedo / static_cast<float>(kPi);  // rho_s = 0: Lambertian
    }
    out.push_back(std::move(m));
  }
  return out;
}

GgxPaintingCase MakeGgxPaintingCase(int resolution_px, uint64_t seed) {
  GgxPaintingCase c;
  // 400 mm: a ~4 mm texel pitch, so the frame's shadow band (25 mm raise, lights down to 15 deg)
  // and the relief's steepest walls cover a few texels of the 96, not a tenth of the canvas.
  c.painting.width_mm = 400;
  c.painting.height_mm = 400;
  c.painting.resolution_px = resolution_px;
  c.painting.seed = seed;
  c.painting.region_count = 6;
  c.photos.cameras = 2;
  c.photos.camera_arc_deg = 30;
  c.photos.lights = 48;
  c.photos.pixels_per_texel = 1.2;
  c.photos.noise_sigma = 0.002;
  c.photos.encoding = PhotoEncoding::kSrgb8;
  c.photos.held_out_lights = 8;
  c.photos.seed = seed;
  c.materials = GgxPaintMaterials();
  return c;
}

std::vector<PaintMaterial> DefaultPaintMaterials(bool with_measured) {
  // name, diffuse albedo (RGB), specular albedo a_s, k, cx, cy. rho_s = a_s (k + 2) / (2 pi):
  // the lobe's integral of rho_s max(0, cos)^k cos over the hemisphere is about a_s, so every
  // material keeps rho_s 2 pi / (k + 2) = a_s <= 1 and albedo + a_s < 1 (no energy created).
  // Specular albedos of 4-8 % are those of oil and varnish (refractive index ~1.5).
  struct Spec {
    const char* name;
    Vec3f albedo;
    float specular_albedo, k, cx, cy;
  };
  const Spec specs[] = {
      {"matte (yellow ochre)", {0.62f, 0.50f, 0.28f}, 0.0f, 1.0f, -1.0f, -1.0f},
      {"satin (vermilion)", {0.50f, 0.13f, 0.08f}, 0.08f, 6.0f, -1.0f, -1.0f},
      {"semi-gloss (green earth)", {0.16f, 0.30f, 0.17f}, 0.06f, 30.0f, -1.0f, -1.0f},
      {"gloss (ultramarine)", {0.07f, 0.09f, 0.33f}, 0.05f, 100.0f, -1.0f, -1.0f},
      {"varnish (dark umber)", {0.09f, 0.065f, 0.05f}, 0.04f, 400.0f, -1.0f, -1.0f},
      // Anisotropic and off-specular: the lobe is narrower along the canvas X axis than along
      // Y, and its peak leans towards the normal (|c| < 1).
      {"anisotropic off-specular (lead white)",
       {0.80f, 0.77f, 0.68f},
       0.06f,
       20.0f,
       -0.95f,
       -0.55f},
  };
  std::vector<PaintMaterial> out;
  for (const Spec& s : specs) {
    PaintMaterial m;
    m.name = s.name;
    m.lafortune.rho_d = s.albedo / static_cast<float>(kPi);
    m.lafortune.rho_s =
        Vec3f::Constant(s.specular_albedo * (s.k + 2.0f) / static_cast<float>(2 * kPi));
    m.lafortune.cx = s.cx;
    m.lafortune.cy = s.cy;
    m.lafortune.cz = 1.0f;
    m.lafortune.k = s.k;
    out.push_back(std::move(m));
  }
  if (with_measured) {
    // Lafortune et al. 1997, "light blue housepaint" (as shipped in LuxRender's bluepaint.cpp and
    // ../shared/data/lafortune_measured_fits.txt); diffuse listed as an albedo.
    PaintMaterial m;
    m.name = "bluepaint (measured)";
    m.is_measured = true;
    m.measured.name = "bluepaint";
    m.measured.diffuse_albedo = Vec3f(0.3094f, 0.39667f, 0.70837f);
    m.measured.lobes = {
        {Vec3f(0.870567f, 0.857255f, 0.670982f), Vec3f(0.803624f, 0.774290f, 0.586674f),
         Vec3f(21.820103f, 18.597755f, 7.472717f)},
        {Vec3f(-0.451218f, -0.406681f, -0.477976f), Vec3f(0.023123f, 0.017625f, 0.227295f),
         Vec3f(2.774499f, 2.581499f, 3.677653f)},
        {Vec3f(-1.031545f, -1.029426f, -1.026588f), Vec3f(0.706734f, 0.696530f, 0.687715f),
         Vec3f(66.899060f, 63.767912f, 57.489181f)},
    };
    // The fitted family's stand-in (unused by the renderer): the measured diffuse term.
    m.lafortune.rho_d = m.measured.diffuse_albedo / static_cast<float>(kPi);
    out.push_back(std::move(m));
  }
  return out;
}

const char* ToString(PhotoEncoding e) {
  switch (e) {
    case PhotoEncoding::kSrgb8:
      return "srgb8";
    case PhotoEncoding::kSrgb16:
      return "srgb16";
    case PhotoEncoding::kLinearExr:
      return "exr";
    case PhotoEncoding::kJpeg:
      return "jpeg";
  }
  return "?";
}

Status PhotoSimOptions::Validate() const {
  auto fail = [](const std::string& what) { return Status(Error{"photo options: " + what}); };
  auto in = [](double v, double lo, double hi) { return std::isfinite(v) && v >= lo && v <= hi; };
  if (cameras < 1 || cameras > 64)
    return fail("cameras must be in [1, 64], got " + std::to_string(cameras));
  if (!in(camera_arc_deg, 0, 80))
    return fail("camera_arc_deg must be in [0, 80], got " + FormatNumber(camera_arc_deg));
  if (!(in(camera_distance_mm, 0, 1e5) && camera_distance_mm > 0))
    return fail("camera_distance_mm must be in (0, 100000], got " +
                FormatNumber(camera_distance_mm));
  if (!(in(pixels_per_texel, 0, 16) && pixels_per_texel > 0))
    return fail("pixels_per_texel must be in (0, 16], got " + FormatNumber(pixels_per_texel));
  if (!in(view_margin, 0, 2))
    return fail("view_margin must be in [0, 2], got " + FormatNumber(view_margin));
  if (lights < 1 || lights > 4096)
    return fail("lights must be in [1, 4096], got " + std::to_string(lights));
  if (!(in(light_min_elevation_deg, 0, 90) && light_min_elevation_deg > 0))
    return fail("light_min_elevation_deg must be in (0, 90], got " +
                FormatNumber(light_min_elevation_deg));
  if (!in(light_max_elevation_deg, light_min_elevation_deg, 90))
    return fail("light_max_elevation_deg must be in [light_min_elevation_deg, 90], got " +
                FormatNumber(light_max_elevation_deg));
  if (!(in(light_distance_mm, 0, 1e5) && light_distance_mm > 0))
    return fail("light_distance_mm must be in (0, 100000], got " + FormatNumber(light_distance_mm));
  if (!(in(white_level, 0, 1e6) && white_level > 0))
    return fail("white_level must be in (0, 1e6] (linear), got " + FormatNumber(white_level));
  if (held_out_lights < 0 || held_out_lights > 4096)
    return fail("held_out_lights must be in [0, 4096], got " + std::to_string(held_out_lights));
  if (!in(held_out_camera_deg, 0, 80))
    return fail("held_out_camera_deg must be in [0, 80], got " + FormatNumber(held_out_camera_deg));
  if (!in(noise_sigma, 0, 1))
    return fail("noise_sigma must be in [0, 1] (linear), got " + FormatNumber(noise_sigma));
  if (encoding != PhotoEncoding::kSrgb8 && encoding != PhotoEncoding::kSrgb16 &&
      encoding != PhotoEncoding::kLinearExr && encoding != PhotoEncoding::kJpeg)
    return fail("encoding must be srgb8, srgb16, exr or jpeg, got " +
                std::to_string(static_cast<int>(encoding)));
  if (jpeg_quality < 50 || jpeg_quality > 100)
    return fail("jpeg_quality must be in [50, 100], got " + std::to_string(jpeg_quality));
  if ((grid_cols == 0) != (grid_rows == 0) || grid_cols < 0 || grid_rows < 0 || grid_cols > 64 ||
      grid_rows > 64)
    return fail("the camera grid must be 0 x 0 (an arc) or 1..64 x 1..64 cells, got " +
                std::to_string(grid_cols) + " x " + std::to_string(grid_rows));
  if (grid() && cameras != 1)
    return fail("a camera grid has one camera per cell: cameras must be 1, got " +
                std::to_string(cameras));
  if (!in(grid_overlap, 0, 1))
    return fail("grid_overlap must be in [0, 1] (share of a cell), got " +
                FormatNumber(grid_overlap));
  if (!in(frame_albedo, 0, 1))
    return fail("frame_albedo must be in [0, 1], got " + FormatNumber(frame_albedo));
  return Status::Ok();
}

std::string SyntheticPhotoSet::Brief() const {
  size_t pixels = 0;
  for (const Photo& p : fit.photos) pixels += static_cast<size_t>(p.camera.width) * p.camera.height;
  const Camera* cam = fit.photos.empty() ? nullptr : &fit.photos.front().camera;
  char buf[320];
  std::snprintf(buf, sizeof buf,
                "%zu images %dx%d (%d camera(s)%s x %d lights, %s) + %zu held-out; %.1f Mpx; "
                "%zu saturated px (%.2f %%), %.1f %% of lit canvas px in shadow; %.2f s",
                fit.photos.size(), cam ? cam->width : 0, cam ? cam->height : 0,
                options.camera_positions(), options.grid() ? " in a grid" : "", options.lights,
                ToString(options.encoding), held_out.photos.size(), pixels * 1e-6, saturated_pixels,
                pixels ? 100.0 * saturated_pixels / pixels : 0.0,
                canvas_lit_pixels ? 100.0 * shadowed_pixels / canvas_lit_pixels : 0.0,
                render_seconds);
  return buf;
}

ReflectanceMaps MaterialTruth(const std::vector<PaintMaterial>& materials) {
  ReflectanceMaps out = ReflectanceMaps::Zeros(static_cast<int>(materials.size()), 1);
  for (size_t i = 0; i < materials.size(); ++i) {
    const int x = static_cast<int>(i);
    const PaintMaterial& m = materials[i];
    if (m.is_measured) {
      LafortuneParams diffuse;  // rho_s = 0: the measured diffuse term only
      diffuse.rho_d = m.measured.diffuse_albedo / static_cast<float>(kPi);
      out.Set(x, 0, diffuse);
      out.status(x, 0) = TexelFitStatus::kDiffuseOnly;
    } else if (m.is_ggx) {
      out.SetGgx(x, 0, m.ggx);
      out.status(x, 0) = TexelFitStatus::kConverged;
    } else {
      out.Set(x, 0, m.lafortune);
      out.status(x, 0) = TexelFitStatus::kConverged;
    }
  }
  return out;
}

SyntheticPhotoSet SimulatePhotoSet(const Scene& scene, const RigidTransform& canvas_from_scan,
                                   const PhotoSimOptions& options,
                                   std::vector<PaintMaterial> materials,
                                   const ProgressCallback& progress, const PhotoSink& sink) {
  const auto start = std::chrono::steady_clock::now();
  const Status valid = options.Validate();
  DIGITIZE_CHECK(valid.ok(), "SimulatePhotoSet: " + valid.message());
  if (materials.empty()) materials = DefaultPaintMaterials(false);
  DIGITIZE_CHECK(materials.size() <= 256, "SimulatePhotoSet: at most 256 materials, got " +
                                              std::to_string(materials.size()));
  for (const PaintMaterial& m : materials) {
    if (m.is_measured) continue;
    if (m.is_ggx) {
      const GgxParams& g = m.ggx;
      DIGITIZE_CHECK(g.rho_d.allFinite() && (g.rho_d.array() >= 0.0f).all() &&
                         (g.f0.array() >= 0.0f).all() && (g.f0.array() <= 1.0f).all() &&
                         g.alpha >= kGgxMinAlpha && g.alpha <= kGgxMaxAlpha,
                     "SimulatePhotoSet: material \"" + m.name +
                         "\": GGX needs rho_d >= 0, F0 in [0, 1], alpha in [" +
                         FormatNumber(kGgxMinAlpha) + ", " + FormatNumber(kGgxMaxAlpha) + "]");
      continue;
    }
    const Status s = m.lafortune.Validate();
    DIGITIZE_CHECK(s.ok(), "SimulatePhotoSet: material \"" + m.name + "\": " + s.message());
  }
  const Painting& painting = scene.painting();
  const int tw = painting.truth.width(), th = painting.truth.height();
  ReportProgress(progress, "render", 0.0);

  SyntheticPhotoSet out;
  out.options = options;
  out.canvas_from_scan = canvas_from_scan;
  out.materials = materials;

  // Which paint each texel is; the truth maps follow it once the photos are rendered (below).
  out.material_index = Grid<uint8_t>(tw, th, 0);
  out.measured_texel = Grid<uint8_t>(tw, th, 0);
  for (int y = 0; y < th; ++y) {
    for (int x = 0; x < tw; ++x) {
      const size_t mi = painting.region(x, y) % materials.size();
      out.material_index(x, y) = static_cast<uint8_t>(mi);
      out.measured_texel(x, y) = materials[mi].is_measured ? 1 : 0;
    }
  }

  // Cameras: the fitting arc (or grid), then the held-out camera off the arc (or over cell 0).
  const double dist = options.camera_distance_mm;
  std::vector<View> views;
  std::vector<Vec3d> light_centres;  // per fitting view: the centre of its dome of lights
  if (options.grid()) {
    for (int r = 0; r < options.grid_rows; ++r) {
      for (int c = 0; c < options.grid_cols; ++c) {
        const ViewRect cell = CellView(painting, options, c, r);
        light_centres.push_back(cell.Centre());
        views.push_back(
            MakeView(painting, options, cell.Centre() + Vec3d(0, 0, dist), cell, canvas_from_scan));
      }
    }
  } else {
    const ViewRect whole = CanvasView(painting, options);
    for (int c = 0; c < options.cameras; ++c) {
      const double a =
          options.cameras == 1
              ? 0.0
              : (-options.camera_arc_deg + 2 * options.camera_arc_deg * c / (options.cameras - 1)) *
                    kDeg;
      light_centres.push_back(whole.Centre());
      views.push_back(MakeView(painting, options,
                               whole.Centre() + dist * Vec3d(std::sin(a), 0, std::cos(a)), whole,
                               canvas_from_scan));
    }
  }
  const int held_out_view = static_cast<int>(views.size());
  // A grid's held-out views look at a cell-sized patch at the canvas centre (not a corner: the
  // frame's shadows would dominate the score); an image of the whole canvas would be the size of
  // the whole painting (gigapixels for a large one).
  ViewRect held_rect = CanvasView(painting, options);
  if (options.grid()) {
    const ViewRect cell = CellView(painting, options, 0, 0);
    const Vec3d half = 0.5 * Vec3d(cell.x1 - cell.x0, cell.y1 - cell.y0, 0);
    const Vec3d mid(0.5 * painting.width_mm, 0.5 * painting.height_mm, 0);
    held_rect = {mid.x() - half.x(), mid.y() - half.y(), mid.x() + half.x(), mid.y() + half.y()};
  }
  {
    const double a = options.held_out_camera_deg * kDeg;
    views.push_back(MakeView(painting, options,
                             held_rect.Centre() + dist * Vec3d(0, std::sin(a), std::cos(a)),
                             held_rect, canvas_from_scan));
  }

  // Lights, grey: a white Lambertian at the centre lit head-on reads white_level.
  const RigidTransform scan_from_canvas = canvas_from_scan.Inverse();
  const float intensity = static_cast<float>(options.white_level * kPi * options.light_distance_mm *
                                             options.light_distance_mm);
  auto make_light = [&](const Vec3d& p_canvas) {
    Light l;
    l.type = LightType::kPoint;
    l.position_mm = scan_from_canvas.Apply(p_canvas);
    l.intensity = Vec3f::Constant(intensity);
    return l;
  };
  std::vector<Vec3d> held_lights;
  for (int j = 0; j < options.held_out_lights; ++j) {
    const double s = HeldOutSpiralPosition(j, options.held_out_lights, options.lights);
    held_lights.push_back(SpiralLight(held_rect.Centre(), options, s, options.lights));
  }

  // Photos (pixels filled below) and the jobs that render them.
  std::vector<std::vector<Job>> jobs_of_view(views.size());
  const ColourEncoding fit_encoding = options.encoding == PhotoEncoding::kLinearExr
                                          ? ColourEncoding::kLinear
                                          : ColourEncoding::kSrgb;
  const char* ext = options.encoding == PhotoEncoding::kLinearExr ? "exr"
                    : options.encoding == PhotoEncoding::kJpeg    ? "jpg"
                                                                  : "png";
  // Every pixel is written by the render loop below: no zero fill (0.3 s of one thread for 64
  // megapixel images), the pages are touched first by the threads that render them.
  auto unfilled = [](int w, int h) {
    Grid<Vec3f> g;
    g.width = w;
    g.height = h;
    g.data.resize(static_cast<size_t>(w) * h);  // Eigen vectors: left uninitialised
    return g;
  };
  auto name = [](const char* dir, int i, const char* e) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%s%03d.%s", dir, i, e);
    return std::string(buf);
  };
  out.fit.source = "synthetic";
  for (int c = 0; c < held_out_view; ++c) {
    for (int j = 0; j < options.lights; ++j) {
      const Vec3d light = SpiralLight(light_centres[c], options, j, options.lights);
      Photo photo;
      const int i = static_cast<int>(out.fit.photos.size());
      photo.path = name("images/img_", i, ext);
      photo.entry = "synthetic: images[" + std::to_string(i) + "]";
      photo.camera = views[c].camera;
      photo.light = make_light(light);
      photo.encoding = fit_encoding;
      out.fit.photos.push_back(std::move(photo));
      jobs_of_view[c].push_back({c, light, false, i});
    }
  }
  out.held_out.source = "synthetic held-out";
  for (int v : {0, held_out_view}) {
    for (int j = 0; j < options.held_out_lights; ++j) {
      Photo photo;
      const int i = static_cast<int>(out.held_out.photos.size());
      photo.path = name("img_", i, "exr");
      photo.entry = "synthetic held-out: images[" + std::to_string(i) + "]";
      photo.camera = views[v].camera;
      photo.light = make_light(held_lights[j]);
      photo.encoding = ColourEncoding::kLinear;
      out.held_out.photos.push_back(std::move(photo));
      out.held_out_mask.emplace_back();
      jobs_of_view[v].push_back({v, held_lights[j], true, i});
    }
  }

  Shading shading;
  shading.materials = &out.materials;
  shading.frame_brdf = static_cast<float>(options.frame_albedo / kPi);
  shading.intensity = intensity;

  // Progress over all rows of all images.
  size_t total_rows = 0;
  for (size_t v = 0; v < views.size(); ++v)
    total_rows += jobs_of_view[v].size() * views[v].camera.height;
  std::atomic<size_t> rows_done{0};
  std::mutex progress_mutex;
  int last_percent = 0;
  auto rows_finished = [&](size_t n) {
    const size_t done = rows_done += n;
    if (!progress) return;
    const int percent = static_cast<int>(100.0 * done / std::max<size_t>(total_rows, 1));
    std::lock_guard<std::mutex> lock(progress_mutex);
    if (percent <= last_percent) return;
    last_percent = percent;
    progress("render", percent / 100.0);
  };

  RenderCounts counts;
  const bool noisy = options.noise_sigma > 0;
  const float sigma = static_cast<float>(options.noise_sigma);
  for (size_t v = 0; v < views.size(); ++v) {
    const std::vector<Job>& jobs = jobs_of_view[v];
    if (jobs.empty()) continue;
    const View& view = views[v];
    const Grid<PixelHit> hits = TracePrimary(scene, view, out.material_index);
    const int w = view.camera.width, h = view.camera.height;
    // Pixels are allocated a camera position at a time (with a sink, only its images are held).
    for (const Job& job : jobs) {
      Photo& photo = job.held_out ? out.held_out.photos[job.index] : out.fit.photos[job.index];
      photo.rgb = unfilled(w, h);
      if (job.held_out) {
        out.held_out_mask[job.index] = Grid<uint8_t>(w, h, 0);
      } else {
        photo.flags = Grid<uint8_t>(w, h, 0);
      }
    }
    const int blocks = (h + kRowGrain - 1) / kRowGrain;
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, jobs.size() * blocks, 1),
        [&](const tbb::blocked_range<size_t>& range) {
          std::vector<Vec3d> origins(static_cast<size_t>(w)), dirs(static_cast<size_t>(w));
          std::vector<float> max_t(static_cast<size_t>(w));
          std::vector<uint8_t> blocked;
          std::vector<Scene::RayHit> blockers;
          std::vector<Vec3f> radiance(static_cast<size_t>(w));
          std::vector<uint8_t> lit(static_cast<size_t>(w));
          for (size_t task = range.begin(); task != range.end(); ++task) {
            const Job& job = jobs[task / blocks];
            const int y0 = static_cast<int>(task % blocks) * kRowGrain;
            const int y1 = std::min(h, y0 + kRowGrain);
            Photo& photo =
                job.held_out ? out.held_out.photos[job.index] : out.fit.photos[job.index];
            const Vec3f light_f = job.light_canvas.cast<float>();
            size_t saturated = 0, canvas_lit = 0, shadowed = 0;
            for (int y = y0; y < y1; ++y) {
              const PixelHit* row = hits.Row(y);
              for (int x = 0; x < w; ++x) {
                bool lit_side = false;
                radiance[x] = Shade(row[x], light_f, shading, &lit_side);
                lit[x] = lit_side;
              }
              if (options.shadows) {
                for (int x = 0; x < w; ++x) {
                  const PixelHit& hit = row[x];
                  if (hit.what == Scene::Hit::kNone) {
                    dirs[x] = Vec3d::Zero();  // never blocked
                    max_t[x] = 0;
                    continue;
                  }
                  origins[x] =
                      (hit.p + hit.n_geo * static_cast<float>(kShadowOffsetMm)).cast<double>();
                  dirs[x] = job.light_canvas - origins[x];
                  max_t[x] = static_cast<float>(dirs[x].norm());
                }
                if (job.held_out) {
                  // What blocks the light first: the mask leaves out frame shadows only.
                  scene.Intersect(origins, dirs, max_t, blockers);
                  Grid<uint8_t>& mask = out.held_out_mask[job.index];
                  for (int x = 0; x < w; ++x) {
                    const Scene::Hit b = blockers[x].what;
                    if (b != Scene::Hit::kNone) radiance[x] = Vec3f::Zero();
                    mask(x, y) = row[x].what == Scene::Hit::kCanvas && b != Scene::Hit::kFrame;
                  }
                } else {
                  scene.Occluded(origins, dirs, max_t, blocked);
                  for (int x = 0; x < w; ++x) {
                    if (!blocked[x]) continue;
                    if (lit[x] && row[x].what == Scene::Hit::kCanvas) ++shadowed;
                    radiance[x] = Vec3f::Zero();
                  }
                }
              } else if (job.held_out) {
                Grid<uint8_t>& mask = out.held_out_mask[job.index];
                for (int x = 0; x < w; ++x) mask(x, y) = row[x].what == Scene::Hit::kCanvas;
              }
              Vec3f* dst = photo.rgb.Row(y);
              if (job.held_out) {
                std::copy(radiance.begin(), radiance.end(), dst);
                continue;
              }
              for (int x = 0; x < w; ++x)
                canvas_lit += lit[x] && row[x].what == Scene::Hit::kCanvas;
              // Fitting image: noise, then the encoding as a camera file would hold it.
              if (noisy) {
                SplitMixEngine rng = RowStream(options.seed, job.index, y);
                std::normal_distribution<float> normal(0.0f, 1.0f);
                for (int x = 0; x < w; ++x) {
                  for (int k = 0; k < 3; ++k) radiance[x][k] += sigma * normal(rng);
                }
              }
              if (options.encoding == PhotoEncoding::kLinearExr) {
                std::copy(radiance.begin(), radiance.end(), dst);
                continue;
              }
              const SrgbCodec& codec = Codec(options.encoding);
              uint8_t* flags = photo.flags.Row(y);
              for (int x = 0; x < w; ++x) {
                int top = 0;
                for (int k = 0; k < 3; ++k) {
                  const int code = codec.Encode(radiance[x][k]);
                  dst[x][k] = codec.linear[static_cast<size_t>(code)];
                  top = std::max(top, code);
                }
                if (top >= codec.max_code) {
                  flags[x] = kPixelSaturated;
                  ++saturated;
                }
              }
            }
            counts.saturated += saturated;
            counts.canvas_lit += canvas_lit;
            counts.shadowed += shadowed;
            rows_finished(static_cast<size_t>(y1 - y0));
          }
        });
    // Per-photo counts, as LoadPhoto reports them (flags empty when nothing is flagged), then
    // the sink takes the finished images and their pixels go.
    std::vector<Status> sunk(jobs.size());
    tbb::parallel_for(size_t{0}, jobs.size(), [&](size_t k) {
      const Job& job = jobs[k];
      Photo& photo = job.held_out ? out.held_out.photos[job.index] : out.fit.photos[job.index];
      if (!job.held_out) {
        photo.saturated_pixels = 0;
        for (uint8_t f : photo.flags.data) photo.saturated_pixels += (f & kPixelSaturated) != 0;
        if (photo.saturated_pixels == 0) photo.flags = Grid<uint8_t>();
      }
      if (!sink) return;
      sunk[k] = sink(photo, job.held_out ? &out.held_out_mask[job.index] : nullptr, job.index);
      photo.rgb = Grid<Vec3f>();
      photo.flags = Grid<uint8_t>();
      if (job.held_out) out.held_out_mask[job.index] = Grid<uint8_t>();
    });
    if (sink) {
      out.pixels_released = true;
      for (const Status& st : sunk) {
        if (!st.ok() && out.sink_status.ok()) out.sink_status = st;
      }
      if (!out.sink_status.ok()) break;
    }
  }

  // Ground truth on the texel grid, made after the render (which reads material_index only), and
  // only for a set kept in memory: a sink's writer makes the truth files a map at a time from
  // material_index. The whole maps (44 bytes a texel) were the generator's peak at 8192 texels.
  if (!sink) {
    const ReflectanceMaps of_material = MaterialTruth(out.materials);
    out.truth = ReflectanceMaps::Zeros(tw, th);
    for (int y = 0; y < th; ++y) {
      for (int x = 0; x < tw; ++x) {
        const int m = out.material_index(x, y);
        out.truth.rho_d(x, y) = of_material.rho_d(m, 0);
        out.truth.rho_s(x, y) = of_material.rho_s(m, 0);
        out.truth.lobe(x, y) = of_material.lobe(m, 0);
        out.truth.status(x, y) = of_material.status(m, 0);
        out.truth.model(x, y) = of_material.model(m, 0);
      }
    }
  }

  PhotoLoadSummary& summary = out.fit.summary;
  for (Photo& photo : out.fit.photos) {
    ++summary.photos_loaded;
    summary.pixels += static_cast<size_t>(photo.camera.width) * photo.camera.height;
    summary.saturated_pixels += photo.saturated_pixels;
    (photo.encoding == ColourEncoding::kSrgb ? summary.srgb_photos : summary.linear_photos) += 1;
  }
  PhotoLoadSummary& held = out.held_out.summary;
  for (const Photo& photo : out.held_out.photos) {
    ++held.photos_loaded;
    held.pixels += static_cast<size_t>(photo.camera.width) * photo.camera.height;
    ++held.linear_photos;
  }
  out.saturated_pixels = counts.saturated;
  out.canvas_lit_pixels = counts.canvas_lit;
  out.shadowed_pixels = counts.shadowed;
  out.render_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  summary.seconds = held.seconds = out.render_seconds;
  ReportProgress(progress, "render", 1.0);
  return out;
}

}  // namespace digitize::synth
