// Texture packs: a multi-part half-float OpenEXR file through OpenImageIO (pack.h).
#include "digitize/pack.h"

#include <OpenImageIO/half.h>
#include <OpenImageIO/hash.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstring>
#include <ctime>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <system_error>

#include "checked_output.h"
#include "digitize/image_io.h"
#include "exr_attribute_size.h"

namespace digitize {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr const char* kGauge = "lafortune1: f = rho_d + rho_s max(0, cx vx lx + cy vy ly + vz lz)^k, "
                               "cz = 1, v and l in the texel's tangent frame (tangent_frame.h)";
constexpr int kParts = 3;
constexpr float kHalfMax = 65504.0f;

// Channel layout of each part, in the order the Pack is filled. EXR stores channels sorted by
// name, so the reader looks them up by name, never by position.
const std::vector<std::string> kSurfaceChannels = {"H", "NX", "NY", "M"};
const std::vector<std::string> kReflectanceChannels = {"rho_d.R", "rho_d.G", "rho_d.B",
                                                       "rho_s.R", "rho_s.G", "rho_s.B",
                                                       "lobe.cx", "lobe.cy", "lobe.k"};
const std::vector<std::string> kBoxChannels = {"present", "h_max", "u_max", "v_max"};
const char* const kPartNames[kParts] = {"surface", "reflectance", "boxes"};

std::string TexelName(int x, int y) { return std::to_string(x) + ", " + std::to_string(y); }

// --- half encoding --------------------------------------------------------------------------

uint16_t ToHalfBits(float v) { return half(v).bits(); }
float FromHalfBits(uint16_t bits) {
  half h;
  h.setBits(bits);
  return static_cast<float>(h);
}

// Rounds a finite half to `bits` mantissa bits (of 10), to nearest; a value that would round up
// into infinity is truncated instead.
uint16_t QuantiseHalfBits(uint16_t h, int bits) {
  if (bits >= 10) return h;
  const uint16_t sign = h & 0x8000u;
  const uint16_t magnitude = h & 0x7fffu;
  const int drop = 10 - bits;
  const uint16_t mask = static_cast<uint16_t>(~((1u << drop) - 1u)) & 0x7fffu;
  uint32_t rounded = (static_cast<uint32_t>(magnitude) + (1u << (drop - 1))) & mask;
  if (rounded >= 0x7c00u) rounded = magnitude & mask;  // would be Inf
  return static_cast<uint16_t>(sign | rounded);
}

float Encode(float v, int bits) { return FromHalfBits(QuantiseHalfBits(ToHalfBits(v), bits)); }

// Normal from its stored (nx, ny): nz >= 0 recomputed, renormalised when rounding pushed
// nx^2 + ny^2 past 1. The single definition both the writer's preview and the reader use.
Vec3f NormalFromXY(float nx, float ny) {
  const float s = nx * nx + ny * ny;
  if (s >= 1.0f) {
    const float inv = 1.0f / std::sqrt(s);
    return {nx * inv, ny * inv, 0.0f};
  }
  return {nx, ny, std::sqrt(1.0f - s)};
}

uint16_t StateStatusCode(TexelState state, TexelFitStatus status) {
  return static_cast<uint16_t>(static_cast<int>(state) + 4 * static_cast<int>(status));
}

// --- metadata -----------------------------------------------------------------------------

std::string Num(double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);  // shortest round-trip form
  return std::string(buf, r.ptr);
}

json ProvenanceJson(const PackProvenance& p) {
  json inputs = json::array();
  for (const PackInput& in : p.inputs)
    inputs.push_back({{"name", in.name}, {"sha1", in.sha1}, {"bytes", in.bytes}});
  json options = json::object();
  if (!p.options_json.empty()) {
    options = json::parse(p.options_json, nullptr, /*allow_exceptions=*/false);
    if (options.is_discarded()) options = p.options_json;  // kept as text rather than lost
  }
  return {{"tool_version", p.tool_version}, {"created_utc", p.created_utc},
          {"fit_brief", p.fit_brief},       {"options", options},
          {"inputs", inputs}};
}

json TransformJson(const RigidTransform& t) {
  json rot = json::array();
  for (int r = 0; r < 3; ++r) rot.push_back({t.rotation(r, 0), t.rotation(r, 1), t.rotation(r, 2)});
  return {{"rotation", rot},
          {"translation_mm", {t.translation.x(), t.translation.y(), t.translation.z()}}};
}

// The physical bounds of pack.h on what a pack states about its geometry. Each message starts
// with the value's name (pitch_mm, delta0_mm, max_height_mm, canvas_from_scan) for the caller to
// prefix: "pack: " in memory, "FILE: digitize:" for a header.
Status CheckPhysicalBounds(double pitch_mm, int w, int h, double delta0_mm, double max_height_mm,
                           const RigidTransform& canvas_from_scan) {
  if (!(std::isfinite(pitch_mm) && pitch_mm >= kMinPackPitchMm))
    return Error{"pitch_mm " + Num(pitch_mm) + " is not a texel pitch (at least " +
                 Num(kMinPackPitchMm) + " mm, finite)"};
  const int texels = std::max(w, h);
  const double extent_mm = pitch_mm * texels;
  if (!(extent_mm <= kMaxPackExtentMm))
    return Error{"pitch_mm " + Num(pitch_mm) + " x " + std::to_string(texels) +
                 " texels = " + Num(extent_mm) + " mm, beyond the " + Num(kMaxPackExtentMm / 1000) +
                 " m a painting may measure"};
  if (!(std::isfinite(max_height_mm) && std::abs(max_height_mm) <= kMaxPackHeightMm))
    return Error{"max_height_mm " + Num(max_height_mm) + " is outside [-" + Num(kMaxPackHeightMm) +
                 ", " + Num(kMaxPackHeightMm) + "] mm"};
  if (!(std::isfinite(delta0_mm) && delta0_mm >= 0 &&
        (delta0_mm <= max_height_mm + 1e-9 || delta0_mm == 0)))
    return Error{"delta0_mm " + Num(delta0_mm) + " is not in [0, max_height_mm " +
                 Num(max_height_mm) + "]"};
  const Mat3d& r = canvas_from_scan.rotation;
  if (!r.allFinite() ||
      !((r * r.transpose() - Mat3d::Identity()).norm() <= kPackRotationTolerance) ||
      !(r.determinant() > 0))
    return Error{"canvas_from_scan rotation is not a rotation (|R R^T - I| above " +
                 Num(kPackRotationTolerance) + ", or det <= 0)"};
  const Vec3d& t = canvas_from_scan.translation;
  if (!t.allFinite() || !(t.norm() <= kMaxPackTranslationMm))
    return Error{"canvas_from_scan translation (" + Num(t.x()) + ", " + Num(t.y()) + ", " +
                 Num(t.z()) + ") mm is farther than " + Num(kMaxPackTranslationMm / 1000) +
                 " m from the scanner"};
  return Status::Ok();
}

std::string QuantisationText(const PackQuantisation& q) {
  return "height=" + std::to_string(q.height_bits) + ",normal=" + std::to_string(q.normal_bits) +
         ",rho=" + std::to_string(q.rho_bits) + ",lobe=" + std::to_string(q.lobe_bits);
}

