// Photo sets: the real RTI capture, calibration JSON round trips, sRGB linearisation, NaN and
// saturation policy, and hostile calibration / .lp files (errors name the file and the entry).
#include "digitize/photo_set.h"

#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "digitize/image_io.h"
#include "digitize/photo_tile_cache.h"
#include "test_paths.h"
#include "test_support.h"

// See io_test.cpp: OIIO 2.4's PNG reader leaks an error string on a libpng longjmp.
extern "C" const char* __lsan_default_suppressions() {
  return "leak:OpenImageIO_v2_4::ImageInput::geterror\n";
}

namespace digitize {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// sRGB EOTF of code 128/255: ((128/255 + 0.055) / 1.055)^2.4, to float precision.
constexpr double kSrgb128 = 0.2158605;
// Linear values go through float: the LUT and the formula agree to a float ulp or so.
constexpr double kFloatTol = 2e-7;

// <repo>/tests/photo_set_test.cpp -> <repo>/../shared/data/rti_icon
fs::path RtiIconDir() {
  return fs::path(DIGITIZE_SOURCE_DIR).parent_path() / "shared" / "data" / "rti_icon";
}

double SrgbExact(double c) { return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4); }

class PhotoSetTest : public test::ScratchDirTest {
 protected:
  PhotoSetTest() : ScratchDirTest("digitize_photo_test") {}

  void WriteText(const std::string& name, const std::string& text) const {
    std::ofstream out(Path(name), std::ios::binary);
    out << text;
  }

  // Writes `values` (interleaved, channels per pixel) as `type` through OIIO.
  template <class T>
  void WriteImage(const std::string& name, int w, int h, int channels, OIIO::TypeDesc type,
                  const std::vector<T>& values) const {
    ASSERT_EQ(values.size(), static_cast<size_t>(w) * h * channels);
    auto out = OIIO::ImageOutput::create(Path(name).string());
    ASSERT_TRUE(out) << name;
    OIIO::ImageSpec spec(w, h, channels, type);
    ASSERT_TRUE(out->open(Path(name).string(), spec)) << out->geterror();
    ASSERT_TRUE(out->write_image(type, values.data())) << out->geterror();
    ASSERT_TRUE(out->close());
  }
};

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

// Bad input must come back as an Error naming the file, the entry or line, and the problem.
template <class T>
void ExpectError(const Result<T>& result, const std::vector<std::string>& words) {
  ASSERT_FALSE(result.ok()) << "expected an error mentioning " << words.front();
  for (const auto& w : words) {
    EXPECT_NE(Lower(result.error().message).find(Lower(w)), std::string::npos)
        << "message does not say '" << w << "': " << result.error().message;
  }
}

// ---------------------------------------------------------------------------------------------
// sRGB.

TEST(SrgbTest, ExactEotfAtKnownPoints) {
  EXPECT_NEAR(SrgbToLinear(128.f / 255.f), kSrgb128, kFloatTol);
  EXPECT_EQ(SrgbToLinear(0.f), 0.f);
  EXPECT_NEAR(SrgbToLinear(1.f), 1.0, 1e-7);
  // The linear toe and the power segment meet at 0.04045 (continuity to ~1e-7 by design).
  EXPECT_NEAR(SrgbToLinear(0.04045f), 0.04045 / 12.92, 1e-7);
  EXPECT_NEAR(SrgbToLinear(0.0405f), SrgbExact(0.0405), 1e-7);
  EXPECT_NEAR(SrgbToLinear(-0.5f), -SrgbExact(0.5), 1e-7);  // odd extension
  for (int code = 0; code < 256; ++code) {
    EXPECT_NEAR(SrgbToLinear(code / 255.f), SrgbExact(code / 255.0), 1e-6) << code;
  }
}

// ---------------------------------------------------------------------------------------------
// The real RTI capture (shared/data/rti_icon).

TEST(RtiIconTest, ReadsTheRealCapture) {
  const fs::path dir = RtiIconDir();
  if (!fs::exists(dir / "dirs.lp")) GTEST_SKIP() << "no RTI capture at " << dir;
  int progress_calls = 0;
  double last_fraction = -1;
  const auto start = std::chrono::steady_clock::now();
  auto set = ReadRtiCapture(dir / "dirs.lp", {}, [&](std::string_view step, double f) {
    ++progress_calls;
    EXPECT_GE(f, last_fraction);
    last_fraction = f;
  });
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_TRUE(set.ok()) << set.error().message;
  std::printf("rti_icon: %s (read in %.3f s)\n", set->summary.Brief().c_str(), seconds);
  EXPECT_TRUE(set->is_rti);
  // Its JPEGs carry no resolution tag (oiiotool --info -v): the pitch is assumed, and said.
  EXPECT_EQ(set->rti_pitch_mm, kRtiAssumedPitchMm);
  EXPECT_TRUE(set->rti_pitch_assumed);
  EXPECT_NE(set->rti_pitch_source.find("402 x 395 mm"), std::string::npos) << set->rti_pitch_source;
  ASSERT_EQ(set->photos.size(), 72u);
  EXPECT_EQ(set->summary.photos_loaded, 72);
  EXPECT_EQ(set->summary.srgb_photos, 72);
  EXPECT_EQ(set->summary.non_finite_pixels, 0u);
  EXPECT_EQ(progress_calls, 73);  // 0, then once per photo
  EXPECT_DOUBLE_EQ(last_fraction, 1.0);
  for (const Photo& p : set->photos) {
    EXPECT_EQ(p.rgb.width, 402);
    EXPECT_EQ(p.rgb.height, 395);
    EXPECT_EQ(p.encoding, ColourEncoding::kSrgb);
    EXPECT_EQ(p.light.type, LightType::kDirectional);
    EXPECT_NEAR(p.light.direction.norm(), 1.0, 1e-12);
    EXPECT_GT(p.light.direction.z(), 0.0);  // every light is above this canvas
    EXPECT_EQ(p.light.irradiance, Vec3f::Ones());
    EXPECT_EQ(p.camera.model, CameraModel::kOrthographic);
  }
  // First line of dirs.lp: image01.jpg 0.205158607891401 -0.237020612397229 0.949595268999854
  EXPECT_EQ(set->photos[0].path.filename(), "image01.jpg");
  EXPECT_NEAR(set->photos[0].light.direction.x(), 0.205158607891401, 1e-6);
  EXPECT_NEAR(set->photos[0].light.direction.y(), -0.237020612397229, 1e-6);

  // Pixels: the decoded 8-bit codes, linearised by the exact EOTF.
  auto in = OIIO::ImageInput::open((dir / "image01.jpg").string());
  ASSERT_TRUE(in);
  std::vector<uint8_t> codes(402 * 395 * 3);
  ASSERT_TRUE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, codes.data()));
  size_t saturated = 0;
  for (int y = 0; y < 395; y += 7) {
    for (int x = 0; x < 402; x += 5) {
      for (int k = 0; k < 3; ++k) {
        const int code = codes[(static_cast<size_t>(y) * 402 + x) * 3 + k];
        ASSERT_NEAR(set->photos[0].rgb(x, y)[k], SrgbExact(code / 255.0), kFloatTol)
            << x << "," << y << " code " << code;
      }
    }
  }
  for (size_t i = 0; i < codes.size(); i += 3) {
    saturated += codes[i] == 255 || codes[i + 1] == 255 || codes[i + 2] == 255;
  }
  EXPECT_EQ(set->photos[0].saturated_pixels, saturated);

  // Geometry: pixel (x, y) sees texel (x, y) of the flat canvas, lit from the stated directions.
  auto flat = FlatCanvasForRti(*set);
  ASSERT_TRUE(flat.ok()) << flat.error().message;
  EXPECT_EQ(flat->width(), 402);
  EXPECT_EQ(flat->height(), 395);
  const Camera& cam = set->photos[0].camera;
  for (const auto& [x, y] : {std::pair{0, 0}, {401, 0}, {0, 394}, {200, 100}}) {
    const Eigen::Vector2d mm = flat->TexelCentreMm(x, y);
    const Eigen::Vector2d px = cam.Project(Vec3d(mm.x(), mm.y(), 0.0));
    EXPECT_NEAR(px.x(), x, 1e-9);
    EXPECT_NEAR(px.y(), y, 1e-9);
    EXPECT_NEAR((cam.DirectionToCamera(Vec3d(mm.x(), mm.y(), 3.0)) - Vec3d::UnitZ()).norm(), 0,
                1e-12);
  }
  EXPECT_TRUE(CheckCamerasSeeCanvas(*set, RigidTransform{}, *flat).ok());
}

