// Synthetic photo sets (data_synthetic/photo_sim.h): analytic checks of the renderer on a flat
// painting (irradiance, inverse square, cosine, the mirror highlight), shadows and held-out masks,
// noise and determinism, the encodings and their saturation flags, the files and their round trip
// through digitize::ReadCalibration, the materials, the options, and `digitize synth --photos`.
#include "digitize_synth/photo_sim.h"

#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "digitize/image_io.h"
#include "digitize/photo_set.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/scan_sim.h"
#include "test_paths.h"
#include "test_support.h"

// See io_test.cpp: OIIO 2.4's PNG reader leaks an error string on a libpng longjmp.
extern "C" const char* __lsan_default_suppressions() {
  return "leak:OpenImageIO_v2_4::ImageInput::geterror\n";
}

namespace digitize::synth {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// A file's bytes with an OpenEXR header's capture date ("capDate", which the EXR writer stamps
// from the wall clock, to the second) blanked: two writes of one image that straddle a second
// differ only there.
std::string ReadFileBytesWithoutCaptureDate(const fs::path& path) {
  std::string bytes = test::ReadFileBytes(path);
  static const std::string kKey("capDate\0string\0", 15);
  const size_t at = bytes.find(kKey);
  if (at == std::string::npos || at + kKey.size() + 4 > bytes.size()) return bytes;
  uint32_t size = 0;
  std::memcpy(&size, bytes.data() + at + kKey.size(), 4);
  const size_t value = at + kKey.size() + 4;
  if (size <= bytes.size() - value) bytes.replace(value, size, size, '#');
  return bytes;
}

constexpr double kPi = std::numbers::pi;
// Renders keep hit points, normals and irradiance in float: analytic values computed in double
// agree to a few float ulps of the largest term (~1e-6 relative); 2e-5 leaves room for the
// hit position's float rounding (~3e-5 mm at 200 mm) moving 1/d^2 and the cosine.
constexpr double kFloatRelTol = 2e-5;

// A flat 200 x 150 mm painting (no weave, strokes, impasto or cracks): height 0, normal +Z.
PaintingOptions FlatPainting(int resolution = 128) {
  PaintingOptions o;
  o.width_mm = 200;
  o.height_mm = 150;
  o.resolution_px = resolution;
  o.weave = o.strokes = o.impasto = o.craquelure = false;
  return o;
}

// With relief: impasto up to 2.5 mm casts shadows a grazing light can see.
PaintingOptions ReliefPainting(int resolution = 128) {
  PaintingOptions o;
  o.width_mm = 200;
  o.height_mm = 150;
  o.resolution_px = resolution;
  o.impasto_count = 12;
  return o;
}

// One top camera, one light at the given elevation (azimuth 0: towards canvas +X), no held-out
// images, no noise, linear EXR: the renderer's values as they are.
PhotoSimOptions OneLight(double elevation_deg) {
  PhotoSimOptions o;
  o.lights = 1;
  o.light_min_elevation_deg = o.light_max_elevation_deg = elevation_deg;
  o.held_out_lights = 0;
  o.noise_sigma = 0;
  o.encoding = PhotoEncoding::kLinearExr;
  return o;
}

PaintMaterial Matte(const Vec3f& albedo) {
  PaintMaterial m;
  m.name = "test matte";
  m.lafortune.rho_d = albedo / static_cast<float>(kPi);
  m.lafortune.rho_s = Vec3f::Zero();
  return m;
}

PaintMaterial Glossy(float k, float specular_albedo) {
  PaintMaterial m;
  m.name = "test gloss";
  m.lafortune.rho_d = Vec3f::Constant(0.02f / static_cast<float>(kPi));
  m.lafortune.rho_s = Vec3f::Constant(specular_albedo * (k + 2) / static_cast<float>(2 * kPi));
  m.lafortune.k = k;
  return m;
}

// A pose of the canvas in some scan frame (not the identity, so frames cannot be mixed up).
RigidTransform SomeCanvasFromScan() {
  RigidTransform t;
  t.rotation = (Eigen::AngleAxisd(0.3, Vec3d(0.2, -0.5, 1.0).normalized()) *
                Eigen::AngleAxisd(kPi, Vec3d::UnitX()))
                   .toRotationMatrix();
  t.translation = Vec3d(120, -40, 950);
  return t;
}

// Canvas-frame point where pixel (u, v)'s ray meets the plane Z = z_mm.
Vec3d PlaneHit(const Camera& cam, const RigidTransform& canvas_from_scan, double u, double v,
               double z_mm = 0) {
  const Vec3d d_scan = cam.camera_from_scan.rotation.transpose() *
                       Vec3d((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1);
  const Vec3d eye = canvas_from_scan.Apply(cam.CentreInScan());
  const Vec3d d = canvas_from_scan.ApplyToDirection(d_scan);
  return eye + (z_mm - eye.z()) / d.z() * d;
}

// Pixel of a canvas-frame point.
Eigen::Vector2d PixelOf(const Camera& cam, const RigidTransform& canvas_from_scan, const Vec3d& p) {
  return cam.Project(canvas_from_scan.Inverse().Apply(p));
}

// Lambertian radiance of a point of the flat canvas (normal +Z) under a point light.
Vec3f FlatLambert(const Vec3f& rho_d, const Light& light, const RigidTransform& canvas_from_scan,
                  const Vec3d& p) {
  const Vec3d l = canvas_from_scan.Apply(light.position_mm) - p;
  const double d = l.norm();
  const double cos_l = l.z() / d;
  return (rho_d.cast<double>() * light.intensity.x() * cos_l / (d * d)).cast<float>();
}

double SrgbOetf(double x) {
  return x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1 / 2.4) - 0.055;
}
double SrgbEotf(double c) { return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4); }

bool SameRgb(const Grid<Vec3f>& a, const Grid<Vec3f>& b) {
  return a.width == b.width && a.height == b.height &&
         std::memcmp(a.data.data(), b.data.data(), a.data.size() * sizeof(Vec3f)) == 0;
}

class PhotoSimTest : public test::ScratchDirTest {
 protected:
  PhotoSimTest() : ScratchDirTest("digitize_photosim_test", /*create=*/false) {}
};

// ---------------------------------------------------------------------------------------------
// Analytic checks on a flat painting.

TEST(PhotoSimAnalytic, CentrePixelIsRhoDTimesIrradiance) {
  const Painting painting = MakePainting(FlatPainting());
  const Scene scene(painting, FrameOptions{});
  const Vec3f albedo(0.5f, 0.3f, 0.1f);
  const PhotoSimOptions o = OneLight(90);  // straight above the canvas centre
  const SyntheticPhotoSet set = SimulatePhotoSet(scene, RigidTransform{}, o, {Matte(albedo)});
  ASSERT_EQ(set.fit.photos.size(), 1u);
  const Photo& photo = set.fit.photos[0];
  // The light: white_level for a white Lambertian at the centre, head-on.
  const double d = o.light_distance_mm;
  EXPECT_NEAR(photo.light.intensity.x() / (kPi * d * d), o.white_level, 1e-6);
  // The pixel nearest the canvas centre sees almost exactly the centre: E = I / d^2 there,
  // radiance = rho_d I / d^2 = albedo * white_level.
  const Vec3d centre(0.5 * painting.width_mm, 0.5 * painting.height_mm, 0);
  const Eigen::Vector2d c = PixelOf(photo.camera, RigidTransform{}, centre);
  const int u = static_cast<int>(std::lround(c.x())), v = static_cast<int>(std::lround(c.y()));
  const Vec3f got = photo.rgb(u, v);
  const Vec3f exact = FlatLambert(albedo / static_cast<float>(kPi), photo.light, RigidTransform{},
                                  PlaneHit(photo.camera, RigidTransform{}, u, v));
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(got[k], exact[k], kFloatRelTol * exact[k]) << "channel " << k;
    // Within half a pixel of the centre, 1/d^2 and the cosine differ from 1 by < 1e-5.
    EXPECT_NEAR(got[k], albedo[k] * o.white_level, 1e-4 * albedo[k]) << "channel " << k;
  }
}