// Integrity: EXR has no checksum, and a flipped bit in ZIP data can decode to other valid-looking
// values. The writer hashes every digitize:* attribute (sorted by name, the checksum excluded)
// and the decoded pixels of every part; the reader recomputes it.
std::string PackChecksum(const OIIO::ImageSpec& meta, const void* const data[kParts],
                         const size_t bytes[kParts]) {
  std::vector<std::pair<std::string, std::string>> attrs;
  for (const OIIO::ParamValue& p : meta.extra_attribs) {
    const std::string name = p.name().string();
    if (name.rfind("digitize:", 0) == 0 && name != "digitize:checksum")
      attrs.emplace_back(name, meta.get_string_attribute(name));
  }
  std::sort(attrs.begin(), attrs.end());
  OIIO::SHA1 sha;
  for (const auto& [k, v] : attrs) {
    sha.append(k);
    sha.append("=", 1);
    sha.append(v);
    sha.append("\n", 1);
  }
  for (int p = 0; p < kParts; ++p) sha.append(data[p], bytes[p]);
  return sha.digest();
}

// --- header pre-scan ------------------------------------------------------------------------
// OpenEXR sizes its line-offset tables and buffers from the data window a header claims. Before
// OpenImageIO opens the file, walk the raw headers (bounded by the file size and
// max_header_bytes) and refuse windows beyond max_texels, so a forged header cannot make the
// reader allocate gigabytes.

struct RawPart {
  int64_t width = 0, height = 0;
};

// A part's channel list (OpenEXR "chlist": per channel a NUL-terminated name, int32 pixel type,
// uint8 pLinear, 3 reserved bytes, int32 x and y sampling; then a NUL). Checked before OpenImageIO
// sees it: OpenImageIO 2.4 aborts the process on a pixel type other than 0-2 (UINT, HALF, FLOAT),
// found by tests/fuzz/fuzz_pack. A pack's channels are never subsampled.
Status CheckChannelList(const std::string& name, size_t part, const char* list, size_t size) {
  const std::string where = name + ": part " + std::to_string(part) + " channel list";
  auto i32 = [&](size_t at) {
    uint32_t u = 0;
    for (int i = 3; i >= 0; --i) u = (u << 8) | static_cast<uint8_t>(list[at + i]);
    int32_t v;
    std::memcpy(&v, &u, 4);
    return v;
  };
  size_t pos = 0;
  for (;;) {
    if (pos >= size) return Error{where + " is truncated"};
    if (list[pos] == '\0') return Status::Ok();  // end of the list
    const void* nul = std::memchr(list + pos, '\0', std::min<size_t>(size - pos, 256));
    if (nul == nullptr) return Error{where + " has a name without an end"};
    const std::string channel(list + pos, static_cast<const char*>(nul) - (list + pos));
    pos += channel.size() + 1;
    if (size - pos < 16) return Error{where + " is truncated"};
    const int32_t pixel_type = i32(pos), x_sampling = i32(pos + 8), y_sampling = i32(pos + 12);
    if (pixel_type < 0 || pixel_type > 2)
      return Error{where + ": channel \"" + EscapeForTerminal(channel.substr(0, 40)) +
                   "\" has unknown pixel type " + std::to_string(pixel_type)};
    if (x_sampling != 1 || y_sampling != 1)
      return Error{where + ": channel \"" + EscapeForTerminal(channel.substr(0, 40)) +
                   "\" is subsampled (" + std::to_string(x_sampling) + ", " +
                   std::to_string(y_sampling) + "); a digitize pack never is"};
    pos += 16;
  }
}

Result<std::vector<RawPart>> ScanExrHeaders(const fs::path& path, uint64_t file_bytes,
                                            const PackReadOptions& options) {
  const std::string name = path.string();
  const uint64_t want = std::min<uint64_t>(file_bytes, static_cast<uint64_t>(options.max_header_bytes) + 8);
  std::vector<char> bytes(want);
  {
    std::ifstream in(path, std::ios::binary);
    if (!in) return Error{name + ": cannot open"};
    in.read(bytes.data(), static_cast<std::streamsize>(want));
    if (static_cast<uint64_t>(in.gcount()) != want) return Error{name + ": read failed"};
  }
  size_t pos = 0;
  auto need = [&](size_t n) { return pos + n <= bytes.size(); };
  auto read_i32 = [&](int32_t& v) {
    if (!need(4)) return false;
    uint32_t u = 0;
    for (int i = 3; i >= 0; --i) u = (u << 8) | static_cast<uint8_t>(bytes[pos + i]);
    std::memcpy(&v, &u, 4);
    pos += 4;
    return true;
  };
  // Attribute and type names: NUL-terminated, at most 31 characters, or 255 with the long-names
  // flag. OpenEXR reads no further than that limit, so a longer name read here would leave the
  // two parsers out of step: OpenEXR then takes name bytes for a size field and allocates what
  // they say (a 3 KB file asked for 2 GB; found by tests/fuzz/fuzz_viewer_load).
  size_t max_name = 31;
  auto read_string = [&](std::string& s) {
    const size_t end = std::min(bytes.size(), pos + max_name + 1);
    for (size_t i = pos; i < end; ++i) {
      if (bytes[i] == '\0') {
        s.assign(bytes.data() + pos, i - pos);
        pos = i + 1;
        return true;
      }
    }
    return false;
  };
  const std::string truncated = name + ": truncated or corrupt OpenEXR header";
  int32_t magic = 0, version = 0;
  if (!read_i32(magic) || magic != 20000630)
    return Error{name + ": not an OpenEXR file (bad magic number), so not a digitize pack"};
  if (!read_i32(version)) return Error{truncated};
  if ((version & 0xff) != 2) return Error{name + ": unsupported OpenEXR version " + std::to_string(version & 0xff)};
  if ((version & 0x800) != 0) return Error{name + ": deep OpenEXR data, not a digitize pack"};
  if ((version & 0x400) != 0) max_name = 255;
  const bool multipart = (version & 0x1000) != 0;
  if (!multipart)
    return Error{name + ": a single-part OpenEXR file; a digitize pack has " +
                 std::to_string(kParts) + " parts (surface, reflectance, boxes)"};
  std::vector<RawPart> parts;
  for (;;) {
    if (!need(1)) {
      return Error{file_bytes > bytes.size() ? name + ": OpenEXR headers larger than " +
                                                   std::to_string(options.max_header_bytes) +
                                                   " bytes (limit)"
                                             : truncated};
    }
    if (bytes[pos] == '\0') {  // empty header: end of the header list
      ++pos;
      break;
    }
    if (parts.size() >= kParts)
      return Error{name + ": more than " + std::to_string(kParts) + " parts; not a digitize pack"};
    RawPart part;
    bool has_window = false;
    for (;;) {
      if (!need(1)) return Error{truncated};
      if (bytes[pos] == '\0') {
        ++pos;
        break;
      }
      std::string attr, type;
      int32_t size = 0;
      for (std::string* s : {&attr, &type}) {
        if (read_string(*s)) continue;
        if (!need(max_name + 1)) return Error{truncated};
        return Error{name + ": part " + std::to_string(parts.size()) +
                     " has an attribute or type name longer than " + std::to_string(max_name) +
                     " characters, OpenEXR's limit" +
                     (max_name < 255 ? " without long names" : "")};
      }
      if (!read_i32(size) || size < 0 || !need(static_cast<size_t>(size))) return Error{truncated};
      if (const std::string problem =
              exr::AttributeSizeProblem(type, bytes.data() + pos, static_cast<size_t>(size));
          !problem.empty())
        return Error{name + ": part " + std::to_string(parts.size()) + " attribute '" +
                     EscapeForTerminal(attr) + "' " + problem + "; corrupt OpenEXR header"};
      if (attr == "dataWindow") {
        if (type != "box2i" || size != 16) return Error{name + ": malformed dataWindow attribute"};
        int32_t box[4] = {0, 0, 0, 0};
        for (int32_t& b : box) (void)read_i32(b);
        const int64_t w = int64_t{box[2]} - box[0] + 1, h = int64_t{box[3]} - box[1] + 1;
        if (w <= 0 || h <= 0)
          return Error{name + ": part " + std::to_string(parts.size()) + " has an empty data window"};
        if (w > options.max_texels || h > options.max_texels || w * h > options.max_texels)
          return Error{name + ": part " + std::to_string(parts.size()) + " claims " +
                       std::to_string(w) + "x" + std::to_string(h) + " pixels, more than the " +
                       std::to_string(options.max_texels) + "-texel limit"};
        part.width = w;
        part.height = h;
        has_window = true;
      } else if (attr == "channels") {
        if (type != "chlist") return Error{name + ": malformed channels attribute"};
        if (Status st = CheckChannelList(name, parts.size(), bytes.data() + pos,
                                         static_cast<size_t>(size));
            !st.ok())
          return Error{st.message()};
        pos += static_cast<size_t>(size);
      } else {
        pos += static_cast<size_t>(size);
      }
    }
    if (!has_window)
      return Error{name + ": part " + std::to_string(parts.size()) + " has no dataWindow"};
    parts.push_back(part);
  }
  if (parts.size() != kParts)
    return Error{name + ": " + std::to_string(parts.size()) + " parts, a digitize pack has " +
                 std::to_string(kParts) + " (surface, reflectance, boxes)"};
  return parts;
}