// ---------------------------------------------------------------------------------------------
// Calibration JSON.

json TransformJson(const RigidTransform& t) {
  json r = json::array();
  for (int i = 0; i < 3; ++i) r.push_back({t.rotation(i, 0), t.rotation(i, 1), t.rotation(i, 2)});
  return {{"rotation", r},
          {"translation_mm", {t.translation.x(), t.translation.y(), t.translation.z()}}};
}

json PinholeJson(int w, int h, const RigidTransform& pose, double fx = 20.0) {
  return {{"model", "pinhole"}, {"width", w},
          {"height", h},        {"fx", fx},
          {"fy", fx + 1},       {"cx", w / 2.0},
          {"cy", h / 2.0},      {"camera_from_scan", TransformJson(pose)}};
}

// A camera 500 mm above (scan frame: the canvas is z = 500 in front of a camera at the origin).
constexpr int kW = 16, kH = 12;

// Three photos: 8-bit PNG (auto -> sRGB), 16-bit PNG (explicit sRGB), float EXR (auto -> linear),
// with shared and inline cameras, point and directional lights.
class CalibrationTest : public PhotoSetTest {
 protected:
  void SetUp() override {
    PhotoSetTest::SetUp();
    std::vector<uint8_t> p8(kW * kH * 3, 128);
    p8[0] = 255;  // pixel (0, 0) saturated in red
    WriteImage("a.png", kW, kH, 3, OIIO::TypeDesc::UINT8, p8);
    std::vector<uint16_t> p16(kW * kH, 32768);  // grey, 1 channel
    p16[5] = 65535;
    WriteImage("b.png", kW, kH, 1, OIIO::TypeDesc::UINT16, p16);
    std::vector<float> pf(kW * kH * 3);
    for (size_t i = 0; i < pf.size(); ++i) pf[i] = 0.001f * static_cast<float>(i);
    WriteImage("c.exr", kW, kH, 3, OIIO::TypeDesc::FLOAT, pf);

    pose_b_.rotation = Eigen::AngleAxisd(0.3, Vec3d(1, 2, 3).normalized()).toRotationMatrix();
    pose_b_.translation = Vec3d(5, -7, 11);
    doc_ = {{"format", "digitize.calibration"},
            {"version", 1},
            {"units", "mm"},
            {"generator", {{"note", "ignored"}}},
            {"cameras", {PinholeJson(kW, kH, RigidTransform{})}},
            {"lights",
             {{{"type", "point"}, {"position_mm", {100, -50, 0}}, {"intensity", {2e5, 1e5, 5e4}}}}},
            {"images",
             {{{"path", "a.png"}, {"camera", 0}, {"light", 0}},
              {{"path", "b.png"},
               {"camera", PinholeJson(kW, kH, pose_b_, 30.0)},
               {"light", {{"type", "directional"}, {"direction", {0, 0, -2}}, {"irradiance", 0.5}}},
               {"encoding", "srgb"}},
              {{"path", "c.exr"}, {"camera", 0}, {"light", 0}, {"comment", "free text"}}}}};
  }
  Result<PhotoSet> Read(const PhotoSetOptions& options = {}) {
    WriteText("calib.json", doc_.dump(2));
    return ReadCalibration(Path("calib.json"), options);
  }

  RigidTransform pose_b_;
  json doc_;
};

TEST_F(CalibrationTest, RoundTrip) {
  auto set = Read();
  ASSERT_TRUE(set.ok()) << set.error().message;
  ASSERT_EQ(set->photos.size(), 3u);
  EXPECT_FALSE(set->is_rti);
  const Photo& a = set->photos[0];
  const Photo& b = set->photos[1];
  const Photo& c = set->photos[2];
  EXPECT_EQ(a.path, Path("a.png"));
  EXPECT_NE(a.entry.find("images[0]"), std::string::npos);

  // Cameras.
  EXPECT_EQ(a.camera.model, CameraModel::kPinhole);
  EXPECT_EQ(a.camera.width, kW);
  EXPECT_DOUBLE_EQ(a.camera.fx, 20.0);
  EXPECT_DOUBLE_EQ(a.camera.fy, 21.0);
  EXPECT_DOUBLE_EQ(a.camera.cx, kW / 2.0);
  const Eigen::Vector2d px = a.camera.Project(Vec3d(10, -5, 500));
  EXPECT_NEAR(px.x(), 20.0 * 10 / 500 + kW / 2.0, 1e-12);
  EXPECT_NEAR(px.y(), 21.0 * -5 / 500 + kH / 2.0, 1e-12);
  EXPECT_NEAR((b.camera.camera_from_scan.rotation - pose_b_.rotation).norm(), 0, 1e-12);
  EXPECT_NEAR((b.camera.CentreInScan() - pose_b_.Inverse().translation).norm(), 0, 1e-12);
  EXPECT_NEAR(b.camera.fx, 30.0, 0);

  // Lights.
  EXPECT_EQ(a.light.type, LightType::kPoint);
  EXPECT_EQ(a.light.position_mm, Vec3d(100, -50, 0));
  EXPECT_EQ(a.light.intensity, Vec3f(2e5f, 1e5f, 5e4f));
  const Vec3d p(100, -50, 100);  // 100 mm from the light
  EXPECT_NEAR(a.light.IrradianceAt(p).x(), 2e5 / 1e4, 1e-4);
  EXPECT_NEAR((a.light.DirectionTo(p) - Vec3d(0, 0, -1)).norm(), 0, 1e-12);
  EXPECT_EQ(b.light.type, LightType::kDirectional);
  EXPECT_EQ(b.light.direction, Vec3d(0, 0, -1));  // normalised
  EXPECT_EQ(b.light.irradiance, Vec3f::Constant(0.5f));

  // Pixels and encodings.
  EXPECT_EQ(a.encoding, ColourEncoding::kSrgb);    // 8-bit PNG, auto
  EXPECT_EQ(b.encoding, ColourEncoding::kSrgb);    // explicit
  EXPECT_EQ(c.encoding, ColourEncoding::kLinear);  // EXR, auto
  EXPECT_NEAR(a.rgb(3, 4).x(), kSrgb128, kFloatTol);
  EXPECT_NEAR(a.rgb(3, 4).z(), kSrgb128, kFloatTol);
  EXPECT_FLOAT_EQ(a.rgb(0, 0).x(), 1.0f);
  EXPECT_EQ(a.Flags(0, 0), kPixelSaturated);
  EXPECT_TRUE(a.Usable(1, 0));
  EXPECT_EQ(a.saturated_pixels, 1u);
  // 16-bit grey: every channel the exact EOTF of 32768 / 65535.
  const double lin16 = SrgbExact(32768.0 / 65535.0);
  EXPECT_NEAR(b.rgb(1, 1).x(), lin16, kFloatTol);
  EXPECT_EQ(b.rgb(1, 1).x(), b.rgb(1, 1).y());
  EXPECT_EQ(b.rgb(1, 1).x(), b.rgb(1, 1).z());
  EXPECT_NE(b.rgb(1, 1).x(), SrgbToLinear(128.f / 255.f));  // not quantised to 8 bits
  EXPECT_EQ(b.Flags(5, 0), kPixelSaturated);
  EXPECT_EQ(b.saturated_pixels, 1u);
  // Linear EXR: values as written.
  EXPECT_FLOAT_EQ(c.rgb(2, 1).y(), 0.001f * ((1 * kW + 2) * 3 + 1));
  EXPECT_TRUE(c.flags.empty());
  EXPECT_EQ(set->summary.photos_loaded, 3);
  EXPECT_EQ(set->summary.saturated_pixels, 2u);
  EXPECT_EQ(set->summary.srgb_photos, 2);
  EXPECT_EQ(set->summary.linear_photos, 1);
}