TEST(PhotoSimAnalytic, InverseSquareAndCosineAcrossTheCanvas) {
  const Painting painting = MakePainting(FlatPainting());
  const Scene scene(painting, FrameOptions{});
  const RigidTransform cfs = SomeCanvasFromScan();
  for (double elevation : {90.0, 40.0}) {
    const Vec3f albedo(0.6f, 0.6f, 0.6f);
    const SyntheticPhotoSet set =
        SimulatePhotoSet(scene, cfs, OneLight(elevation), {Matte(albedo)});
    const Photo& photo = set.fit.photos[0];
    const Vec3d light = cfs.Apply(photo.light.position_mm);
    // Points spread over the canvas, clear of the frame's shadow: at 40 deg from +X it covers
    // 25 mm raise / tan 40 = 30 mm along the +X edge, so stay 40 mm from that edge.
    const double W = painting.width_mm, H = painting.height_mm;
    int checked = 0;
    for (const Vec3d& p :
         {Vec3d(0.5 * W, 0.5 * H, 0), Vec3d(10, 10, 0), Vec3d(W - 40, 10, 0), Vec3d(10, H - 10, 0),
          Vec3d(W - 40, H - 40, 0), Vec3d(0.3 * W, 0.7 * H, 0)}) {
      const Eigen::Vector2d px = PixelOf(photo.camera, cfs, p);
      const int u = static_cast<int>(std::lround(px.x())),
                v = static_cast<int>(std::lround(px.y()));
      const Vec3d hit = PlaneHit(photo.camera, cfs, u, v);
      const Vec3f exact = FlatLambert(albedo / static_cast<float>(kPi), photo.light, cfs, hit);
      EXPECT_NEAR(photo.rgb(u, v).x(), exact.x(), kFloatRelTol * exact.x())
          << "elevation " << elevation << ", canvas point " << p.transpose();
      ++checked;
    }
    EXPECT_EQ(checked, 6);
    // The same law as a ratio: corner / centre = cos_corner d_centre^2 / (cos_centre d_corner^2).
    if (elevation == 90.0) {
      const Vec3d a(0.5 * W, 0.5 * H, 0), b(10, 10, 0);
      const Eigen::Vector2d pa = PixelOf(photo.camera, cfs, a), pb = PixelOf(photo.camera, cfs, b);
      const Vec3d ha = PlaneHit(photo.camera, cfs, std::lround(pa.x()), std::lround(pa.y()));
      const Vec3d hb = PlaneHit(photo.camera, cfs, std::lround(pb.x()), std::lround(pb.y()));
      const double da = (light - ha).norm(), db = (light - hb).norm();
      const double expected_ratio = (light.z() / db) / (light.z() / da) * (da * da) / (db * db);
      const double ratio = photo.rgb(std::lround(pb.x()), std::lround(pb.y())).x() /
                           photo.rgb(std::lround(pa.x()), std::lround(pa.y())).x();
      EXPECT_NEAR(ratio, expected_ratio, 1e-4);
      EXPECT_LT(ratio, 0.99);  // the law is visible: corners are darker than the centre
    }
  }
}

TEST(PhotoSimAnalytic, Srgb8IsTheQuantisedRadiance) {
  const Painting painting = MakePainting(FlatPainting());
  const Scene scene(painting, FrameOptions{});
  PhotoSimOptions o = OneLight(60);
  const auto linear = SimulatePhotoSet(scene, RigidTransform{}, o, {Matte({0.5f, 0.3f, 0.1f})});
  o.encoding = PhotoEncoding::kSrgb8;
  const auto srgb = SimulatePhotoSet(scene, RigidTransform{}, o, {Matte({0.5f, 0.3f, 0.1f})});
  const Photo& a = linear.fit.photos[0];
  const Photo& b = srgb.fit.photos[0];
  EXPECT_EQ(b.encoding, ColourEncoding::kSrgb);
  ASSERT_EQ(a.rgb.size(), b.rgb.size());
  for (size_t i = 0; i < a.rgb.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      // The code of a value, and the linear value the reader gives that code.
      const double x = std::clamp(double(a.rgb.data[i][k]), 0.0, 1.0);
      const long code = std::lround(SrgbOetf(x) * 255);
      ASSERT_NEAR(b.rgb.data[i][k], SrgbEotf(code / 255.0), 1e-7) << "pixel " << i;
      // Within half a code of the radiance (in the encoded domain).
      ASSERT_LE(std::abs(SrgbOetf(b.rgb.data[i][k]) - SrgbOetf(x)), 0.5 / 255 + 1e-6);
    }
  }
}

TEST(PhotoSimAnalytic, GlossyHighlightAtTheMirrorPoint) {
  const Painting painting = MakePainting(FlatPainting());
  const Scene scene(painting, FrameOptions{});
  const RigidTransform cfs = SomeCanvasFromScan();
  // High enough (84 deg, from +X) for the mirror point to fall on the canvas, at X ~ 154 mm.
  const PhotoSimOptions o = OneLight(84);
  const SyntheticPhotoSet set = SimulatePhotoSet(scene, cfs, o, {Glossy(400, 0.04f)});
  const Photo& photo = set.fit.photos[0];
  // Mirror point on Z = 0: where the line from the camera to the light's mirror image crosses.
  const Vec3d eye = cfs.Apply(photo.camera.CentreInScan());
  Vec3d mirrored = cfs.Apply(photo.light.position_mm);
  mirrored.z() = -mirrored.z();
  const Vec3d m = eye + (mirrored - eye) * (eye.z() / (eye.z() - mirrored.z()));
  ASSERT_GT(m.x(), 0);
  ASSERT_LT(m.x(), painting.width_mm);  // on the canvas
  const Eigen::Vector2d expected = PixelOf(photo.camera, cfs, m);
  // Brightest pixel.
  int best = 0;
  for (size_t i = 1; i < photo.rgb.size(); ++i) {
    if (photo.rgb.data[i].y() > photo.rgb.data[best].y()) best = static_cast<int>(i);
  }
  const int bu = best % photo.rgb.width, bv = best / photo.rgb.width;
  // The lobe (k = 400, ~3 deg wide) peaks at the mirror direction; 1/d^2 and the cosine shift
  // the radiance peak by ~1 mm (< 1 px at 1.6 mm per pixel).
  EXPECT_NEAR(bu, expected.x(), 1.5);
  EXPECT_NEAR(bv, expected.y(), 1.5);
  // Its value: (rho_d + rho_s) cos E at the mirror point, within the lobe's fall-off over the
  // pixel's distance from it (< 1 px = 1.6 mm moves the mirror angle by ~0.2 deg: the lobe
  // loses < 1 % there) and the slope of cos E / d^2 (+0.2 % at most over that distance).
  const Light& light = photo.light;
  const Vec3d lp = cfs.Apply(light.position_mm);
  const double d = (lp - m).norm();
  const PaintMaterial g = Glossy(400, 0.04f);
  const double peak = (g.lafortune.rho_d.y() + g.lafortune.rho_s.y()) * (lp.z() / d) *
                      light.intensity.y() / (d * d);
  EXPECT_LT(photo.rgb(bu, bv).y(), peak * 1.005);
  EXPECT_GT(photo.rgb(bu, bv).y(), peak * 0.98);
  // 130 mm away (on the canvas, towards -X: the mirror angle is 15 deg off) only the diffuse
  // term is left.
  const Eigen::Vector2d far = PixelOf(photo.camera, cfs, Vec3d(20, m.y(), 0));
  EXPECT_LT(photo.rgb(std::lround(far.x()), std::lround(far.y())).y(), 0.01 * peak);
}

// ---------------------------------------------------------------------------------------------
// Shadows and held-out masks.

