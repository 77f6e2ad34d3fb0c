// RTI captures (docs/formats.md, "RTI captures (.lp)"): an .lp file of image names and light
// directions, the images straight-on and orthographic, their pitch given, tagged or assumed.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "digitize/photo_set.h"
#include "json_fields.h"
#include "photo_set_internal.h"
#include "text_tokens.h"

namespace digitize {

using namespace photo_detail;
namespace fs = std::filesystem;

namespace {

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
    const auto tokens = SplitTokens(line, kAsciiSpace);
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
      if (!ParseWholeNumber(t, count) || count <= 0 || count > 1000000) {
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
    for (double v = 0; numbers + 1 < n && ParseWholeNumber(tokens[n - 1 - numbers].text, v, true);)
      ++numbers;
    if (numbers > 3) {
      const TextToken& name_end = tokens[n - 1 - numbers];
      Fail(at(line_no) + "expected \"filename x y z\" (a file name and 3 numbers), got " +
           std::to_string(numbers) + " numbers after \"" +
           std::string(line.substr(tokens[0].begin,
                                   name_end.begin + name_end.text.size() - tokens[0].begin)) +
           "\"");
    }
    // The file name is everything before the three numbers (it may contain spaces): from its
    // first token to the end of its last, so no separator (\r, \v, \f too) sticks to it.
    const TextToken& last = tokens[n - 4];
    e.image =
        std::string(line.substr(tokens[0].begin, last.begin + last.text.size() - tokens[0].begin));
    // A name with a NUL would be cut short by the OS and open another file than the one named.
    if (e.image.find('\0') != std::string::npos) {
      Fail(at(line_no) + "the file name contains a NUL character");
    }
    static const char* kAxis[3] = {"x", "y", "z"};
    for (int k = 0; k < 3; ++k) {
      const std::string_view t = tokens[n - 3 + k].text;
      double v = 0;
      if (!ParseWholeNumber(t, v, /*plus_allowed=*/true)) {
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

// 72 and 96 per inch are what cameras and image software write when they know no scale: a
// camera's RTI photos tagged so do not show the canvas at 0.35 or 0.26 mm per pixel.
bool IsPlaceholderResolution(double mm_per_pixel) {
  for (double dpi : {72.0, 96.0})
    if (std::abs(mm_per_pixel - 25.4 / dpi) < 1e-6 * mm_per_pixel) return true;
  return false;
}

}  // namespace

Result<std::vector<RtiLightEntry>> ParseRtiLightsText(std::string_view text,
                                                      const fs::path& source) {
  return CatchBadInput([&] { return ParseLp(source, text); });
}

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
    const std::string why =
        tagged_mm_per_pixel > 0
            ? "the images' " + tag.substr(tag.find("resolution tag")) +
                  (IsPlaceholderResolution(tagged_mm_per_pixel)
                       ? " is a software default, not the canvas's scale"
                       : " is not a plausible scale (" +
                             FormatNumber(kMinRtiPitchMm, kShownDigits) + " to " +
                             FormatNumber(kMaxRtiPitchMm, kShownDigits) + " mm per pixel)")
            : "the images have no resolution tag";
    set.rti_pitch_source = "assumed: " + why + ", so the physical size (" +
                           FormatNumber(width * kRtiAssumedPitchMm, kShownDigits) + " x " +
                           FormatNumber(height * kRtiAssumedPitchMm, kShownDigits) +
                           " mm) is made up";
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