TEST_F(CalibrationTest, LazyLoadingThenLoad) {
  PhotoSetOptions options;
  options.load_pixels = false;
  auto set = Read(options);
  ASSERT_TRUE(set.ok()) << set.error().message;
  for (const Photo& p : set->photos) EXPECT_FALSE(p.loaded());
  EXPECT_EQ(set->photos[0].encoding, ColourEncoding::kSrgb);  // resolved from the header
  EXPECT_EQ(set->photos[2].encoding, ColourEncoding::kLinear);
  ASSERT_TRUE(LoadPhotoPixels(*set).ok());
  for (const Photo& p : set->photos) EXPECT_TRUE(p.loaded());
}

TEST_F(CalibrationTest, SaturationThresholdAndEncodingOverride) {
  doc_["images"][0]["encoding"] = "linear";
  PhotoSetOptions options;
  options.saturation_encoded = 0.5f;  // 128/255 = 0.502 counts as saturated now
  options.float_saturation_level = 0.5f;
  auto set = Read(options);
  ASSERT_TRUE(set.ok()) << set.error().message;
  EXPECT_NEAR(set->photos[0].rgb(3, 4).x(), 128.0 / 255.0, 1e-7);  // linear as declared
  EXPECT_EQ(set->photos[0].saturated_pixels, static_cast<size_t>(kW * kH));
  // EXR: values >= 0.5 in some channel (0.001 * index).
  size_t expected = 0;
  for (int i = 0; i < kW * kH; ++i) expected += 0.001f * static_cast<float>(3 * i + 2) >= 0.5f;
  EXPECT_EQ(set->photos[2].saturated_pixels, expected);
}

TEST_F(CalibrationTest, NanPixelsAreCountedAndZeroed) {
  std::vector<float> pf(kW * kH * 3, 0.25f);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  pf[0] = nan;                                             // pixel 0
  pf[3 * 7 + 2] = std::numeric_limits<float>::infinity();  // pixel 7
  pf[3 * 9 + 1] = -nan;                                    // pixel 9
  WriteImage("c.exr", kW, kH, 3, OIIO::TypeDesc::FLOAT, pf);
  auto set = Read();
  ASSERT_TRUE(set.ok()) << set.error().message;
  const Photo& c = set->photos[2];
  EXPECT_EQ(c.non_finite_pixels, 3u);
  EXPECT_EQ(set->summary.non_finite_pixels, 3u);
  for (int i : {0, 7, 9}) {
    EXPECT_EQ(c.rgb(i, 0), Vec3f::Zero()) << i;
    EXPECT_EQ(c.Flags(i, 0), kPixelNonFinite) << i;
  }
  EXPECT_EQ(c.rgb(1, 0), Vec3f::Constant(0.25f));
  for (const Photo& p : set->photos) {
    for (const Vec3f& v : p.rgb.data) ASSERT_TRUE(v.allFinite());
  }
  // A photo that is mostly NaN is corrupt: refused, naming the file.
  std::fill(pf.begin(), pf.begin() + pf.size() * 3 / 4, nan);
  WriteImage("c.exr", kW, kH, 3, OIIO::TypeDesc::FLOAT, pf);
  ExpectError(Read(), {"calib.json", "images[2]", "c.exr", "NaN"});
}

TEST_F(CalibrationTest, Progress) {
  std::vector<double> fractions;
  WriteText("calib.json", doc_.dump());
  auto set = ReadCalibration(Path("calib.json"), {},
                             [&](std::string_view step, double f) { fractions.push_back(f); });
  ASSERT_TRUE(set.ok()) << set.error().message;
  ASSERT_EQ(fractions.size(), 4u);
  EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()));
  EXPECT_DOUBLE_EQ(fractions.back(), 1.0);
}

TEST_F(CalibrationTest, HostileGeometry) {
  {  // scaled rotation: det 0.512
    json camera = PinholeJson(kW, kH, RigidTransform{});
    camera["camera_from_scan"]["rotation"] = {{0.8, 0, 0}, {0, 0.8, 0}, {0, 0, 0.8}};
    doc_["images"][1]["camera"] = camera;
    ExpectError(Read(), {"calib.json", "images[1].camera.camera_from_scan.rotation",
                         "not a rotation", "det 0.512"});
  }
  {  // reflection
    json camera = PinholeJson(kW, kH, RigidTransform{});
    camera["camera_from_scan"]["rotation"] = {{1, 0, 0}, {0, 1, 0}, {0, 0, -1}};
    doc_["images"][1]["camera"] = camera;
    ExpectError(Read(), {"calib.json", "images[1]", "rotation", "reflection"});
  }
  {  // rounded to 6 decimals: accepted and snapped onto a rotation
    json camera = PinholeJson(kW, kH, pose_b_);
    for (auto& row : camera["camera_from_scan"]["rotation"])
      for (auto& v : row) v = std::round(v.get<double>() * 1e6) / 1e6;
    doc_["images"][1]["camera"] = camera;
    auto set = Read();
    ASSERT_TRUE(set.ok()) << set.error().message;
    const Mat3d& R = set->photos[1].camera.camera_from_scan.rotation;
    EXPECT_NEAR((R.transpose() * R - Mat3d::Identity()).norm(), 0, 1e-12);
    EXPECT_NEAR((R - pose_b_.rotation).norm(), 0, 1e-5);
  }
  doc_["images"][1]["camera"] = PinholeJson(kW, kH, pose_b_);
  {  // negative focal length in a shared camera
    doc_["cameras"][0]["fx"] = -500;
    ExpectError(Read(), {"calib.json", "cameras[0].fx", "> 0", "-500"});
    doc_["cameras"][0]["fx"] = 20.0;
  }
  {
    doc_["cameras"][0]["width"] = 0;
    ExpectError(Read(), {"calib.json", "cameras[0].width"});
    doc_["cameras"][0]["width"] = kW;
  }
  {
    doc_["images"][2]["camera"] = 3;
    ExpectError(Read(), {"calib.json", "images[2].camera", "cameras"});
    doc_["images"][2]["camera"] = 0;
  }
  {
    doc_["images"][1]["light"]["direction"] = {0, 0, 0};
    ExpectError(Read(), {"calib.json", "images[1].light.direction", "zero"});
    doc_["images"][1]["light"]["direction"] = {0, 0, 1};
  }
  {
    doc_["lights"][0]["intensity"] = {1, -1, 1};
    ExpectError(Read(), {"calib.json", "lights[0].intensity"});
    doc_["lights"][0]["intensity"] = 0;
    ExpectError(Read(), {"calib.json", "lights[0].intensity", "zero"});
    doc_["lights"][0]["intensity"] = 1e5;
  }
  {
    doc_["lights"][0]["type"] = "spot";
    ExpectError(Read(), {"calib.json", "lights[0].type", "spot"});
    doc_["lights"][0]["type"] = "point";
  }
  EXPECT_TRUE(Read().ok());
}

