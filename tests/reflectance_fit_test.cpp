// Samples from photos and the fit stage on analytic scenes: a flat (or ridged) canvas seen by an
// orthographic camera straight above, whose pixels are the canvas texels, lit by directional
// lights; the photos are rendered here in closed form, so every sample and fitted value has an
// exact expected value. The stress cases that need no generator live here too.
#include "digitize/reflectance_fit.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <limits>
#include <nlohmann/json.hpp>
#include <vector>

#include "digitize/image_io.h"
#include "digitize/reflectance_samples.h"
#include "digitize/relight.h"
#include "digitize/tangent_frame.h"
#include "test_support.h"

namespace digitize {
namespace {

constexpr double kPitch = 0.5;  // mm per texel and per pixel

HeightField FlatCanvas(int w, int h) { return test::MakeFlatField(w, h, kPitch); }

// Orthographic camera 1 m above the canvas, looking down, pixel (x, y) = texel (x, y).
Camera TopCamera(int w, int h) {
  Camera c;
  c.model = CameraModel::kOrthographic;
  c.width = w;
  c.height = h;
  c.pixel_pitch_mm = kPitch;
  c.camera_from_scan.rotation << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  c.camera_from_scan.translation = {-0.5 * kPitch, (h - 0.5) * kPitch, 1000.0};
  return c;
}

Light Directional(double elevation_deg, double azimuth_deg, float irradiance = 1.0f) {
  const double e = elevation_deg * M_PI / 180, a = azimuth_deg * M_PI / 180;
  Light l;
  l.type = LightType::kDirectional;
  l.direction =
      Vec3d(std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e)).normalized();
  l.irradiance = Vec3f::Constant(irradiance);
  return l;
}

// Photos of a flat canvas with one Lafortune material, rendered exactly (no shadows: flat).
PhotoSet RenderFlat(const HeightField& canvas, const LafortuneParams& m,
                    const std::vector<Light>& lights) {
  PhotoSet set;
  set.source = "analytic.json";
  const Camera cam = TopCamera(canvas.width(), canvas.height());
  for (size_t i = 0; i < lights.size(); ++i) {
    Photo p;
    p.entry = "analytic.json: images[" + std::to_string(i) + "]";
    p.path = "img" + std::to_string(i) + ".exr";
    p.camera = cam;
    p.light = lights[i];
    p.encoding = ColourEncoding::kLinear;
    p.rgb = Grid<Vec3f>(cam.width, cam.height);
    const Vec3f v(0, 0, 1);
    const Vec3f l = lights[i].direction.cast<float>();
    const Vec3f f = EvaluateLafortune(m, v, l);
    for (Vec3f& c : p.rgb.data) c = f.cwiseProduct(lights[i].irradiance) * std::max(0.0f, l.z());
    set.photos.push_back(std::move(p));
  }
  return set;
}

std::vector<Light> Dome(int n, double min_elev = 20, double max_elev = 80) {
  std::vector<Light> out;
  for (int i = 0; i < n; ++i)
    out.push_back(Directional(min_elev + (max_elev - min_elev) * (i + 0.5) / n, 137.5 * i));
  return out;
}

Grid<Vec3f> UpNormals(const HeightField& f) {
  return Grid<Vec3f>(f.width(), f.height(), Vec3f::UnitZ());
}

TEST(ReflectanceSamples, FlatCanvasSamplesAreExact) {
  const HeightField canvas = FlatCanvas(12, 10);
  LafortuneParams m;
  m.rho_d = {0.2f, 0.1f, 0.05f};
  const std::vector<Light> lights = Dome(6);
  const PhotoSet set = RenderFlat(canvas, m, lights);
  const Grid<Vec3f> normals = UpNormals(canvas);
  auto tracer = HeightFieldTracer::Build(canvas);
  ASSERT_TRUE(tracer.ok()) << tracer.error().message;
  const SampleScene scene{&canvas, &normals, RigidTransform{}, &set, &*tracer};
  ASSERT_TRUE(ValidateSampleScene(scene).ok());
  std::vector<uint32_t> texels = {0, 5, 119};
  BrdfSamples samples;
  SampleStats stats;
  GatherSamples(scene, texels, {}, samples, stats);
  ASSERT_EQ(samples.texel_count(), 3u);
  EXPECT_EQ(stats.candidates, 3u * lights.size());
  EXPECT_EQ(stats.kept, 3u * lights.size());
  for (size_t t = 0; t < 3; ++t) {
    ASSERT_EQ(samples.Texel(t).size(), lights.size());
    for (size_t i = 0; i < lights.size(); ++i) {
      const BrdfSample& s = samples.Texel(t)[i];
      // Flat canvas: the tangent frame is the canvas frame; float directions to ~1e-6.
      EXPECT_NEAR((s.view_dir - Vec3f::UnitZ()).norm(), 0, 1e-6);
      EXPECT_NEAR((s.light_dir - lights[i].direction.cast<float>()).norm(), 0, 1e-6);
      const float cos_l = static_cast<float>(lights[i].direction.z());
      EXPECT_NEAR(s.irradiance.x(), cos_l, 1e-6);
      EXPECT_NEAR(s.radiance.x(), 0.2f * cos_l, 1e-6);
    }
  }
  // Flat: every upward ray is proven free, none traced.
  EXPECT_EQ(stats.light_rays.skipped, stats.light_rays.rays);
  EXPECT_EQ(stats.shadowed + stats.hidden, 0u);
}

// Pixel maps (MapPixelsToTexels) against the analytic ray-plane intersection: an orthographic
// camera tilted 40 degrees about the canvas Y axis over a flat canvas, its pixels 1.1 texels apart
// along X on the canvas (0.84 along Y, so 1.08 pixels per texel of area): every pixel's texel is
// the one nearest to where its ray meets the plane; photos of the one camera share one map; a
// texel whose column the pixels step over gets only the bilinear value, its neighbours' paint,
// which is dropped where the texel has min_direct_samples others (0 here: always) and kept where
// it would have too few (the default 8 against these 2 photos).
TEST(ReflectanceSamples, PixelMapsSeeWhatTheRaysSee) {
  const int w = 40, h = 30;
  const HeightField canvas = FlatCanvas(w, h);
  const double a = 40.0 * M_PI / 180.0;
  Camera cam;
  cam.model = CameraModel::kOrthographic;
  cam.width = 36;
  cam.height = 34;
  cam.pixel_pitch_mm = 1.1 * kPitch * std::cos(a);
  cam.cx = (cam.width - 1) / 2.0;
  cam.cy = (cam.height - 1) / 2.0;
  cam.camera_from_scan.rotation << std::cos(a), 0, std::sin(a), 0, -1, 0, std::sin(a), 0,
      -std::cos(a);
  const Vec3d centre(w * kPitch / 2, h * kPitch / 2, 0);
  cam.camera_from_scan.translation = -(cam.camera_from_scan.rotation * centre) + Vec3d(0, 0, 1000);
  PhotoSet set;
  set.source = "tilted.json";
  for (int i = 0; i < 2; ++i) {
    Photo p;
    p.entry = "tilted.json: images[" + std::to_string(i) + "]";
    p.camera = cam;
    p.light = Directional(50 + 10 * i, 30 * i);
    p.encoding = ColourEncoding::kLinear;
    // Pixel colour = its texel's column index, so a sample tells which pixels it averaged.
    p.rgb = Grid<Vec3f>(cam.width, cam.height, Vec3f::Zero());
    set.photos.push_back(std::move(p));
  }
  auto tracer = HeightFieldTracer::Build(canvas);
  ASSERT_TRUE(tracer.ok());
  const PixelTexelMaps maps = MapPixelsToTexels(set, canvas, RigidTransform{}, *tracer);
  ASSERT_EQ(maps.maps.size(), 1u);
  EXPECT_EQ(maps.of_photo, (std::vector<uint32_t>{0, 0}));
  EXPECT_EQ(maps.rays, static_cast<size_t>(cam.width * cam.height));
  std::vector<int> pixels_of_column(w, 0);
  for (int v = 0; v < cam.height; ++v)
    for (int u = 0; u < cam.width; ++u) {
      Vec3d o, d;
      cam.Ray(u, v, o, d);
      const Vec3d hit = o + (-o.z() / d.z()) * d;
      const Eigen::Vector2d t = canvas.TexelFromMm(hit.x(), hit.y());
      const int tx = static_cast<int>(std::lround(t.x())),
                ty = static_cast<int>(std::lround(t.y()));
      const uint32_t expect =
          tx >= 0 && ty >= 0 && tx < w && ty < h ? static_cast<uint32_t>(ty * w + tx) : kNoTexel;
      ASSERT_EQ(maps.maps[0](u, v), expect) << "pixel (" << u << ", " << v << ")";
      if (expect != kNoTexel) {
        ++pixels_of_column[tx];
        for (Photo& p : set.photos) p.rgb(u, v) = Vec3f::Constant(static_cast<float>(tx));
      }
    }
  // Along one row of texels in the middle of the view: the columns no pixel sees.
  const int row = h / 2;
  std::vector<uint32_t> texels;
  int unseen = 0;
  for (int x = 12; x < 28; ++x) {
    texels.push_back(static_cast<uint32_t>(row * w + x));
    unseen += pixels_of_column[x] == 0;
  }
  ASSERT_GT(unseen, 0) << "pixels 1.1 texels apart must step over some column";
  const Grid<Vec3f> normals = UpNormals(canvas);
  for (int min_direct : {0, 8}) {
    for (bool with_maps : {true, false}) {
      const SampleScene scene{&canvas, &normals, RigidTransform{},
                              &set,    &*tracer, with_maps ? &maps : nullptr};
      BrdfSamples samples;
      SampleStats stats;
      SampleOptions options;
      options.min_direct_samples = min_direct;
      GatherSamples(scene, texels, options, samples, stats);
      int blended = 0;
      for (size_t k = 0; k < texels.size(); ++k) {
        const int x = static_cast<int>(texels[k] % w);
        for (const BrdfSample& s : samples.Texel(k)) {
          if (with_maps && pixels_of_column[x]) {
            EXPECT_FLOAT_EQ(s.radiance.x(), static_cast<float>(x)) << "texel column " << x;
          }
          // A blend is a value no single pixel has: pixels carry their column's index, and no
          // pixel has an unseen column's (which a blend of x - 1 and x + 1 can give exactly).
          const float r = s.radiance.x();
          const bool one_pixel = r == std::round(r) && r >= 0.0f && r < static_cast<float>(w) &&
                                 pixels_of_column[static_cast<int>(r)] > 0;
          blended += !one_pixel;
        }
        const bool dropped = with_maps && min_direct == 0 && !pixels_of_column[x];
        EXPECT_EQ(samples.Texel(k).size(), dropped ? 0u : 2u) << x;
      }
      EXPECT_EQ(stats.hidden, 0u);
      EXPECT_EQ(stats.stepped_over, with_maps && min_direct == 0 ? 2u * unseen : 0u);
      EXPECT_EQ(stats.kept, 2 * texels.size() - stats.stepped_over);
      if (!with_maps || min_direct > 0)
        EXPECT_GE(blended, 2 * unseen) << "the bilinear fallback blends columns";
      else
        EXPECT_EQ(blended, 0);
    }
  }
}

TEST(ReflectanceFit, RecoversAGlossyFlatMaterialExactly) {
  const HeightField canvas = FlatCanvas(8, 8);
  LafortuneParams m;
  m.rho_d = {0.15f, 0.10f, 0.05f};
  m.rho_s = {0.6f, 0.6f, 0.6f};
  m.k = 12;
  // One camera above: directions vary only through the lights, so spread them widely.
  const PhotoSet set = RenderFlat(canvas, m, Dome(48, 15, 88));
  ReflectanceFitOptions o;
  o.fit.noise_sigma = 1e-4;
  auto fit = FitReflectance(canvas, UpNormals(canvas), {}, set, o);
  ASSERT_TRUE(fit.ok()) << fit.error().message;
  const LafortuneParams p = fit->maps.At(3, 4);
  // Noise-free samples of the fitted family: the fit is exact up to solver tolerance. cx, cy are
  // weakly determined with v = z (only vz lz matters at vx = vy = 0), so the lobe is judged by
  // relighting below rather than by (cx, cy).
  EXPECT_NEAR(p.rho_d.x(), 0.15f, 2e-3);
  EXPECT_NEAR(p.rho_s.x(), 0.6f, 0.03);
  EXPECT_NEAR(std::log10(p.k), std::log10(12.0), 0.02);
  EXPECT_EQ(fit->maps.status(3, 4), TexelFitStatus::kConverged);
  // Held-out lights, relit: radiance within 1 % of the peak.
  auto tracer = HeightFieldTracer::Build(canvas);
  const PhotoSet held = RenderFlat(canvas, m, {Directional(63, 10), Directional(33, 250)});
  auto score = EvaluateHeldOut(canvas, UpNormals(canvas), fit->maps, {}, held);
  ASSERT_TRUE(score.ok()) << score.error().message;
  EXPECT_GT(score->psnr_db, 50.0);
  EXPECT_EQ(score->pixels, 2u * 64u);
}

// Issue 10: a one-photo capture used to "succeed" with every texel "too few samples" (a black
// pack). A texel that is left with one sample still falls back to a diffuse fit of it.
TEST(ReflectanceFit, OnePhotoIsRefusedNamingTheCountAndTheMinimum) {
  const HeightField canvas = FlatCanvas(6, 6);
  LafortuneParams m;
  m.rho_d = Vec3f::Constant(0.3f);
  auto fit = FitReflectance(canvas, UpNormals(canvas), {},
                            RenderFlat(canvas, m, {Directional(50, 0)}), {});
  ASSERT_FALSE(fit.ok());
  for (const char* words : {"analytic.json", "only 1 distinct", "in 1 photo", "at least 8",
                            "min_samples 8", "too few samples"})
    EXPECT_NE(fit.error().message.find(words), std::string::npos)
        << words << ": " << fit.error().message;
  // The minimum follows min_samples, but never drops below kMinDistinctPhotoDirections.
  ReflectanceFitOptions o;
  o.fit.min_samples = 1;
  fit =
      FitReflectance(canvas, UpNormals(canvas), {}, RenderFlat(canvas, m, {Directional(50, 0)}), o);
  ASSERT_FALSE(fit.ok());
  EXPECT_NE(fit.error().message.find("at least 2"), std::string::npos) << fit.error().message;
  const PhotoSet seven = RenderFlat(canvas, m, Dome(7));
  ASSERT_FALSE(FitReflectance(canvas, UpNormals(canvas), {}, seven, {}).ok());
  o.fit.min_samples = 7;
  EXPECT_TRUE(FitReflectance(canvas, UpNormals(canvas), {}, seven, o).ok());

  // Eight photos, but texel (2, 2) is flagged in seven of them: its one sample explains rho_d.
  PhotoSet set = RenderFlat(canvas, m, Dome(8));
  for (size_t i = 1; i < set.photos.size(); ++i) {
    set.photos[i].flags = Grid<uint8_t>(6, 6, 0);
    set.photos[i].flags(2, 2) = kPixelNonFinite;
    set.photos[i].rgb(2, 2) = Vec3f::Zero();
  }
  fit = FitReflectance(canvas, UpNormals(canvas), {}, set, {});
  ASSERT_TRUE(fit.ok()) << fit.error().message;
  EXPECT_EQ(fit->maps.status(2, 2), TexelFitStatus::kTooFewSamples);
  EXPECT_NEAR(fit->maps.rho_d(2, 2).x(), 0.3f, 1e-4);
  EXPECT_EQ(fit->maps.rho_s(2, 2).maxCoeff(), 0.0f);
}

// Sixteen photos under one light are one measurement: refused like one photo. Lights within
// kSameDirectionDeg of each other count once; 2 degrees apart they count apart.
TEST(ReflectanceFit, IdenticalLightsCountOnce) {
  const HeightField canvas = FlatCanvas(6, 6);
  LafortuneParams m;
  m.rho_d = Vec3f::Constant(0.1f);
  m.rho_s = Vec3f::Constant(0.5f);
  m.k = 20;
  auto fit = FitReflectance(canvas, UpNormals(canvas), {},
                            RenderFlat(canvas, m, std::vector<Light>(16, Directional(60, 30))), {});
  ASSERT_FALSE(fit.ok());
  EXPECT_NE(fit.error().message.find("only 1 distinct"), std::string::npos) << fit.error().message;
  EXPECT_NE(fit.error().message.find("in 16 photos"), std::string::npos) << fit.error().message;
  std::vector<Light> close, apart;
  for (int i = 0; i < 8; ++i) {
    close.push_back(Directional(60 + 0.02 * i, 30 + 0.02 * i));  // < 0.25 deg from the first
    apart.push_back(Directional(60, 30 + 4.0 * i));              // 2 deg apart at 60 deg elevation
  }
  fit = FitReflectance(canvas, UpNormals(canvas), {}, RenderFlat(canvas, m, close), {});
  ASSERT_FALSE(fit.ok());
  EXPECT_NE(fit.error().message.find("only 1 distinct"), std::string::npos) << fit.error().message;
  fit = FitReflectance(canvas, UpNormals(canvas), {}, RenderFlat(canvas, m, apart), {});
  ASSERT_TRUE(fit.ok()) << fit.error().message;
  EXPECT_EQ(fit->report.distinct_directions, 8);
  ASSERT_TRUE(fit->maps.Validate().ok());
  // What was seen is reproduced, whatever else the narrow fan of lights leaves open.
  auto score = EvaluateHeldOut(canvas, UpNormals(canvas), fit->maps, {},
                               RenderFlat(canvas, m, {Directional(60, 42)}));
  ASSERT_TRUE(score.ok());
  EXPECT_GT(score->psnr_db, 40.0);
}

TEST(ReflectanceFit, LightsAtAndBelowTheHorizonAreRejectedNotFitted) {
  const HeightField canvas = FlatCanvas(6, 6);
  LafortuneParams m;
  m.rho_d = Vec3f::Constant(0.2f);
  std::vector<Light> lights = Dome(12);
  lights.push_back(Directional(-10, 0));  // below the canvas
  lights.push_back(Directional(-89, 45));
  lights.push_back(Directional(1, 90));  // grazing: 89 deg from the normal, kept
  PhotoSet set = RenderFlat(canvas, m, lights);
  // Below the canvas the photos show what an actual light there would: nothing.
  for (size_t i = 12; i < 14; ++i)
    for (Vec3f& c : set.photos[i].rgb.data) c = Vec3f::Zero();
  auto fit = FitReflectance(canvas, UpNormals(canvas), {}, set, {});
  ASSERT_TRUE(fit.ok());
  EXPECT_EQ(fit->report.samples.light_below_horizon, 2u * 36u);
  EXPECT_NEAR(fit->maps.rho_d(2, 2).x(), 0.2f, 1e-3);
}

TEST(ReflectanceFit, BlackPaintGivesZeroNotNaN) {
  const HeightField canvas = FlatCanvas(6, 6);
  const PhotoSet set = RenderFlat(canvas, LafortuneParams{}, Dome(16));
  auto fit = FitReflectance(canvas, UpNormals(canvas), {}, set, {});
  ASSERT_TRUE(fit.ok());
  EXPECT_EQ(fit->report.samples.black, 16u * 36u);  // clipped at the floor: no information
  for (size_t i = 0; i < fit->maps.rho_d.size(); ++i) {
    EXPECT_EQ(fit->maps.rho_d.data[i], Vec3f::Zero());  // stated fallback: zeros, relight black
    EXPECT_EQ(fit->maps.status.data[i], TexelFitStatus::kTooFewSamples);
  }
}

TEST(ReflectanceFit, NaNAndSaturatedPixelsAreDroppedAndCounted) {
  const HeightField canvas = FlatCanvas(6, 6);
  LafortuneParams m;
  m.rho_d = Vec3f::Constant(0.2f);
  PhotoSet set = RenderFlat(canvas, m, Dome(16));
  // Photo 0: pixel (2, 2) is NaN (the loader zeroes it and flags it); photo 1: (4, 4) saturated.
  set.photos[0].flags = Grid<uint8_t>(6, 6, 0);
  set.photos[0].flags(2, 2) = kPixelNonFinite;
  set.photos[0].rgb(2, 2) = Vec3f::Zero();
  set.photos[1].flags = Grid<uint8_t>(6, 6, 0);
  set.photos[1].flags(4, 4) = kPixelSaturated;
  set.photos[1].rgb(4, 4) = Vec3f::Constant(1.0f);
  auto fit = FitReflectance(canvas, UpNormals(canvas), {}, set, {});
  ASSERT_TRUE(fit.ok());
  // The sample point of texel (x, y) is pixel (x, y) exactly: one texel per flagged pixel.
  EXPECT_EQ(fit->report.samples.non_finite, 1u);
  EXPECT_EQ(fit->report.samples.saturated, 1u);
  EXPECT_NEAR(fit->maps.rho_d(2, 2).x(), 0.2f, 1e-3);
  EXPECT_NEAR(fit->maps.rho_d(4, 4).x(), 0.2f, 1e-3);
}

// A canvas with a tall wall along its left edge: lights from the left (azimuth 180, elevation e)
// shadow every texel within H / tan(e) of the wall.
HeightField WalledCanvas(int w, int h, float wall_mm) {
  HeightField f = FlatCanvas(w, h);
  for (int y = 0; y < h; ++y) f.height_mm(0, y) = f.height_mm(1, y) = wall_mm;
  return f;
}

TEST(ReflectanceFit, EverySampleShadowedGivesTheStatedFallbackEverywhere) {
  const int w = 16, h = 8;
  const HeightField canvas = WalledCanvas(w, h, 1000.0f);  // casts a shadow over everything
  LafortuneParams m;
  m.rho_d = Vec3f::Constant(0.2f);
  std::vector<Light> lights;
  for (int i = 0; i < 12; ++i) lights.push_back(Directional(10 + 5 * i, 180));  // along -X
  PhotoSet set = RenderFlat(canvas, m, lights);
  for (Photo& p : set.photos)
    for (int y = 0; y < h; ++y)
      for (int x = 2; x < w; ++x) p.rgb(x, y) = Vec3f::Constant(0.01f);  // shadow + stray light
  Grid<Vec3f> normals = UpNormals(canvas);
  auto fit = FitReflectance(canvas, normals, {}, set, {});
  ASSERT_TRUE(fit.ok());
  ASSERT_TRUE(fit->maps.Validate().ok());
  EXPECT_GT(fit->report.samples.shadowed, 0u);
  for (int y = 0; y < h; ++y)
    for (int x = 3; x < w; ++x) {
      EXPECT_EQ(fit->maps.status(x, y), TexelFitStatus::kTooFewSamples) << x << "," << y;
      EXPECT_EQ(fit->maps.rho_d(x, y), Vec3f::Zero());
    }
}

TEST(ReflectanceFit, ShadowRaysRejectExactlyTheAnalyticShadow) {
  const int w = 40, h = 4;
  const float wall = 5.0f;  // mm; light at 45 deg from the left: shadow 5 mm = 10 texels
  const HeightField canvas = WalledCanvas(w, h, wall);
  LafortuneParams m;
  m.rho_d = Vec3f::Constant(0.2f);
  PhotoSet set = RenderFlat(canvas, m, {Directional(45, 180)});
  Grid<Vec3f> normals = UpNormals(canvas);
  auto tracer = HeightFieldTracer::Build(canvas);
  ASSERT_TRUE(tracer.ok());
  const SampleScene scene{&canvas, &normals, RigidTransform{}, &set, &*tracer};
  for (bool skip : {true, false}) {
    SampleOptions o;
    o.trace.skip_unblockable = skip;
    o.visibility_rays = false;
    std::vector<uint32_t> row;
    for (int x = 2; x < w; ++x) row.push_back(static_cast<uint32_t>(x + w));  // row 1
    BrdfSamples samples;
    SampleStats stats;
    GatherSamples(scene, row, o, samples, stats);
    // The wall's top edge is the centre of texel 1, X = 0.75 mm; 5 mm of shadow: texel centres
    // at X = (x + 0.5) 0.5 mm < 5.75 mm, i.e. x <= 10, are shadowed. Texel 2 is the foot of the
    // wall's 84-degree slope, which its own ray meets within the self-intersection offset: with
    // the flat normals given here it is ambiguous, so it is left out (real normals there face
    // away from the light).
    for (int x = 3; x < w; ++x)
      EXPECT_EQ(samples.Texel(static_cast<size_t>(x - 2)).size(), x <= 10 ? 0u : 1u)
          << "x " << x << " skip " << skip;
    EXPECT_GE(stats.shadowed, 8u);
    EXPECT_LE(stats.shadowed, 9u);
    if (skip) {
      EXPECT_GT(stats.light_rays.skipped, 0u);
    } else {
      EXPECT_EQ(stats.light_rays.skipped, 0u);
    }
  }
}

// Relief (ridges, a 3 mm block with steep walls), a frame box on the left, two tilted cameras
// with four photos each (point lights low enough to cast shadows, one directional), pixels of
// random colour: what the camera alone decides is computed once per camera position
// (SampleOptions::share_view_rays) and the horizon bounds skip most rays, yet every sample,
// every map and every rejection count equals the per-photo path's, with and without pixel maps.
TEST(ReflectanceSamples, SharedViewsAndHorizonsGiveExactlyThePerPhotoSamples) {
  const int w = 48, h = 40;
  HeightField canvas = FlatCanvas(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      canvas.height_mm(x, y) = static_cast<float>(0.4 * std::sin(0.7 * x) * std::cos(0.45 * y) +
                                                  (x >= 20 && x < 26 && y >= 14 && y < 22 ? 3 : 0));
  canvas.frame.raise_mm = {4.0f, 0.0f, 0.0f, 0.0f};
  canvas.frame.width_mm = {3.0f, 0.0f, 0.0f, 0.0f};
  // Normals by central differences (canvas frame; texel y grows as Y falls).
  Grid<Vec3f> normals(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const auto z = [&](int i, int j) {
        return canvas.height_mm(std::clamp(i, 0, w - 1), std::clamp(j, 0, h - 1));
      };
      const float dzdx = (z(x + 1, y) - z(x - 1, y)) / (2 * kPitch);
      const float dzdy = -(z(x, y + 1) - z(x, y - 1)) / (2 * kPitch);
      normals(x, y) = Vec3f(-dzdx, -dzdy, 1).normalized();
    }
  PhotoSet set;
  set.source = "relief.json";
  uint32_t seed = 12345;
  const auto random = [&seed] {
    seed = seed * 1664525u + 1013904223u;
    return static_cast<float>(seed >> 8) / static_cast<float>(1u << 24);
  };
  for (int c = 0; c < 2; ++c) {
    const double a = (c ? -35.0 : 30.0) * M_PI / 180.0;
    Camera cam;
    cam.model = CameraModel::kOrthographic;
    cam.width = 52;
    cam.height = 44;
    cam.pixel_pitch_mm = 0.9 * kPitch;
    cam.cx = (cam.width - 1) / 2.0;
    cam.cy = (cam.height - 1) / 2.0;
    cam.camera_from_scan.rotation << std::cos(a), 0, std::sin(a), 0, -1, 0, std::sin(a), 0,
        -std::cos(a);
    const Vec3d centre(w * kPitch / 2, h * kPitch / 2, 0);
    cam.camera_from_scan.translation =
        -(cam.camera_from_scan.rotation * centre) + Vec3d(0, 0, 1000);
    for (int i = 0; i < 4; ++i) {
      Photo p;
      p.entry = "relief.json: images[" + std::to_string(4 * c + i) + "]";
      p.camera = cam;
      if (i == 3) {
        p.light = Directional(25, 200);
      } else {
        const double e = (12.0 + 10.0 * i) * M_PI / 180, az = (90.0 * i + 40.0 * c) * M_PI / 180;
        p.light.type = LightType::kPoint;
        p.light.position_mm = centre + 60.0 * Vec3d(std::cos(e) * std::cos(az),
                                                    std::cos(e) * std::sin(az), std::sin(e));
        p.light.intensity = Vec3f::Constant(3600.0f);
      }
      p.encoding = ColourEncoding::kLinear;
      p.rgb = Grid<Vec3f>(cam.width, cam.height);
      for (Vec3f& v : p.rgb.data) v = Vec3f(random(), random(), random());
      set.photos.push_back(std::move(p));
    }
  }
  auto tracer = HeightFieldTracer::Build(canvas);
  ASSERT_TRUE(tracer.ok()) << tracer.error().message;
  const PixelTexelMaps maps = MapPixelsToTexels(set, canvas, RigidTransform{}, *tracer);
  // Every texel (rows of 8 side by side: the bounds' vector path), and every texel but each
  // fifth (runs of 4: the bounds' one-texel path).
  for (const int skip : {0, 5})
    for (bool with_maps : {false, true}) {
      std::vector<uint32_t> texels;
      for (uint32_t t = 0; t < static_cast<uint32_t>(w * h); ++t)
        if (skip == 0 || t % skip != 0) texels.push_back(t);
      const SampleScene scene{&canvas, &normals, RigidTransform{},
                              &set,    &*tracer, with_maps ? &maps : nullptr};
      ASSERT_TRUE(ValidateSampleScene(scene).ok());
      const auto gather = [&](bool share, int sectors, SampleStats& stats) {
        SampleOptions o;
        o.share_view_rays = share;
        o.horizon_sectors = sectors;
        BrdfSamples samples;
        GatherSamples(scene, texels, o, samples, stats);
        return samples;
      };
      SampleStats before;
      const BrdfSamples reference = gather(false, 0, before);
      // The scene must exercise what is compared: shadows, hidden texels (from the relief and the
      // frame) and several rejections.
      EXPECT_GT(before.shadowed, 100u);
      if (!with_maps) {
        EXPECT_GT(before.hidden, 10u);
      }
      EXPECT_GT(before.facing_away + before.light_below_horizon, 0u);
      size_t traced_without_horizon = 0;
      for (int sectors : {0, 4, 16, 32}) {
        SampleStats stats;
        const BrdfSamples samples = gather(true, sectors, stats);
        ASSERT_EQ(samples.texel_begin, reference.texel_begin) << sectors << " " << with_maps;
        for (size_t k = 0; k < samples.samples.size(); ++k) {
          const BrdfSample& a = samples.samples[k];
          const BrdfSample& b = reference.samples[k];
          ASSERT_TRUE(a.view_dir == b.view_dir && a.light_dir == b.light_dir &&
                      a.radiance == b.radiance && a.irradiance == b.irradiance)
              << "sample " << k << ", " << sectors << " sectors, maps " << with_maps;
        }
        for (const auto& [n, m] :
             {std::pair{stats.behind_camera, before.behind_camera},
              std::pair{stats.outside_image, before.outside_image},
              std::pair{stats.facing_away, before.facing_away},
              std::pair{stats.light_below_horizon, before.light_below_horizon},
              std::pair{stats.black, before.black}, std::pair{stats.hidden, before.hidden},
              std::pair{stats.shadowed, before.shadowed},
              std::pair{stats.stepped_over, before.stepped_over},
              std::pair{stats.kept, before.kept}})
          EXPECT_EQ(n, m) << sectors << " sectors, maps " << with_maps;
        EXPECT_EQ(stats.light_rays.rays, before.light_rays.rays);
        if (sectors == 0) {
          traced_without_horizon = stats.light_rays.traced;
        } else {
          // The horizon proves rays free without the tracer (few here: most texels are within
          // reach of the block or the frame, under lights 12-32 degrees high).
          EXPECT_LT(stats.light_rays.traced, traced_without_horizon) << sectors;
        }
      }
    }
}

TEST(ReflectanceFit, InputErrorsNameTheEntry) {
  const HeightField canvas = FlatCanvas(6, 6);
  LafortuneParams m;
  m.rho_d = Vec3f::Constant(0.2f);
  PhotoSet set = RenderFlat(canvas, m, Dome(4));
  {  // a camera under the canvas, looking up at its back
    PhotoSet bad = set;
    Camera& c = bad.photos[2].camera;
    c.camera_from_scan.rotation << 1, 0, 0, 0, 1, 0, 0, 0, 1;
    c.camera_from_scan.translation = {-1.5, -1.5, 1000};
    auto fit = FitReflectance(canvas, UpNormals(canvas), {}, bad, {});
    ASSERT_FALSE(fit.ok());
    EXPECT_NE(fit.error().message.find("images[2]"), std::string::npos) << fit.error().message;
  }
  {  // pixels of another size than the camera
    PhotoSet bad = set;
    bad.photos[1].rgb = Grid<Vec3f>(5, 6);
    auto fit = FitReflectance(canvas, UpNormals(canvas), {}, bad, {});
    ASSERT_FALSE(fit.ok());
    EXPECT_NE(fit.error().message.find("images[1]"), std::string::npos) << fit.error().message;
  }
  {  // normals of another size
    auto fit = FitReflectance(canvas, Grid<Vec3f>(5, 5, Vec3f::UnitZ()), {}, set, {});
    ASSERT_FALSE(fit.ok());
  }
  {  // bad options
    ReflectanceFitOptions o;
    o.tile_texels = 0;
    EXPECT_FALSE(FitReflectance(canvas, UpNormals(canvas), {}, set, o).ok());
  }
}

TEST(ReflectanceFit, MapsRoundTripThroughTheOutputFolder) {
  const HeightField canvas = FlatCanvas(7, 5);
  LafortuneParams m;
  m.rho_d = {0.2f, 0.1f, 0.3f};
  m.rho_s = Vec3f::Constant(0.4f);
  m.k = 30;
  const PhotoSet set = RenderFlat(canvas, m, Dome(24, 15, 88));
  ReflectanceFitOptions o;
  auto fit = FitReflectance(canvas, UpNormals(canvas), {}, set, o);
  ASSERT_TRUE(fit.ok());
  const auto dir = test::FreshScratchDir("digitize_reflectance_roundtrip", "", /*create=*/false);
  ASSERT_TRUE(WriteReflectanceOutputs(dir, *fit, o, {"analytic"}).ok());
  auto back = ReadReflectanceMaps(dir);
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(back->rho_d.data, fit->maps.rho_d.data);  // float EXR: bit-exact
  EXPECT_EQ(back->lobe.data, fit->maps.lobe.data);
  EXPECT_EQ(back->status.data, fit->maps.status.data);
  // Windows (the tiled merge's reads): each the same texels as the whole, every map.
  ImageRegionReader reader(64);
  for (const std::array<int, 4> r : {std::array{0, 0, 7, 5}, {2, 1, 4, 3}, {6, 4, 1, 1}}) {
    auto part = ReadReflectanceMapsWindow(dir, r[0], r[1], r[2], r[3], reader);
    ASSERT_TRUE(part.ok()) << part.error().message;
    ASSERT_EQ(part->width(), r[2]);
    ASSERT_EQ(part->height(), r[3]);
    for (int y = 0; y < r[3]; ++y)
      for (int x = 0; x < r[2]; ++x) {
        const int wx = r[0] + x, wy = r[1] + y;
        EXPECT_EQ(part->rho_d(x, y), back->rho_d(wx, wy));
        EXPECT_EQ(part->rho_s(x, y), back->rho_s(wx, wy));
        EXPECT_EQ(part->lobe(x, y), back->lobe(wx, wy));
        EXPECT_EQ(part->fit_error(x, y), back->fit_error(wx, wy));
        EXPECT_EQ(part->status(x, y), back->status(wx, wy));
        EXPECT_EQ(part->model(x, y), back->model(wx, wy));
      }
  }
  auto outside = ReadReflectanceMapsWindow(dir, 4, 2, 4, 3, reader);  // one column past the edge
  ASSERT_FALSE(outside.ok());
  EXPECT_NE(outside.error().message.find("rho_d.exr"), std::string::npos)
      << outside.error().message;
  std::filesystem::remove(dir / "lobe.exr");
  auto missing = ReadReflectanceMaps(dir);
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().message.find("lobe.exr"), std::string::npos);
  std::filesystem::remove_all(dir);
}

// Lights at or below the canvas plane: a warning naming how many photos, in the report and its
// JSON; not an error while enough photos are left, and counted out of the minimum otherwise.
TEST(ReflectanceFit, LightsBelowTheCanvasAreAWarningWithTheirCount) {
  const HeightField canvas = FlatCanvas(6, 6);
  LafortuneParams m;
  m.rho_d = Vec3f::Constant(0.2f);
  PhotoSet set = RenderFlat(canvas, m, Dome(10));
  // A point light in the canvas plane, a point light under it, a directional light from below.
  set.photos[0].light.type = LightType::kPoint;
  set.photos[0].light.position_mm = {1.5, 1.5, 0.0};
  set.photos[0].light.intensity = Vec3f::Constant(1e4f);
  set.photos[4].light.type = LightType::kPoint;
  set.photos[4].light.position_mm = {100, 0, -20};
  set.photos[4].light.intensity = Vec3f::Constant(1e4f);
  set.photos[7].light = Directional(-30, 45);
  for (size_t i : {0, 4, 7})
    for (Vec3f& c : set.photos[i].rgb.data) c = Vec3f::Zero();
  set.photos[9].light.type = LightType::kPoint;  // above: not counted
  set.photos[9].light.position_mm = {1.5, 1.5, 400};
  set.photos[9].light.intensity = Vec3f::Constant(1.6e5f);
  auto fit = FitReflectance(canvas, UpNormals(canvas), {}, set, {});
  ASSERT_FALSE(fit.ok()) << "7 photos lit from above: fewer than min_samples 8";
  EXPECT_NE(fit.error().message.find("3 lit from at or below"), std::string::npos)
      << fit.error().message;
  ReflectanceFitOptions o;
  o.fit.min_samples = 6;
  fit = FitReflectance(canvas, UpNormals(canvas), {}, set, o);
  ASSERT_TRUE(fit.ok()) << fit.error().message;
  const ReflectanceFitReport& r = fit->report;
  EXPECT_EQ(r.photos, 10u);
  EXPECT_EQ(r.distinct_directions, 7);
  ASSERT_EQ(r.light_below_canvas.size(), 3u);
  EXPECT_EQ(r.light_below_canvas[0], "analytic.json: images[0]");
  EXPECT_EQ(r.light_below_canvas[2], "analytic.json: images[7]");
  ASSERT_EQ(r.Warnings().size(), 1u);
  EXPECT_NE(r.Warnings()[0].find("3 of 10 photos"), std::string::npos) << r.Warnings()[0];
  EXPECT_NE(r.Warnings()[0].find("images[4]"), std::string::npos) << r.Warnings()[0];
  const auto doc = nlohmann::json::parse(ReflectanceReportJson(*fit, o, {"analytic.json"}));
  EXPECT_EQ(doc["photos"]["light_below_canvas"], 3);
  EXPECT_EQ(doc["photos"]["distinct_directions"], 7);
  EXPECT_EQ(doc["warnings"].size(), 1u);
  // Nothing amiss: no warning.
  auto clean = FitReflectance(canvas, UpNormals(canvas), {}, RenderFlat(canvas, m, Dome(10)), {});
  ASSERT_TRUE(clean.ok());
  EXPECT_TRUE(clean->report.Warnings().empty());
}

}  // namespace
}  // namespace digitize
