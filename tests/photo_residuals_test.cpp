// CheckPhotoResiduals against photos with a known fault: a synthetic painting's true maps, the
// generator's cameras and lights, and photos rendered from the truth by RenderRelit itself (plus
// the generator's default noise), so the "fit" is exact and every disagreement is the one planted:
// a light 1.3x brighter than declared, a camera 4 texels off sideways, a black photo.
#include "digitize/photo_residuals.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "digitize/height_field_tracer.h"
#include "digitize/relight.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/photo_sim.h"
#include "digitize_synth/scan_sim.h"

namespace digitize {
namespace {

constexpr double kNoiseSigma = 0.002;  // the generator's default photo noise (linear)

struct Scenario {
  synth::Painting painting;
  synth::SyntheticPhotoSet sim;  // cameras, lights and the true maps
  PhotoSet photos;               // re-rendered below, faults planted by the caller
};

Scenario MakeScenario(int lights = 6, bool generator_photos = false, int grid = 0) {
  Scenario s;
  synth::PaintingOptions po;
  po.resolution_px = 160;
  s.painting = synth::MakePainting(po);
  const synth::Scene scene(s.painting, synth::FrameOptions{});
  synth::PhotoSimOptions so;
  so.lights = lights;
  so.held_out_lights = 0;
  if (!generator_photos) {  // the photos are re-rendered by the tests
    so.noise_sigma = 0;
    so.encoding = synth::PhotoEncoding::kLinearExr;
  }
  so.pixels_per_texel = 2.07;  // not a whole number: shifts are not whole pixels either
  so.grid_cols = so.grid_rows = grid;
  s.sim = synth::SimulatePhotoSet(scene, RigidTransform{}, so);
  s.photos = s.sim.fit;
  return s;
}

// Renders photo i from the true maps under `camera` and `light` (which may differ from the
// declared ones), adds Gaussian noise, and clears its flags.
void Render(Scenario& s, size_t i, const Camera& camera, const Light& light, uint64_t seed) {
  const HeightFieldTracer tracer = HeightFieldTracer::Build(s.painting.truth).value();
  const RelitImage img =
      RenderRelit(tracer, s.painting.truth, s.painting.normals, s.sim.truth, {}, camera, light);
  Photo& photo = s.photos.photos[i];
  photo.rgb = img.rgb;
  photo.flags = {};
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> noise(0.0f, static_cast<float>(kNoiseSigma));
  for (Vec3f& c : photo.rgb.data)
    for (int k = 0; k < 3; ++k) c[k] += noise(rng);
}

void RenderAll(Scenario& s) {
  for (size_t i = 0; i < s.photos.photos.size(); ++i)
    Render(s, i, s.photos.photos[i].camera, s.photos.photos[i].light, 100 + i);
}

PhotoResidualReport Check(const Scenario& s) {
  auto report =
      CheckPhotoResiduals(s.painting.truth, s.painting.normals, s.sim.truth, {}, s.photos);
  EXPECT_TRUE(report.ok()) << report.error().message;
  const PhotoResidualReport r = std::move(report).value();
  for (const PhotoResidual& p : r.photos)
    std::printf(
        "  %s: gain %.4f (%zu px), shift (%.3f, %.3f) px = %.3f texels, response %.3f, "
        "rms %.5f -> %.5f, flags %d\n",
        p.entry.c_str(), p.gain, p.gain_pixels, p.shift_x_px, p.shift_y_px, p.shift_texels,
        p.shift_response, p.rms, p.rms_after_gain, p.flags);
  std::printf("  %s\n", r.Brief().c_str());
  for (const std::string& w : r.Warnings()) std::printf("  warning: %s\n", w.c_str());
  return r;
}

// Gain: noise 0.002 on ~10^4 well-exposed pixels of luminance >= 0.01 averages out to far below
// 1 %. Shift: noise-free identical geometry correlates at 0 to the peak's sub-pixel rounding;
// 0.1 px is what the task asks of a clean set.
constexpr double kCleanGainTol = 0.01;
constexpr double kCleanShiftTolPx = 0.1;

void ExpectClean(const PhotoResidual& p) {
  EXPECT_NEAR(p.gain, 1.0, kCleanGainTol) << p.entry;
  EXPECT_LT(p.shift_px, kCleanShiftTolPx) << p.entry;
  EXPECT_EQ(p.flags, 0) << p.entry;
  EXPECT_GT(p.gain_pixels, 10000u) << p.entry;
  // Only the planted noise is left.
  EXPECT_NEAR(p.rms, kNoiseSigma, 0.2 * kNoiseSigma) << p.entry;
}

TEST(PhotoResiduals, PhotosOfTheFitAreClean) {
  Scenario s = MakeScenario();
  RenderAll(s);
  const PhotoResidualReport r = Check(s);
  ASSERT_EQ(r.photos.size(), s.photos.photos.size());
  for (const PhotoResidual& p : r.photos) ExpectClean(p);
  EXPECT_TRUE(r.Warnings().empty());
}

TEST(PhotoResiduals, BrighterLightIsMeasuredAndNamed) {
  Scenario s = MakeScenario();
  RenderAll(s);
  constexpr size_t kOff = 2;
  Light bright = s.photos.photos[kOff].light;
  bright.intensity *= 1.3f;
  Render(s, kOff, s.photos.photos[kOff].camera, bright, 7);
  const PhotoResidualReport r = Check(s);
  ASSERT_EQ(r.photos.size(), s.photos.photos.size());
  for (size_t i = 0; i < r.photos.size(); ++i) {
    if (i == kOff) continue;
    ExpectClean(r.photos[i]);
  }
  const PhotoResidual& off = r.photos[kOff];
  // Linear photos do not clip, so the ratio is 1.3 but for noise: 2 % is the task's bound.
  EXPECT_NEAR(off.gain, 1.3, 0.02 * 1.3);
  EXPECT_EQ(off.flags, kResidualGainOff);
  EXPECT_LT(off.shift_px, kCleanShiftTolPx);
  // Applying the gain leaves only the noise.
  EXPECT_GT(off.rms, 5 * off.rms_after_gain);
  const std::vector<std::string> warnings = r.Warnings();
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find(s.photos.photos[kOff].entry), std::string::npos) << warnings[0];
  EXPECT_NE(warnings[0].find(s.photos.photos[kOff].path.string()), std::string::npos);
  EXPECT_NE(warnings[0].find("1.30x"), std::string::npos) << warnings[0];
}

TEST(PhotoResiduals, CameraOffSidewaysIsMeasuredAndNamed) {
  Scenario s = MakeScenario();
  RenderAll(s);
  constexpr size_t kOff = 4;
  constexpr double kTexels = 4.0;
  const Camera nominal = s.photos.photos[kOff].camera;
  Camera moved = nominal;
  // The camera moves kTexels texels along its own x axis (sideways, parallel to the canvas).
  moved.camera_from_scan.translation.x() -= kTexels * s.painting.truth.pitch_mm;
  Render(s, kOff, moved, s.photos.photos[kOff].light, 9);
  // Where the canvas centre lands in the photo vs where the declared camera puts it: the true
  // shift of the photo's content (the relief's parallax over 4 texels is ~1e-4 px).
  const Vec3d centre(s.painting.width_mm / 2, s.painting.height_mm / 2, 0);
  const Eigen::Vector2d want = moved.Project(centre) - nominal.Project(centre);
  std::printf("  planted shift (%.3f, %.3f) px\n", want.x(), want.y());
  ASSERT_GT(want.norm(), 7.0);  // 4 texels at ~2.07 px per texel

  const PhotoResidualReport r = Check(s);
  ASSERT_EQ(r.photos.size(), s.photos.photos.size());
  for (size_t i = 0; i < r.photos.size(); ++i) {
    if (i == kOff) continue;
    ExpectClean(r.photos[i]);
  }
  const PhotoResidual& off = r.photos[kOff];
  // 0.3 px: the task's bound; phase correlation's sub-pixel peak on a textured image does better.
  EXPECT_NEAR(off.shift_x_px, want.x(), 0.3);
  EXPECT_NEAR(off.shift_y_px, want.y(), 0.3);
  EXPECT_NEAR(off.shift_texels, kTexels, 0.3);
  EXPECT_EQ(off.flags, kResidualShifted);
  // The gain is measured on the relit image moved onto the photo: not biased by the shift.
  EXPECT_NEAR(off.gain, 1.0, kCleanGainTol);
  bool named = false;
  for (const std::string& w : r.Warnings())
    if (w.find(s.photos.photos[kOff].entry) != std::string::npos &&
        w.find("misregistration") != std::string::npos)
      named = true;
  EXPECT_TRUE(named);
}

// The generator's own photos (its renderer, 8-bit sRGB with noise, frame in view and frame
// shadows on the canvas, saturated highlights flagged) against the true maps: nothing is off, and
// the check must not cry wolf over what the fit does not model.
TEST(PhotoResiduals, GeneratorPhotosOfTheTruthAreClean) {
  const Scenario s = MakeScenario(6, true);
  const PhotoResidualReport r = Check(s);
  ASSERT_EQ(r.photos.size(), 6u);
  for (const PhotoResidual& p : r.photos) {
    EXPECT_NEAR(p.gain, 1.0, kCleanGainTol) << p.entry;
    EXPECT_LT(p.shift_px, kCleanShiftTolPx) << p.entry;
    EXPECT_EQ(p.flags, 0) << p.entry;
  }
  EXPECT_TRUE(r.Warnings().empty());
}

// A tiled photo set (a camera above each of 2 x 2 cells, each image a part of the canvas with the
// frame along two sides, lights around each cell): the same, no photo is called off. (The fitted
// case that once was: tests/tiles_test.cpp, TiledPhotoSet.NoPhotoOfAFittedGridIsCalledOff.)
TEST(PhotoResiduals, GridOfGeneratorPhotosOfTheTruthIsClean) {
  const Scenario s = MakeScenario(8, true, 2);
  const PhotoResidualReport r = Check(s);
  ASSERT_EQ(r.photos.size(), 32u);
  for (const PhotoResidual& p : r.photos) {
    EXPECT_NEAR(p.gain, 1.0, 2 * kCleanGainTol) << p.entry;
    EXPECT_EQ(p.flags & (kResidualShifted | kResidualGainOff), 0) << p.entry;
  }
  EXPECT_TRUE(r.Warnings().empty());
}

// Large images are averaged down for the correlation: the shift is scaled back to photo pixels.
TEST(PhotoResiduals, SubsampledCorrelationKeepsTheShift) {
  Scenario s = MakeScenario(2);
  RenderAll(s);
  Camera moved = s.photos.photos[1].camera;
  moved.camera_from_scan.translation.y() += 3.0 * s.painting.truth.pitch_mm;
  const Vec3d centre(s.painting.width_mm / 2, s.painting.height_mm / 2, 0);
  const Eigen::Vector2d want = moved.Project(centre) - s.photos.photos[1].camera.Project(centre);
  Render(s, 1, moved, s.photos.photos[1].light, 11);
  PhotoResidualOptions options;
  options.max_correlation_side_px = 100;  // the canvas spans ~330 x 250 px: factor 4
  auto r =
      CheckPhotoResiduals(s.painting.truth, s.painting.normals, s.sim.truth, {}, s.photos, options);
  ASSERT_TRUE(r.ok());
  const PhotoResidual& off = r->photos[1];
  std::printf("  planted (%.3f, %.3f) px, measured (%.3f, %.3f) px at 1/4 resolution\n", want.x(),
              want.y(), off.shift_x_px, off.shift_y_px);
  // A quarter-resolution correlation's 0.1 px is 0.4 photo px.
  EXPECT_NEAR(off.shift_x_px, want.x(), 0.4);
  EXPECT_NEAR(off.shift_y_px, want.y(), 0.4);
  EXPECT_LT(r->photos[0].shift_px, 0.4);
}

TEST(PhotoResiduals, BlackPhotoGivesFiniteOutputAndIsNamed) {
  Scenario s = MakeScenario(3);
  RenderAll(s);
  for (Vec3f& c : s.photos.photos[1].rgb.data) c = Vec3f::Zero();
  const PhotoResidualReport r = Check(s);
  ASSERT_EQ(r.photos.size(), 3u);
  const PhotoResidual& black = r.photos[1];
  EXPECT_EQ(black.gain, 1.0);
  EXPECT_EQ(black.shift_px, 0.0);
  EXPECT_EQ(black.flags, kResidualTooFewPixels);
  EXPECT_TRUE(std::isfinite(black.rms));
  EXPECT_GT(black.rms, 0.01);  // the relit image is not black
  ExpectClean(r.photos[0]);
  ExpectClean(r.photos[2]);
  const std::vector<std::string> warnings = r.Warnings();
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find(s.photos.photos[1].entry), std::string::npos) << warnings[0];
  EXPECT_NE(warnings[0].find("black"), std::string::npos) << warnings[0];
}