TEST_F(CalibrationTest, HostileFiles) {
  {  // image of the wrong size
    WriteImage("small.png", kW - 1, kH, 3, OIIO::TypeDesc::UINT8,
               std::vector<uint8_t>((kW - 1) * kH * 3, 7));
    doc_["images"][1]["path"] = "small.png";
    ExpectError(Read(), {"calib.json", "images[1]", "small.png", "15x12", "16x12"});
  }
  {  // missing image
    doc_["images"][1]["path"] = "nowhere.png";
    ExpectError(Read(), {"calib.json", "images[1]", "nowhere.png", "no such file"});
  }
  {  // not an image
    WriteText("junk.png", "this is not a PNG");
    doc_["images"][1]["path"] = "junk.png";
    ExpectError(Read(), {"calib.json", "images[1]", "junk.png", "unreadable"});
  }
  {  // 2 channels (grey + alpha) is not a photo this reads
    WriteImage("ga.png", kW, kH, 2, OIIO::TypeDesc::UINT8, std::vector<uint8_t>(kW * kH * 2, 9));
    doc_["images"][1]["path"] = "ga.png";
    ExpectError(Read(), {"images[1]", "ga.png", "channels"});
  }
  {  // RGBA (a PNG saved with alpha) is read as its RGB; alpha is dropped
    std::vector<uint8_t> rgba(kW * kH * 4, 9);
    for (size_t i = 3; i < rgba.size(); i += 4) rgba[i] = 0;  // fully transparent: ignored
    WriteImage("rgba.png", kW, kH, 4, OIIO::TypeDesc::UINT8, rgba);
    doc_["images"][1]["path"] = "rgba.png";
    auto set = Read();
    ASSERT_TRUE(set.ok()) << set.error().message;
    EXPECT_NEAR(set->photos[1].rgb(2, 3).y(), SrgbToLinear(9.0f / 255.0f), 1e-7);
  }
  {  // RGBA as float (an EXR, linear): the same, through the float path; values exact
    std::vector<float> rgba(kW * kH * 4);
    for (size_t i = 0; i < rgba.size(); i += 4) {
      rgba[i] = 0.25f, rgba[i + 1] = 0.5f, rgba[i + 2] = 0.75f;
      rgba[i + 3] = 0.0f;
    }
    WriteImage("rgba.exr", kW, kH, 4, OIIO::TypeDesc::FLOAT, rgba);
    doc_["images"][1]["path"] = "rgba.exr";
    const json declared = doc_["images"][1].value("encoding", json());
    doc_["images"][1]["encoding"] = "linear";
    auto set = Read();
    ASSERT_TRUE(set.ok()) << set.error().message;
    EXPECT_EQ(set->photos[1].rgb(2, 3), Vec3f(0.25f, 0.5f, 0.75f));
    if (declared.is_null())
      doc_["images"][1].erase("encoding");
    else
      doc_["images"][1]["encoding"] = declared;
  }
  doc_["images"][1]["path"] = "b.png";
  {
    doc_["version"] = 2;
    ExpectError(Read(), {"calib.json", "version 2", "not supported"});
    doc_["version"] = 1;
  }
  {
    doc_["format"] = "digitize.boxes";
    ExpectError(Read(), {"calib.json", "not a calibration file"});
    doc_["format"] = "digitize.calibration";
  }
  {
    doc_["images"][0]["encodng"] = "linear";
    ExpectError(Read(), {"calib.json", "images[0]", "unknown key", "encodng"});
    doc_["images"][0].erase("encodng");
  }
  {
    doc_["images"][0]["encoding"] = "gamma22";
    ExpectError(Read(), {"calib.json", "images[0].encoding", "gamma22"});
    doc_["images"][0].erase("encoding");
  }
  {
    doc_["images"] = json::array();
    ExpectError(Read(), {"calib.json", "images", "empty"});
  }
  {
    WriteText("calib.json", "{\"format\": \"digitize.calibration\", \"version\": 1,");
    ExpectError(ReadCalibration(Path("calib.json")), {"calib.json", "not valid JSON"});
  }
  ExpectError(ReadCalibration(Path("absent.json")), {"absent.json", "no such file"});
  PhotoSetOptions bad;
  bad.saturation_encoded = 0;
  ExpectError(ReadCalibration(Path("calib.json"), bad), {"saturation_encoded"});
}

// A shared capture must not make the reader open files outside its folder: "..", absolute paths
// and symbolic links that leave it are refused, naming the file, the entry and the path, unless
// allow_outside_paths says otherwise.
TEST_F(CalibrationTest, ImagePathsOutsideTheCaptureFolderAreRefused) {
  fs::create_directories(Path("capture/images"));
  fs::copy_file(Path("a.png"), Path("capture/images/a.png"));
  fs::create_symlink(Path("b.png"), Path("capture/link.png"));
  auto read = [&](const std::string& image, const PhotoSetOptions& options = {}) {
    doc_["images"] = {{{"path", image}, {"camera", 0}, {"light", 0}}};
    WriteText("capture/calib.json", doc_.dump(2));
    return ReadCalibration(Path("capture/calib.json"), options);
  };
  EXPECT_TRUE(read("images/a.png").ok());
  EXPECT_TRUE(read("images/../images/a.png").ok());  // ".." that stays inside
  for (const std::string& outside : {std::string("../a.png"), Path("c.exr").string(),
                                     std::string("link.png"), std::string("/etc/passwd")}) {
    SCOPED_TRACE(outside);
    ExpectError(read(outside), {"capture/calib.json: images[0]", outside,
                                "outside the capture folder", "--allow-outside-paths"});
  }
  PhotoSetOptions allow;
  allow.allow_outside_paths = true;
  EXPECT_TRUE(read("../a.png", allow).ok());
  EXPECT_TRUE(read("link.png", allow).ok());
}

// ---------------------------------------------------------------------------------------------
// Cameras and the canvas.

TEST(CameraTest, SeesCanvasOrNot) {
  // Canvas 200 x 100 mm; scan frame = canvas frame. A camera 500 mm above its centre looking down.
  const Eigen::Vector2d extent(200, 100);
  Camera cam;
  cam.width = 640;
  cam.height = 480;
  cam.fx = cam.fy = 1000;
  cam.cx = 319.5;
  cam.cy = 239.5;
  cam.camera_from_scan.rotation = Vec3d(1, -1, -1).asDiagonal();
  cam.camera_from_scan.translation = Vec3d(-100, 50, 500);  // centre at (100, 50, 500)
  ASSERT_TRUE(cam.Validate("cam").ok());
  EXPECT_NEAR((cam.CentreInScan() - Vec3d(100, 50, 500)).norm(), 0, 1e-12);
  EXPECT_TRUE(CheckCameraSeesCanvas(cam, RigidTransform{}, extent, "cam").ok());
  const Eigen::Vector2d c = cam.Project(Vec3d(100, 50, 0));
  EXPECT_NEAR(c.x(), 319.5, 1e-12);
  EXPECT_NEAR(c.y(), 239.5, 1e-12);

  // Under the canvas, looking up at its back.
  Camera under = cam;
  under.camera_from_scan.rotation = Mat3d::Identity();
  under.camera_from_scan.translation = Vec3d(-100, -50, 500);  // centre at (100, 50, -500)
  Status s = CheckCameraSeesCanvas(under, RigidTransform{}, extent, "calib.json: images[4]");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("images[4]"), std::string::npos);
  EXPECT_NE(s.message().find("behind the canvas"), std::string::npos) << s.message();

  // Above, but looking away (the canvas is behind the camera).
  Camera away = cam;
  away.camera_from_scan.rotation = Mat3d::Identity();
  away.camera_from_scan.translation = -Vec3d(100, 50, 500);
  s = CheckCameraSeesCanvas(away, RigidTransform{}, extent, "calib.json: images[5]");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("behind the camera"), std::string::npos) << s.message();

  // Looking down, but far to the side: sees none of it.
  Camera aside = cam;
  aside.camera_from_scan.translation = Vec3d(-5000, 50, 500);
  s = CheckCameraSeesCanvas(aside, RigidTransform{}, extent, "x");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("none of the canvas"), std::string::npos) << s.message();

  // A non-rotation built in code is caught by Validate.
  Camera sheared = cam;
  sheared.camera_from_scan.rotation(0, 1) = 0.2;
  EXPECT_FALSE(sheared.Validate("cam").ok());
}

// ---------------------------------------------------------------------------------------------
// RTI .lp files.

class LpTest : public PhotoSetTest {
 protected:
  void SetUp() override {
    PhotoSetTest::SetUp();
    for (const char* name : {"i1.png", "i2.png", "i 3.png"}) {
      WriteImage(name, 8, 6, 3, OIIO::TypeDesc::UINT8, std::vector<uint8_t>(8 * 6 * 3, 128));
    }
  }
  Result<PhotoSet> ReadLp(const std::string& text) {
    WriteText("dirs.lp", text);
    return ReadRtiCapture(Path("dirs.lp"));
  }
};

