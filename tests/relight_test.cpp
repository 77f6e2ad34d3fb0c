// RenderRelit and CompareImages against analytic renders: a flat Lambertian canvas under a
// directional and a point light (orthographic and pinhole cameras), a mirror lobe, a tilted plane,
// the shadow strip of a ridge, misses and kOutside texels; image comparison with known answers.
#include "digitize/relight.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

#include "digitize/normals.h"
#include "test_support.h"

namespace digitize {
namespace {

// Radiance is a product of float factors (BRDF, cosine, irradiance): a few float ulps relative.
constexpr double kRelTol = 1e-5;

ReflectanceMaps Uniform(int w, int h, const LafortuneParams& p) {
  ReflectanceMaps m = ReflectanceMaps::Zeros(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) m.Set(x, y, p);
  return m;
}

LafortuneParams Lambertian(const Vec3f& rho_d) {
  LafortuneParams p;
  p.rho_d = rho_d;
  p.rho_s = Vec3f::Zero();
  return p;
}

// Orthographic camera looking straight down (-Z of the scan frame = canvas frame here) from
// 1000 mm, one pixel per texel: pixel (u, v) looks at the centre of texel (u - margin, v - margin).
Camera OrthoAbove(const HeightField& f, int margin_px = 0) {
  Camera c;
  c.model = CameraModel::kOrthographic;
  c.width = f.width() + 2 * margin_px;
  c.height = f.height() + 2 * margin_px;
  c.pixel_pitch_mm = f.pitch_mm;
  c.cx = (c.width - 1) / 2.0;
  c.cy = (c.height - 1) / 2.0;
  // Camera x = X, y = -Y (rows go down the canvas), z = -Z.
  c.camera_from_scan.rotation = Eigen::Vector3d(1, -1, -1).asDiagonal();
  const Vec3d centre(f.width() * f.pitch_mm / 2, f.height() * f.pitch_mm / 2, 1000.0);
  c.camera_from_scan.translation = -(c.camera_from_scan.rotation * centre);
  return c;
}

Light Directional(double azimuth_rad, double elevation_rad, const Vec3f& irradiance) {
  Light l;
  l.type = LightType::kDirectional;
  l.direction = Vec3d(std::cos(elevation_rad) * std::cos(azimuth_rad),
                      std::cos(elevation_rad) * std::sin(azimuth_rad), std::sin(elevation_rad));
  l.irradiance = irradiance;
  return l;
}

Grid<Vec3f> Up(int w, int h) { return Grid<Vec3f>(w, h, Vec3f(0, 0, 1)); }

void ExpectNearRel(const Vec3f& got, const Vec3d& want, const std::string& where) {
  for (int c = 0; c < 3; ++c)
    EXPECT_NEAR(got[c], want[c], kRelTol * std::abs(want[c]) + 1e-12) << where << " channel " << c;
}

double Deg(double d) { return d * std::numbers::pi / 180.0; }

HeightFieldTracer Tracer(const HeightField& f) { return HeightFieldTracer::Build(f).value(); }

// ---------------------------------------------------------------------------------------------

TEST(RenderRelit, FlatLambertianUnderADirectionalLight) {
  const HeightField canvas = test::MakeFlatField(40, 30, 0.5, 0.25f);
  const HeightFieldTracer tracer = Tracer(canvas);
  const Vec3f rho(0.2f / std::numbers::pi_v<float>, 0.5f / std::numbers::pi_v<float>, 0.05f);
  const Vec3f E(2.0f, 1.5f, 0.7f);
  const double e = Deg(35);
  const RelitImage img =
      RenderRelit(tracer, canvas, Up(40, 30), Uniform(40, 30, Lambertian(rho)), RigidTransform{},
                  OrthoAbove(canvas), Directional(Deg(120), e, E));
  const Vec3d want = rho.cast<double>().cwiseProduct(E.cast<double>()) * std::sin(e);
  ASSERT_EQ(img.rgb.width, 40);
  ASSERT_EQ(img.rgb.height, 30);
  for (int v = 0; v < 30; ++v)
    for (int u = 0; u < 40; ++u) {
      ASSERT_EQ(img.mask(u, v), 1) << u << ", " << v;
      ExpectNearRel(img.rgb(u, v), want, std::to_string(u) + ", " + std::to_string(v));
    }
  EXPECT_EQ(img.shadowed_pixels, 0u);
}

TEST(RenderRelit, MirrorLobeSeenFromAbove) {
  // v = +Z (local), l at elevation e: mirror lobe base = vz lz = sin(e), so
  // f = rho_d + rho_s sin(e)^k.
  const HeightField canvas = test::MakeFlatField(12, 10, 1.0);
  const HeightFieldTracer tracer = Tracer(canvas);
  LafortuneParams p;
  p.rho_d = Vec3f(0.1f, 0.2f, 0.3f);
  p.rho_s = Vec3f(2.0f, 1.0f, 0.5f);
  p.k = 7.0f;
  const double e = Deg(62);
  const RelitImage img =
      RenderRelit(tracer, canvas, Up(12, 10), Uniform(12, 10, p), RigidTransform{},
                  OrthoAbove(canvas), Directional(Deg(10), e, Vec3f::Ones()));
  const double s = std::sin(e);
  const Vec3d want = (p.rho_d.cast<double>() + p.rho_s.cast<double>() * std::pow(s, 7.0)) * s;
  for (int v = 0; v < 10; ++v)
    for (int u = 0; u < 12; ++u) ExpectNearRel(img.rgb(u, v), want, "pixel");
}

TEST(RenderRelit, PointLightFallsOffAsInverseSquareAndCosine) {
  // E = I / d^2 and cos = Z_light / d at a texel centre on the plane Z = 0:
  // radiance = rho_d I Z / d^3.
  const HeightField canvas = test::MakeFlatField(50, 40, 0.4);
  const HeightFieldTracer tracer = Tracer(canvas);
  const Vec3f rho(0.3f, 0.2f, 0.1f);
  Light light;
  light.type = LightType::kPoint;
  light.position_mm = Vec3d(5.0, 11.0, 9.0);
  light.intensity = Vec3f(400.0f, 300.0f, 200.0f);
  const RelitImage img = RenderRelit(tracer, canvas, Up(50, 40), Uniform(50, 40, Lambertian(rho)),
                                     RigidTransform{}, OrthoAbove(canvas), light);
  for (auto [u, v] : {std::pair{0, 0}, {49, 39}, {12, 7}, {30, 20}, {49, 0}, {3, 33}}) {
    const Eigen::Vector2d c = canvas.TexelCentreMm(u, v);
    const Vec3d to_light = light.position_mm - Vec3d(c.x(), c.y(), 0.0);
    const double d = to_light.norm();
    const Vec3d want = rho.cast<double>().cwiseProduct(light.intensity.cast<double>()) *
                       (to_light.z() / (d * d * d));
    ASSERT_EQ(img.mask(u, v), 1);
    ExpectNearRel(img.rgb(u, v), want, "pixel " + std::to_string(u) + ", " + std::to_string(v));
  }
}

TEST(RenderRelit, PinholeCameraSeesWhereItsRaysLand) {
  // A pinhole 200 mm above the canvas centre looking down, with a point light: pixel (u, v) sees
  // the plane point X = Xc + (u - cx) Zc / fx, Y = Yc - (v - cy) Zc / fy.
  const HeightField canvas = test::MakeFlatField(100, 80, 0.25);
  const HeightFieldTracer tracer = Tracer(canvas);
  Camera cam;
  cam.model = CameraModel::kPinhole;
  cam.width = 64;
  cam.height = 48;
  cam.fx = 1000;
  cam.fy = 1100;
  cam.cx = 31.5;
  cam.cy = 23.5;
  cam.camera_from_scan.rotation = Eigen::Vector3d(1, -1, -1).asDiagonal();
  const Vec3d centre(12.5, 10.0, 200.0);
  cam.camera_from_scan.translation = -(cam.camera_from_scan.rotation * centre);
  Light light;
  light.type = LightType::kPoint;
  light.position_mm = Vec3d(20.0, 4.0, 15.0);
  light.intensity = Vec3f(1000.0f, 1000.0f, 1000.0f);
  const Vec3f rho(0.25f, 0.25f, 0.25f);
  const RelitImage img = RenderRelit(tracer, canvas, Up(100, 80), Uniform(100, 80, Lambertian(rho)),
                                     RigidTransform{}, cam, light);
  for (int v = 0; v < cam.height; v += 7)
    for (int u = 0; u < cam.width; u += 9) {
      const Vec3d p(centre.x() + (u - cam.cx) * centre.z() / cam.fx,
                    centre.y() - (v - cam.cy) * centre.z() / cam.fy, 0.0);
      const Vec3d to_light = light.position_mm - p;
      const double d = to_light.norm();
      const double want = 0.25 * 1000.0 * to_light.z() / (d * d * d);
      ASSERT_EQ(img.mask(u, v), 1);
      // The hit point carries float rounding of ~1e-5 mm; the radiance changes by
      // 3 dE/E ~ 3e-5 / 15 relative there: still within kRelTol.
      EXPECT_NEAR(img.rgb(u, v).x(), want, kRelTol * want) << u << ", " << v;
    }
}

TEST(RenderRelit, TiltedPlaneFollowsItsNormal) {
  // Plane Z = a X + b Y: normals from ComputeNormals are the plane's; Lambertian radiance is
  // rho E n.l at every texel, seen from above (the camera ray meets the plane at the texel centre).
  constexpr double a = 0.3, b = -0.15;
  HeightField canvas = test::MakeFlatField(30, 20, 0.5);
  for (int y = 0; y < 20; ++y)
    for (int x = 0; x < 30; ++x) {
      const Eigen::Vector2d c = canvas.TexelCentreMm(x, y);
      canvas.height_mm(x, y) = static_cast<float>(a * c.x() + b * c.y() + 2.0);
    }
  const HeightFieldTracer tracer = Tracer(canvas);
  const Grid<Vec3f> normals = ComputeNormals(canvas);
  const Light light = Directional(Deg(200), Deg(40), Vec3f(1.0f, 2.0f, 3.0f));
  const Vec3f rho(0.3f, 0.3f, 0.3f);
  const RelitImage img = RenderRelit(tracer, canvas, normals, Uniform(30, 20, Lambertian(rho)),
                                     RigidTransform{}, OrthoAbove(canvas), light);
  const Vec3d n = Vec3d(-a, -b, 1).normalized();
  const double cos_l = n.dot(light.direction);
  ASSERT_GT(cos_l, 0.1);
  const Vec3d want = rho.cast<double>().cwiseProduct(light.irradiance.cast<double>()) * cos_l;
  // Normals are float (~1e-7) and the hit lies on a texel centre to float rounding: kRelTol holds.
  for (int v = 0; v < 20; ++v)
    for (int u = 0; u < 30; ++u) {
      ASSERT_EQ(img.mask(u, v), 1);
      ExpectNearRel(img.rgb(u, v), want, std::to_string(u) + ", " + std::to_string(v));
    }
  EXPECT_EQ(img.shadowed_pixels, 0u) << "a plane does not shadow itself";
}

TEST(RenderRelit, RidgeShadowMatchesTheAnalyticStrip) {
  // A ridge of height H over texel columns 20..24 (all rows); light towards -X at elevation e
  // with H / tan(e) = 10.5 texels: the plane texels 25..34 behind the ridge are in shadow (their
  // distance to the crest, 1..10 texels, is below 10.5), 35.. are lit. Normals are +Z everywhere
  // (so every pixel faces the light) to isolate visibility.
  constexpr int kW = 80, kH = 16;
  constexpr double kPitch = 0.1;
  constexpr float kRidge = 1.0f;
  HeightField canvas = test::MakeFlatField(kW, kH, kPitch);
  for (int y = 0; y < kH; ++y)
    for (int x = 20; x <= 24; ++x) canvas.height_mm(x, y) = kRidge;
  const HeightFieldTracer tracer = Tracer(canvas);
  const double e = std::atan(kRidge / (10.5 * kPitch));
  const Light light = Directional(std::numbers::pi, e, Vec3f(1.0f, 1.0f, 1.0f));
  const ReflectanceMaps maps = Uniform(kW, kH, Lambertian(Vec3f(0.2f, 0.2f, 0.2f)));
  RelightOptions with, without;
  without.shadows = false;
  const RelitImage on = RenderRelit(tracer, canvas, Up(kW, kH), maps, RigidTransform{},
                                    OrthoAbove(canvas), light, with);
  const RelitImage off = RenderRelit(tracer, canvas, Up(kW, kH), maps, RigidTransform{},
                                     OrthoAbove(canvas), light, without);
  EXPECT_EQ(on.shadowed_pixels, static_cast<size_t>(10 * kH));
  EXPECT_EQ(off.shadowed_pixels, 0u);
  const float lit = static_cast<float>(0.2 * std::sin(e));
  size_t differ = 0;
  for (int v = 0; v < kH; ++v)
    for (int u = 0; u < kW; ++u) {
      const bool in_strip = u >= 25 && u <= 34;
      EXPECT_NEAR(off.rgb(u, v).x(), lit, kRelTol * lit) << u << ", " << v;
      if (on.rgb(u, v) != off.rgb(u, v)) {
        ++differ;
        EXPECT_TRUE(in_strip) << "differs outside the strip at " << u << ", " << v;
        EXPECT_EQ(on.rgb(u, v), Vec3f::Zero());
      } else {
        EXPECT_FALSE(in_strip) << "lit inside the strip at " << u << ", " << v;
      }
    }
  EXPECT_EQ(differ, static_cast<size_t>(10 * kH));
}

TEST(RenderRelit, MissesAndOutsideTexelsAreMaskedBlack) {
  HeightField canvas = test::MakeFlatField(20, 16, 0.5);
  canvas.state(3, 4) = TexelState::kOutside;
  const HeightFieldTracer tracer = Tracer(canvas);
  constexpr int kMargin = 5;  // pixels beyond the canvas on every side
  const RelitImage img = RenderRelit(
      tracer, canvas, Up(20, 16), Uniform(20, 16, Lambertian(Vec3f(0.3f, 0.3f, 0.3f))),
      RigidTransform{}, OrthoAbove(canvas, kMargin), Directional(0, Deg(60), Vec3f::Ones()));
  size_t seen = 0;
  for (int v = 0; v < img.mask.height; ++v)
    for (int u = 0; u < img.mask.width; ++u) {
      const int x = u - kMargin, y = v - kMargin;
      const bool on_canvas = x >= 0 && y >= 0 && x < 20 && y < 16 && !(x == 3 && y == 4);
      EXPECT_EQ(img.mask(u, v), on_canvas ? 1 : 0) << u << ", " << v;
      if (!on_canvas) {
        EXPECT_EQ(img.rgb(u, v), Vec3f::Zero()) << u << ", " << v;
      }
      seen += img.mask(u, v);
    }
  EXPECT_EQ(seen, 20u * 16u - 1u);
}

TEST(RenderRelit, ZeroMapsAndBacklightRenderBlackNotNaN) {
  const HeightField canvas = test::MakeFlatField(8, 8, 1.0);
  const HeightFieldTracer tracer = Tracer(canvas);
  // Light below the canvas plane: n.l < 0 everywhere.
  const RelitImage below =
      RenderRelit(tracer, canvas, Up(8, 8), Uniform(8, 8, Lambertian(Vec3f::Ones())),
                  RigidTransform{}, OrthoAbove(canvas), Directional(0, Deg(-20), Vec3f::Ones()));
  const RelitImage zeros =
      RenderRelit(tracer, canvas, Up(8, 8), ReflectanceMaps::Zeros(8, 8), RigidTransform{},
                  OrthoAbove(canvas), Directional(0, Deg(50), Vec3f::Ones()));
  for (const auto* img : {&below, &zeros})
    for (int i = 0; i < 64; ++i) {
      EXPECT_EQ(img->rgb.data[i], Vec3f::Zero());
      EXPECT_EQ(img->mask.data[i], 1);
    }
}

TEST(RenderRelit, CanvasFromScanMovesCameraAndLightTogether) {
  // The same scene expressed in a scan frame rotated and shifted against the canvas frame renders
  // the same image.
  const HeightField canvas = test::MakeFlatField(24, 18, 0.5);
  const HeightFieldTracer tracer = Tracer(canvas);
  const ReflectanceMaps maps = Uniform(24, 18, Lambertian(Vec3f(0.2f, 0.3f, 0.4f)));
  Light light;
  light.type = LightType::kPoint;
  light.position_mm = Vec3d(3.0, 14.0, 12.0);
  light.intensity = Vec3f(500.0f, 500.0f, 500.0f);
  const Camera cam = OrthoAbove(canvas);
  const RelitImage ref =
      RenderRelit(tracer, canvas, Up(24, 18), maps, RigidTransform{}, cam, light);
  RigidTransform canvas_from_scan;
  canvas_from_scan.rotation =
      Eigen::AngleAxisd(0.4, Vec3d(1, 2, 3).normalized()).toRotationMatrix();
  canvas_from_scan.translation = Vec3d(-30.0, 12.0, 250.0);
  const RigidTransform scan_from_canvas = canvas_from_scan.Inverse();
  Camera cam2 = cam;
  cam2.camera_from_scan = cam.camera_from_scan * canvas_from_scan;
  Light light2 = light;
  light2.position_mm = scan_from_canvas.Apply(light.position_mm);
  const RelitImage moved =
      RenderRelit(tracer, canvas, Up(24, 18), maps, canvas_from_scan, cam2, light2);
  EXPECT_EQ(moved.mask.data, ref.mask.data);
  for (size_t i = 0; i < ref.rgb.size(); ++i)
    ExpectNearRel(moved.rgb.data[i], ref.rgb.data[i].cast<double>(), "pixel " + std::to_string(i));
}

TEST(RenderRelit, SizeMismatchIsAnInvariantError) {
  const HeightField canvas = test::MakeFlatField(8, 8, 1.0);
  const HeightFieldTracer tracer = Tracer(canvas);
  const Camera cam = OrthoAbove(canvas);
  const Light light = Directional(0, 1, Vec3f::Ones());
  EXPECT_THROW(RenderRelit(tracer, canvas, Up(7, 8), ReflectanceMaps::Zeros(8, 8), RigidTransform{},
                           cam, light),
               InvariantError);
  EXPECT_THROW(RenderRelit(tracer, canvas, Up(8, 8), ReflectanceMaps::Zeros(8, 9), RigidTransform{},
                           cam, light),
               InvariantError);
  const HeightField other = test::MakeFlatField(9, 8, 1.0);
  EXPECT_THROW(RenderRelit(tracer, other, Up(9, 8), ReflectanceMaps::Zeros(9, 8), RigidTransform{},
                           cam, light),
               InvariantError);
  RelightOptions bad;
  bad.num_threads = -2;
  EXPECT_FALSE(bad.Validate().ok());
}

// ---------------------------------------------------------------------------------------------

TEST(CompareImages, IdenticalImagesHaveInfinitePsnr) {
  Grid<Vec3f> a(5, 4, Vec3f(0.1f, 0.2f, 0.3f));
  Grid<uint8_t> mask(5, 4, 1);
  const ImageComparison c = CompareImages(a, a, mask, 1.0);
  EXPECT_TRUE(std::isinf(c.psnr_db) && c.psnr_db > 0);
  EXPECT_EQ(c.rmse, 0.0);
  EXPECT_EQ(c.pixels, 20u);
}

TEST(CompareImages, KnownOffsetGivesKnownPsnr) {
  // Every channel off by delta: MSE = delta^2, PSNR = 20 log10(peak / delta).
  constexpr float kDelta = 0.01f;
  Grid<Vec3f> ref(6, 5, Vec3f(0.4f, 0.5f, 0.6f));
  Grid<Vec3f> test = ref;
  for (auto& c : test.data) c += Vec3f::Constant(kDelta);
  Grid<uint8_t> mask(6, 5, 1);
  mask(0, 0) = 0;
  test(0, 0) = Vec3f(9.0f, 9.0f, 9.0f);                      // masked out: must not count
  test(1, 0).x() = std::numeric_limits<float>::quiet_NaN();  // non-finite: skipped
  const ImageComparison c = CompareImages(test, ref, mask, 2.0);
  EXPECT_EQ(c.pixels, 28u);
  // Float differences of values ~0.5 carry ~3e-8 absolute error on delta = 0.01: 3e-6 relative.
  EXPECT_NEAR(c.rmse, kDelta, 1e-7);
  EXPECT_NEAR(c.psnr_db, 20.0 * std::log10(2.0 / kDelta), 1e-4);
}

TEST(CompareImages, EmptyMaskComparesNothing) {
  Grid<Vec3f> a(3, 3, Vec3f(1, 1, 1)), b(3, 3, Vec3f(0, 0, 0));
  const ImageComparison c = CompareImages(a, b, Grid<uint8_t>(3, 3, 0), 1.0);
  EXPECT_EQ(c.pixels, 0u);
  EXPECT_EQ(c.psnr_db, 0.0);
  EXPECT_EQ(c.rmse, 0.0);
  const ImageComparison none = CompareImages({}, {}, {}, 1.0);
  EXPECT_EQ(none.pixels, 0u);
  EXPECT_THROW(CompareImages(a, Grid<Vec3f>(3, 2), Grid<uint8_t>(3, 3, 1), 1.0), InvariantError);
  EXPECT_THROW(CompareImages(a, b, Grid<uint8_t>(3, 3, 1), 0.0), InvariantError);
}

}  // namespace
}  // namespace digitize