TEST(PhotoResiduals, CameraThatMissesTheCanvasIsNotJudged) {
  Scenario s = MakeScenario(2);
  RenderAll(s);
  // The declared camera is three canvas widths to the side: no pixel sees the canvas.
  s.photos.photos[0].camera.camera_from_scan.translation.x() -= 3 * s.painting.width_mm;
  const PhotoResidualReport r = Check(s);
  ASSERT_EQ(r.photos.size(), 2u);
  EXPECT_EQ(r.photos[0].pixels, 0u);
  EXPECT_EQ(r.photos[0].flags, kResidualTooFewPixels);
  EXPECT_EQ(r.photos[0].rms, 0.0);
  ExpectClean(r.photos[1]);
}

TEST(PhotoResiduals, Errors) {
  Scenario s = MakeScenario(2);
  RenderAll(s);
  PhotoResidualOptions bad;
  bad.max_shift_px = 0;
  auto r =
      CheckPhotoResiduals(s.painting.truth, s.painting.normals, s.sim.truth, {}, s.photos, bad);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("max_shift_px must be > 0"), std::string::npos);
  s.photos.photos[1].rgb = {};
  r = CheckPhotoResiduals(s.painting.truth, s.painting.normals, s.sim.truth, {}, s.photos);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find(s.photos.photos[1].entry), std::string::npos);
  EXPECT_NE(r.error().message.find("not loaded"), std::string::npos);
}

}  // namespace
}  // namespace digitize