TEST_F(LpTest, ToleratesBomCrlfBlankLinesCommentsTabsAndUnnormalised) {
  auto set = ReadLp(
      "\xEF\xBB\xBF# written by hand, UTF-8 BOM first\r\n\r\n3\r\n"
      "i1.png 0 0 1\r\n"
      "\r\n"
      "  i2.png\t0.6\t0.0\t0.8   # comment\r\n"
      "i 3.png 0 +3 4\r\n");
  ASSERT_TRUE(set.ok()) << set.error().message;
  ASSERT_EQ(set->photos.size(), 3u);
  EXPECT_EQ(set->photos[2].path.filename(), "i 3.png");
  EXPECT_NEAR((set->photos[2].light.direction - Vec3d(0, 0.6, 0.8)).norm(), 0, 1e-15);
  EXPECT_NEAR((set->photos[1].light.direction - Vec3d(0.6, 0, 0.8)).norm(), 0, 1e-15);
  EXPECT_NE(set->photos[1].entry.find("line 6"), std::string::npos) << set->photos[1].entry;
  EXPECT_NEAR(set->photos[0].rgb(7, 5).y(), kSrgb128, kFloatTol);
  // Windows paths from the capture machine: looked up by file name.
  set = ReadLp("2\nC:\\capture\\day1\\i1.png 0 0 1\n/elsewhere/i2.png 0 1 1");
  ASSERT_TRUE(set.ok()) << set.error().message;
  EXPECT_EQ(set->photos[0].path, Path("i1.png"));
  EXPECT_EQ(set->photos[1].path, Path("i2.png"));
  EXPECT_NEAR(set->photos[1].light.direction.norm(), 1, 1e-15);
}

TEST_F(LpTest, Hostile) {
  ExpectError(ReadLp("3\ni1.png 0 0 1\ni2.png 0 0 1\n"),
              {"dirs.lp", "line 1", "announces 3", "lists 2"});
  ExpectError(ReadLp("1\ni1.png 0 0 1\ni2.png 0 0 1\n"), {"dirs.lp", "line 3", "more entries"});
  ExpectError(ReadLp("three\ni1.png 0 0 1\n"), {"dirs.lp", "line 1", "bad image count"});
  ExpectError(ReadLp("-2\ni1.png 0 0 1\n"), {"dirs.lp", "line 1", "count"});
  ExpectError(ReadLp("2\ni1.png 0 0 1\ni2.png 0 abc 1\n"),
              {"dirs.lp", "line 3", "abc", "not a number", "y of i2.png"});
  ExpectError(ReadLp("2\ni1.png 0 0 1\ni2.png 0 nan 1\n"), {"dirs.lp", "line 3", "not finite"});
  ExpectError(ReadLp("2\ni1.png 0 0 1\n\ni2.png 0 0 0\n"),
              {"dirs.lp", "line 4", "zero light direction", "i2.png"});
  ExpectError(ReadLp("2\ni1.png 0 0 1\ni2.png 0 1\n"), {"dirs.lp", "line 3", "filename x y z"});
  ExpectError(ReadLp("2\ni1.png 0 0 1\ngone.png 0 0 1\n"),
              {"dirs.lp", "line 3", "gone.png", "no such file"});
  ExpectError(ReadLp(""), {"dirs.lp", "no image count"});
  ExpectError(ReadLp("# only a comment\n\n"), {"dirs.lp", "no image count"});
  ExpectError(ReadRtiCapture(Path("absent.lp")), {"absent.lp", "no such file"});
  // An image of another size than the first.
  WriteImage("big.png", 9, 6, 3, OIIO::TypeDesc::UINT8, std::vector<uint8_t>(9 * 6 * 3, 1));
  ExpectError(ReadLp("2\ni1.png 0 0 1\nbig.png 0 0 1\n"),
              {"dirs.lp", "line 3", "big.png", "9x6", "8x6"});
  // Not RTI: no flat canvas.
  EXPECT_FALSE(FlatCanvasForRti(PhotoSet{}).ok());
}

TEST_F(LpTest, ImagePathsOutsideTheCaptureFolderAreRefused) {
  fs::create_directories(Path("capture"));
  fs::copy_file(Path("i1.png"), Path("capture/i1.png"));
  fs::create_symlink(Path("i2.png"), Path("capture/link.png"));
  auto read = [&](const std::string& text, const PhotoSetOptions& options = {}) {
    WriteText("capture/dirs.lp", text);
    return ReadRtiCapture(Path("capture/dirs.lp"), options);
  };
  EXPECT_TRUE(read("1\ni1.png 0 0 1\n").ok());
  ExpectError(read("2\ni1.png 0 0 1\n../i2.png 0 0 1\n"),
              {"capture/dirs.lp, line 3", "../i2.png", "outside the capture folder"});
  ExpectError(read("2\ni1.png 0 0 1\n" + Path("i2.png").string() + " 0 0 1\n"),
              {"capture/dirs.lp, line 3", "outside the capture folder"});
  ExpectError(read("2\ni1.png 0 0 1\nlink.png 0 0 1\n"),
              {"capture/dirs.lp, line 3", "link.png", "outside the capture folder"});
  // A path of the capture machine that does not exist here still falls back to the file name.
  EXPECT_TRUE(read("1\n/capture-pc/day1/i1.png 0 0 1\n").ok());
  PhotoSetOptions allow;
  allow.allow_outside_paths = true;
  EXPECT_TRUE(read("2\ni1.png 0 0 1\n../i2.png 0 0 1\n", allow).ok());
}

// An RTI capture's pixel pitch: given, else the first image's resolution tag (TIFF, JPEG JFIF,
// PNG pHYs, as OpenImageIO reads them), else assumed and said.
TEST_F(LpTest, PitchFromResolutionTagsElseSaidToBeAssumed) {
  auto write_tagged = [&](const std::string& name, float per_unit, const char* unit) {
    auto out = OIIO::ImageOutput::create(Path(name).string());
    ASSERT_TRUE(out) << name;
    OIIO::ImageSpec spec(8, 6, 3, OIIO::TypeDesc::UINT8);
    spec.attribute("XResolution", per_unit);
    spec.attribute("YResolution", per_unit);
    spec.attribute("ResolutionUnit", unit);
    const std::vector<uint8_t> px(8 * 6 * 3, 128);
    ASSERT_TRUE(out->open(Path(name).string(), spec)) << out->geterror();
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, px.data())) << out->geterror();
    ASSERT_TRUE(out->close());
  };
  struct Case {
    const char* name;
    float per_unit;
    const char* unit;
    double mm;
    double tol;  // PNG stores whole pixels per metre
  };
  for (const Case& c :
       {Case{"t.tif", 300, "in", 25.4 / 300, 1e-9}, Case{"t.jpg", 40, "cm", 10.0 / 40, 1e-9},
        Case{"t.png", 600, "in", 25.4 / 600, 1e-4 * 25.4 / 600}}) {
    write_tagged(c.name, c.per_unit, c.unit);
    auto set = ReadLp(std::string("2\n") + c.name + " 0 0 1\ni1.png 0.6 0 0.8\n");
    ASSERT_TRUE(set.ok()) << set.error().message;
    EXPECT_NEAR(set->rti_pitch_mm, c.mm, c.tol) << c.name;
    EXPECT_FALSE(set->rti_pitch_assumed) << c.name;
    EXPECT_NE(set->rti_pitch_source.find(c.name), std::string::npos) << set->rti_pitch_source;
    EXPECT_NEAR(set->photos[1].camera.pixel_pitch_mm, c.mm, c.tol) << "one camera for all photos";
    auto flat = FlatCanvasForRti(*set);
    ASSERT_TRUE(flat.ok());
    EXPECT_NEAR(flat->pitch_mm, c.mm, c.tol);
  }
  // Given: overrides the tag.
  PhotoSetOptions given;
  given.rti_pixel_pitch_mm = 0.5;
  WriteText("dirs.lp", "2\nt.tif 0 0 1\ni1.png 0.6 0 0.8\n");
  auto set = ReadRtiCapture(Path("dirs.lp"), given);
  ASSERT_TRUE(set.ok()) << set.error().message;
  EXPECT_EQ(set->rti_pitch_mm, 0.5);
  EXPECT_FALSE(set->rti_pitch_assumed);
  EXPECT_NE(set->rti_pitch_source.find("given"), std::string::npos) << set->rti_pitch_source;
  // No tag on the first image: assumed, with the size it makes up.
  set = ReadLp("2\ni1.png 0 0 1\nt.tif 0.6 0 0.8\n");
  ASSERT_TRUE(set.ok()) << set.error().message;
  EXPECT_EQ(set->rti_pitch_mm, kRtiAssumedPitchMm);
  EXPECT_TRUE(set->rti_pitch_assumed);
  EXPECT_NE(set->rti_pitch_source.find("8 x 6 mm"), std::string::npos) << set->rti_pitch_source;
  // A camera's 72 (or 96) per inch is a software default, not the canvas's scale: assumed, and
  // said why.
  for (float dpi : {72.0f, 96.0f}) {
    write_tagged("default.jpg", dpi, "in");
    set = ReadLp("2\ndefault.jpg 0 0 1\ni1.png 0.6 0 0.8\n");
    ASSERT_TRUE(set.ok()) << set.error().message;
    EXPECT_EQ(set->rti_pitch_mm, kRtiAssumedPitchMm) << dpi;
    EXPECT_TRUE(set->rti_pitch_assumed) << dpi;
    EXPECT_NE(set->rti_pitch_source.find("software default"), std::string::npos)
        << set->rti_pitch_source;
  }
  // A tag of 0.01 per inch (2.54 m per pixel) is no scale either.
  write_tagged("default.jpg", 0.01f, "in");
  set = ReadLp("2\ndefault.jpg 0 0 1\ni1.png 0.6 0 0.8\n");
  ASSERT_TRUE(set.ok()) << set.error().message;
  EXPECT_TRUE(set->rti_pitch_assumed);
  EXPECT_NE(set->rti_pitch_source.find("not a plausible scale"), std::string::npos)
      << set->rti_pitch_source;
  // A negative, non-finite or absurd pitch is refused by name (1e-300 used to reach the pack).
  for (double bad : {-1.0, 1e-300, 1e9, std::numeric_limits<double>::quiet_NaN()}) {
    given.rti_pixel_pitch_mm = bad;
    ExpectError(ReadRtiCapture(Path("dirs.lp"), given), {"rti_pixel_pitch_mm"});
  }
}