TEST(PhotoSimShadows, FrameShadowsAreRenderedAndLeftOutOfTheHeldOutMask) {
  const Painting painting = MakePainting(ReliefPainting());
  FrameOptions frame;
  frame.raise_mm = 25;
  const Scene scene(painting, frame);
  // A grazing light (20 deg) from +X for the fitting image, and a held-out one from the same
  // elevation (azimuth 0.5 x golden angle = 69 deg).
  PhotoSimOptions o = OneLight(20);
  o.held_out_lights = 1;
  PhotoSimOptions no_shadows = o;
  no_shadows.shadows = false;
  const auto lit = SimulatePhotoSet(scene, RigidTransform{}, o);
  const auto bare = SimulatePhotoSet(scene, RigidTransform{}, no_shadows);

  // Fitting image: canvas pixels darkened by shadows, near the frame on the light's side.
  {
    const Photo& a = lit.fit.photos[0];
    const Photo& b = bare.fit.photos[0];
    size_t near_frame = 0, darker = 0;
    for (int v = 0; v < a.rgb.height; ++v) {
      for (int u = 0; u < a.rgb.width; ++u) {
        if (a.rgb(u, v).sum() >= b.rgb(u, v).sum()) continue;
        ++darker;
        EXPECT_EQ(a.rgb(u, v), Vec3f::Zero());  // a point light: hard shadows
        const Vec3d p = PlaneHit(a.camera, RigidTransform{}, u, v);
        // The frame's shadow reaches 25 / tan(20 deg) = 69 mm in from X = 200.
        if (p.x() > painting.width_mm - 75 && p.x() < painting.width_mm) ++near_frame;
      }
    }
    EXPECT_GT(near_frame, 1000u);
    EXPECT_GT(darker, near_frame);  // the relief casts shadows too
    EXPECT_GT(lit.shadowed_pixels, near_frame);
    EXPECT_EQ(bare.shadowed_pixels, 0u);
  }

  // Held-out image: the mask drops the frame's shadow, keeps the relief's.
  ASSERT_EQ(lit.held_out.photos.size(), 2u);  // first camera + the extra camera
  for (size_t i = 0; i < lit.held_out.photos.size(); ++i) {
    const Photo& a = lit.held_out.photos[i];
    const Photo& b = bare.held_out.photos[i];
    const Grid<uint8_t>& mask = lit.held_out_mask[i];
    const Grid<uint8_t>& bare_mask = bare.held_out_mask[i];  // no shadows: every canvas pixel
    size_t frame_shadow = 0, relief_shadow = 0;
    for (int v = 0; v < a.rgb.height; ++v) {
      for (int u = 0; u < a.rgb.width; ++u) {
        ASSERT_LE(mask(u, v), bare_mask(u, v));
        if (bare_mask(u, v) && !mask(u, v)) {
          ++frame_shadow;
          EXPECT_EQ(a.rgb(u, v), Vec3f::Zero());
        }
        if (mask(u, v) && a.rgb(u, v).sum() < b.rgb(u, v).sum()) ++relief_shadow;
        // Outside the shadows, shadows change nothing.
        if (mask(u, v) && a.rgb(u, v).sum() > 0) {
          ASSERT_EQ(a.rgb(u, v), b.rgb(u, v));
        }
      }
    }
    EXPECT_GT(frame_shadow, 500u) << "held-out image " << i;
    EXPECT_GT(relief_shadow, 20u) << "held-out image " << i;
  }
}

TEST(PhotoSimShadows, FlatCanvasUnderAHighLightHasNoShadowAcne) {
  // Shadow rays start on the surface: lifted too little they hit it again and speckle the
  // image; every canvas pixel must be lit here.
  const Painting painting = MakePainting(FlatPainting(160));
  const Scene scene(painting, FrameOptions{});
  PhotoSimOptions o = OneLight(90);  // straight above: not even the frame casts a shadow
  o.pixels_per_texel = 1.0;          // pixel centres on texel centres, the grid's vertices
  const auto set = SimulatePhotoSet(scene, RigidTransform{}, o, {Matte({0.5f, 0.5f, 0.5f})});
  EXPECT_GT(set.canvas_lit_pixels, 10000u);
  EXPECT_EQ(set.shadowed_pixels, 0u);
}

TEST(PhotoSimShadows, NoPixelSeesTheWallThroughTheCanvas) {
  // A top view at 1 pixel per texel sends rays exactly through grid vertices, where Embree's
  // grid primitive lets a few slip through; the renderer traces those again.
  // The default painting at pitch 1 mm: without the retrace, 5-10 pixels per image (~1e-4) see
  // the wall; a flat painting happens not to show it.
  PaintingOptions relief;
  relief.resolution_px = 400;
  const Painting painting = MakePainting(relief);
  const Scene scene(painting, FrameOptions{});
  PhotoSimOptions o = OneLight(90);
  o.held_out_lights = 1;
  o.shadows = false;
  const auto set = SimulatePhotoSet(scene, RigidTransform{}, o, {Matte({0.5f, 0.5f, 0.5f})});
  const Photo& photo = set.held_out.photos[0];
  const Grid<uint8_t>& mask = set.held_out_mask[0];
  size_t inside = 0;
  for (int v = 0; v < photo.rgb.height; ++v) {
    for (int u = 0; u < photo.rgb.width; ++u) {
      const Vec3d p = PlaneHit(photo.camera, RigidTransform{}, u, v);
      if (p.x() < 1 || p.y() < 1 || p.x() > painting.width_mm - 1 || p.y() > painting.height_mm - 1)
        continue;
      ++inside;
      EXPECT_EQ(mask(u, v), 1) << "pixel " << u << ", " << v << " does not see the canvas";
    }
  }
  EXPECT_GT(inside, 10000u);
}

// ---------------------------------------------------------------------------------------------
// Noise and determinism.

TEST(PhotoSimNoise, SameSeedSameImagesOtherSeedOtherNoise) {
  const Painting painting = MakePainting(ReliefPainting(96));
  const Scene scene(painting, FrameOptions{});
  PhotoSimOptions o;
  o.lights = 3;
  o.held_out_lights = 1;
  o.noise_sigma = 0.01;
  o.encoding = PhotoEncoding::kLinearExr;
  const auto a = SimulatePhotoSet(scene, RigidTransform{}, o);
  SyntheticPhotoSet b;
  {
    // One thread: the result must not depend on the scheduling.
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    b = SimulatePhotoSet(scene, RigidTransform{}, o);
  }
  o.seed = 2;
  const auto c = SimulatePhotoSet(scene, RigidTransform{}, o);
  o.noise_sigma = 0;
  const auto clean = SimulatePhotoSet(scene, RigidTransform{}, o);
  for (size_t i = 0; i < a.fit.photos.size(); ++i) {
    EXPECT_TRUE(SameRgb(a.fit.photos[i].rgb, b.fit.photos[i].rgb)) << "image " << i;
    EXPECT_FALSE(SameRgb(a.fit.photos[i].rgb, c.fit.photos[i].rgb)) << "image " << i;
    // Noise: zero mean, sigma as asked, independent of the image (the same seed, another
    // image, another stream).
    double sum = 0, sum2 = 0;
    size_t n = 0;
    for (size_t p = 0; p < a.fit.photos[i].rgb.size(); ++p) {
      for (int k = 0; k < 3; ++k) {
        const double e = a.fit.photos[i].rgb.data[p][k] - clean.fit.photos[i].rgb.data[p][k];
        sum += e;
        sum2 += e * e;
        ++n;
      }
    }
    const double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
    // n ~ 4e4 samples: the mean's standard error is 5e-5, the sd's 0.7 %.
    EXPECT_NEAR(mean, 0.0, 3e-4) << "image " << i;
    EXPECT_NEAR(sd, 0.01, 0.0005) << "image " << i;
  }
  // Held-out images are noise-free whatever the seed.
  EXPECT_TRUE(SameRgb(a.held_out.photos[0].rgb, c.held_out.photos[0].rgb));
  EXPECT_TRUE(SameRgb(a.held_out.photos[0].rgb, clean.held_out.photos[0].rgb));
  EXPECT_NE(a.fit.photos[0].rgb.data[0], a.fit.photos[1].rgb.data[0]);
}

// ---------------------------------------------------------------------------------------------
// Encodings and saturation.

