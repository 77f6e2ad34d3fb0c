// An RTI capture's canvas (rti_canvas.h): intensities, normals and height from the photos alone,
// and the intensity a held-out light's direction predicts.
#include "digitize/rti_canvas.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace digitize {
namespace {

constexpr int kW = 64, kH = 48;
constexpr double kPitch = 0.5;  // mm per pixel

// A bump field z = A cos(x) cos(y) (mm): its exact normals.
Vec3f BumpNormal(int x, int y) {
  const double a = 2.0, f = 2 * kPi / (kW * kPitch / 2);  // two periods across
  const double X = (x + 0.5) * kPitch, Y = (kH - y - 0.5) * kPitch;
  const double dzdx = -a * f * std::sin(f * X) * std::cos(f * Y);
  const double dzdy = -a * f * std::cos(f * X) * std::sin(f * Y);
  return Vec3d(-dzdx, -dzdy, 1.0).normalized().cast<float>();
}

Vec3d DomeDirection(int i, int n) {
  const double elevation = (20.0 + 55.0 * (i % 4) / 3.0) * kPi / 180.0;
  const double azimuth = 2 * kPi * i / n + 0.3 * (i % 4);
  return {std::cos(elevation) * std::cos(azimuth), std::cos(elevation) * std::sin(azimuth),
          std::sin(elevation)};
}

// Lambertian photos of the bump under `n` directional lights of the given intensities, declared
// with irradiance 1 (as an .lp declares them).
PhotoSet LambertianCapture(const std::vector<double>& intensity) {
  PhotoSet set;
  set.is_rti = true;
  set.rti_pitch_mm = kPitch;
  set.source = "synthetic.lp";
  const int n = static_cast<int>(intensity.size());
  for (int i = 0; i < n; ++i) {
    Photo photo;
    photo.entry = "synthetic.lp:" + std::to_string(i + 2);
    photo.path = "img" + std::to_string(i) + ".png";
    photo.camera.model = CameraModel::kOrthographic;
    photo.camera.width = kW;
    photo.camera.height = kH;
    photo.light.type = LightType::kDirectional;
    photo.light.direction = DomeDirection(i, n);
    photo.rgb = Grid<Vec3f>(kW, kH);
    const Vec3f albedo(0.5f, 0.3f, 0.2f);
    for (int y = 0; y < kH; ++y)
      for (int x = 0; x < kW; ++x) {
        const float shade =
            std::max(0.0f, BumpNormal(x, y).dot(photo.light.direction.cast<float>()));
        photo.rgb(x, y) = albedo * shade * static_cast<float>(intensity[i]);
      }
    set.photos.push_back(std::move(photo));
  }
  return set;
}

TEST(RtiCanvasTest, RecoversIntensitiesNormalsAndRelief) {
  std::vector<double> truth;
  for (int i = 0; i < 24; ++i) truth.push_back(1.0 + 0.3 * std::sin(1.7 * i));
  double mean = 0;
  for (double e : truth) mean += e / truth.size();
  PhotoSet set = LambertianCapture(truth);
  auto canvas = RtiCanvasFor(set);
  ASSERT_TRUE(canvas.ok()) << canvas.error().message;
  ASSERT_EQ(canvas->intensities.size(), truth.size());
  // The estimate's gauge is mean 1; on exact data its error is the photometric stereo's own
  // (photometric_stereo_test: < 1 % on exact Lambertian data).
  for (size_t i = 0; i < truth.size(); ++i) {
    EXPECT_NEAR(canvas->intensities[i], truth[i] / mean, 0.02 * truth[i] / mean) << i;
    EXPECT_NEAR(set.photos[i].light.irradiance.x(), canvas->intensities[i], 1e-5) << i;
  }
  std::vector<double> errors;
  for (int y = 2; y < kH - 2; ++y)
    for (int x = 2; x < kW - 2; ++x)
      errors.push_back(
          AngleDeg(canvas->canvas.normals(x, y).cast<double>(), BumpNormal(x, y).cast<double>()));
  std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
  EXPECT_LT(errors[errors.size() / 2], 1.0);  // the bound for noise-free normals
  // The integrated bump spans ~2 A = 4 mm peak to peak; the relief step finds it.
  float lo = 1e9f, hi = -1e9f;
  for (float z : canvas->canvas.field.height_mm.data) lo = std::min(lo, z), hi = std::max(hi, z);
  EXPECT_GT(hi - lo, 3.0f);
  EXPECT_LT(hi - lo, 5.0f);
  EXPECT_FALSE(canvas->canvas.boxes.empty());
  EXPECT_NE(canvas->Brief().find("normals:"), std::string::npos) << canvas->Brief();
}

TEST(RtiCanvasTest, FlatOptionKeepsTheOldCanvasAndLights) {
  PhotoSet set = LambertianCapture(std::vector<double>(8, 1.5));
  RtiCanvasOptions options;
  options.normals = false;  // height stays on: ignored without normals (--rti-flat alone)
  auto canvas = RtiCanvasFor(set, options);
  ASSERT_TRUE(canvas.ok()) << canvas.error().message;
  for (const Vec3f& n : canvas->canvas.normals.data) EXPECT_EQ(n, Vec3f::UnitZ());
  for (const Photo& p : set.photos) EXPECT_EQ(p.light.irradiance, Vec3f::Ones());
  for (double e : canvas->intensities) EXPECT_EQ(e, 1.0);
  for (float z : canvas->canvas.field.height_mm.data) EXPECT_EQ(z, 0.0f);
  EXPECT_TRUE(canvas->canvas.boxes.empty());
}

TEST(RtiCanvasTest, RefusesBadInput) {
  PhotoSet set = LambertianCapture(std::vector<double>(8, 1.0));
  set.photos[3].rgb = Grid<Vec3f>();
  auto unloaded = RtiCanvasFor(set);
  ASSERT_FALSE(unloaded.ok());
  EXPECT_NE(unloaded.error().message.find("synthetic.lp:5"), std::string::npos);
  EXPECT_NE(unloaded.error().message.find("not loaded"), std::string::npos);
  PhotoSet not_rti = LambertianCapture(std::vector<double>(8, 1.0));
  not_rti.is_rti = false;
  EXPECT_FALSE(RtiCanvasFor(not_rti).ok());
  RtiCanvasOptions bad;
  bad.intensity_kernel_deg = 0;
  EXPECT_FALSE(RtiCanvasFor(set, bad).ok());
}

TEST(RtiCanvasTest, PredictedIntensityFollowsTheNearestLights) {
  PhotoSet fitted = LambertianCapture(std::vector<double>(2, 1.0));
  fitted.photos[0].light.direction = Vec3d(0, 0, 1);
  fitted.photos[1].light.direction = Vec3d(1, 0, 1).normalized();  // 45 deg away
  const std::vector<double> e = {2.0, 0.5};
  // At a fitted direction with a narrow kernel: that light's intensity.
  EXPECT_NEAR(PredictRtiIntensity(fitted, e, Vec3d(0, 0, 1), 5.0), 2.0, 1e-6);
  EXPECT_NEAR(PredictRtiIntensity(fitted, e, Vec3d(1, 0, 1), 5.0), 0.5, 1e-6);
  // Half way, equal weights: the geometric mean.
  const Vec3d half = (Vec3d(0, 0, 1) + Vec3d(1, 0, 1).normalized()).normalized();
  EXPECT_NEAR(PredictRtiIntensity(fitted, e, half, 8.0), 1.0, 1e-6);
  // Far from every light (the kernel's weights underflow): the nearest one, never 0 or NaN.
  EXPECT_NEAR(PredictRtiIntensity(fitted, e, Vec3d(-1, 0, 0.05), 0.5), 2.0, 1e-6);
  // No fitted light: 1.
  EXPECT_EQ(PredictRtiIntensity(PhotoSet{}, {}, Vec3d(0, 0, 1), 8.0), 1.0);

  PhotoSet held = LambertianCapture(std::vector<double>(1, 1.0));
  held.photos[0].light.direction = Vec3d(0, 0, 1);
  ApplyPredictedIntensities(fitted, e, 5.0, held);
  EXPECT_NEAR(held.photos[0].light.irradiance.x(), 2.0f, 1e-5f);
}

}  // namespace
}  // namespace digitize