// ---------------------------------------------------------------------------------------------
// Load timing at the SPEC's size (64 photos of 2048x2048). Not a timed test: run by hand with
//   photo_set_test --gtest_also_run_disabled_tests --gtest_filter='*Load64*'
// It writes ~64 JPEGs (about 100 MB) and 8 16-bit PNGs to the temporary folder first.

TEST_F(PhotoSetTest, DISABLED_Load64Photos2048) {
  constexpr int kSide = 2048, kJpegs = 64, kPngs = 8;
  std::vector<uint8_t> p8(static_cast<size_t>(kSide) * kSide * 3);
  std::vector<uint16_t> p16(p8.size());
  std::string lp = std::to_string(kJpegs) + "\n", lp16 = std::to_string(kPngs) + "\n";
  for (int i = 0; i < kJpegs; ++i) {
    for (size_t j = 0; j < p8.size(); ++j) {
      const size_t px = j / 3;
      p8[j] = static_cast<uint8_t>((px % kSide + px / kSide * 3 + i * 17 + (j % 3) * 40) & 255);
      p16[j] = static_cast<uint16_t>(p8[j] * 257 + (px & 255));
    }
    const std::string name = "img" + std::to_string(i) + ".jpg";
    WriteImage(name, kSide, kSide, 3, OIIO::TypeDesc::UINT8, p8);
    lp += name + " 0.1 0.2 0.9\n";
    if (i < kPngs) {
      WriteImage("img" + std::to_string(i) + ".png", kSide, kSide, 3, OIIO::TypeDesc::UINT16, p16);
      lp16 += "img" + std::to_string(i) + ".png 0.1 0.2 0.9\n";
    }
  }
  WriteText("jpegs.lp", lp);
  WriteText("pngs.lp", lp16);
  for (const char* name : {"jpegs.lp", "pngs.lp"}) {
    const auto start = std::chrono::steady_clock::now();
    auto set = ReadRtiCapture(Path(name));
    const double s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    ASSERT_TRUE(set.ok()) << set.error().message;
    std::printf("%s: %s; total %.2f s, %.1f ms per photo\n", name, set->summary.Brief().c_str(), s,
                1e3 * s / set->photos.size());
  }
}

// ---------------------------------------------------------------------------------------------
// Absurd inputs (docs/refusals.md): intrinsics, canvas footprint, duplicate images, extra .lp
// columns.

TEST_F(CalibrationTest, AbsurdIntrinsicsAreRefusedNamingTheEntry) {
  // fx = 1e-300 "fitted 76.9 % converged": a 180-degree view in which the canvas is one pixel.
  doc_["cameras"][0]["fx"] = 1e-300;
  ExpectError(Read(), {"calib.json", "cameras[0].fx", "field of view", "180 deg", "0.1 to 170"});
  doc_["cameras"][0]["fx"] = 1e9;  // 1e-6 deg: fx in nm, or a stray exponent
  ExpectError(Read(), {"calib.json", "cameras[0].fx", "horizontal field of view"});
  doc_["cameras"][0]["fx"] = 20.0;
  doc_["images"][1]["camera"]["fy"] = 0.5;  // 170.5 deg vertically over 12 px
  ExpectError(Read(), {"calib.json", "images[1].camera.fy", "vertical field of view", "170.5"});
  doc_["images"][1]["camera"]["fy"] = 31.0;
  doc_["cameras"][0]["cx"] = 3 * kW + 0.5;  // two image widths beyond the right edge
  ExpectError(Read(), {"calib.json", "cameras[0].cx", "outside", "-16 to 32"});
  doc_["cameras"][0]["cx"] = -kW;  // exactly one image width to the left: a shifted lens, kept
  ASSERT_TRUE(Read().ok());
  doc_["cameras"][0]["cy"] = -2.0 * kH;
  ExpectError(Read(), {"calib.json", "cameras[0].cy"});
  doc_["cameras"][0]["cx"] = kW / 2.0;
  doc_["cameras"][0]["cy"] = kH / 2.0;
  // Just inside the bounds: accepted.
  doc_["cameras"][0]["fx"] = kW / (2 * std::tan(0.5 * kMaxFieldOfViewDeg * M_PI / 180)) * 1.001;
  EXPECT_TRUE(Read().ok());
}