// --- reading helpers ------------------------------------------------------------------------

Result<double> ParseNumber(const std::string& file, const OIIO::ImageSpec& spec,
                           const std::string& key) {
  const std::string text = spec.get_string_attribute(key);
  if (text.empty()) return Error{file + ": header attribute " + key + " is missing"};
  double v = 0;
  const auto r = std::from_chars(text.data(), text.data() + text.size(), v);
  if (r.ec != std::errc() || r.ptr != text.data() + text.size() || !std::isfinite(v))
    return Error{file + ": header attribute " + key + " = \"" +
                 EscapeForTerminal(text.substr(0, 40)) + "\" is not a finite number"};
  return v;
}

// Index of each wanted channel in spec.channelnames; error when one is missing or the part has
// channels we do not know (a pack from a newer writer that did not bump the version).
Result<std::vector<int>> ChannelIndices(const std::string& file, const OIIO::ImageSpec& spec,
                                        const char* part, const std::vector<std::string>& wanted) {
  std::vector<int> index;
  for (const std::string& w : wanted) {
    const auto it = std::find(spec.channelnames.begin(), spec.channelnames.end(), w);
    if (it == spec.channelnames.end())
      return Error{file + ": part \"" + part + "\" lacks channel " + w};
    index.push_back(static_cast<int>(it - spec.channelnames.begin()));
  }
  if (spec.nchannels != static_cast<int>(wanted.size()))
    return Error{file + ": part \"" + part + "\" has " + std::to_string(spec.nchannels) +
                 " channels, expected " + std::to_string(wanted.size())};
  return index;
}

Result<PackProvenance> ParseProvenance(const std::string& file, const std::string& text) {
  PackProvenance p;
  const json doc = json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (doc.is_discarded() || !doc.is_object())
    return Error{file + ": digitize:provenance is not a JSON object"};
  try {
    p.tool_version = doc.value("tool_version", "");
    p.created_utc = doc.value("created_utc", "");
    p.fit_brief = doc.value("fit_brief", "");
    if (doc.contains("options")) p.options_json = doc["options"].dump();
    if (doc.contains("inputs")) {
      const json& inputs = doc["inputs"];
      if (!inputs.is_array()) return Error{file + ": digitize:provenance inputs is not an array"};
      for (const json& in : inputs) {
        PackInput input;
        input.name = in.at("name").get<std::string>();
        input.sha1 = in.value("sha1", "");
        input.bytes = in.value("bytes", uint64_t{0});
        p.inputs.push_back(std::move(input));
      }
    }
  } catch (const json::exception& e) {
    return Error{file + ": digitize:provenance: " + e.what()};
  }
  return p;
}

Result<RigidTransform> ParseTransform(const std::string& file, const std::string& text) {
  const json doc = json::parse(text, nullptr, false);
  RigidTransform t;
  try {
    if (doc.is_discarded()) throw std::runtime_error("not JSON");
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) t.rotation(r, c) = doc.at("rotation").at(r).at(c).get<double>();
    for (int r = 0; r < 3; ++r) t.translation(r) = doc.at("translation_mm").at(r).get<double>();
  } catch (const std::exception& e) {
    return Error{file + ": digitize:canvas_from_scan is malformed (" + e.what() + ")"};
  }
  const Mat3d& R = t.rotation;
  if (!R.allFinite() || !t.translation.allFinite() ||
      (R * R.transpose() - Mat3d::Identity()).norm() > 1e-4 || R.determinant() < 0)
    return Error{file + ": digitize:canvas_from_scan rotation is not a rotation"};
  return t;
}

// digitize:size_mm ("W x H", mm) must say what pitch x texels says: a reader that shows one and
// computes with the other would mislead.
Status CheckSizeMm(const std::string& file, const std::string& text, const PackSummary& s) {
  double size[2] = {0, 0};
  const char* p = text.data();
  const char* end = text.data() + text.size();
  bool ok = true;
  for (int i = 0; i < 2 && ok; ++i) {
    const auto r = std::from_chars(p, end, size[i]);
    ok = r.ec == std::errc() && std::isfinite(size[i]);
    p = r.ptr;
    if (ok && i == 0) {
      ok = std::string_view(p, end - p).rfind(" x ", 0) == 0;
      p += 3;
    }
  }
  if (!ok || p != end)
    return Error{file + ": header attribute digitize:size_mm = \"" +
                 EscapeForTerminal(text.substr(0, 40)) + "\" is not \"WIDTH x HEIGHT\" in mm"};
  const double want[2] = {s.width * s.pitch_mm, s.height * s.pitch_mm};
  for (int i = 0; i < 2; ++i)
    if (!(std::abs(size[i] - want[i]) <= kPackSizeTolerance * want[i]))
      return Error{file + ": digitize:size_mm " + Num(size[0]) + " x " + Num(size[1]) +
                   " mm disagrees with pitch_mm x texels = " + Num(want[0]) + " x " + Num(want[1]) +
                   " mm"};
  return Status::Ok();
}

struct Header {
  PackSummary summary;
  RigidTransform canvas_from_scan;
  int cells_x = 0, cells_y = 0;
};