TEST(PhotoSimEncoding, Srgb8FlagsEveryChannelAtCode255) {
  const Painting painting = MakePainting(ReliefPainting(96));
  const Scene scene(painting, FrameOptions{});
  PhotoSimOptions o;
  o.lights = 2;
  o.held_out_lights = 0;
  o.noise_sigma = 0;
  o.white_level = 2.5;  // white paint over-exposed: some radiance > 1
  o.encoding = PhotoEncoding::kLinearExr;
  const auto linear = SimulatePhotoSet(scene, RigidTransform{}, o);
  o.encoding = PhotoEncoding::kSrgb8;
  const auto srgb = SimulatePhotoSet(scene, RigidTransform{}, o);
  // Code 255 is reached from EOTF(254.5 / 255) up.
  const double threshold = SrgbEotf(254.5 / 255);
  size_t flagged = 0, above_one = 0;
  for (size_t i = 0; i < srgb.fit.photos.size(); ++i) {
    const Photo& s = srgb.fit.photos[i];
    const Photo& l = linear.fit.photos[i];
    size_t in_photo = 0;
    for (int v = 0; v < s.rgb.height; ++v) {
      for (int u = 0; u < s.rgb.width; ++u) {
        const double x = l.rgb(u, v).maxCoeff();
        above_one += x > 1;
        const bool sat = s.Flags(u, v) & kPixelSaturated;
        in_photo += sat;
        if (std::abs(x - threshold) < 1e-6) continue;  // float rounding decides
        ASSERT_EQ(sat, x > threshold) << "image " << i << " pixel " << u << ", " << v;
        if (sat) {
          ASSERT_EQ(s.rgb(u, v).maxCoeff(), 1.0f);  // the top code reads 1
        }
      }
    }
    EXPECT_EQ(s.saturated_pixels, in_photo);
    flagged += in_photo;
  }
  EXPECT_GT(above_one, 100u);
  EXPECT_GE(flagged, above_one);
  EXPECT_EQ(srgb.saturated_pixels, flagged);
  EXPECT_EQ(srgb.fit.summary.saturated_pixels, flagged);
  EXPECT_EQ(linear.saturated_pixels, 0u);  // float images: no clipping, no flags
  for (const Photo& p : linear.fit.photos) EXPECT_TRUE(p.flags.empty());
}

// ---------------------------------------------------------------------------------------------
// Geometry of the set.

TEST(PhotoSimGeometry, CamerasAndLightsWhereTheOptionsPutThem) {
  const Painting painting = MakePainting(FlatPainting());
  const Scene scene(painting, FrameOptions{});
  const RigidTransform cfs = SomeCanvasFromScan();
  PhotoSimOptions o;
  o.cameras = 3;
  o.camera_arc_deg = 30;
  o.lights = 12;
  o.held_out_lights = 4;
  o.pixels_per_texel = 1.5;
  const auto set = SimulatePhotoSet(scene, cfs, o);
  ASSERT_EQ(set.fit.photos.size(), 36u);
  ASSERT_EQ(set.held_out.photos.size(), 8u);
  ASSERT_EQ(set.held_out_mask.size(), 8u);
  const Vec3d centre(0.5 * painting.width_mm, 0.5 * painting.height_mm, 0);
  const double pitch = painting.truth.pitch_mm;

  // Cameras: on the arc, aimed at the centre (principal point), canvas + margin in view.
  for (int c = 0; c < 3; ++c) {
    const Camera& cam = set.fit.photos[c * 12].camera;
    const Vec3d eye = cfs.Apply(cam.CentreInScan());
    EXPECT_NEAR((eye - centre).norm(), o.camera_distance_mm, 1e-6);
    EXPECT_NEAR(AngleDeg(eye - centre, Vec3d::UnitZ()), c == 1 ? 0.0 : 30.0, 1e-6);
    EXPECT_NEAR(eye.y(), centre.y(), 1e-6);  // the arc is in the XZ plane
    const Eigen::Vector2d pc = PixelOf(cam, cfs, centre);
    EXPECT_NEAR(pc.x(), cam.cx, 1e-6);
    EXPECT_NEAR(pc.y(), cam.cy, 1e-6);
    EXPECT_NEAR(cam.cx, 0.5 * (cam.width - 1), 1e-12);
    EXPECT_EQ(cam.fx, cam.fy);
    for (double X : {-0.08 * painting.width_mm, 1.08 * painting.width_mm})
      for (double Y : {-0.08 * painting.height_mm, 1.08 * painting.height_mm})
        EXPECT_TRUE(cam.InImage(PixelOf(cam, cfs, Vec3d(X, Y, 0)))) << "camera " << c;
    // Upright: canvas +X to the right, canvas +Y up (towards row 0) near the centre.
    EXPECT_GT(PixelOf(cam, cfs, centre + Vec3d(10, 0, 0)).x(), pc.x());
    EXPECT_LT(PixelOf(cam, cfs, centre + Vec3d(0, 10, 0)).y(), pc.y());
    for (int j = 0; j < 12; ++j)
      EXPECT_EQ(set.fit.photos[c * 12 + j].light.position_mm, set.fit.photos[j].light.position_mm);
  }
  // The top view samples the centre at pixels_per_texel.
  const Camera& top = set.fit.photos[12].camera;
  EXPECT_NEAR((PixelOf(top, cfs, centre + Vec3d(pitch, 0, 0)) - PixelOf(top, cfs, centre)).norm(),
              1.5, 1e-3);
  ASSERT_TRUE(CheckCamerasSeeCanvas(set.fit, cfs, painting.truth).ok());
  ASSERT_TRUE(CheckCamerasSeeCanvas(set.held_out, cfs, painting.truth).ok());

  // Held-out cameras: the first fitting camera, then one off the arc.
  EXPECT_EQ(set.held_out.photos[0].camera.camera_from_scan.translation,
            set.fit.photos[0].camera.camera_from_scan.translation);
  const Vec3d extra = cfs.Apply(set.held_out.photos[4].camera.CentreInScan());
  EXPECT_NEAR(AngleDeg(extra - centre, Vec3d::UnitZ()), o.held_out_camera_deg, 1e-6);
  EXPECT_NEAR(extra.x(), centre.x(), 1e-6);  // azimuth 90 deg off the arc

  // Lights: on the dome, within the elevations, none repeated; held-out ones between them.
  std::vector<Vec3d> fit_dirs, held_dirs;
  for (int j = 0; j < 12; ++j)
    fit_dirs.push_back(cfs.Apply(set.fit.photos[j].light.position_mm) - centre);
  for (int j = 0; j < 4; ++j)
    held_dirs.push_back(cfs.Apply(set.held_out.photos[j].light.position_mm) - centre);
  for (const auto* dirs : {&fit_dirs, &held_dirs}) {
    for (const Vec3d& d : *dirs) {
      EXPECT_NEAR(d.norm(), o.light_distance_mm, 1e-6);
      const double elevation = 90 - AngleDeg(d, Vec3d::UnitZ());
      EXPECT_GE(elevation, o.light_min_elevation_deg - 1e-9);
      EXPECT_LE(elevation, o.light_max_elevation_deg + 1e-9);
    }
  }
  for (const Vec3d& h : held_dirs)
    for (const Vec3d& f : fit_dirs) EXPECT_GT(AngleDeg(h, f), 2.0);
  for (size_t i = 0; i < fit_dirs.size(); ++i)
    for (size_t j = i + 1; j < fit_dirs.size(); ++j)
      EXPECT_GT(AngleDeg(fit_dirs[i], fit_dirs[j]), 5.0);
  // Lights on every side of the canvas (the spiral turns by the golden angle).
  int quadrants = 0;
  for (int q = 0; q < 4; ++q) {
    bool any = false;
    for (const Vec3d& d : fit_dirs)
      any |= static_cast<int>(std::floor((std::atan2(d.y(), d.x()) + kPi) / (kPi / 2))) % 4 == q;
    quadrants += any;
  }
  EXPECT_EQ(quadrants, 4);
}