TEST(CameraTest, CanvasFootprintMustBeUsable) {
  // Canvas 200 x 100 mm, pitch 0.5 mm; a 640x480 camera 500 mm above: 2 px per mm.
  const Eigen::Vector2d extent(200, 100);
  Camera cam;
  cam.width = 640;
  cam.height = 480;
  cam.fx = cam.fy = 1000;
  cam.cx = 319.5;
  cam.cy = 239.5;
  cam.camera_from_scan.rotation = Vec3d(1, -1, -1).asDiagonal();
  cam.camera_from_scan.translation = Vec3d(-100, 50, 500);
  EXPECT_TRUE(CheckCanvasFootprint(cam, RigidTransform{}, extent, 0.5, "cam").ok());

  // A kilometre away (distance in mm read as m): the canvas is 0.2 x 0.1 px.
  Camera far = cam;
  far.camera_from_scan.translation.z() = 1e6;
  ASSERT_TRUE(CheckCameraSeesCanvas(far, RigidTransform{}, extent, "x").ok());
  Status s = CheckCanvasFootprint(far, RigidTransform{}, extent, 0.5, "calib.json: images[2]");
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message().rfind("calib.json: images[2]: ", 0), 0u) << s.message();
  EXPECT_NE(s.message().find("spans only 0.2 x 0.1 px"), std::string::npos) << s.message();

  // A canvas of pitch 1 um in this photo: each pixel spans 500 texels.
  s = CheckCanvasFootprint(cam, RigidTransform{}, extent, 0.001, "cam");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("spans 500 texels"), std::string::npos) << s.message();
  EXPECT_TRUE(
      CheckCanvasFootprint(cam, RigidTransform{}, extent, 0.5 / kMaxTexelsPerPixel * 1.01, "cam")
          .ok());

  // An orthographic camera of 0.1 um pixels: one 0.5 mm texel spans 5000 px.
  Camera ortho = cam;
  ortho.model = CameraModel::kOrthographic;
  ortho.pixel_pitch_mm = 1e-4;
  s = CheckCanvasFootprint(ortho, RigidTransform{}, extent, 0.5, "cam");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("spans 5000 pixels"), std::string::npos) << s.message();

  // Seen edge-on at 89.9 deg: the canvas is a line in the photo.
  Camera grazing = cam;
  const double a = 89.9 * M_PI / 180;
  grazing.camera_from_scan.rotation =
      Vec3d(1, -1, -1).asDiagonal() * Eigen::AngleAxisd(a, Vec3d::UnitX()).toRotationMatrix();
  const Vec3d centre(100, 50, 0);
  const Vec3d eye = centre + 500 * Vec3d(0, std::sin(a), std::cos(a));
  grazing.camera_from_scan.translation = -(grazing.camera_from_scan.rotation * eye);
  ASSERT_NEAR(grazing.camera_from_scan.Apply(centre).x(), 0, 1e-9);
  s = CheckCanvasFootprint(grazing, RigidTransform{}, extent, 0.5, "cam");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("spans only 400 x "), std::string::npos) << s.message();

  // Through the set check: the set's entry is named.
  PhotoSet set;
  set.photos.resize(2);
  set.photos[0].camera = cam;
  set.photos[0].entry = "calib.json: images[0]";
  set.photos[1].camera = far;
  set.photos[1].entry = "calib.json: images[1]";
  HeightField canvas;
  canvas.height_mm = Grid<float>(400, 200, 0.0f);
  canvas.state = Grid<TexelState>(400, 200, TexelState::kMeasured);
  canvas.pitch_mm = 0.5;
  s = CheckCamerasSeeCanvas(set, RigidTransform{}, canvas);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message().rfind("calib.json: images[1]: the canvas spans only", 0), 0u)
      << s.message();
}

TEST_F(CalibrationTest, DuplicateImagesAreRefusedNamingBothEntries) {
  doc_["images"][2]["path"] = "sub/../a.png";  // images[0] is "a.png"
  ExpectError(Read(), {"calib.json: images[2]", "a.png", "same image as", "calib.json: images[0]"});
  // Through the parser alone too (what the fuzz targets see).
  ExpectError(ParseCalibrationText(doc_.dump(), Path("calib.json")),
              {"images[2]", "same image", "images[0]"});
  doc_["images"][2]["path"] = Path("a.png").string();  // absolute
  ExpectError(Read(), {"images[2]", "images[0]"});
  doc_["images"][2]["path"] = "c.exr";
  EXPECT_TRUE(Read().ok());
}

TEST_F(LpTest, DuplicateImagesAndExtraColumnsAreRefusedNamingTheLine) {
  ExpectError(ReadLp("3\ni1.png 0 0 1\ni2.png 0 1 1\n./i1.png 1 0 1\n"),
              {"dirs.lp, line 4", "i1.png", "same image as", "dirs.lp, line 2"});
  // A Windows path from the capture machine that falls back onto an image already listed.
  ExpectError(ReadLp("2\ni1.png 0 0 1\nC:\\capture\\i1.png 0 1 1\n"),
              {"line 3", "same image as", "line 2"});
  // Extra columns were read as part of the name ("i2.png 0.1: no such file").
  ExpectError(ReadLp("2\ni1.png 0 0 1\ni2.png 0.1 0.2 0.3 0.4\n"),
              {"dirs.lp, line 3", "filename x y z", "3 numbers", "got 4 numbers after \"i2.png\""});
  ExpectError(ReadLp("2\ni1.png 0 0 1 1 1 1\ni2.png 0 0 1\n"),
              {"line 2", "got 6 numbers after \"i1.png\""});
  ExpectError(ParseRtiLightsText("1\ni 3.png 1 2 3 4\n", "x.lp"),
              {"x.lp, line 2", "got 4 numbers after \"i 3.png\""});
  // Names with spaces still read; a name that is a number alone is still a name.
  auto set = ReadLp("2\ni 3.png 0 0 1\ni2.png 0 1 1\n");
  ASSERT_TRUE(set.ok()) << set.error().message;
  auto entries = ParseRtiLightsText("1\n12 0 0 1\n", "x.lp");
  ASSERT_TRUE(entries.ok()) << entries.error().message;
  EXPECT_EQ(entries->front().image, "12");
}

// ---- Tiled copies of PNG / JPEG photos (photo_tile_cache.h) ----

class PhotoTileCacheTest : public PhotoSetTest {
 protected:
  // A w x h photo of smooth gradients and noise (JPEG keeps some of it), `channels` of `type`.
  template <class T>
  void WritePhoto(const std::string& name, int w, int h, int channels, OIIO::TypeDesc type,
                  uint32_t seed) {
    std::vector<T> values(static_cast<size_t>(w) * h * channels);
    const double top = std::numeric_limits<T>::max();
    uint32_t state = seed;
    for (size_t i = 0; i < values.size(); ++i) {
      state = state * 1664525u + 1013904223u;
      const size_t px = i / channels;
      const double x = static_cast<double>(px % w) / w, y = static_cast<double>(px / w) / h;
      const double v = 0.5 + 0.3 * std::sin(9 * x + 3 * (i % channels)) * std::cos(7 * y) +
                       0.1 * ((state >> 8) / 16777216.0 - 0.5);
      values[i] = static_cast<T>(std::clamp(v, 0.0, 1.0) * top + 0.5);
    }
    WriteImage(name, w, h, channels, type, values);
  }

  // A set of the named files (headers only, as the tile jobs read it).
  PhotoSet SetOf(const std::vector<std::string>& names) const {
    PhotoSet set;
    for (size_t i = 0; i < names.size(); ++i) {
      auto header = ReadImageHeader(Path(names[i]));
      EXPECT_TRUE(header.ok()) << names[i];
      Photo p;
      p.path = Path(names[i]);
      p.entry = "photo " + std::to_string(i);
      p.camera.width = header.ok() ? header->width : 0;
      p.camera.height = header.ok() ? header->height : 0;
      p.camera.fx = p.camera.fy = 1000;
      set.photos.push_back(p);
    }
    return set;
  }
};

// A copy is its photo sample for sample: every region (partial tiles at the right and bottom
// edges, one pixel, the whole) reads back the same floats, the same depth and integer flag, and
// LoadPhotoRegion converts it to the same linear pixels and flags. PNG 8 / 16 bits, grey and
// RGB, and JPEG (whose decoder the copy must not re-run differently).
TEST_F(PhotoTileCacheTest, CopiesReadBackAsTheirPhotos) {
  WritePhoto<uint8_t>("rgb8.png", 301, 187, 3, OIIO::TypeDesc::UINT8, 1);
  WritePhoto<uint16_t>("rgb16.png", 301, 187, 3, OIIO::TypeDesc::UINT16, 2);
  WritePhoto<uint8_t>("grey8.png", 300, 260, 1, OIIO::TypeDesc::UINT8, 3);
  WritePhoto<uint8_t>("rgb8.jpg", 517, 300, 3, OIIO::TypeDesc::UINT8, 4);
  ImageRegionReader original(64), copied(64);
  for (const std::string name : {"rgb8.png", "rgb16.png", "grey8.png", "rgb8.jpg"}) {
    SCOPED_TRACE(name);
    const fs::path copy = Path(name + ".tif");
    ASSERT_TRUE(WriteTiledCopy(Path(name), copy, 128).ok());
    auto source = ReadImageHeader(Path(name));
    auto header = ReadImageHeader(copy);
    ASSERT_TRUE(source.ok() && header.ok());
    EXPECT_FALSE(source->tiled);
    EXPECT_TRUE(header->tiled);
    EXPECT_EQ(header->format, "tiff");
    EXPECT_EQ(header->width, source->width);
    EXPECT_EQ(header->height, source->height);
    EXPECT_EQ(header->channels, source->channels);
    EXPECT_EQ(header->bits_per_sample, source->bits_per_sample);
    const int w = source->width, h = source->height;
    const std::vector<std::array<int, 4>> regions = {
        {0, 0, w, h}, {w - 45, h - 59, 45, 59}, {100, 120, 1, 1}, {127, 1, 130, 150}};
    for (const auto& [x, y, rw, rh] : regions) {
      auto a = original.Read(Path(name), x, y, rw, rh);
      auto b = copied.Read(copy, x, y, rw, rh);
      ASSERT_TRUE(a.ok() && b.ok());
      EXPECT_EQ(a->pixels, b->pixels) << x << ", " << y << " " << rw << " x " << rh;
      EXPECT_EQ(a->bits_per_sample, b->bits_per_sample);
      EXPECT_EQ(a->integer_samples, b->integer_samples);
    }
    PhotoSet set = SetOf({name});
    const PixelRect rect{w / 3, h / 4, w / 2, h / 2};
    auto direct = LoadPhotoRegion(set.photos[0], rect, original);
    auto via_copy = LoadPhotoRegion(set.photos[0], rect, copied, {}, copy);
    ASSERT_TRUE(direct.ok() && via_copy.ok());
    EXPECT_EQ(direct->rgb.data, via_copy->rgb.data);
    EXPECT_EQ(direct->flags.data, via_copy->flags.data);
    EXPECT_EQ(direct->encoding, via_copy->encoding);
    EXPECT_EQ(direct->path, via_copy->path);  // still the photo: its name says it is a JPEG
  }
}