// Opens the file and checks everything but the pixels.
Result<Header> ReadHeader(const fs::path& path, const PackReadOptions& options,
                          std::unique_ptr<OIIO::ImageInput>* keep_open) {
  const std::string file = path.string();
  std::error_code ec;
  const auto st = fs::status(path, ec);
  if (!fs::exists(st)) return Error{file + ": no such file"};
  if (!fs::is_regular_file(st)) return Error{file + ": not a regular file"};
  const uint64_t bytes = fs::file_size(path, ec);
  if (ec) return Error{file + ": cannot get the file size: " + ec.message()};
  if (bytes < 8) return Error{file + ": " + std::to_string(bytes) + " bytes, too short for a pack"};
  auto raw = ScanExrHeaders(path, bytes, options);
  if (!raw.ok()) return raw.error();

  auto in = OIIO::ImageInput::open(file);
  if (!in) return Error{file + ": OpenEXR reader refused it: " + OneLine(OIIO::geterror())};
  OIIO::ImageSpec spec = in->spec();
  Header h;
  PackSummary& s = h.summary;
  s.file_bytes = bytes;
  const std::string format = spec.get_string_attribute("digitize:format");
  if (format != kPackFormatName)
    return Error{file + ": not a digitize pack (header digitize:format is \"" +
                 EscapeForTerminal(format.substr(0, 40)) + "\", expected \"" + kPackFormatName +
                 "\")"};
  auto version = ParseNumber(file, spec, "digitize:version");
  if (!version.ok()) return version.error();
  if (*version != std::floor(*version) || *version < 1)
    return Error{file + ": bad pack version " + FormatNumber(*version)};
  if (*version > kPackVersion)
    return Error{file + ": pack version " + FormatNumber(*version) + " is newer than this reader (" +
                 std::to_string(kPackVersion) + "); update digitize"};
  s.version = static_cast<int>(*version);
  s.width = spec.width;
  s.height = spec.height;
  if (spec.width != raw->at(0).width || spec.height != raw->at(0).height)
    return Error{file + ": part sizes disagree between the raw header and the reader"};

  for (auto [key, target] : {std::pair<const char*, double*>{"digitize:pitch_mm", &s.pitch_mm},
                             {"digitize:delta0_mm", &s.delta0_mm},
                             {"digitize:max_height_mm", &s.max_height_mm}}) {
    auto v = ParseNumber(file, spec, key);
    if (!v.ok()) return v.error();
    *target = *v;
  }
  auto cell = ParseNumber(file, spec, "digitize:cell_px");
  if (!cell.ok()) return cell.error();
  if (*cell != std::floor(*cell) || *cell < 1 || *cell > 65536)
    return Error{file + ": digitize:cell_px must be an integer in [1, 65536]"};
  s.cell_px = static_cast<int>(*cell);
  auto box_count = ParseNumber(file, spec, "digitize:box_count");
  if (!box_count.ok()) return box_count.error();

  const std::string encoding = spec.get_string_attribute("digitize:encoding");
  if (encoding == "half") {
    s.encoding = PackEncoding::kHalf;
  } else if (encoding == "quantised") {
    s.encoding = PackEncoding::kQuantised;
    const std::string q = spec.get_string_attribute("digitize:quantisation");
    int hb = -1, nb = -1, rb = -1, lb = -1;
    if (std::sscanf(q.c_str(), "height=%d,normal=%d,rho=%d,lobe=%d", &hb, &nb, &rb, &lb) != 4)
      return Error{file + ": digitize:quantisation \"" + EscapeForTerminal(q.substr(0, 60)) +
                   "\" is malformed"};
    s.quantisation = {hb, nb, rb, lb};
    if (Status st = s.quantisation.Validate(); !st.ok())
      return Error{file + ": digitize:quantisation: " + st.message()};
  } else {
    return Error{file + ": digitize:encoding \"" + EscapeForTerminal(encoding.substr(0, 40)) +
                 "\" is neither half nor quantised"};
  }
  s.gauge = spec.get_string_attribute("digitize:gauge");
  if (s.gauge.rfind("lafortune1", 0) != 0)
    return Error{file + ": digitize:gauge \"" + EscapeForTerminal(s.gauge.substr(0, 40)) +
                 "\" is not the one-lobe Lafortune gauge this reader knows"};
  auto prov = ParseProvenance(file, spec.get_string_attribute("digitize:provenance"));
  if (!prov.ok()) return prov.error();
  s.provenance = std::move(prov).value();
  auto transform = ParseTransform(file, spec.get_string_attribute("digitize:canvas_from_scan"));
  if (!transform.ok()) return transform.error();
  h.canvas_from_scan = *transform;
  if (Status st = CheckPhysicalBounds(s.pitch_mm, s.width, s.height, s.delta0_mm, s.max_height_mm,
                                      h.canvas_from_scan);
      !st.ok())
    return Error{file + ": digitize:" + st.message()};
  if (Status st = CheckSizeMm(file, spec.get_string_attribute("digitize:size_mm"), s); !st.ok())
    return Error{st.message()};

  h.cells_x = (s.width + s.cell_px - 1) / s.cell_px;
  h.cells_y = (s.height + s.cell_px - 1) / s.cell_px;
  if (*box_count != std::floor(*box_count) || *box_count < 0 ||
      *box_count > double(h.cells_x) * h.cells_y)
    return Error{file + ": digitize:box_count " + Num(*box_count) + " exceeds the " +
                 std::to_string(h.cells_x) + "x" + std::to_string(h.cells_y) + " cells"};
  s.box_count = static_cast<size_t>(*box_count);

  for (int part = 1; part < kParts; ++part) {
    if (!in->seek_subimage(part, 0))
      return Error{file + ": part " + std::to_string(part) + " (" + kPartNames[part] +
                   ") cannot be read: " + OneLine(in->geterror())};
    const OIIO::ImageSpec& ps = in->spec();
    const int want_w = part == 2 ? h.cells_x : s.width, want_h = part == 2 ? h.cells_y : s.height;
    if (ps.width != want_w || ps.height != want_h || ps.width != raw->at(part).width ||
        ps.height != raw->at(part).height)
      return Error{file + ": part " + kPartNames[part] + " is " + std::to_string(ps.width) + "x" +
                   std::to_string(ps.height) + ", expected " + std::to_string(want_w) + "x" +
                   std::to_string(want_h)};
  }
  for (int part = 0; part < 2; ++part) {
    (void)in->seek_subimage(part, 0);
    s.raw_bytes_per_texel += static_cast<int>(in->spec().pixel_bytes(/*native=*/true));
  }
  if (in->seek_subimage(kParts, 0))
    return Error{file + ": more than " + std::to_string(kParts) + " parts"};
  if (!in->seek_subimage(0, 0)) return Error{file + ": cannot return to part 0"};
  if (keep_open) *keep_open = std::move(in);
  return h;
}

// Reads one part's channels as `type` into `out` (nchannels interleaved per pixel).
template <class T>
Status ReadPart(const std::string& file, OIIO::ImageInput& in, int part, OIIO::TypeDesc type,
                std::vector<T>& out) {
  if (!in.seek_subimage(part, 0))
    return Error{file + ": cannot seek to part " + std::to_string(part)};
  const OIIO::ImageSpec& spec = in.spec();
  out.resize(static_cast<size_t>(spec.width) * spec.height * spec.nchannels);
  if (!in.read_image(part, 0, 0, spec.nchannels, type, out.data()))
    return Error{file + ": part " + kPartNames[part] + " is corrupt or truncated (" +
                 OneLine(in.geterror()) + ")"};
  return Status::Ok();
}

}  // namespace

const char* ToString(PackEncoding encoding) {
  return encoding == PackEncoding::kHalf ? "half" : "quantised";
}