TEST(PhotoSimGeometry, TruthMapsFollowThePaintRegions) {
  const Painting painting = MakePainting(ReliefPainting(96));
  const Scene scene(painting, FrameOptions{});
  PhotoSimOptions o;
  o.lights = 1;
  o.held_out_lights = 0;
  const auto materials = DefaultPaintMaterials(true);
  const auto set = SimulatePhotoSet(scene, RigidTransform{}, o, materials);
  ASSERT_TRUE(set.truth.Validate().ok()) << set.truth.Validate().message();
  ASSERT_EQ(set.truth.width(), painting.truth.width());
  ASSERT_EQ(set.materials.size(), materials.size());
  for (int y = 0; y < painting.truth.height(); ++y) {
    for (int x = 0; x < painting.truth.width(); ++x) {
      const size_t mi = painting.region(x, y) % materials.size();
      ASSERT_EQ(set.material_index(x, y), mi);
      const PaintMaterial& m = materials[mi];
      ASSERT_EQ(set.measured_texel(x, y), m.is_measured ? 1 : 0);
      const LafortuneParams t = set.truth.At(x, y);
      if (m.is_measured) {
        EXPECT_EQ(t.rho_d, m.measured.diffuse_albedo / static_cast<float>(kPi));
        EXPECT_EQ(t.rho_s, Vec3f::Zero());
        EXPECT_EQ(set.truth.status(x, y), TexelFitStatus::kDiffuseOnly);
      } else {
        EXPECT_EQ(t.rho_d, m.lafortune.rho_d);
        EXPECT_EQ(t.rho_s, m.lafortune.rho_s);
        EXPECT_EQ(t.k, m.lafortune.k);
        EXPECT_EQ(t.cx, m.lafortune.cx);
        EXPECT_EQ(set.truth.status(x, y), TexelFitStatus::kConverged);
      }
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Files.

// Writes a set, reads it back with the library's reader, and compares.
void ExpectRoundTrip(const fs::path& dir, const SyntheticPhotoSet& set) {
  ASSERT_TRUE(WriteSyntheticPhotoSet(dir, set).ok());
  auto read = ReadCalibration(dir / "calib.json");
  ASSERT_TRUE(read.ok()) << read.error().message;
  ASSERT_EQ(read->photos.size(), set.fit.photos.size());
  for (size_t i = 0; i < set.fit.photos.size(); ++i) {
    const Photo& a = set.fit.photos[i];
    const Photo& b = read->photos[i];
    EXPECT_EQ(b.encoding, a.encoding);
    EXPECT_EQ(b.camera.width, a.camera.width);
    EXPECT_EQ(b.camera.height, a.camera.height);
    EXPECT_EQ(b.camera.fx, a.camera.fx);
    EXPECT_EQ(b.camera.cy, a.camera.cy);
    // JSON numbers round trip; the reader snaps the rotation to the nearest one (~1e-16).
    EXPECT_LT((b.camera.camera_from_scan.rotation - a.camera.camera_from_scan.rotation).norm(),
              1e-12);
    EXPECT_EQ(b.camera.camera_from_scan.translation, a.camera.camera_from_scan.translation);
    EXPECT_EQ(b.light.type, LightType::kPoint);
    EXPECT_EQ(b.light.position_mm, a.light.position_mm);
    EXPECT_EQ(b.light.intensity, a.light.intensity);
    // Pixels: what the reader decodes is what the renderer said it would (bit for bit), flags
    // included.
    ASSERT_TRUE(SameRgb(a.rgb, b.rgb)) << "image " << i << " (" << b.path << ")";
    EXPECT_EQ(b.saturated_pixels, a.saturated_pixels);
    EXPECT_EQ(b.flags.data, a.flags.data);
  }
  if (set.held_out.photos.empty()) {
    EXPECT_FALSE(fs::exists(dir / "held_out" / "calib.json"));
  } else {
    auto held = ReadCalibration(dir / "held_out" / "calib.json");
    ASSERT_TRUE(held.ok()) << held.error().message;
    ASSERT_EQ(held->photos.size(), set.held_out.photos.size());
    for (size_t i = 0; i < held->photos.size(); ++i) {
      EXPECT_EQ(held->photos[i].encoding, ColourEncoding::kLinear);
      EXPECT_TRUE(SameRgb(held->photos[i].rgb, set.held_out.photos[i].rgb));
      char name[32];
      std::snprintf(name, sizeof name, "mask_%03zu.png", i);
      auto mask = ReadImage(dir / "held_out" / name);
      ASSERT_TRUE(mask.ok()) << mask.error().message;
      ASSERT_EQ(mask->pixels.size(), set.held_out_mask[i].size());
      for (size_t p = 0; p < mask->pixels.size(); ++p)
        ASSERT_EQ(mask->pixels[p] > 0.5f, set.held_out_mask[i].data[p] != 0);
    }
  }
  // Truth.
  auto lobe = ReadImage(dir / "truth" / "lobe.exr");
  ASSERT_TRUE(lobe.ok()) << lobe.error().message;
  ASSERT_EQ(lobe->channels, 3);  // cx, cy, k (cz = 1: the gauge)
  EXPECT_EQ(lobe->channel_names, (std::vector<std::string>{"cx", "cy", "k"}));
  for (size_t p = 0; p < set.truth.lobe.size(); ++p) {
    const auto& c = set.truth.lobe.data[p];
    ASSERT_EQ(lobe->pixels[3 * p], c[0]);
    ASSERT_EQ(lobe->pixels[3 * p + 1], c[1]);
    ASSERT_EQ(lobe->pixels[3 * p + 2], c[3]);
  }
  // The files are made from material_index a map at a time; they hold the set's truth exactly.
  for (const auto& [file, truth] :
       {std::pair{"rho_d.exr", &set.truth.rho_d}, std::pair{"rho_s.exr", &set.truth.rho_s}}) {
    auto map = ReadImage(dir / "truth" / file);
    ASSERT_TRUE(map.ok()) << map.error().message;
    ASSERT_EQ(map->pixels.size(), 3 * truth->size()) << file;
    for (size_t p = 0; p < truth->size(); ++p)
      for (int c = 0; c < 3; ++c) ASSERT_EQ(map->pixels[3 * p + c], truth->data[p][c]) << file;
  }
  auto material = ReadImage(dir / "truth" / "material.png");
  ASSERT_TRUE(material.ok());
  for (size_t p = 0; p < set.material_index.size(); ++p)
    ASSERT_EQ(std::lround(material->pixels[p] * 255), set.material_index.data[p]);
  std::ifstream in(dir / "truth" / "materials.json");
  const json materials = json::parse(in);
  EXPECT_EQ(materials["format"], "digitize.synthetic_materials");
  EXPECT_EQ(materials["materials"].size(), set.materials.size());
  // No temporary files left behind.
  for (const auto& e : fs::recursive_directory_iterator(dir))
    EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
}

TEST_F(PhotoSimTest, EveryEncodingRoundTripsThroughReadCalibration) {
  const Painting painting = MakePainting(ReliefPainting(96));
  const Scene scene(painting, FrameOptions{});
  PhotoSimOptions o;
  o.cameras = 2;
  o.lights = 3;
  o.held_out_lights = 2;
  o.noise_sigma = 0.003;
  o.white_level = 1.5;  // some saturation in the integer encodings
  const auto materials = DefaultPaintMaterials(true);
  for (PhotoEncoding e :
       {PhotoEncoding::kSrgb8, PhotoEncoding::kSrgb16, PhotoEncoding::kLinearExr}) {
    SCOPED_TRACE(ToString(e));
    o.encoding = e;
    const auto set = SimulatePhotoSet(scene, SomeCanvasFromScan(), o, materials);
    if (e != PhotoEncoding::kLinearExr) {
      EXPECT_GT(set.saturated_pixels, 0u);
    }
    ExpectRoundTrip(dir_ / ToString(e), set);
    EXPECT_TRUE(fs::exists(dir_ / ToString(e) / "images" /
                           (e == PhotoEncoding::kLinearExr ? "img_005.exr" : "img_005.png")));
  }
  // 16 bits are 16 bits on disk.
  auto header = ReadImage(dir_ / "srgb16" / "images" / "img_000.png");
  ASSERT_TRUE(header.ok());
  EXPECT_EQ(header->bits_per_sample, 16);
}

TEST_F(PhotoSimTest, NoHeldOutImagesWritesNoHeldOutCalibration) {
  const Painting painting = MakePainting(FlatPainting(96));
  const Scene scene(painting, FrameOptions{});
  PhotoSimOptions o = OneLight(45);
  o.encoding = PhotoEncoding::kSrgb8;
  const auto set = SimulatePhotoSet(scene, RigidTransform{}, o);
  EXPECT_TRUE(set.held_out.photos.empty());
  EXPECT_TRUE(set.held_out_mask.empty());
  ExpectRoundTrip(dir_, set);
}

TEST_F(PhotoSimTest, UnwritableFolderIsAnErrorNamingIt) {
  const Painting painting = MakePainting(FlatPainting(64));
  const Scene scene(painting, FrameOptions{});
  const auto set = SimulatePhotoSet(scene, RigidTransform{}, OneLight(45));
  fs::create_directories(dir_);
  std::ofstream(dir_ / "file") << "x";
  const Status s = WriteSyntheticPhotoSet(dir_ / "file" / "photos", set);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("file"), std::string::npos) << s.message();
}

// ---------------------------------------------------------------------------------------------
// Tiled photo sets (a camera grid) and the streamed writer.

// A painting photographed a cell at a time: 3 x 2 cameras straight above their cells, each image
// holding its cell and grid_overlap of a cell around it, each under its own dome of lights.
TEST(PhotoSimGrid, CellsCoverTheCanvasWithOverlapUnderTheirOwnLights) {
  const Painting painting = MakePainting(ReliefPainting(120));
  const Scene scene(painting, FrameOptions{});
  PhotoSimOptions o;
  o.grid_cols = 3;
  o.grid_rows = 2;
  o.grid_overlap = 0.1;
  o.lights = 4;
  o.held_out_lights = 2;
  o.noise_sigma = 0;
  const RigidTransform cfs = SomeCanvasFromScan();
  const auto set = SimulatePhotoSet(scene, cfs, o);
  ASSERT_EQ(set.fit.photos.size(), 6u * 4u);
  ASSERT_EQ(set.held_out.photos.size(), 2u * 2u);
  const RigidTransform scan_from_canvas = cfs.Inverse();
  const double cw = painting.width_mm / 3, ch = painting.height_mm / 2;
  for (int c = 0; c < 6; ++c) {
    SCOPED_TRACE("camera " + std::to_string(c));
    const Vec3d cell(((c % 3) + 0.5) * cw, painting.height_mm - ((c / 3) + 0.5) * ch,
                     0);  // row 0 on top
    const Camera& cam = set.fit.photos[4 * c].camera;
    // Straight down at its cell's centre: the image centre is the cell centre, the view along -Z.
    const Eigen::Vector2d centre = cam.Project(scan_from_canvas.Apply(cell));
    EXPECT_NEAR(centre.x(), cam.cx, 1e-6);
    EXPECT_NEAR(centre.y(), cam.cy, 1e-6);
    const Vec3d view = (cam.camera_from_scan * scan_from_canvas).rotation.row(2).transpose();
    EXPECT_NEAR(view.z(), -1.0, 1e-12);
    // The cell grown by the overlap is in the image, 1.5 overlaps out is not (both ways).
    for (double grow : {0.099, 0.15}) {
      const bool inside = grow < o.grid_overlap;
      for (double sx : {-1.0, 1.0}) {
        const Vec3d p = cell + Vec3d(sx * (0.5 + grow) * cw, 0, 0);
        EXPECT_EQ(cam.InImage(cam.Project(scan_from_canvas.Apply(p))), inside) << grow;
        const Vec3d q = cell + Vec3d(0, sx * (0.5 + grow) * ch, 0);
        EXPECT_EQ(cam.InImage(cam.Project(scan_from_canvas.Apply(q))), inside) << grow;
      }
    }
    // Its own lights: on the dome around its cell, at light_distance_mm.
    for (int j = 0; j < 4; ++j) {
      const Vec3d light = cfs.Apply(set.fit.photos[4 * c + j].light.position_mm);
      EXPECT_NEAR((light - cell).norm(), o.light_distance_mm, 1e-9);
      EXPECT_EQ(set.fit.photos[4 * c + j].camera.camera_from_scan.translation,
                cam.camera_from_scan.translation);
    }
    EXPECT_EQ(set.fit.photos[4 * c].rgb.width, cam.width);  // no sink: the pixels are there
  }
  // Every texel is seen by at least one camera, those in an overlap by two or more; none by all.
  size_t twice = 0;
  for (int y = 0; y < painting.truth.height(); ++y) {
    for (int x = 0; x < painting.truth.width(); ++x) {
      const Eigen::Vector2d mm = painting.truth.TexelCentreMm(x, y);
      int seen = 0;
      for (int c = 0; c < 6; ++c) {
        const Camera& cam = set.fit.photos[4 * c].camera;
        seen += cam.InImage(cam.Project(scan_from_canvas.Apply(Vec3d(mm.x(), mm.y(), 0))));
      }
      ASSERT_GE(seen, 1) << x << ", " << y;
      ASSERT_LT(seen, 6) << x << ", " << y;
      twice += seen >= 2;
    }
  }
  EXPECT_GT(twice, painting.truth.width() * painting.truth.height() / 10);
  // Held out: a cell-sized patch at the canvas centre, from above and tilted, lights around it.
  const Vec3d cell0(0.5 * painting.width_mm, 0.5 * painting.height_mm, 0);
  EXPECT_EQ(set.held_out.photos[0].camera.width, set.fit.photos[0].camera.width);
  const Camera& tilted = set.held_out.photos[2].camera;
  const Eigen::Vector2d c0 = tilted.Project(scan_from_canvas.Apply(cell0));
  EXPECT_NEAR(c0.x(), tilted.cx, 1e-6);
  EXPECT_NEAR(c0.y(), tilted.cy, 1e-6);
  EXPECT_NEAR((cfs.Apply(set.held_out.photos[0].light.position_mm) - cell0).norm(),
              o.light_distance_mm, 1e-9);
  // What a cell's image shows is the painting: lit canvas, not black.
  double sum = 0;
  for (const Vec3f& v : set.fit.photos[4 * 5].rgb.data) sum += v.sum();
  EXPECT_GT(sum / set.fit.photos[4 * 5].rgb.size(), 0.05);
  EXPECT_NE(set.Brief().find("6 camera(s) in a grid x 4 lights"), std::string::npos) << set.Brief();
}

// RenderSyntheticPhotoSet writes each camera position's images as soon as they are rendered:
// the same files, byte for byte (but for the EXR header's capture date), as rendering the set in
// memory and writing it.
TEST_F(PhotoSimTest, StreamedWriterWritesTheFilesOfTheInMemoryOne) {
  const Painting painting = MakePainting(ReliefPainting(96));
  const Scene scene(painting, FrameOptions{});
  PhotoSimOptions o;
  o.grid_cols = 2;
  o.grid_rows = 2;
  o.lights = 3;
  o.held_out_lights = 2;
  const auto materials = DefaultPaintMaterials(false);
  const auto in_memory = SimulatePhotoSet(scene, SomeCanvasFromScan(), o, materials);
  ASSERT_TRUE(WriteSyntheticPhotoSet(dir_ / "memory", in_memory).ok());
  SyntheticPhotoSet summary;
  ASSERT_TRUE(RenderSyntheticPhotoSet(dir_ / "streamed", scene, SomeCanvasFromScan(), o, materials,
                                      nullptr, &summary)
                  .ok());
  EXPECT_TRUE(summary.pixels_released);
  EXPECT_TRUE(summary.fit.photos[0].rgb.data.empty());
  // Nor the truth maps (44 bytes a texel): the files under truth/ are made from material_index.
  EXPECT_TRUE(summary.truth.empty());
  EXPECT_EQ(summary.material_index.data, in_memory.material_index.data);
  EXPECT_EQ(summary.saturated_pixels, in_memory.saturated_pixels);
  EXPECT_EQ(summary.Brief().substr(0, 60), in_memory.Brief().substr(0, 60));
  size_t files = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir_ / "memory")) {
    if (!e.is_regular_file()) continue;
    const fs::path rel = fs::relative(e.path(), dir_ / "memory");
    ASSERT_TRUE(fs::exists(dir_ / "streamed" / rel)) << rel;
    EXPECT_EQ(ReadFileBytesWithoutCaptureDate(e.path()),
              ReadFileBytesWithoutCaptureDate(dir_ / "streamed" / rel))
        << rel;
    ++files;
  }
  EXPECT_EQ(files, 12u + 4u + 4u + 2u + 5u);  // images, held-out + masks, calibrations, truth
  // A set whose pixels went to a sink cannot be written again.
  EXPECT_FALSE(WriteSyntheticPhotoSet(dir_ / "again", summary).ok());
  // A sink's error stops the rendering and is reported.
  int calls = 0;
  const auto failed = SimulatePhotoSet(scene, SomeCanvasFromScan(), o, materials, nullptr,
                                       [&](const Photo&, const Grid<uint8_t>*, int) -> Status {
                                         ++calls;
                                         return Error{"disk full"};
                                       });
  EXPECT_EQ(failed.sink_status.message(), "disk full");
  EXPECT_EQ(calls, 3 + 2);  // the first camera position's images only (3 fitting, 2 held out)
}