// What a copy cannot hold exactly is read as it is: RGBA (alpha), an already tiled file. The
// copier refuses RGBA itself, naming the file.
TEST_F(PhotoTileCacheTest, CopiesOnlyWhatItHoldsExactly) {
  WritePhoto<uint8_t>("rgba.png", 64, 48, 4, OIIO::TypeDesc::UINT8, 5);
  WritePhoto<uint8_t>("rgb.jpg", 64, 48, 3, OIIO::TypeDesc::UINT8, 6);
  ASSERT_TRUE(WriteTiledCopy(Path("rgb.jpg"), Path("tiled.tif"), 16).ok());
  const Status refused = WriteTiledCopy(Path("rgba.png"), Path("rgba.tif"));
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.message().find("rgba.png: 4 channel(s)"), std::string::npos)
      << refused.message();
  EXPECT_FALSE(fs::exists(Path("rgba.tif")));
  EXPECT_FALSE(WriteTiledCopy(Path("rgb.jpg"), Path("odd.tif"), 100).ok());  // not 16k
  const PhotoSet set = SetOf({"rgba.png", "tiled.tif", "rgb.jpg"});
  auto made = WritePhotoTileCache(set, Path("cache"));
  ASSERT_TRUE(made.ok()) << made.error().message;
  EXPECT_EQ(made->photos, 3u);
  EXPECT_EQ(made->copied, 1u);
  EXPECT_EQ(made->direct, 2u);
  EXPECT_GT(made->bytes, 0u);
  const auto copies = FindPhotoTileCopies(set, Path("cache"));
  ASSERT_EQ(copies.size(), 3u);
  EXPECT_TRUE(copies[0].empty());
  EXPECT_TRUE(copies[1].empty());
  EXPECT_EQ(copies[2], Path("cache") / "00002.tif");
}

// Converted once: a second call keeps every copy; a photo replaced since (other size or time) is
// read from its own file until the cache is made again, which copies it alone.
TEST_F(PhotoTileCacheTest, KeepsCurrentCopiesAndIgnoresStaleOnes) {
  WritePhoto<uint8_t>("a.jpg", 90, 70, 3, OIIO::TypeDesc::UINT8, 7);
  WritePhoto<uint8_t>("b.png", 90, 70, 3, OIIO::TypeDesc::UINT8, 8);
  WritePhoto<uint16_t>("c.png", 90, 70, 1, OIIO::TypeDesc::UINT16, 9);
  const PhotoSet set = SetOf({"a.jpg", "b.png", "c.png"});
  auto first = WritePhotoTileCache(set, Path("cache"));
  ASSERT_TRUE(first.ok()) << first.error().message;
  EXPECT_EQ(first->copied, 3u);
  const auto copy_time = fs::last_write_time(Path("cache") / "00000.tif");
  auto second = WritePhotoTileCache(set, Path("cache"));
  ASSERT_TRUE(second.ok());
  EXPECT_EQ(second->copied, 0u);
  EXPECT_EQ(second->kept, 3u);
  EXPECT_EQ(fs::last_write_time(Path("cache") / "00000.tif"), copy_time);
  // b.png replaced by another image of the same size, its time moved on.
  WritePhoto<uint8_t>("b.png", 90, 70, 3, OIIO::TypeDesc::UINT8, 10);
  fs::last_write_time(Path("b.png"), fs::last_write_time(Path("b.png")) + std::chrono::seconds(5));
  auto copies = FindPhotoTileCopies(set, Path("cache"));
  EXPECT_FALSE(copies[0].empty());
  EXPECT_TRUE(copies[1].empty());
  EXPECT_FALSE(copies[2].empty());
  auto third = WritePhotoTileCache(set, Path("cache"));
  ASSERT_TRUE(third.ok());
  EXPECT_EQ(third->copied, 1u);
  EXPECT_EQ(third->kept, 2u);
  copies = FindPhotoTileCopies(set, Path("cache"));
  ASSERT_FALSE(copies[1].empty());
  ImageRegionReader reader(64);
  auto now = reader.Read(Path("b.png"), 0, 0, 90, 70);
  auto copy = reader.Read(copies[1], 0, 0, 90, 70);
  ASSERT_TRUE(now.ok() && copy.ok());
  EXPECT_EQ(now->pixels, copy->pixels);  // the new image's copy, not the old one
  // A copy that is gone is not used.
  fs::remove(copies[2]);
  EXPECT_TRUE(FindPhotoTileCopies(set, Path("cache"))[2].empty());
}

// The index is untrusted: a copy name that leaves the folder, a wrong format or broken JSON make
// the whole cache unused, and the note says why; no folder at all is no note.
TEST_F(PhotoTileCacheTest, AnIndexThatCannotBeUsedIsIgnored) {
  WritePhoto<uint8_t>("a.jpg", 40, 30, 3, OIIO::TypeDesc::UINT8, 11);
  const PhotoSet set = SetOf({"a.jpg"});
  std::string note = "stale";
  EXPECT_TRUE(FindPhotoTileCopies(set, Path("none"), &note)[0].empty());
  EXPECT_EQ(note, "");
  ASSERT_TRUE(WritePhotoTileCache(set, Path("cache")).ok());
  ASSERT_FALSE(FindPhotoTileCopies(set, Path("cache"), &note)[0].empty());
  EXPECT_EQ(note, "");
  auto index = json::parse(test::ReadFileBytes(Path("cache/index.json")));
  const json good = index;
  struct Case {
    std::string what, text;
  };
  json escape = good, format = good, missing = good;
  escape["copies"][0]["copy"] = "../a.jpg";
  format["format"] = "something else";
  missing["copies"][0].erase("mtime_ns");
  for (const Case& c : std::vector<Case>{{"copy \"../a.jpg\"", escape.dump()},
                                         {"not a version 1", format.dump()},
                                         {"without photo", missing.dump()},
                                         {"not a JSON object", "{\"copies\": ["}}) {
    test::WriteFileBytes(Path("cache/index.json"), c.text);
    EXPECT_TRUE(FindPhotoTileCopies(set, Path("cache"), &note)[0].empty()) << c.what;
    EXPECT_NE(note.find("index.json"), std::string::npos) << note;
    EXPECT_NE(note.find(c.what), std::string::npos) << note;
  }
  // Making the cache again over a broken index copies afresh.
  auto again = WritePhotoTileCache(set, Path("cache"));
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->copied, 1u);
  EXPECT_FALSE(FindPhotoTileCopies(set, Path("cache"))[0].empty());
}

}  // namespace
}  // namespace digitize