Status PackQuantisation::Validate() const {
  for (auto [name, v] : {std::pair<const char*, int>{"height_bits", height_bits},
                         {"normal_bits", normal_bits}, {"rho_bits", rho_bits},
                         {"lobe_bits", lobe_bits}})
    if (v < 0 || v > 10)
      return Error{std::string(name) + " must be in [0, 10] (half mantissa bits), got " +
                   std::to_string(v)};
  return Status::Ok();
}

Status PackWriteOptions::Validate() const { return quantisation.Validate(); }

Status Pack::Validate() const {
  const int w = width(), h = height();
  if (w <= 0 || h <= 0) return Error{"pack: empty grid"};
  if (Status s =
          CheckPhysicalBounds(field.pitch_mm, w, h, delta0_mm, max_height_mm, canvas_from_scan);
      !s.ok())
    return Error{"pack: " + s.message()};
  if (field.state.width != w || field.state.height != h || normals.width != w ||
      normals.height != h || maps.width() != w || maps.height() != h)
    return Error{"pack: the height field, normals and reflectance maps differ in size"};
  if (Status s = maps.Validate(); !s.ok()) return Error{"pack: " + s.message()};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (!(std::abs(field.height_mm(x, y)) <= kMaxPackHeightMm))
        return Error{"pack: height at texel " + TexelName(x, y) + " = " +
                     FormatNumber(field.height_mm(x, y)) + " mm is not finite or beyond " +
                     Num(kMaxPackHeightMm) + " mm"};
      if (static_cast<int>(field.state(x, y)) > 3)
        return Error{"pack: texel state at " + TexelName(x, y) + " is not a TexelState"};
      const Vec3f& n = normals(x, y);
      if (!IsValid(n) || std::abs(n.norm() - 1.0f) > 1e-3f || n.z() < 0)
        return Error{"pack: normal at texel " + TexelName(x, y) + " is not a unit vector with nz >= 0"};
    }
  if (cell_px < 1) return Error{"pack: cell_px must be >= 1, got " + std::to_string(cell_px)};
  if (!boxes.empty() && !(delta0_mm > 0))
    return Error{"pack: boxes need a bump plane above the canvas (delta0_mm > 0)"};
  for (size_t i = 0; i < boxes.size(); ++i) {
    const ReliefBox& b = boxes[i];
    const std::string name = "pack: box " + std::to_string(i);
    if (b.x0 < 0 || b.y0 < 0 || b.width < 1 || b.height < 1 || b.x0 + int64_t{b.width} > w ||
        b.y0 + int64_t{b.height} > h)
      return Error{name + " is not inside the " + std::to_string(w) + "x" + std::to_string(h) + " grid"};
    if (b.x0 % cell_px != 0 || b.y0 % cell_px != 0 ||
        b.width != std::min(cell_px, w - b.x0) || b.height != std::min(cell_px, h - b.y0))
      return Error{name + " is not a cell of the " + std::to_string(cell_px) + "-texel grid"};
    if (b.u_max < b.x0 || b.u_max >= b.x0 + b.width || b.v_max < b.y0 || b.v_max >= b.y0 + b.height)
      return Error{name + ": its highest texel (u_max, v_max) lies outside the box"};
    if (!(b.h_max_mm >= -kMaxPackHeightMm) ||
        b.h_max_mm > max_height_mm + 1e-6 * (1 + std::abs(max_height_mm)))
      return Error{name + ": h_max_mm " + FormatNumber(b.h_max_mm) + " is not finite or above H"};
    if (i > 0) {
      const ReliefBox& a = boxes[i - 1];
      if (std::make_pair(b.y0, b.x0) <= std::make_pair(a.y0, a.x0))
        return Error{name + ": boxes must be distinct cells in row-major order"};
    }
  }
  return Status::Ok();
}

Pack EncodePackValues(const Pack& pack, const PackWriteOptions& options) {
  const bool q = options.encoding == PackEncoding::kQuantised;
  const PackQuantisation bits = q ? options.quantisation : PackQuantisation{10, 10, 10, 10};
  Pack out = pack;
  out.maps.fit_error = Grid<float>(pack.width(), pack.height(), 0.0f);
  for (size_t i = 0; i < pack.field.height_mm.size(); ++i) {
    out.field.height_mm.data[i] = Encode(pack.field.height_mm.data[i], bits.height_bits);
    const Vec3f& n = pack.normals.data[i];
    out.normals.data[i] = NormalFromXY(Encode(n.x(), bits.normal_bits), Encode(n.y(), bits.normal_bits));
    for (int c = 0; c < 3; ++c) {
      out.maps.rho_d.data[i][c] = Encode(pack.maps.rho_d.data[i][c], bits.rho_bits);
      out.maps.rho_s.data[i][c] = Encode(pack.maps.rho_s.data[i][c], bits.rho_bits);
    }
    auto& lobe = out.maps.lobe.data[i];
    lobe = {Encode(lobe[0], bits.lobe_bits), Encode(lobe[1], bits.lobe_bits), 1.0f,
            Encode(lobe[3], bits.lobe_bits)};
  }
  return out;
}