// JPEG: the files are what the 8-bit codes were, within JPEG's loss at quality 95 (4:4:4), and
// read back as sRGB through the calibration. Measured on these noisy renders: 39.6-39.7 dB
// against the codes (an RMS of ~2.7 codes, most of it the sensor noise JPEG cannot keep), peaks
// of 16-24 codes at impasto edges; the bounds leave ~2.5 dB and ~15 codes for other libjpegs.
TEST_F(PhotoSimTest, JpegPhotosReadBackWithinTheCompressionLoss) {
  const Painting painting = MakePainting(ReliefPainting(96));
  const Scene scene(painting, FrameOptions{});
  PhotoSimOptions o;
  o.lights = 2;
  o.held_out_lights = 0;
  o.encoding = PhotoEncoding::kJpeg;
  const auto set = SimulatePhotoSet(scene, SomeCanvasFromScan(), o);
  ASSERT_TRUE(WriteSyntheticPhotoSet(dir_, set).ok());
  ASSERT_TRUE(fs::exists(dir_ / "images" / "img_001.jpg"));
  auto read = ReadCalibration(dir_ / "calib.json");
  ASSERT_TRUE(read.ok()) << read.error().message;
  ASSERT_EQ(read->photos.size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    const Photo& a = set.fit.photos[i];
    const Photo& b = read->photos[i];
    EXPECT_EQ(b.encoding, ColourEncoding::kSrgb);
    ASSERT_EQ(b.rgb.size(), a.rgb.size());
    // Error in 8-bit codes: quality 95 keeps the mean well under one code and the peak small.
    double sum2 = 0, peak = 0;
    for (size_t p = 0; p < a.rgb.size(); ++p) {
      for (int k = 0; k < 3; ++k) {
        auto code = [](float lin) {
          const double c = lin <= 0.0031308 ? 12.92 * lin : 1.055 * std::pow(lin, 1 / 2.4) - 0.055;
          return 255.0 * c;
        };
        const double d = code(a.rgb.data[p][k]) - code(b.rgb.data[p][k]);
        sum2 += d * d;
        peak = std::max(peak, std::abs(d));
      }
    }
    const double psnr = 10 * std::log10(255.0 * 255.0 / (sum2 / (3.0 * a.rgb.size())));
    std::printf("jpeg image %zu: %.2f dB against its codes, peak %.0f codes\n", i, psnr, peak);
    EXPECT_GT(psnr, 37.0);
    EXPECT_LT(peak, 40.0);
  }
}

