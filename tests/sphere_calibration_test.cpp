// Light directions from a reflective sphere: analytic renders of a shiny sphere with a known light.
#include "digitize/sphere_calibration.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <vector>

namespace digitize {
namespace {

// A dark glossy sphere (a little diffuse, a sharp mirror lobe) on a darker background, seen by an
// orthographic camera along -z.
Grid<float> RenderSphere(int w, int h, const SphereCircle& c, const Vec3d& light) {
  Grid<float> im(w, h, 0.02f);
  const Vec3d half = (light + Vec3d::UnitZ()).normalized();
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const double nx = (x - c.cx) / c.radius_px, ny = -(y - c.cy) / c.radius_px;
      const double q = nx * nx + ny * ny;
      if (q > 1) continue;
      const Vec3d n(nx, ny, std::sqrt(1 - q));
      const double diffuse = 0.25 + 0.1 * std::max(0.0, n.dot(light));
      im(x, y) = static_cast<float>(diffuse + std::pow(std::max(0.0, n.dot(half)), 3000.0));
    }
  return im;
}

TEST(SphereCalibration, DetectsTheSphereAndRecoversTheLights) {
  const int w = 320, h = 240;
  const SphereCircle truth{150.3, 118.7, 80.0};
  std::vector<Vec3d> lights;
  for (int i = 0; i < 16; ++i) {
    const double el = (15 + 60.0 * i / 15) * kPi / 180, az = i * 2.39996;
    lights.emplace_back(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
  }
  std::vector<Grid<float>> images;
  for (const Vec3d& l : lights) images.push_back(RenderSphere(w, h, truth, l));
  Grid<float> mean(w, h, 0.0f);
  for (const auto& im : images)
    for (size_t i = 0; i < mean.size(); ++i) mean.data[i] += im.data[i] / images.size();
  auto circle = DetectSphere(mean);
  ASSERT_TRUE(circle.ok()) << circle.error().message;
  std::printf("circle (%.2f, %.2f) r %.2f, truth (%.2f, %.2f) r %.2f\n", circle->cx, circle->cy,
              circle->radius_px, truth.cx, truth.cy, truth.radius_px);
  // Refined on the edge to a fraction of a pixel (the edge is sampled every 0.25 px).
  EXPECT_NEAR(circle->cx, truth.cx, 0.5);
  EXPECT_NEAR(circle->cy, truth.cy, 0.5);
  EXPECT_NEAR(circle->radius_px, truth.radius_px, 0.5);

  std::vector<const Grid<float>*> ptrs;
  for (const auto& im : images) ptrs.push_back(&im);
  for (const bool detected : {false, true}) {
    const SphereCircle c = detected ? *circle : truth;
    auto found = LightsFromSphere(ptrs, c);
    ASSERT_TRUE(found.ok()) << found.error().message;
    double worst = 0;
    for (size_t i = 0; i < lights.size(); ++i) {
      ASSERT_TRUE((*found)[i].found);
      worst = std::max(worst, AngleDeg((*found)[i].direction, lights[i]));
    }
    std::printf("%s circle: worst light error %.3f deg\n", detected ? "detected" : "true", worst);
    // With the true circle only the highlight's pixel centroid errs (a fraction of a pixel on an
    // 80-px sphere: ~0.5 deg of normal, twice that of light); the detected circle's sub-pixel
    // error adds up to ~1 deg at the lowest lights.
    EXPECT_LT(worst, detected ? 2.0 : 1.0);
  }
}

TEST(SphereCalibration, DegenerateAndBadInput) {
  Grid<float> dark(64, 64, 0.0f);
  EXPECT_FALSE(DetectSphere(dark).ok());  // uniform
  EXPECT_FALSE(DetectSphere(Grid<float>()).ok());
  auto r = LightsFromSphere({&dark}, SphereCircle{32, 32, 20});
  ASSERT_TRUE(r.ok());
  EXPECT_FALSE((*r)[0].found);  // no highlight: the light was behind, or off
  EXPECT_EQ((*r)[0].direction, Vec3d::UnitZ());
  EXPECT_FALSE(LightsFromSphere({&dark}, SphereCircle{10, 32, 20}).ok());  // off the image
  EXPECT_FALSE(LightsFromSphere({}, SphereCircle{32, 32, 20}).ok());
}

}  // namespace
}  // namespace digitize