Status WritePack(const fs::path& path, const Pack& pack, const PackWriteOptions& options) {
  const std::string file = path.string();
  if (Status s = options.Validate(); !s.ok()) return Error{file + ": " + s.message()};
  if (Status s = pack.Validate(); !s.ok()) return Error{file + ": " + s.message()};
  const int w = pack.width(), h = pack.height();
  // Values must survive half: a texel beyond its range would read back as Inf.
  auto check_range = [&](const char* map, size_t i, float v) -> Status {
    if (std::abs(v) > kHalfMax)
      return Error{file + ": " + map + " at texel " + TexelName(int(i % w), int(i / w)) + " = " +
                   FormatNumber(v) + " exceeds the half-float range (65504)"};
    return Status::Ok();
  };
  for (size_t i = 0; i < pack.field.height_mm.size(); ++i) {
    Status s = check_range("height", i, pack.field.height_mm.data[i]);
    for (int c = 0; c < 3 && s.ok(); ++c) s = check_range("rho_d", i, pack.maps.rho_d.data[i][c]);
    for (int c = 0; c < 3 && s.ok(); ++c) s = check_range("rho_s", i, pack.maps.rho_s.data[i][c]);
    for (int c : {0, 1, 3})
      if (s.ok()) s = check_range("lobe", i, pack.maps.lobe.data[i][c]);
    if (!s.ok()) return s;
  }
  const Pack enc = EncodePackValues(pack, options);
  const size_t n = static_cast<size_t>(w) * h;

  std::vector<uint16_t> surface(n * 4), reflectance(n * 9);
  for (size_t i = 0; i < n; ++i) {
    surface[4 * i + 0] = ToHalfBits(enc.field.height_mm.data[i]);
    surface[4 * i + 1] = ToHalfBits(enc.normals.data[i].x());
    surface[4 * i + 2] = ToHalfBits(enc.normals.data[i].y());
    surface[4 * i + 3] = ToHalfBits(StateStatusCode(pack.field.state.data[i], pack.maps.status.data[i]));
    uint16_t* r = &reflectance[9 * i];
    for (int c = 0; c < 3; ++c) {
      r[c] = ToHalfBits(enc.maps.rho_d.data[i][c]);
      r[3 + c] = ToHalfBits(enc.maps.rho_s.data[i][c]);
    }
    r[6] = ToHalfBits(enc.maps.lobe.data[i][0]);
    r[7] = ToHalfBits(enc.maps.lobe.data[i][1]);
    r[8] = ToHalfBits(enc.maps.lobe.data[i][3]);
  }
  const int cells_x = (w + pack.cell_px - 1) / pack.cell_px, cells_y = (h + pack.cell_px - 1) / pack.cell_px;
  std::vector<float> cells(static_cast<size_t>(cells_x) * cells_y * 4, 0.0f);
  for (const ReliefBox& b : pack.boxes) {
    float* c = &cells[4 * (static_cast<size_t>(b.y0 / pack.cell_px) * cells_x + b.x0 / pack.cell_px)];
    c[0] = 1.0f;
    c[1] = b.h_max_mm;
    c[2] = static_cast<float>(b.u_max - b.x0);
    c[3] = static_cast<float>(b.v_max - b.y0);
  }

  OIIO::ImageSpec specs[kParts];
  specs[0] = OIIO::ImageSpec(w, h, 4, OIIO::TypeDesc::HALF);
  specs[0].channelnames = kSurfaceChannels;
  specs[1] = OIIO::ImageSpec(w, h, 9, OIIO::TypeDesc::HALF);
  specs[1].channelnames = kReflectanceChannels;
  specs[2] = OIIO::ImageSpec(cells_x, cells_y, 4, OIIO::TypeDesc::FLOAT);
  specs[2].channelnames = kBoxChannels;
  // Multi-part OpenEXR wants one display window for all parts: the texel grid's.
  specs[2].full_width = w;
  specs[2].full_height = h;
  for (int p = 0; p < kParts; ++p) {
    specs[p].alpha_channel = -1;
    specs[p].attribute("oiio:subimagename", kPartNames[p]);
    specs[p].attribute("compression", "zip");
  }
  OIIO::ImageSpec& meta = specs[0];
  meta.attribute("digitize:format", kPackFormatName);
  meta.attribute("digitize:version", std::to_string(kPackVersion));
  meta.attribute("digitize:encoding", ToString(options.encoding));
  if (options.encoding == PackEncoding::kQuantised)
    meta.attribute("digitize:quantisation", QuantisationText(options.quantisation));
  meta.attribute("digitize:gauge", kGauge);
  meta.attribute("digitize:units",
                 "H mm above the canvas plane; NX NY unit normal (nz = sqrt(1 - nx^2 - ny^2)); "
                 "M = texel state + 4 x fit status; rho_d rho_s 1/sr; boxes: h_max mm, u/v_max texels "
                 "from the cell corner");
  meta.attribute("digitize:pitch_mm", Num(pack.field.pitch_mm));
  meta.attribute("digitize:size_mm", Num(pack.width_mm()) + " x " + Num(pack.height_mm()));
  meta.attribute("digitize:delta0_mm", Num(pack.delta0_mm));
  meta.attribute("digitize:max_height_mm", Num(pack.max_height_mm));
  meta.attribute("digitize:cell_px", std::to_string(pack.cell_px));
  meta.attribute("digitize:box_count", std::to_string(pack.boxes.size()));
  meta.attribute("digitize:canvas_from_scan", TransformJson(pack.canvas_from_scan).dump());
  // File names are bytes, not always UTF-8 (a capture machine's Latin-1 names): replaced, not
  // thrown on.
  meta.attribute(
      "digitize:provenance",
      ProvenanceJson(pack.provenance).dump(-1, ' ', false, json::error_handler_t::replace));
  const void* data[kParts] = {surface.data(), reflectance.data(), cells.data()};
  const size_t data_bytes[kParts] = {surface.size() * 2, reflectance.size() * 2, cells.size() * 4};
  meta.attribute("digitize:checksum", PackChecksum(meta, data, data_bytes));

  // Not through WriteImageAtomically: OpenImageIO's multi-part OpenEXR open ignores I/O
  // proxies. OpenEXR reports failed writes itself; a full disk is named from the file system.
  return WriteAtomically(path, [&](const fs::path& temp) -> Status {
    auto out = OIIO::ImageOutput::create("openexr");
    if (!out) return Error{file + ": no OpenEXR writer: " + OneLine(OIIO::geterror())};
    if (!out->supports("multiimage"))
      return Error{file + ": this OpenImageIO cannot write multi-part OpenEXR"};
    if (!out->open(temp.string(), kParts, specs))
      return WithDiskFull(Error{file + ": cannot open for writing: " + OneLine(out->geterror())},
                          path);
    for (int p = 0; p < kParts; ++p) {
      if (p > 0 && !out->open(temp.string(), specs[p], OIIO::ImageOutput::AppendSubimage))
        return WithDiskFull(
            Error{file + ": cannot start part " + kPartNames[p] + ": " + OneLine(out->geterror())},
            path);
      if (!out->write_image(specs[p].format, data[p]))
        return WithDiskFull(Error{file + ": write failed: " + OneLine(out->geterror())}, path);
    }
    if (!out->close())
      return WithDiskFull(Error{file + ": write failed: " + OneLine(out->geterror())}, path);
    return Status::Ok();
  });
}

Result<Pack> AssemblePack(PreprocessedCanvas canvas, ReflectanceMaps maps, PackProvenance provenance) {
  if (maps.width() != canvas.field.width() || maps.height() != canvas.field.height())
    return Error{"reflectance maps are " + std::to_string(maps.width()) + "x" +
                 std::to_string(maps.height()) + " texels, the canvas " +
                 std::to_string(canvas.field.width()) + "x" + std::to_string(canvas.field.height()) +
                 ": fitted on another canvas?"};
  Pack pack;
  pack.field = std::move(canvas.field);
  pack.normals = std::move(canvas.normals);
  pack.maps = std::move(maps);
  pack.delta0_mm = canvas.delta0_mm;
  pack.max_height_mm = canvas.max_height_mm;
  pack.cell_px = canvas.cell_px;
  pack.boxes = std::move(canvas.boxes);
  pack.canvas_from_scan = canvas.canvas_from_scan;
  pack.provenance = std::move(provenance);
  if (Status s = pack.Validate(); !s.ok()) return Error{s.message()};
  return pack;
}

Result<PackSummary> InspectPack(const fs::path& path, const PackReadOptions& options) {
  auto header = ReadHeader(path, options, nullptr);
  if (!header.ok()) return header.error();
  return header->summary;
}

