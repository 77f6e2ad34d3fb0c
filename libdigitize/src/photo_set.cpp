// Photo sets: the calibration JSON, RTI .lp captures, and their pixels as linear RGB.
#include "digitize/photo_set.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <mutex>
#include <new>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <string_view>
#include <tuple>
#include <vector>

#include "digitize/image_io.h"
#include "digitize/output_dir.h"

namespace digitize {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// A rotation read from a file may be off orthonormal by its printed precision (6 decimals give
// ~1e-6); further than this it is a wrong matrix, not a rounded one.
constexpr double kRotationSnapTolerance = 1e-4;
// A rotation built in code (after snapping) must be orthonormal to about float precision.
constexpr double kRotationTolerance = 1e-6;
// Below this length a light direction is a zero vector, not a direction.
constexpr double kMinDirectionNorm = 1e-9;
// Text files larger than this are not calibrations or .lp files (a wrong file given).
constexpr uintmax_t kMaxTextFileBytes = uintmax_t{64} << 20;
// Images larger than this per side are refused in a camera (a corrupt value, not a sensor).
constexpr int kMaxImageSide = 1 << 16;

// Bad input found deep in a parser: thrown inside this file only, turned into an Error at the
// API boundary (no exception crosses it).
struct BadInput {
  std::string message;
};
[[noreturn]] void Fail(std::string message) { throw BadInput{std::move(message)}; }

std::string Num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}
std::string Size(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

Result<std::string> ReadTextFile(const fs::path& path, const char* what) {
  std::error_code ec;
  const auto status = fs::status(path, ec);
  if (!fs::exists(status)) return Error{path.string() + ": no such file"};
  if (fs::is_directory(status)) return Error{path.string() + ": is a directory, not a " + what};
  const uintmax_t bytes = fs::file_size(path, ec);
  if (!ec && bytes > kMaxTextFileBytes) {
    return Error{path.string() + ": " + std::to_string(bytes) + " bytes, too large for a " + what};
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{path.string() + ": cannot open for reading"};
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) return Error{path.string() + ": read failed"};
  return text.str();
}

// ---------------------------------------------------------------------------------------------
// Pixels.

double SrgbToLinearD(double c) {
  const double a = std::abs(c);
  const double linear = a <= 0.04045 ? a / 12.92 : std::pow((a + 0.055) / 1.055, 2.4);
  return c < 0 ? -linear : linear;
}

// Linear value of every integer code, for 8-bit (256 entries) or 16-bit (65536) images.
const std::vector<float>& SrgbLut(int max_code) {
  static const auto make = [](int n) {
    std::vector<float> lut(static_cast<size_t>(n) + 1);
    for (int i = 0; i <= n; ++i) lut[i] = static_cast<float>(SrgbToLinearD(double(i) / n));
    return lut;
  };
  static const std::vector<float> lut8 = make(255);
  static const std::vector<float> lut16 = make(65535);
  return max_code == 255 ? lut8 : lut16;
}
// code / max_code, for integer images declared linear.
const std::vector<float>& LinearLut(int max_code) {
  static const auto make = [](int n) {
    std::vector<float> lut(static_cast<size_t>(n) + 1);
    for (int i = 0; i <= n; ++i) lut[i] = static_cast<float>(double(i) / n);
    return lut;
  };
  static const std::vector<float> lut8 = make(255);
  static const std::vector<float> lut16 = make(65535);
  return max_code == 255 ? lut8 : lut16;
}

// The header only (cheap), so that a missing, unreadable or wrongly sized image is reported
// before seconds are spent decoding the others. Errors name the file.
Result<ImageHeader> ReadHeader(const fs::path& path) {
  const std::string name = path.string();
  auto read = ReadImageHeader(path);
  if (!read.ok()) return read.error();
  const ImageHeader header = *read;
  if (header.channels != 1 && header.channels != 3 && header.channels != 4) {
    return Error{name + ": " + std::to_string(header.channels) +
                 " channels; photos must be 1-channel (grey), 3-channel (RGB) or RGBA"};
  }
  return header;
}

ColourEncoding Resolve(ColourEncoding declared, bool integer_samples) {
  if (declared != ColourEncoding::kAuto) return declared;
  return integer_samples ? ColourEncoding::kSrgb : ColourEncoding::kLinear;
}

// Checks the header of a photo's image against its camera and resolves its encoding.
Status ProbePhoto(Photo& photo) {
  auto header = ReadHeader(photo.path);
  if (!header) return Error{photo.entry + ": " + header.error().message};
  if (header->width != photo.camera.width || header->height != photo.camera.height) {
    return Error{photo.entry + ": " + photo.path.string() + ": image is " +
                 Size(header->width, header->height) + ", its camera says " +
                 Size(photo.camera.width, photo.camera.height)};
  }
  photo.encoding = Resolve(photo.encoding, header->integer_samples);
  return Status::Ok();
}

// Decoded samples -> linear RGB + flags. Rows in parallel (nested inside the per-photo tasks,
// which TBB composes) so that a single large photo also keeps every core busy.
struct Converted {
  Grid<Vec3f> rgb;
  Grid<uint8_t> flags;
  size_t non_finite = 0, saturated = 0;
};

struct RowCounts {
  size_t non_finite = 0, saturated = 0;
};

// Integer samples: OpenImageIO hands them over as code / max_code; rounding recovers the code
// exactly, and a table gives its linear value (sRGB EOTF or code / max_code).
template <int C>
RowCounts IntegerRow(const float* src, int w, float max_code, int sat_code, const float* lut,
                     Vec3f* dst, uint8_t* flags) {
  RowCounts n;
  const int top = static_cast<int>(max_code);
  for (int x = 0; x < w; ++x, src += C) {
    int code[3];
    for (int k = 0; k < C; ++k) code[k] = std::min(static_cast<int>(src[k] * max_code + 0.5f), top);
    if constexpr (C == 1) code[1] = code[2] = code[0];
    code[0] = std::max(code[0], 0), code[1] = std::max(code[1], 0), code[2] = std::max(code[2], 0);
    dst[x] = Vec3f(lut[code[0]], lut[code[1]], lut[code[2]]);
    if (std::max({code[0], code[1], code[2]}) >= sat_code) {
      flags[x] = kPixelSaturated;
      ++n.saturated;
    }
  }
  return n;
}

// Float samples (EXR, float TIFF): finite check, optional sRGB curve, saturation level.
template <int C>
RowCounts FloatRow(const float* src, int w, bool srgb, float sat_level, Vec3f* dst,
                   uint8_t* flags) {
  RowCounts n;
  for (int x = 0; x < w; ++x, src += C) {
    Vec3f v =
        C == 1 ? Vec3f::Constant(src[0]) : Vec3f(src[0], src[C > 1 ? 1 : 0], src[C > 2 ? 2 : 0]);
    if (srgb) v = Vec3f(SrgbToLinear(v.x()), SrgbToLinear(v.y()), SrgbToLinear(v.z()));
    if (!v.allFinite()) {
      dst[x] = Vec3f::Zero();
      flags[x] = kPixelNonFinite;
      ++n.non_finite;
      continue;
    }
    dst[x] = v;
    if (v.maxCoeff() >= sat_level) {
      flags[x] = kPixelSaturated;
      ++n.saturated;
    }
  }
  return n;
}

Converted Convert(const FloatImage& image, ColourEncoding encoding, const PhotoSetOptions& o) {
  Converted out;
  const int w = image.width, h = image.height, c = image.channels;
  out.rgb.width = w;
  out.rgb.height = h;
  out.rgb.data.resize(static_cast<size_t>(w) * h);  // Eigen leaves it unset: written below
  out.flags = Grid<uint8_t>(w, h, 0);
  const bool srgb = encoding == ColourEncoding::kSrgb;
  // 8-bit and 16-bit codes go through a table; deeper integers (rare) through the float path,
  // which is exact for them too.
  const int max_code = !image.integer_samples        ? 0
                       : image.bits_per_sample <= 8  ? 255
                       : image.bits_per_sample <= 16 ? 65535
                                                     : 0;
  const std::vector<float>* lut = max_code == 0 ? nullptr
                                  : srgb        ? &SrgbLut(max_code)
                                                : &LinearLut(max_code);
  // The smallest code at or above the saturation threshold.
  const int sat_code =
      static_cast<int>(std::ceil(static_cast<double>(o.saturation_encoded) * max_code - 1e-9));
  // Integer images beyond 16 bits: the threshold applies to the encoded value as for the others.
  const float sat_level = image.integer_samples
                              ? (srgb ? SrgbToLinear(o.saturation_encoded) : o.saturation_encoded)
                              : o.float_saturation_level;

  std::atomic<size_t> non_finite{0}, saturated{0};
  tbb::parallel_for(tbb::blocked_range<int>(0, h, 16), [&](const tbb::blocked_range<int>& rows) {
    RowCounts total;
    for (int y = rows.begin(); y != rows.end(); ++y) {
      const float* src = image.pixels.data() + static_cast<size_t>(y) * w * c;
      Vec3f* dst = out.rgb.Row(y);
      uint8_t* flags = out.flags.Row(y);
      RowCounts n;
      if (lut) {
        n = c == 1 ? IntegerRow<1>(src, w, float(max_code), sat_code, lut->data(), dst, flags)
                   : IntegerRow<3>(src, w, float(max_code), sat_code, lut->data(), dst, flags);
      } else {
        n = c == 1 ? FloatRow<1>(src, w, srgb, sat_level, dst, flags)
                   : FloatRow<3>(src, w, srgb, sat_level, dst, flags);
      }
      total.non_finite += n.non_finite;
      total.saturated += n.saturated;
    }
    non_finite += total.non_finite;
    saturated += total.saturated;
  });
  out.non_finite = non_finite;
  out.saturated = saturated;
  if (out.non_finite == 0 && out.saturated == 0) out.flags = Grid<uint8_t>();
  return out;
}

// ---------------------------------------------------------------------------------------------
// Calibration JSON.

// A JSON value as an error message shows it: at most kShownDepth levels deep and about
// kShownChars characters. Not json::dump: a hostile file can be huge, and dump recurses once per
// nesting level (a 400 KB file of nested arrays overflowed the stack).
constexpr int kShownDepth = 2;
constexpr size_t kShownChars = 80;

void ShowInto(const json& v, int depth, std::string& out) {
  if (out.size() > kShownChars) return;
  if (!v.is_structured()) {
    out += v.dump();  // a scalar: no recursion (a long string is cut below)
    return;
  }
  const bool array = v.is_array();
  if (v.empty() || depth == 0) {
    out += v.empty() ? (array ? "[]" : "{}") : (array ? "[...]" : "{...}");
    return;
  }
  out += array ? '[' : '{';
  bool first = true;
  for (auto it = v.begin(); it != v.end() && out.size() <= kShownChars; ++it) {
    if (!first) out += ", ";
    first = false;
    if (!array) out += json(it.key()).dump() + ": ";
    ShowInto(*it, depth - 1, out);
  }
  out += array ? ']' : '}';
}

std::string Show(const json& v) {
  std::string out;
  ShowInto(v, kShownDepth, out);
  if (out.size() > kShownChars) {
    size_t cut = kShownChars;
    while (cut > 0 && (static_cast<unsigned char>(out[cut]) & 0xC0) == 0x80) --cut;  // UTF-8
    out.resize(cut);
    out += "...";
  }
  return out;
}

// Reading one JSON object, with the key path of every value for the error messages.
class Fields {
 public:
  Fields(const json& object, std::string where) : object_(object), where_(std::move(where)) {
    if (!object_.is_object()) Fail(where_ + " must be an object, got " + TypeName(object_));
  }
  const std::string& where() const { return where_; }
  std::string At(const std::string& key) const { return where_ + "." + key; }
  bool Has(const std::string& key) const { return object_.contains(key); }
  const json& Get(const std::string& key) const {
    if (!object_.contains(key)) Fail(where_ + ": missing \"" + key + "\"");
    return object_.at(key);
  }
  double Number(const std::string& key) const { return NumberOf(Get(key), At(key)); }
  int Integer(const std::string& key) const {
    const json& v = Get(key);
    if (!v.is_number_integer()) Fail(At(key) + " must be an integer, got " + Show(v));
    const auto i = v.get<int64_t>();
    if (i < -kMaxImageSide || i > kMaxImageSide) Fail(At(key) + " is out of range: " + Show(v));
    return static_cast<int>(i);
  }
  std::string String(const std::string& key) const {
    const json& v = Get(key);
    if (!v.is_string()) Fail(At(key) + " must be a string, got " + Show(v));
    return v.get<std::string>();
  }
  Vec3d Vector3(const std::string& key) const {
    const json& v = Get(key);
    if (!v.is_array() || v.size() != 3)
      Fail(At(key) + " must be an array of 3 numbers, got " + Show(v));
    Vec3d out;
    for (int i = 0; i < 3; ++i) out[i] = NumberOf(v[i], At(key) + "[" + std::to_string(i) + "]");
    return out;
  }
  // An RGB triple, or one number for grey.
  Vec3f Rgb(const std::string& key) const {
    const json& v = Get(key);
    if (v.is_number()) {
      const double g = NumberOf(v, At(key));
      return Vec3f::Constant(static_cast<float>(g));
    }
    return Vector3(key).cast<float>();
  }
  // Unknown keys are typos ("encodng") until proven otherwise; "comment" and "_..." are free.
  void OnlyKeys(std::initializer_list<const char*> allowed) const {
    for (const auto& [key, value] : object_.items()) {
      if (key == "comment" || key.starts_with("_")) continue;
      bool known = false;
      for (const char* a : allowed) known = known || key == a;
      if (!known) {
        std::string list;
        for (const char* a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
        Fail(where_ + ": unknown key \"" + key + "\" (expected: " + list + ")");
      }
    }
  }

  static std::string TypeName(const json& v) { return v.type_name(); }
  static double NumberOf(const json& v, const std::string& where) {
    if (!v.is_number()) Fail(where + " must be a number, got " + Show(v));
    const double d = v.get<double>();
    if (!std::isfinite(d)) Fail(where + " is not finite");
    return d;
  }

 private:
  const json& object_;
  std::string where_;
};

RigidTransform ParseTransform(const Fields& f) {
  f.OnlyKeys({"rotation", "translation_mm"});
  const std::string rwhere = f.At("rotation");
  const json& r = f.Get("rotation");
  if (!r.is_array() || r.size() != 3)
    Fail(rwhere + " must be 3 rows of 3 numbers, got " + Show(r));
  Mat3d R;
  for (int i = 0; i < 3; ++i) {
    if (!r[i].is_array() || r[i].size() != 3) {
      Fail(rwhere + " must be 3 rows of 3 numbers, row " + std::to_string(i) + " is " +
           Show(r[i]));
    }
    for (int j = 0; j < 3; ++j) {
      R(i, j) = Fields::NumberOf(r[i][j],
                                 rwhere + "[" + std::to_string(i) + "][" + std::to_string(j) + "]");
    }
  }
  const double det = R.determinant();
  const double off = (R.transpose() * R - Mat3d::Identity()).norm();
  if (!(det > 0) || off > kRotationSnapTolerance) {
    Fail(rwhere + " is not a rotation (det " + Num(det) + ", |R^T R - I| " + Num(off) + ")" +
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
  camera.width = f.Integer("width");
  camera.height = f.Integer("height");
  camera.cx = f.Number("cx");
  camera.cy = f.Number("cy");
  camera.camera_from_scan =
      ParseTransform(Fields(f.Get("camera_from_scan"), f.At("camera_from_scan")));
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
  json doc;
  try {
    doc = json::parse(text);
  } catch (const json::exception& e) {
    // parse_error, and also out_of_range for a number beyond double ("1e400"): both bad input.
    Fail(file + ": not valid JSON (" + e.what() + ")");
  }
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

// ---------------------------------------------------------------------------------------------
// RTI .lp files.

struct Token {
  std::string_view text;
  size_t begin = 0;  // offset in the line
};

std::vector<Token> Tokens(std::string_view line) {
  std::vector<Token> tokens;
  size_t i = 0;
  const auto space = [](char ch) {
    return ch == ' ' || ch == '\t' || ch == '\r' || ch == '\v' || ch == '\f';
  };
  while (i < line.size()) {
    while (i < line.size() && space(line[i])) ++i;
    const size_t b = i;
    while (i < line.size() && !space(line[i])) ++i;
    if (i > b) tokens.push_back({line.substr(b, i - b), b});
  }
  return tokens;
}

bool ParseDouble(std::string_view s, double* out) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), *out);
  return ec == std::errc() && end == s.data() + s.size();
}

std::vector<RtiLightEntry> ParseLp(const fs::path& lp_path, std::string_view text) {
  const std::string file = lp_path.string();
  const auto at = [&](int line) { return file + ", line " + std::to_string(line) + ": "; };
  std::vector<RtiLightEntry> entries;
  long long count = -1;
  int count_line = 0;
  int line_no = 0;
  size_t pos = text.starts_with("\xEF\xBB\xBF") ? 3 : 0;  // a UTF-8 BOM (Windows editors)
  while (pos <= text.size()) {
    size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    std::string_view line(text.data() + pos, end - pos);
    pos = end + 1;
    ++line_no;
    if (const size_t hash = line.find('#'); hash != std::string_view::npos)
      line = line.substr(0, hash);
    const auto tokens = Tokens(line);
    if (tokens.empty()) {
      if (end == text.size()) break;
      continue;
    }
    if (count < 0) {
      if (tokens.size() != 1) {
        Fail(at(line_no) + "expected the image count alone on the first line, got \"" +
             std::string(line) + "\"");
      }
      const std::string_view t = tokens[0].text;
      const auto [p, ec] = std::from_chars(t.data(), t.data() + t.size(), count);
      if (ec != std::errc() || p != t.data() + t.size() || count <= 0 || count > 1000000) {
        Fail(at(line_no) + "bad image count \"" + std::string(t) +
             "\" (a positive integer expected)");
      }
      count_line = line_no;
      continue;
    }
    if (tokens.size() < 4) {
      Fail(at(line_no) + "expected \"filename x y z\", got \"" + std::string(line) + "\"");
    }
    if (static_cast<long long>(entries.size()) >= count) {
      Fail(at(line_no) + "more entries than the " + std::to_string(count) +
           " images announced on line " + std::to_string(count_line));
    }
    RtiLightEntry e;
    e.line = line_no;
    const size_t n = tokens.size();
    // Extra columns (intensities, a second direction) would otherwise be read as part of the name
    // ("img12.jpg 0.1: no such file"). The first token is always the name; an image name's last
    // word ends with its extension, so it does not parse as a number.
    size_t numbers = 0;
    for (double v = 0; numbers + 1 < n && ParseDouble(tokens[n - 1 - numbers].text, &v);) ++numbers;
    if (numbers > 3) {
      const Token& name_end = tokens[n - 1 - numbers];
      Fail(at(line_no) + "expected \"filename x y z\" (a file name and 3 numbers), got " +
           std::to_string(numbers) + " numbers after \"" +
           std::string(line.substr(tokens[0].begin,
                                   name_end.begin + name_end.text.size() - tokens[0].begin)) +
           "\"");
    }
    // The file name is everything before the three numbers (it may contain spaces): from its
    // first token to the end of its last, so no separator (\r, \v, \f too) sticks to it.
    const Token& last = tokens[n - 4];
    e.image = std::string(
        line.substr(tokens[0].begin, last.begin + last.text.size() - tokens[0].begin));
    // A name with a NUL would be cut short by the OS and open another file than the one named.
    if (e.image.find('\0') != std::string::npos) {
      Fail(at(line_no) + "the file name contains a NUL character");
    }
    static const char* kAxis[3] = {"x", "y", "z"};
    for (int k = 0; k < 3; ++k) {
      const std::string_view t = tokens[n - 3 + k].text;
      double v = 0;
      if (!ParseDouble(t, &v)) {
        Fail(at(line_no) + "\"" + std::string(t) + "\" is not a number (" + kAxis[k] + " of " +
             e.image + ")");
      }
      if (!std::isfinite(v)) {
        Fail(at(line_no) + "\"" + std::string(t) + "\" is not finite (" + kAxis[k] + " of " +
             e.image + ")");
      }
      e.direction[k] = v;
    }
    // stableNorm: finite components whose squares overflow (1e200) are still a direction; norm()
    // gave inf and a zero "unit" vector (found by fuzz_lp).
    const double norm = e.direction.stableNorm();
    if (!(norm > kMinDirectionNorm)) Fail(at(line_no) + "zero light direction for " + e.image);
    e.direction /= norm;
    entries.push_back(std::move(e));
  }
  if (count < 0) Fail(file + ": no image count (the first line must hold the number of images)");
  if (static_cast<long long>(entries.size()) != count) {
    Fail(file + ": line " + std::to_string(count_line) + " announces " + std::to_string(count) +
         " images, the file lists " + std::to_string(entries.size()));
  }
  return entries;
}

// `name` as written in the .lp: relative to its folder; Windows separators and absolute paths
// from the capturing machine are common, so a path that does not exist falls back to its file name
// in the .lp's folder.
fs::path ResolveLpImage(const fs::path& dir, std::string name) {
  std::replace(name.begin(), name.end(), '\\', '/');
  const fs::path written(name);
  const fs::path direct = written.is_absolute() ? written : dir / written;
  std::error_code ec;
  if (fs::exists(direct, ec)) return direct;
  const fs::path by_name = dir / written.filename();
  if (fs::exists(by_name, ec)) return by_name;
  return direct;
}

// PhotoSetOptions::allow_outside_paths: `image` (what `entry` of the file in `dir` names, as
// `written`) must resolve, symbolic links and ".." included, to a path inside dir's.
Status CheckImageInsideFolder(const fs::path& image, const fs::path& dir, const std::string& entry,
                              const std::string& written, const PhotoSetOptions& options) {
  if (options.allow_outside_paths) return Status::Ok();
  const fs::path base = ResolvePath(dir.empty() ? fs::path(".") : dir);
  const fs::path resolved = ResolvePath(image);
  if (resolved != base && IsWithinFolder(resolved, base)) return Status::Ok();
  return Error{entry + ": image \"" + written + "\" lies outside the capture folder " +
               base.string() + " (it resolves to " + resolved.string() +
               "); refused unless allowed (--allow-outside-paths)"};
}

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

Status ProbeAll(PhotoSet& set) {
  for (Photo& photo : set.photos) {
    if (Status s = ProbePhoto(photo); !s) return s;
  }
  return Status::Ok();
}

}  // namespace

// ---------------------------------------------------------------------------------------------

const char* ToString(ColourEncoding encoding) {
  switch (encoding) {
    case ColourEncoding::kSrgb:
      return "srgb";
    case ColourEncoding::kLinear:
      return "linear";
    case ColourEncoding::kAuto:
      break;
  }
  return "auto";
}

float SrgbToLinear(float encoded) { return static_cast<float>(SrgbToLinearD(encoded)); }

Status Camera::Validate(const std::string& what) const {
  const auto bad = [&](const std::string& field, const std::string& problem) {
    return Error{what + "." + field + " " + problem};
  };
  if (width <= 0 || width > kMaxImageSide)
    return bad("width", "must be in 1.." + std::to_string(kMaxImageSide) + " px, got " +
                            std::to_string(width));
  if (height <= 0 || height > kMaxImageSide)
    return bad("height", "must be in 1.." + std::to_string(kMaxImageSide) + " px, got " +
                             std::to_string(height));
  if (model == CameraModel::kPinhole) {
    if (!(std::isfinite(fx) && fx > 0)) return bad("fx", "must be > 0 px, got " + Num(fx));
    if (!(std::isfinite(fy) && fy > 0)) return bad("fy", "must be > 0 px, got " + Num(fy));
    // The field of view over the whole image, whatever the principal point: a focal length off
    // by orders of magnitude (in mm instead of px, or a stray exponent) shows here first.
    const auto fov_deg = [](int size, double f) {
      return 2.0 * std::atan(size / (2.0 * f)) * 180.0 / M_PI;
    };
    for (const auto& [key, size, f, way] :
         {std::tuple{"fx", width, fx, "horizontal"}, std::tuple{"fy", height, fy, "vertical"}}) {
      const double fov = fov_deg(size, f);
      if (!(fov >= kMinFieldOfViewDeg && fov <= kMaxFieldOfViewDeg)) {
        return bad(key, Num(f) + " px gives a " + way + " field of view of " + Num(fov) +
                            " deg over " + std::to_string(size) + " px; a camera has " +
                            Num(kMinFieldOfViewDeg) + " to " + Num(kMaxFieldOfViewDeg) + " deg");
      }
    }
  } else {
    if (!(std::isfinite(pixel_pitch_mm) && pixel_pitch_mm > 0)) {
      return bad("pixel_pitch_mm", "must be > 0 mm, got " + Num(pixel_pitch_mm));
    }
  }
  if (!std::isfinite(cx)) return bad("cx", "is not finite");
  if (!std::isfinite(cy)) return bad("cy", "is not finite");
  // Shifted lenses move the principal point, but not by more than the image's own size.
  for (const auto& [key, c, size] : {std::tuple{"cx", cx, width}, std::tuple{"cy", cy, height}}) {
    const double margin = kMaxPrincipalPointOffset * size;
    if (!(c >= -margin && c <= size + margin)) {
      return bad(key, Num(c) + " px is further outside the " + std::to_string(size) +
                          "-px image than " + Num(kMaxPrincipalPointOffset) +
                          " image size (allowed " + Num(-margin) + " to " + Num(size + margin) +
                          ")");
    }
  }
  const Mat3d& R = camera_from_scan.rotation;
  if (!R.allFinite()) return bad("camera_from_scan.rotation", "is not finite");
  const double det = R.determinant();
  const double off = (R.transpose() * R - Mat3d::Identity()).norm();
  if (!(det > 0) || off > kRotationTolerance) {
    return bad("camera_from_scan.rotation",
               "is not a rotation (det " + Num(det) + ", |R^T R - I| " + Num(off) + ")");
  }
  if (!camera_from_scan.translation.allFinite()) {
    return bad("camera_from_scan.translation_mm", "is not finite");
  }
  return Status::Ok();
}

Status Light::Validate(const std::string& what) const {
  const auto rgb_ok = [](const Vec3f& v) {
    return v.allFinite() && v.minCoeff() >= 0 && v.maxCoeff() > 0;
  };
  const auto show = [](const Vec3f& v) {
    return "[" + Num(v.x()) + ", " + Num(v.y()) + ", " + Num(v.z()) + "]";
  };
  if (type == LightType::kPoint) {
    if (!position_mm.allFinite()) return Error{what + ".position_mm is not finite"};
    if (!rgb_ok(intensity)) {
      return Error{what + ".intensity must be >= 0 and not all zero, got " + show(intensity)};
    }
  } else {
    if (!direction.allFinite() || std::abs(direction.norm() - 1.0) > 1e-6) {
      return Error{what + ".direction must be a unit vector, got |d| = " + Num(direction.norm())};
    }
    if (!rgb_ok(irradiance)) {
      return Error{what + ".irradiance must be >= 0 and not all zero, got " + show(irradiance)};
    }
  }
  return Status::Ok();
}

Status PhotoSetOptions::Validate() const {
  if (!(saturation_encoded > 0 && saturation_encoded <= 1)) {
    return Error{"saturation_encoded must be in (0, 1] (fraction of the maximum code), got " +
                 Num(saturation_encoded)};
  }
  if (!(float_saturation_level > 0)) {
    return Error{"float_saturation_level must be > 0 (linear value; inf = never), got " +
                 Num(float_saturation_level)};
  }
  if (!(max_non_finite_fraction >= 0 && max_non_finite_fraction <= 1)) {
    return Error{"max_non_finite_fraction must be in [0, 1], got " + Num(max_non_finite_fraction)};
  }
  if (max_pixels_per_image == 0) return Error{"max_pixels_per_image must be > 0"};
  if (!(rti_pixel_pitch_mm == 0 ||
        (rti_pixel_pitch_mm >= kMinRtiPitchMm && rti_pixel_pitch_mm <= kMaxRtiPitchMm))) {
    return Error{"rti_pixel_pitch_mm must be " + Num(kMinRtiPitchMm) + " to " +
                 Num(kMaxRtiPitchMm) + " mm (or 0: from the images), got " +
                 Num(rti_pixel_pitch_mm)};
  }
  if (!(std::isfinite(rti_camera_distance_mm) && rti_camera_distance_mm > 0)) {
    return Error{"rti_camera_distance_mm must be > 0 mm, got " + Num(rti_camera_distance_mm)};
  }
  return Status::Ok();
}

std::string PhotoLoadSummary::Brief() const {
  char buf[256];
  const double mpx = pixels / 1e6;
  const double sat_pct = pixels ? 100.0 * saturated_pixels / pixels : 0.0;
  std::snprintf(buf, sizeof buf,
                "%d photos (%d sRGB, %d linear), %.1f Mpx, %zu NaN/Inf px, %zu saturated px "
                "(%.2f %%); %.2f s",
                photos_loaded, srgb_photos, linear_photos, mpx, non_finite_pixels, saturated_pixels,
                sat_pct, seconds);
  return buf;
}

Status LoadPhoto(Photo& photo, const PhotoSetOptions& options) {
  if (Status s = options.Validate(); !s) return s;
  auto image = ReadImage(photo.path, options.max_pixels_per_image);
  if (!image) return Error{photo.entry + ": " + image.error().message};
  if (image->width != photo.camera.width || image->height != photo.camera.height) {
    return Error{photo.entry + ": " + photo.path.string() + ": image is " +
                 Size(image->width, image->height) + ", its camera says " +
                 Size(photo.camera.width, photo.camera.height)};
  }
  if (image->channels == 4) {
    // RGBA (a PNG saved with alpha): the colour is what was photographed; alpha is dropped.
    float* p = image->pixels.data();
    const size_t n = static_cast<size_t>(image->width) * static_cast<size_t>(image->height);
    for (size_t i = 0; i < n; ++i)
      for (int c = 0; c < 3; ++c) p[i * 3 + c] = p[i * 4 + c];
    image->pixels.resize(n * 3);
    image->channels = 3;
  }
  if (image->channels != 1 && image->channels != 3) {
    return Error{photo.entry + ": " + photo.path.string() + ": " + std::to_string(image->channels) +
                 " channels; photos must be 1-channel (grey), 3-channel (RGB) or RGBA"};
  }
  const ColourEncoding encoding = Resolve(photo.encoding, image->integer_samples);
  Converted c;
  try {
    c = Convert(*image, encoding, options);
  } catch (const std::bad_alloc&) {
    return Error{photo.entry + ": " + photo.path.string() + ": not enough memory for " +
                 Size(image->width, image->height) + " float RGB pixels"};
  }
  const size_t pixels = c.rgb.size();
  if (c.non_finite > options.max_non_finite_fraction * static_cast<double>(pixels)) {
    return Error{photo.entry + ": " + photo.path.string() + ": " + std::to_string(c.non_finite) +
                 " of " + std::to_string(pixels) + " pixels are NaN/Inf (more than " +
                 Num(100 * options.max_non_finite_fraction) + " %): corrupt image"};
  }
  photo.encoding = encoding;
  photo.rgb = std::move(c.rgb);
  photo.flags = std::move(c.flags);
  photo.non_finite_pixels = c.non_finite;
  photo.saturated_pixels = c.saturated;
  return Status::Ok();
}

Status LoadPhotoPixels(PhotoSet& set, const PhotoSetOptions& options,
                       const ProgressCallback& progress) {
  if (Status s = options.Validate(); !s) return s;
  const auto start = std::chrono::steady_clock::now();
  const size_t n = set.photos.size();
  std::vector<Status> status(n);
  std::atomic<bool> failed{false};
  std::atomic<size_t> done{0};
  std::mutex progress_mutex;
  ReportProgress(progress, "load photos", 0.0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (failed.load(std::memory_order_relaxed)) return;  // the set is refused anyway
      status[i] = LoadPhoto(set.photos[i], options);
      if (!status[i].ok()) failed = true;
      const size_t finished = ++done;
      if (progress) {
        std::lock_guard<std::mutex> lock(progress_mutex);
        progress("load photos", static_cast<double>(finished) / static_cast<double>(n));
      }
    }
  });
  if (failed) {
    for (Photo& photo : set.photos) {  // no partial state
      photo.rgb = Grid<Vec3f>();
      photo.flags = Grid<uint8_t>();
      photo.non_finite_pixels = photo.saturated_pixels = 0;
    }
    set.summary = PhotoLoadSummary{};
    for (const Status& s : status) {
      if (!s.ok()) return s;
    }
  }
  PhotoLoadSummary summary;
  for (const Photo& photo : set.photos) {
    ++summary.photos_loaded;
    summary.pixels += photo.rgb.size();
    summary.non_finite_pixels += photo.non_finite_pixels;
    summary.saturated_pixels += photo.saturated_pixels;
    (photo.encoding == ColourEncoding::kSrgb ? summary.srgb_photos : summary.linear_photos) += 1;
  }
  summary.seconds = Seconds(start);
  set.summary = summary;
  return Status::Ok();
}