// ---------------------------------------------------------------------------------------------
// Materials.

TEST(PhotoSimMaterials, DefaultsSpanMatteToVarnishWithinTheEnergyBound) {
  const auto one_lobe = DefaultPaintMaterials(false);
  ASSERT_GE(one_lobe.size(), 6u);
  float k_min = 1e9f, k_max = 0;
  bool matte = false, anisotropic = false;
  std::vector<Vec3f> colours;
  for (const PaintMaterial& m : one_lobe) {
    SCOPED_TRACE(m.name);
    EXPECT_FALSE(m.is_measured);
    ASSERT_TRUE(m.lafortune.Validate().ok()) << m.lafortune.Validate().message();
    const Vec3f albedo = m.lafortune.rho_d * static_cast<float>(kPi);
    EXPECT_GE(albedo.minCoeff(), 0.05f - 1e-6f);
    EXPECT_LE(albedo.maxCoeff(), 0.8f + 1e-6f);
    // Specular albedo rho_s 2 pi / (k + 2): at most 1, and with the diffuse albedo below 1.
    const float a_s =
        m.lafortune.rho_s.maxCoeff() * 2 * static_cast<float>(kPi) / (m.lafortune.k + 2);
    EXPECT_LE(a_s, 1.0f);
    EXPECT_LT(albedo.maxCoeff() + a_s, 1.0f);
    EXPECT_LE(std::abs(m.lafortune.cx), 1.0f);
    EXPECT_LE(std::abs(m.lafortune.cy), 1.0f);
    if (m.lafortune.rho_s.maxCoeff() == 0) {
      matte = true;
    } else {
      k_min = std::min(k_min, m.lafortune.k);
      k_max = std::max(k_max, m.lafortune.k);
    }
    anisotropic |= m.lafortune.cx != m.lafortune.cy;
    for (const Vec3f& c : colours) EXPECT_GT((c - albedo).norm(), 0.05f);
    colours.push_back(albedo);
  }
  EXPECT_TRUE(matte);
  EXPECT_TRUE(anisotropic);
  EXPECT_LE(k_min, 8.0f);
  EXPECT_GE(k_max, 300.0f);
  const auto with_measured = DefaultPaintMaterials(true);
  ASSERT_EQ(with_measured.size(), one_lobe.size() + 1);
  EXPECT_TRUE(with_measured.back().is_measured);
  EXPECT_EQ(with_measured.back().measured.name, "bluepaint");
  EXPECT_EQ(with_measured.back().measured.lobes.size(), 3u);
  EXPECT_FLOAT_EQ(with_measured.back().measured.lobes[2].n.x(), 66.899060f);
}

TEST(PhotoSimMaterials, MeasuredPaintIsNonNegativeReciprocalAndNoOneLobeMaterial) {
  const auto materials = DefaultPaintMaterials(true);
  const PaintMaterial& blue = materials.back();
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<float> unit(0, 1);
  auto direction = [&] {  // cosine-weighted upper hemisphere
    const float r = std::sqrt(unit(rng)), phi = 2 * static_cast<float>(kPi) * unit(rng);
    return Vec3f(r * std::cos(phi), r * std::sin(phi), std::sqrt(std::max(0.0f, 1 - r * r)));
  };
  std::vector<std::pair<Vec3f, Vec3f>> pairs;
  for (int i = 0; i < 2000; ++i) pairs.emplace_back(direction(), direction());
  for (const auto& [v, l] : pairs) {
    const Vec3f f = blue.Evaluate(v, l);
    ASSERT_TRUE(f.allFinite());
    ASSERT_GE(f.minCoeff(), 0.0f);
    ASSERT_LE((f - blue.Evaluate(l, v)).norm(), 1e-5f * (1 + f.norm()));
  }
  EXPECT_EQ(blue.Evaluate(Vec3f(0, 0, 1), Vec3f(0.6f, 0, -0.8f)), Vec3f::Zero());  // below horizon
  // Not any of the one-lobe materials: the BRDFs differ by > 20 % (RMS, relative) somewhere.
  for (size_t m = 0; m + 1 < materials.size(); ++m) {
    double diff = 0, norm = 0;
    for (const auto& [v, l] : pairs) {
      diff += (blue.Evaluate(v, l) - materials[m].Evaluate(v, l)).squaredNorm();
      norm += blue.Evaluate(v, l).squaredNorm();
    }
    EXPECT_GT(std::sqrt(diff / norm), 0.2) << materials[m].name;
  }
  // Outside the fitted family altogether: its lobe 0 scatters backwards (Cxy > 0), so at 37 deg
  // retro-reflection (v = l) is brighter than the mirror direction, which no one-lobe material
  // with a forward lobe (cx, cy < 0) can do.
  const Vec3f l(0.6f, 0, 0.8f), mirror(-0.6f, 0, 0.8f);
  EXPECT_GT(blue.Evaluate(l, l).x(), blue.Evaluate(mirror, l).x());
  for (size_t m = 0; m + 1 < materials.size(); ++m)
    EXPECT_LE(materials[m].Evaluate(l, l).x(), materials[m].Evaluate(mirror, l).x())
        << materials[m].name;
}