Result<Pack> ReadPack(const fs::path& path, const PackReadOptions& options) {
  const std::string file = path.string();
  std::unique_ptr<OIIO::ImageInput> in;
  auto header = ReadHeader(path, options, &in);
  if (!header.ok()) return header.error();
  const PackSummary& s = header->summary;
  const int w = s.width, h = s.height;
  const size_t n = static_cast<size_t>(w) * h;

  std::vector<int> surface_ch, refl_ch, box_ch;
  OIIO::ImageSpec meta;
  {
    if (!in->seek_subimage(0, 0)) return Error{file + ": cannot read part 0"};
    meta = in->spec();
    auto c = ChannelIndices(file, in->spec(), kPartNames[0], kSurfaceChannels);
    if (!c.ok()) return c.error();
    surface_ch = *c;
    if (!in->seek_subimage(1, 0)) return Error{file + ": cannot read part 1"};
    c = ChannelIndices(file, in->spec(), kPartNames[1], kReflectanceChannels);
    if (!c.ok()) return c.error();
    refl_ch = *c;
    if (!in->seek_subimage(2, 0)) return Error{file + ": cannot read part 2"};
    c = ChannelIndices(file, in->spec(), kPartNames[2], kBoxChannels);
    if (!c.ok()) return c.error();
    box_ch = *c;
  }
  std::vector<uint16_t> surface, reflectance;
  std::vector<float> cells;
  if (Status st = ReadPart(file, *in, 0, OIIO::TypeDesc::HALF, surface); !st.ok()) return Error{st.message()};
  if (Status st = ReadPart(file, *in, 1, OIIO::TypeDesc::HALF, reflectance); !st.ok()) return Error{st.message()};
  if (Status st = ReadPart(file, *in, 2, OIIO::TypeDesc::FLOAT, cells); !st.ok()) return Error{st.message()};
  // Into the writer's channel order (the file's order is EXR's, sorted by name), so the checksum
  // and everything below index by the canonical layout.
  auto canonical = [](auto& data, const std::vector<int>& ch) {
    const size_t nc = ch.size();
    std::vector<typename std::decay_t<decltype(data)>::value_type> out(data.size());
    for (size_t i = 0; i < data.size() / nc; ++i)
      for (size_t k = 0; k < nc; ++k) out[i * nc + k] = data[i * nc + static_cast<size_t>(ch[k])];
    data.swap(out);
  };
  canonical(surface, surface_ch);
  canonical(reflectance, refl_ch);
  canonical(cells, box_ch);
  {
    const void* data[kParts] = {surface.data(), reflectance.data(), cells.data()};
    const size_t data_bytes[kParts] = {surface.size() * 2, reflectance.size() * 2, cells.size() * 4};
    const std::string stored = meta.get_string_attribute("digitize:checksum");
    if (stored.empty()) return Error{file + ": header attribute digitize:checksum is missing"};
    const bool intact = PackChecksum(meta, data, data_bytes) == stored;
#ifndef FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION
    if (!intact)
      return Error{file + ": checksum mismatch: the file was modified or corrupted after writing"};
#else
    // The fuzz build (tests/fuzz/) goes on, so that mutated inputs reach the value checks below.
    (void)intact;
#endif
  }

  Pack pack;
  pack.field.pitch_mm = s.pitch_mm;
  pack.field.height_mm = Grid<float>(w, h);
  pack.field.state = Grid<TexelState>(w, h, TexelState::kOutside);
  pack.normals = Grid<Vec3f>(w, h);
  pack.maps = ReflectanceMaps::Zeros(w, h);
  pack.delta0_mm = s.delta0_mm;
  pack.max_height_mm = s.max_height_mm;
  pack.cell_px = s.cell_px;
  pack.canvas_from_scan = header->canvas_from_scan;
  pack.provenance = s.provenance;
  auto bad = [&](size_t i, const std::string& what) {
    return Error{file + ": texel " + TexelName(int(i % w), int(i / w)) + ": " + what};
  };
  for (size_t i = 0; i < n; ++i) {
    const uint16_t* sp = &surface[4 * i];
    const uint16_t* rp = &reflectance[9 * i];
    const float height = FromHalfBits(sp[0]);
    const float nx = FromHalfBits(sp[1]), ny = FromHalfBits(sp[2]);
    const float code = FromHalfBits(sp[3]);
    if (!(std::abs(height) <= kMaxPackHeightMm))
      return bad(i, "height " + FormatNumber(height) + " mm is not finite or beyond " +
                        Num(kMaxPackHeightMm) + " mm");
    if (!(std::abs(nx) <= 1.001f && std::abs(ny) <= 1.001f && nx * nx + ny * ny <= 1.002f))
      return bad(i, "normal (" + FormatNumber(nx) + ", " + FormatNumber(ny) + ") is not a unit normal's x, y");
    if (!(code >= 0 && code < 4 * kTexelFitStatusCount && code == std::floor(code)))
      return bad(i, "M = " + FormatNumber(code) + " is not a texel state + 4 x fit status");
    const int c = static_cast<int>(code);
    pack.field.height_mm.data[i] = height;
    pack.field.state.data[i] = static_cast<TexelState>(c % 4);
    pack.maps.status.data[i] = static_cast<TexelFitStatus>(c / 4);
    pack.normals.data[i] = NormalFromXY(nx, ny);
    float v[9];
    for (int k = 0; k < 9; ++k) {
      v[k] = FromHalfBits(rp[k]);
      if (!std::isfinite(v[k])) return bad(i, kReflectanceChannels[k] + " is not finite");
    }
    for (int k = 0; k < 6; ++k)
      if (v[k] < 0) return bad(i, kReflectanceChannels[k] + " is negative");
    if (v[8] < 0) return bad(i, "lobe.k is negative");
    pack.maps.rho_d.data[i] = Vec3f(v[0], v[1], v[2]);
    pack.maps.rho_s.data[i] = Vec3f(v[3], v[4], v[5]);
    pack.maps.lobe.data[i] = {v[6], v[7], 1.0f, v[8]};
  }
  const int cells_x = header->cells_x, cells_y = header->cells_y;
  for (int cy = 0; cy < cells_y; ++cy)
    for (int cx = 0; cx < cells_x; ++cx) {
      const float* c = &cells[4 * (static_cast<size_t>(cy) * cells_x + cx)];
      const float present = c[0], hmax = c[1], du = c[2], dv = c[3];
      const std::string cell = file + ": box cell " + std::to_string(cx) + ", " + std::to_string(cy);
      if (present == 0) continue;
      if (present != 1) return Error{cell + ": present must be 0 or 1"};
      ReliefBox b;
      b.x0 = cx * s.cell_px;
      b.y0 = cy * s.cell_px;
      b.width = std::min(s.cell_px, w - b.x0);
      b.height = std::min(s.cell_px, h - b.y0);
      if (!(du >= 0 && dv >= 0 && du < b.width && dv < b.height && du == std::floor(du) &&
            dv == std::floor(dv)))
        return Error{cell + ": highest texel offset (" + FormatNumber(du) + ", " + FormatNumber(dv) +
                     ") is not a texel of the cell"};
      if (!(std::abs(hmax) <= kMaxPackHeightMm))
        return Error{cell + ": h_max " + FormatNumber(hmax) + " mm is not finite or beyond " +
                     Num(kMaxPackHeightMm) + " mm"};
      b.h_max_mm = hmax;
      b.u_max = b.x0 + static_cast<int>(du);
      b.v_max = b.y0 + static_cast<int>(dv);
      pack.boxes.push_back(b);
    }
  if (pack.boxes.size() != s.box_count)
    return Error{file + ": " + std::to_string(pack.boxes.size()) + " boxes, the header says " +
                 std::to_string(s.box_count)};
  if (Status st = pack.Validate(); !st.ok()) return Error{file + ": " + st.message()};
  return pack;
}