namespace {

// One image listed twice would weigh as two measurements of one light and view. Paths are compared
// once resolved and lexically normalised ("a/../x.png" is "x.png"); the same file under two names
// (a copy, a link) is not looked for: that would mean reading every image's bytes for a mistake
// that a path comparison already catches in the cases met (a line pasted twice, an edited index).
Status CheckDistinctImages(const PhotoSet& set) {
  std::map<fs::path, const Photo*> seen;
  for (const Photo& photo : set.photos) {
    const auto [it, added] = seen.emplace(photo.path.lexically_normal(), &photo);
    if (!added) {
      return Error{photo.entry + ": " + photo.path.string() + " is the same image as " +
                   it->second->entry + " (each image may be listed once)"};
    }
  }
  return Status::Ok();
}

}  // namespace

Result<PhotoSet> ParseCalibrationText(std::string_view text, const fs::path& source) {
  try {
    PhotoSet set = ParseCalibration(source, text);
    if (Status s = CheckDistinctImages(set); !s) return Error{s.message()};
    return set;
  } catch (const BadInput& bad) {
    return Error{bad.message};
  }
}

Result<std::vector<RtiLightEntry>> ParseRtiLightsText(std::string_view text,
                                                      const fs::path& source) {
  try {
    return ParseLp(source, text);
  } catch (const BadInput& bad) {
    return Error{bad.message};
  }
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

namespace {

// 72 and 96 per inch are what cameras and image software write when they know no scale: a
// camera's RTI photos tagged so do not show the canvas at 0.35 or 0.26 mm per pixel.
bool IsPlaceholderResolution(double mm_per_pixel) {
  for (double dpi : {72.0, 96.0})
    if (std::abs(mm_per_pixel - 25.4 / dpi) < 1e-6 * mm_per_pixel) return true;
  return false;
}

}  // namespace

Result<PhotoSet> ReadRtiCapture(const fs::path& lp_path, const PhotoSetOptions& options,
                                const ProgressCallback& progress) {
  if (Status s = options.Validate(); !s) return Error{s.message()};
  auto text = ReadTextFile(lp_path, ".lp light file");
  if (!text) return text.error();
  auto entries = ParseRtiLightsText(*text, lp_path);
  if (!entries) return entries.error();
  const fs::path dir = lp_path.parent_path();
  PhotoSet set;
  set.source = lp_path;
  set.is_rti = true;

  // The first image fixes the grid and the pitch; the camera looks straight down at the canvas
  // centre.
  int width = 0, height = 0;
  double tagged_mm_per_pixel = 0;
  std::string tag;
  for (const RtiLightEntry& e : *entries) {
    Photo photo;
    photo.entry = lp_path.string() + ", line " + std::to_string(e.line);
    photo.path = ResolveLpImage(dir, e.image);
    if (Status s = CheckImageInsideFolder(photo.path, dir, photo.entry, e.image, options); !s)
      return Error{s.message()};
    auto header = ReadHeader(photo.path);
    if (!header) return Error{photo.entry + ": " + header.error().message};
    if (width == 0) {
      width = header->width;
      height = header->height;
      tagged_mm_per_pixel = header->mm_per_pixel;
      tag = photo.path.filename().string() + "'s resolution tag (" + header->resolution_tag + ")";
    } else if (header->width != width || header->height != height) {
      return Error{photo.entry + ": " + photo.path.string() + ": image is " +
                   Size(header->width, header->height) + ", the first image (" +
                   set.photos.front().path.filename().string() + ") is " + Size(width, height)};
    }
    photo.encoding = Resolve(ColourEncoding::kAuto, header->integer_samples);
    photo.light.type = LightType::kDirectional;
    photo.light.direction = e.direction;
    photo.light.irradiance = Vec3f::Ones();
    set.photos.push_back(std::move(photo));
  }
  if (options.rti_pixel_pitch_mm > 0) {
    set.rti_pitch_mm = options.rti_pixel_pitch_mm;
    set.rti_pitch_source = "given (rti_pixel_pitch_mm)";
  } else if (tagged_mm_per_pixel >= kMinRtiPitchMm && tagged_mm_per_pixel <= kMaxRtiPitchMm &&
             !IsPlaceholderResolution(tagged_mm_per_pixel)) {
    set.rti_pitch_mm = tagged_mm_per_pixel;
    set.rti_pitch_source = "from " + tag;
  } else {
    set.rti_pitch_mm = kRtiAssumedPitchMm;
    set.rti_pitch_assumed = true;
    const std::string why = tagged_mm_per_pixel > 0
                                ? "the images' " + tag.substr(tag.find("resolution tag")) +
                                      (IsPlaceholderResolution(tagged_mm_per_pixel)
                                           ? " is a software default, not the canvas's scale"
                                           : " is not a plausible scale (" + Num(kMinRtiPitchMm) +
                                                 " to " + Num(kMaxRtiPitchMm) + " mm per pixel)")
                                : "the images have no resolution tag";
    set.rti_pitch_source = "assumed: " + why + ", so the physical size (" +
                           Num(width * kRtiAssumedPitchMm) + " x " +
                           Num(height * kRtiAssumedPitchMm) + " mm) is made up";
  }
  Camera camera;
  camera.model = CameraModel::kOrthographic;
  camera.width = width;
  camera.height = height;
  camera.pixel_pitch_mm = set.rti_pitch_mm;
  // Pixel (u, v) centre <-> texel centre X = (u + 0.5) p, Y = (H - v - 0.5) p (height_field.h):
  // camera x = X - W p / 2, y = H p / 2 - Y, z = d - Z, principal point at the image centre.
  camera.cx = (width - 1) / 2.0;
  camera.cy = (height - 1) / 2.0;
  camera.camera_from_scan.rotation = Vec3d(1, -1, -1).asDiagonal();
  camera.camera_from_scan.translation =
      Vec3d(-width * camera.pixel_pitch_mm / 2, height * camera.pixel_pitch_mm / 2,
            options.rti_camera_distance_mm);
  for (Photo& photo : set.photos) photo.camera = camera;
  if (Status s = CheckDistinctImages(set); !s) return Error{s.message()};
  if (options.load_pixels) {
    if (Status s = LoadPhotoPixels(set, options, progress); !s) return Error{s.message()};
  }
  return set;
}

Status CheckCameraSeesCanvas(const Camera& camera, const RigidTransform& canvas_from_scan,
                             const Eigen::Vector2d& extent_mm, const std::string& what) {
  const RigidTransform scan_from_canvas = canvas_from_scan.Inverse();
  const Vec3d centre_scan = scan_from_canvas.Apply(Vec3d(extent_mm.x() / 2, extent_mm.y() / 2, 0));
  const double depth = camera.camera_from_scan.Apply(centre_scan).z();
  if (!(depth > 0)) {
    return Error{what + ": the canvas centre is behind the camera (depth " + Num(depth) + " mm)"};
  }
  // The side of the canvas the camera is on: towards-camera direction in the canvas frame.
  const double side = canvas_from_scan.ApplyToDirection(camera.DirectionToCamera(centre_scan)).z();
  if (!(side > 0)) {
    return Error{what +
                 ": the camera is behind the canvas (it looks at the canvas's back; "
                 "direction to the camera has canvas Z " +
                 Num(side) + ")"};
  }
  constexpr int kLattice = 9;
  for (int j = 0; j < kLattice; ++j) {
    for (int i = 0; i < kLattice; ++i) {
      const Vec3d p = scan_from_canvas.Apply(
          Vec3d(extent_mm.x() * i / (kLattice - 1), extent_mm.y() * j / (kLattice - 1), 0));
      if (camera.InFront(p) && camera.InImage(camera.Project(p))) return Status::Ok();
    }
  }
  const Eigen::Vector2d c = camera.Project(centre_scan);
  return Error{what + ": the camera sees none of the canvas (its centre projects to pixel (" +
               Num(c.x()) + ", " + Num(c.y()) + "), the image is " +
               Size(camera.width, camera.height) + ")"};
}

Status CheckCanvasFootprint(const Camera& camera, const RigidTransform& canvas_from_scan,
                            const Eigen::Vector2d& extent_mm, double pitch_mm,
                            const std::string& what) {
  const RigidTransform scan_from_canvas = canvas_from_scan.Inverse();
  const Vec3d centre = scan_from_canvas.Apply(Vec3d(extent_mm.x() / 2, extent_mm.y() / 2, 0));
  const Vec3d p = camera.camera_from_scan.Apply(centre);
  // Derivative of the projection along a canvas axis at the centre, px per mm: analytic, so that
  // absurd scales (1e-300) come out as what they are rather than as rounding noise.
  const auto px_per_mm = [&](const Vec3d& axis_canvas) {
    const Vec3d d = camera.camera_from_scan.rotation * (scan_from_canvas.rotation * axis_canvas);
    Eigen::Vector2d j;
    if (camera.model == CameraModel::kOrthographic) {
      j = Eigen::Vector2d(d.x(), d.y()) / camera.pixel_pitch_mm;
    } else {
      j = Eigen::Vector2d(camera.fx * (d.x() * p.z() - p.x() * d.z()),
                          camera.fy * (d.y() * p.z() - p.y() * d.z())) /
          (p.z() * p.z());
    }
    return j.norm();
  };
  const double sx = px_per_mm(Vec3d::UnitX()), sy = px_per_mm(Vec3d::UnitY());
  const double wide = sx * extent_mm.x(), tall = sy * extent_mm.y();
  if (!(wide >= kMinCanvasFootprintPx && tall >= kMinCanvasFootprintPx)) {
    return Error{what + ": the canvas spans only " + Num(wide) + " x " + Num(tall) +
                 " px in this photo (at least " + Num(kMinCanvasFootprintPx) +
                 " px along each axis): its focal length, pixel pitch or distance is off"};
  }
  for (const auto& [axis, s] : {std::pair{"X", sx}, std::pair{"Y", sy}}) {
    const double px_per_texel = s * pitch_mm;
    if (!(px_per_texel >= 1.0 / kMaxTexelsPerPixel)) {
      return Error{what + ": one pixel of this photo spans " + Num(1.0 / px_per_texel) +
                   " texels along the canvas's " + axis + " (at most " + Num(kMaxTexelsPerPixel) +
                   "): too coarse for a canvas of pitch " + Num(pitch_mm) + " mm"};
    }
    if (!(px_per_texel <= kMaxPixelsPerTexel)) {
      return Error{what + ": one texel of the canvas (pitch " + Num(pitch_mm) + " mm) spans " +
                   Num(px_per_texel) + " pixels of this photo along the canvas's " + axis +
                   " (at most " + Num(kMaxPixelsPerTexel) +
                   "): its focal length, pixel pitch or distance is off"};
    }
  }
  return Status::Ok();
}

Status CheckCamerasSeeCanvas(const PhotoSet& set, const RigidTransform& canvas_from_scan,
                             const HeightField& canvas) {
  const Eigen::Vector2d extent(canvas.width() * canvas.pitch_mm, canvas.height() * canvas.pitch_mm);
  for (const Photo& photo : set.photos) {
    if (Status s = CheckCameraSeesCanvas(photo.camera, canvas_from_scan, extent, photo.entry); !s) {
      return s;
    }
    if (Status s = CheckCanvasFootprint(photo.camera, canvas_from_scan, extent, canvas.pitch_mm,
                                        photo.entry);
        !s) {
      return s;
    }
  }
  return Status::Ok();
}

Result<HeightField> FlatCanvasForRti(const PhotoSet& set) {
  if (!set.is_rti || set.photos.empty()) {
    return Error{set.source.string() +
                 ": not an RTI capture, a flat canvas needs an RTI photo set"};
  }
  HeightField field;
  const Camera& camera = set.photos.front().camera;
  field.height_mm = Grid<float>(camera.width, camera.height, 0.0f);
  field.state = Grid<TexelState>(camera.width, camera.height, TexelState::kMeasured);
  field.pitch_mm = set.rti_pitch_mm;
  return field;
}

}  // namespace digitize