// ---------------------------------------------------------------------------------------------
// Options and progress.

TEST(PhotoSimOptionsTest, ValidateNamesTheBadOption) {
  EXPECT_TRUE(PhotoSimOptions{}.Validate().ok());
  struct Case {
    void (*spoil)(PhotoSimOptions&);
    const char* field;
  };
  const Case cases[] = {
      {[](PhotoSimOptions& o) { o.cameras = 0; }, "cameras"},
      {[](PhotoSimOptions& o) { o.camera_arc_deg = 95; }, "camera_arc_deg"},
      {[](PhotoSimOptions& o) { o.camera_distance_mm = 0; }, "camera_distance_mm"},
      {[](PhotoSimOptions& o) { o.camera_distance_mm = std::nan(""); }, "camera_distance_mm"},
      {[](PhotoSimOptions& o) { o.pixels_per_texel = -1; }, "pixels_per_texel"},
      {[](PhotoSimOptions& o) { o.view_margin = -0.1; }, "view_margin"},
      {[](PhotoSimOptions& o) { o.lights = 0; }, "lights"},
      {[](PhotoSimOptions& o) { o.light_min_elevation_deg = 0; }, "light_min_elevation_deg"},
      {[](PhotoSimOptions& o) { o.light_max_elevation_deg = 10; }, "light_max_elevation_deg"},
      {[](PhotoSimOptions& o) { o.light_max_elevation_deg = 91; }, "light_max_elevation_deg"},
      {[](PhotoSimOptions& o) { o.light_distance_mm = -5; }, "light_distance_mm"},
      {[](PhotoSimOptions& o) { o.white_level = 0; }, "white_level"},
      {[](PhotoSimOptions& o) { o.held_out_lights = -1; }, "held_out_lights"},
      {[](PhotoSimOptions& o) { o.held_out_camera_deg = 100; }, "held_out_camera_deg"},
      {[](PhotoSimOptions& o) { o.noise_sigma = -0.1; }, "noise_sigma"},
      {[](PhotoSimOptions& o) { o.encoding = static_cast<PhotoEncoding>(7); }, "encoding"},
      {[](PhotoSimOptions& o) { o.frame_albedo = 1.5; }, "frame_albedo"},
      {[](PhotoSimOptions& o) { o.jpeg_quality = 30; }, "jpeg_quality"},
      {[](PhotoSimOptions& o) { o.grid_cols = 2; }, "camera grid"},
      {[](PhotoSimOptions& o) { o.grid_cols = o.grid_rows = 65; }, "camera grid"},
      {[](PhotoSimOptions& o) { o.grid_cols = o.grid_rows = 2, o.cameras = 3; }, "cameras"},
      {[](PhotoSimOptions& o) { o.grid_cols = o.grid_rows = 2, o.grid_overlap = 2; },
       "grid_overlap"},
  };
  for (const Case& c : cases) {
    PhotoSimOptions o;
    c.spoil(o);
    const Status s = o.Validate();
    ASSERT_FALSE(s.ok()) << c.field;
    EXPECT_NE(s.message().find(c.field), std::string::npos) << s.message();
  }
  // SimulatePhotoSet refuses them (a caller's bug: validate first).
  const Painting painting = MakePainting(FlatPainting(64));
  const Scene scene(painting, FrameOptions{});
  PhotoSimOptions bad;
  bad.lights = 0;
  EXPECT_THROW(SimulatePhotoSet(scene, RigidTransform{}, bad), InvariantError);
  PaintMaterial broken = Matte({0.5f, 0.5f, 0.5f});
  broken.lafortune.k = -1;
  EXPECT_THROW(SimulatePhotoSet(scene, RigidTransform{}, OneLight(45), {broken}), InvariantError);
  EXPECT_STREQ(ToString(PhotoEncoding::kSrgb16), "srgb16");
}

TEST(PhotoSimOptionsTest, ProgressRisesToOneUnderTheStepRender) {
  const Painting painting = MakePainting(FlatPainting(64));
  const Scene scene(painting, FrameOptions{});
  PhotoSimOptions o;
  o.lights = 4;
  o.held_out_lights = 2;
  std::vector<double> fractions;
  const auto set =
      SimulatePhotoSet(scene, RigidTransform{}, o, {}, [&](std::string_view step, double f) {
        EXPECT_EQ(step, "render");
        fractions.push_back(f);
      });
  ASSERT_GE(fractions.size(), 2u);
  EXPECT_EQ(fractions.front(), 0.0);
  EXPECT_EQ(fractions.back(), 1.0);
  EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()));
  EXPECT_LE(fractions.size(), 110u);
  EXPECT_NE(set.Brief().find("4 images"), std::string::npos) << set.Brief();
}

// ---------------------------------------------------------------------------------------------
// The command line.

int RunCli(const std::string& args, std::string* output) {
  const fs::path log = test::ScratchPath("digitize_photosim_cli").string() + ".log";
  const std::string command =
      std::string(DIGITIZE_CLI) + " " + args + " > " + log.string() + " 2>&1";
  const int status = std::system(command.c_str());
  std::ifstream in(log);
  std::stringstream text;
  text << in.rdbuf();
  *output = text.str();
  fs::remove(log);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST_F(PhotoSimTest, SynthPhotosWritesACalibrationInTheScanFrame) {
  const fs::path out = dir_ / "synth";
  std::string text;
  ASSERT_EQ(RunCli("synth -o " + out.string() +
                       " --resolution 96 --scan-size 128 128 --photos --lights 3 --cameras 2 "
                       "--photo-encoding srgb16 --photo-noise 0.001 --measured",
                   &text),
            0)
      << text;
  EXPECT_NE(text.find("photo set:"), std::string::npos) << text;
  auto set = ReadCalibration(out / "photos" / "calib.json");
  ASSERT_TRUE(set.ok()) << set.error().message;
  EXPECT_EQ(set->photos.size(), 6u);
  EXPECT_TRUE(fs::exists(out / "photos" / "held_out" / "calib.json"));
  EXPECT_TRUE(fs::exists(out / "scan.exr"));
  // The cameras see the canvas through the scan's ground-truth pose.
  std::ifstream in(out / "truth.json");
  const json truth = json::parse(in);
  RigidTransform cfs;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) cfs.rotation(r, c) = truth["canvas_from_scan"]["rotation"][r][c];
    cfs.translation(r) = truth["canvas_from_scan"]["translation"][r];
  }
  const Painting painting = MakePainting([] {
    PaintingOptions o;
    o.resolution_px = 96;
    o.region_count = 7;
    return o;
  }());
  EXPECT_TRUE(CheckCamerasSeeCanvas(*set, cfs, painting.truth).ok());
  const Vec3d centre_scan =
      cfs.Inverse().Apply(Vec3d(0.5 * painting.width_mm, 0.5 * painting.height_mm, 0));
  const Camera& cam = set->photos[0].camera;
  EXPECT_NEAR(cam.Project(centre_scan).x(), cam.cx, 1e-3);
  // --measured puts the measured paint on a region.
  std::ifstream min(out / "photos" / "truth" / "materials.json");
  const json materials = json::parse(min);
  EXPECT_EQ(materials["materials"].back()["model"], "lafortune-measured");

  // Photo flags without --photos are a usage error; without any, the scan alone as before.
  EXPECT_NE(RunCli("synth -o " + (dir_ / "x").string() + " --resolution 64 --lights 3", &text), 0);
  ASSERT_EQ(
      RunCli("synth -o " + (dir_ / "plain").string() + " --resolution 64 --scan-size 64 64", &text),
      0)
      << text;
  EXPECT_FALSE(fs::exists(dir_ / "plain" / "photos"));
  ASSERT_EQ(RunCli("synth --help", &text), 0);
  for (const char* flag :
       {"--photos", "--lights", "--cameras", "--photo-encoding", "--photo-noise", "--measured"})
    EXPECT_NE(text.find(flag), std::string::npos) << flag;
}

}  // namespace
}  // namespace digitize::synth
