// The calibration JSON (docs/formats.md, "Calibration JSON"): cameras, lights and the images that
// use them, every value checked with its key path in the message.
#include <Eigen/SVD>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "digitize/photo_set.h"
#include "json_fields.h"
#include "photo_set_internal.h"

namespace digitize {

using namespace photo_detail;
namespace fs = std::filesystem;

namespace {

using nlohmann::json;

// A rotation read from a file may be off orthonormal by its printed precision (6 decimals give
// ~1e-6); further than this it is a wrong matrix, not a rounded one.
constexpr double kRotationSnapTolerance = 1e-4;

RigidTransform ParseTransform(const Fields& f) {
  f.OnlyKeys({"rotation", "translation_mm"});
  const Mat3d R = f.Matrix3("rotation");
  const double det = R.determinant();
  const double off = (R.transpose() * R - Mat3d::Identity()).norm();
  if (!(det > 0) || off > kRotationSnapTolerance) {
    Fail(f.At("rotation") + " is not a rotation (det " + FormatNumber(det, kShownDigits) +
         ", |R^T R - I| " + FormatNumber(off, kShownDigits) + ")" +
         (det < 0 ? ": a reflection" : ""));
  }
  // Snap to the nearest rotation: rounding in the file must not leak a shear into projections.
  Eigen::JacobiSVD<Mat3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
  RigidTransform t;
  t.rotation = svd.matrixU() * svd.matrixV().transpose();
  t.translation = f.Vector3("translation_mm");
  return t;
}

Camera ParseCamera(const Fields& f) {
  Camera camera;
  if (f.Has("distortion")) {
    Fail(f.where() + ": lens distortion is not supported (undistort the images first)");
  }
  const std::string model = f.Has("model") ? f.String("model") : "pinhole";
  if (model == "pinhole") {
    f.OnlyKeys({"model", "width", "height", "fx", "fy", "cx", "cy", "camera_from_scan"});
    camera.model = CameraModel::kPinhole;
    camera.fx = f.Number("fx");
    camera.fy = f.Number("fy");
  } else if (model == "orthographic") {
    f.OnlyKeys({"model", "width", "height", "pixel_pitch_mm", "cx", "cy", "camera_from_scan"});
    camera.model = CameraModel::kOrthographic;
    camera.pixel_pitch_mm = f.Number("pixel_pitch_mm");
  } else {
    Fail(f.At("model") + " must be \"pinhole\" or \"orthographic\", got \"" + model + "\"");
  }
  camera.width = static_cast<int>(f.Integer("width", -kMaxImageSide, kMaxImageSide));
  camera.height = static_cast<int>(f.Integer("height", -kMaxImageSide, kMaxImageSide));
  camera.cx = f.Number("cx");
  camera.cy = f.Number("cy");
  camera.camera_from_scan = ParseTransform(f.Object("camera_from_scan"));
  if (Status s = camera.Validate(f.where()); !s) Fail(s.message());
  return camera;
}

Light ParseLight(const Fields& f) {
  Light light;
  const std::string type = f.String("type");
  if (type == "point") {
    f.OnlyKeys({"type", "position_mm", "intensity"});
    light.type = LightType::kPoint;
    light.position_mm = f.Vector3("position_mm");
    light.intensity = f.Rgb("intensity");
  } else if (type == "directional") {
    f.OnlyKeys({"type", "direction", "irradiance"});
    light.type = LightType::kDirectional;
    const Vec3d d = f.Vector3("direction");
    // stableNorm: finite components whose squares overflow (1e200) are still a direction.
    const double norm = d.stableNorm();
    if (!(norm > kMinDirectionNorm)) Fail(f.At("direction") + " is a zero vector");
    light.direction = d / norm;
    light.irradiance = f.Rgb("irradiance");
  } else {
    Fail(f.At("type") + " must be \"point\" or \"directional\", got \"" + type + "\"");
  }
  if (Status s = light.Validate(f.where()); !s) Fail(s.message());
  return light;
}

// "camera": an index into the shared "cameras" array, or an object.
template <class T, class Parse>
T ParseRef(const Fields& image, const char* key, const std::vector<T>& shared,
           const char* shared_key, Parse parse) {
  const json& v = image.Get(key);
  if (v.is_number_integer()) {
    const auto i = v.get<int64_t>();
    if (i < 0 || i >= static_cast<int64_t>(shared.size())) {
      Fail(image.At(key) + " = " + std::to_string(i) + " but \"" + shared_key + "\" has " +
           std::to_string(shared.size()) + " entries");
    }
    return shared[static_cast<size_t>(i)];
  }
  return parse(Fields(v, image.At(key)));
}

template <class T, class Parse>
std::vector<T> ParseShared(const Fields& top, const char* key, const std::string& file,
                           Parse parse) {
  std::vector<T> out;
  if (!top.Has(key)) return out;
  const json& list = top.Get(key);
  if (!list.is_array()) Fail(file + ": \"" + key + "\" must be an array");
  for (size_t i = 0; i < list.size(); ++i) {
    out.push_back(parse(Fields(list[i], file + ": " + key + "[" + std::to_string(i) + "]")));
  }
  return out;
}

ColourEncoding ParseEncoding(const Fields& f) {
  if (!f.Has("encoding")) return ColourEncoding::kAuto;
  const std::string e = f.String("encoding");
  if (e == "srgb" || e == "sRGB") return ColourEncoding::kSrgb;
  if (e == "linear") return ColourEncoding::kLinear;
  if (e == "auto") return ColourEncoding::kAuto;
  Fail(f.At("encoding") + " must be \"srgb\", \"linear\" or \"auto\", got \"" + e + "\"");
}

PhotoSet ParseCalibration(const fs::path& json_path, std::string_view text) {
  const std::string file = json_path.string();
  const json doc = ParseJson(text, file);
  if (!doc.is_object()) Fail(file + ": the top level must be an object");
  const Fields top(doc, file);
  if (!top.Has("format") || !top.Get("format").is_string() ||
      top.String("format") != "digitize.calibration") {
    Fail(file + ": not a calibration file (\"format\" must be \"digitize.calibration\", got " +
         (top.Has("format") ? Show(top.Get("format")) : std::string("nothing")) + ")");
  }
  if (!top.Has("version") || !top.Get("version").is_number_integer()) {
    Fail(file + ": \"version\" must be an integer (this build reads version 1)");
  }
  if (const auto version = top.Get("version").get<int64_t>(); version != 1) {
    Fail(file + ": version " + std::to_string(version) +
         " is not supported (this build reads version 1)");
  }
  if (top.Has("units") && top.String("units") != "mm") {
    Fail(file + ": \"units\" must be \"mm\", got \"" + top.String("units") + "\"");
  }
  // Other top-level keys (generator metadata, notes) are ignored on purpose.
  const auto cameras = ParseShared<Camera>(top, "cameras", file, ParseCamera);
  const auto lights = ParseShared<Light>(top, "lights", file, ParseLight);

  const json& images = top.Get("images");
  if (!images.is_array()) Fail(file + ": \"images\" must be an array");
  if (images.empty()) Fail(file + ": \"images\" is empty, a photo set needs at least one image");

  PhotoSet set;
  set.source = json_path;
  const fs::path dir = json_path.parent_path();
  for (size_t i = 0; i < images.size(); ++i) {
    const Fields f(images[i], file + ": images[" + std::to_string(i) + "]");
    f.OnlyKeys({"path", "camera", "light", "encoding"});
    Photo photo;
    photo.entry = f.where();
    const std::string rel = f.String("path");
    if (rel.empty()) Fail(f.At("path") + " is empty");
    // A path with a NUL would be cut short by the OS and open another file than the one named.
    if (rel.find('\0') != std::string::npos) Fail(f.At("path") + " contains a NUL character");
    photo.path = fs::path(rel).is_absolute() ? fs::path(rel) : dir / rel;
    photo.camera = ParseRef<Camera>(f, "camera", cameras, "cameras", ParseCamera);
    photo.light = ParseRef<Light>(f, "light", lights, "lights", ParseLight);
    photo.encoding = ParseEncoding(f);
    set.photos.push_back(std::move(photo));
  }
  return set;
}

}  // namespace

Result<PhotoSet> ParseCalibrationText(std::string_view text, const fs::path& source) {
  auto set = CatchBadInput([&] { return ParseCalibration(source, text); });
  if (!set) return set;
  if (Status s = CheckDistinctImages(*set); !s) return Error{s.message()};
  return set;
}

Result<PhotoSet> ReadCalibration(const fs::path& json_path, const PhotoSetOptions& options,
                                 const ProgressCallback& progress) {
  if (Status s = options.Validate(); !s) return Error{s.message()};
  auto text = ReadTextFile(json_path, "calibration file");
  if (!text) return text.error();
  auto parsed = ParseCalibrationText(*text, json_path);
  if (!parsed) return parsed.error();
  PhotoSet set = std::move(*parsed);
  for (const Photo& photo : set.photos) {
    if (Status s = CheckImageInsideFolder(photo.path, json_path.parent_path(), photo.entry,
                                          photo.path.string(), options);
        !s)
      return Error{s.message()};
  }
  if (Status s = ProbeAll(set); !s) return Error{s.message()};
  if (options.load_pixels) {
    if (Status s = LoadPhotoPixels(set, options, progress); !s) return Error{s.message()};
  }
  return set;
}

}  // namespace digitize