Result<PackVerification> VerifyPack(const fs::path& path, const PackReadOptions& options) {
  const std::string file = path.string();
  auto summary = InspectPack(path, options);
  if (!summary.ok()) return summary.error();
  auto pack = ReadPack(path, options);
  if (!pack.ok()) return pack.error();
  PackVerification v;
  v.summary = *summary;
  const Pack& p = *pack;
  v.checks.push_back("container: OpenEXR, 3 parts, version " + std::to_string(v.summary.version) +
                     ", " + ToString(v.summary.encoding) + " encoding");
  v.checks.push_back("geometry: pitch " + Num(p.field.pitch_mm) + " mm, " + Num(p.width_mm()) +
                     " x " + Num(p.height_mm()) + " mm (as digitize:size_mm, within " +
                     Num(kMaxPackExtentMm / 1000) + " m), heights, H and delta0 within " +
                     Num(kMaxPackHeightMm) + " mm, canvas_from_scan a rotation within " +
                     Num(kMaxPackTranslationMm / 1000) + " m");
  // ReadPack refused the file unless its checksum matched; verify's output says it was checked.
  v.checks.push_back(
      "checksum: digitize:checksum (SHA-1) matches every digitize:* attribute and "
      "every decoded value");
  v.checks.push_back("values: " + std::to_string(p.width()) + "x" + std::to_string(p.height()) +
                     " texels, every value finite, rho >= 0, k >= 0, unit normals, states and "
                     "statuses known");
  // Heights are stored in half (or fewer bits): compare within that rounding.
  const double rel = std::ldexp(1.0, -(v.summary.encoding == PackEncoding::kQuantised
                                           ? v.summary.quantisation.height_bits
                                           : 10));
  auto tol = [&](double hgt) { return rel * std::abs(hgt) + 1e-6; };
  float highest = -std::numeric_limits<float>::infinity();
  for (int y = 0; y < p.height(); ++y)
    for (int x = 0; x < p.width(); ++x)
      if (HasHeight(p.field.state(x, y))) highest = std::max(highest, p.field.height_mm(x, y));
  if (std::isfinite(highest) && highest > p.max_height_mm + tol(p.max_height_mm))
    return Error{file + ": a height of " + FormatNumber(highest) + " mm exceeds max_height_mm " +
                 FormatNumber(p.max_height_mm)};
  for (size_t i = 0; i < p.boxes.size(); ++i) {
    const ReliefBox& b = p.boxes[i];
    float cell_max = -std::numeric_limits<float>::infinity();
    for (int y = b.y0; y < b.y0 + b.height; ++y)
      for (int x = b.x0; x < b.x0 + b.width; ++x)
        if (HasHeight(p.field.state(x, y))) cell_max = std::max(cell_max, p.field.height_mm(x, y));
    const float at_peak = p.field.height_mm(b.u_max, b.v_max);
    if (!std::isfinite(cell_max) || std::abs(cell_max - b.h_max_mm) > tol(b.h_max_mm) ||
        std::abs(at_peak - b.h_max_mm) > tol(b.h_max_mm))
      return Error{file + ": box " + std::to_string(i) + " (cell at texel " +
                   TexelName(b.x0, b.y0) + "): h_max " + FormatNumber(b.h_max_mm) +
                   " mm is not its cell's highest height (" + FormatNumber(cell_max) + " mm; " +
                   FormatNumber(at_peak) + " mm at (u_max, v_max))"};
  }
  v.checks.push_back("boxes: " + std::to_string(p.boxes.size()) + " of " +
                     std::to_string(((p.width() + p.cell_px - 1) / p.cell_px) *
                                    ((p.height() + p.cell_px - 1) / p.cell_px)) +
                     " cells; each h_max is its cell's highest height, at (u_max, v_max)");
  v.checks.push_back("heights: all <= max_height_mm " + FormatNumber(p.max_height_mm) + " mm");
  if (v.summary.provenance.tool_version.empty())
    return Error{file + ": provenance has no tool_version"};
  v.checks.push_back("provenance: " + EscapeForTerminal(v.summary.provenance.tool_version) + ", " +
                     std::to_string(v.summary.provenance.inputs.size()) + " inputs");
  return v;
}

Result<std::string> FileSha1(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{path.string() + ": cannot open to hash"};
  OIIO::SHA1 sha;
  std::vector<char> buf(1 << 20);
  while (in) {
    in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
    if (in.gcount() > 0) sha.append(buf.data(), static_cast<size_t>(in.gcount()));
  }
  if (in.bad()) return Error{path.string() + ": read failed while hashing"};
  return sha.digest();
}

}  // namespace digitize

namespace digitize {

PackProvenance NewProvenance() {
  PackProvenance p;
  p.tool_version = std::string("digitize ") + DIGITIZE_VERSION;
  const std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm utc{};
  gmtime_r(&now, &utc);
  char when[32];
  std::strftime(when, sizeof when, "%Y-%m-%dT%H:%M:%SZ", &utc);
  p.created_utc = when;
  return p;
}

namespace {

// The name provenance records for `file` (AddProvenanceInputs).
std::string ProvenanceName(const fs::path& file, const fs::path& relative_to) {
  if (relative_to.empty()) return (file.is_absolute() ? file.filename() : file).generic_string();
  std::error_code ec;
  const fs::path a = fs::absolute(file, ec).lexically_normal();
  const fs::path b = fs::absolute(relative_to, ec).lexically_normal();
  const fs::path rel = a.lexically_relative(b);
  return (rel.empty() ? file.filename() : rel).generic_string();
}

}  // namespace

Status AddProvenanceInputs(PackProvenance& provenance, const std::vector<fs::path>& files,
                           const fs::path& relative_to) {
  for (const fs::path& f : files) {
    auto sha = FileSha1(f);
    if (!sha.ok()) return sha.error();
    std::error_code ec;
    provenance.inputs.push_back(
        {ProvenanceName(f, relative_to), *sha, static_cast<uint64_t>(fs::file_size(f, ec))});
  }
  return Status::Ok();
}

Result<PackProvenance> ProvenanceFromOutputs(const fs::path& canvas_dir, const fs::path& fit_dir,
                                             const std::string& pack_options_json) {
  PackProvenance p = NewProvenance();
  json options = json::object();
  const json pack_options = json::parse(pack_options_json, nullptr, false);
  options["pack"] = pack_options.is_discarded() ? json(pack_options_json) : pack_options;
  for (const auto& [stage, dir] : {std::pair<const char*, fs::path>{"preprocess", canvas_dir},
                                   {"fit", fit_dir}}) {
    if (dir.empty()) continue;
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) return Error{dir.string() + ": not a folder"};
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(dir, ec))
      if (e.is_regular_file() && e.path().filename().string().front() != '.') files.push_back(e.path());
    if (ec) return Error{dir.string() + ": cannot list: " + ec.message()};
    std::sort(files.begin(), files.end());
    for (const fs::path& f : files) {
      auto sha = FileSha1(f);
      if (!sha.ok()) return sha.error();
      p.inputs.push_back({(dir.filename().empty() ? dir.parent_path().filename() : dir.filename()).string() +
                              "/" + f.filename().string(),
                          *sha, static_cast<uint64_t>(fs::file_size(f, ec))});
    }
    std::ifstream report(dir / "report.json");
    if (!report) return Error{(dir / "report.json").string() + ": cannot open (not a " + stage + " output folder?)"};
    std::stringstream text;
    text << report.rdbuf();
    const json doc = json::parse(text.str(), nullptr, false);
    if (doc.is_discarded() || !doc.is_object())
      return Error{(dir / "report.json").string() + ": not JSON"};
    json inputs = doc.value("inputs", json::array());
    for (json& in : inputs)
      if (in.is_string()) in = ProvenanceName(in.get<std::string>(), {});
    json entry = {{"options", doc.value("options", json::object())}, {"inputs", inputs}};
    options[stage] = entry;
    if (std::string(stage) == "fit") p.fit_brief = doc.value("brief", "");
  }
  p.options_json = options.dump(-1, ' ', false, json::error_handler_t::replace);
  return p;
}

}  // namespace digitize
