// Texture packs: the bounded reader (pack.h: ReadPack, InspectPack), what tests/fuzz/fuzz_pack
// targets. The raw headers are walked before OpenImageIO opens the file, so a forged header
// cannot make it allocate what it claims.
#include <OpenImageIO/hash.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <system_error>

#include "digitize/image_io.h"
#include "digitize/pack.h"
#include "digitize/pack_tiled.h"
#include "exr_attribute_size.h"
#include "json_fields.h"
#include "options_json.h"
#include "pack_exr.h"

namespace digitize {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using namespace pack_exr;

// --- header pre-scan ------------------------------------------------------------------------
// OpenEXR sizes its line-offset tables and buffers from the data window a header claims. Before
// OpenImageIO opens the file, walk the raw headers (bounded by the file size and
// max_header_bytes) and refuse windows beyond max_texels, so a forged header cannot make the
// reader allocate gigabytes.

struct RawPart {
  int64_t width = 0, height = 0;
  int tile_x = 0, tile_y = 0, tile_mode = -1;  // tiled parts: OpenEXR's tile description
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
  const uint64_t want =
      std::min<uint64_t>(file_bytes, static_cast<uint64_t>(options.max_header_bytes) + 8);
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
  if ((version & 0xff) != 2)
    return Error{name + ": unsupported OpenEXR version " + std::to_string(version & 0xff)};
  if ((version & 0x800) != 0) return Error{name + ": deep OpenEXR data, not a digitize pack"};
  if ((version & 0x400) != 0) max_name = 255;
  const bool multipart = (version & 0x1000) != 0;
  if (!multipart)
    return Error{name + ": a single-part OpenEXR file; a digitize pack has " +
                 std::to_string(kParts) + " parts (surface, reflectance, boxes)"};
  std::vector<RawPart> parts;
  for (;;) {
    if (!need(1)) {
      return Error{file_bytes > bytes.size()
                       ? name + ": OpenEXR headers larger than " +
                             std::to_string(options.max_header_bytes) + " bytes (limit)"
                       : truncated};
    }
    if (bytes[pos] == '\0') {  // empty header: end of the header list
      ++pos;
      break;
    }
    if (parts.size() >= kTiledParts)
      return Error{name + ": more than " + std::to_string(kTiledParts) +
                   " parts; not a digitize pack"};
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
        if (type != "box2i")  // its size is checked above, as every fixed-size type
          return Error{name + ": malformed dataWindow attribute"};
        int32_t box[4] = {0, 0, 0, 0};
        for (int32_t& b : box) (void)read_i32(b);
        const int64_t w = int64_t{box[2]} - box[0] + 1, h = int64_t{box[3]} - box[1] + 1;
        if (w <= 0 || h <= 0)
          return Error{name + ": part " + std::to_string(parts.size()) +
                       " has an empty data window"};
        // Checked against max_texels once the part is known to be scanline (below): a tiled
        // part is read a tile at a time.
        const int64_t limit = std::max(options.max_texels, options.max_tiled_texels);
        if (w > limit || h > limit || w * h > limit)
          return Error{name + ": part " + std::to_string(parts.size()) + " claims " +
                       std::to_string(w) + "x" + std::to_string(h) + " pixels, more than the " +
                       std::to_string(limit) + "-texel limit"};
        part.width = w;
        part.height = h;
        has_window = true;
      } else if (attr == "tiles") {
        // tiledesc: uint32 x size, uint32 y size, uint8 mode (its size is checked above). OpenEXR
        // sizes its tile offset tables from these and the data window: a forged 1 x 1 tile over
        // 2^32 texels would ask for 32 GB.
        if (type != "tiledesc") return Error{name + ": malformed tiles attribute"};
        int32_t tx = 0, ty = 0;
        (void)read_i32(tx);
        (void)read_i32(ty);
        part.tile_x = tx;
        part.tile_y = ty;
        part.tile_mode = static_cast<uint8_t>(bytes[pos]);
        pos += 1;
        if (Status st = CheckPackTileSize(tx); !st.ok() || tx != ty)
          return Error{name + ": part " + std::to_string(parts.size()) + " has " +
                       std::to_string(tx) + " x " + std::to_string(ty) +
                       " tiles; a digitize pack's are square, a power of two in [" +
                       std::to_string(kMinPackTileSize) + ", " + std::to_string(kMaxPackTileSize) +
                       "]"};
        if (part.tile_mode != kTileModeMipmapRoundUp)
          return Error{name + ": part " + std::to_string(parts.size()) + " has tile mode " +
                       std::to_string(part.tile_mode) +
                       "; a digitize pack's tiles are mip-mapped, rounding sizes up (17)"};
      } else if (attr == "channels") {
        if (type != "chlist") return Error{name + ": malformed channels attribute"};
        if (Status st =
                CheckChannelList(name, parts.size(), bytes.data() + pos, static_cast<size_t>(size));
            !st.ok())
          return Error{st.message()};
        pos += static_cast<size_t>(size);
      } else {
        pos += static_cast<size_t>(size);
      }
    }
    if (!has_window)
      return Error{name + ": part " + std::to_string(parts.size()) + " has no dataWindow"};
    if (part.tile_mode < 0 &&
        (part.width > options.max_texels || part.height > options.max_texels ||
         part.width * part.height > options.max_texels))
      return Error{name + ": part " + std::to_string(parts.size()) + " claims " +
                   std::to_string(part.width) + "x" + std::to_string(part.height) +
                   " pixels, more than the " + std::to_string(options.max_texels) + "-texel limit"};
    parts.push_back(part);
  }
  if (parts.size() != kParts && parts.size() != kTiledParts)
    return Error{name + ": " + std::to_string(parts.size()) + " parts, a digitize pack has " +
                 std::to_string(kParts) + " (surface, reflectance, boxes) or, tiled, " +
                 std::to_string(kTiledParts) + " (and checksums)"};
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

Result<RigidTransform> ParseTransform(const std::string& file, const std::string& text) {
  const std::string where = file + ": digitize:canvas_from_scan";
  auto parsed = CatchBadInput([&] { return TransformFrom(Fields(ParseJson(text, where), where)); });
  if (!parsed.ok()) return parsed.error();
  const RigidTransform t = *parsed;
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
      return Error{
          file + ": digitize:size_mm " + FormatNumber(size[0], kRoundTripDigits) + " x " +
          FormatNumber(size[1], kRoundTripDigits) +
          " mm disagrees with pitch_mm x texels = " + FormatNumber(want[0], kRoundTripDigits) +
          " x " + FormatNumber(want[1], kRoundTripDigits) + " mm"};
  return Status::Ok();
}

// "lafortune = 0, ggx = 1": the models this reader knows, with their codes.
std::string KnownModels() {
  std::string text;
  for (int m = 0; m < kReflectanceModelCount; ++m)
    text += std::string(m > 0 ? ", " : "") + ToString(static_cast<ReflectanceModel>(m)) + " = " +
            std::to_string(m);
  return text;
}

// digitize:models ("lafortune=N,ggx=M", every model in ReflectanceModel order, counts adding up to
// the texels).
Status ParseModelCounts(const std::string& file, const std::string& text, int64_t texels,
                        std::array<int64_t, kReflectanceModelCount>& counts) {
  const std::string bad = file + ": header attribute digitize:models = \"" +
                          EscapeForTerminal(text.substr(0, 60)) +
                          "\" is not texel counts per model (\"lafortune=N,ggx=N\", every "
                          "model of " +
                          KnownModels() + " in order)";
  if (text.empty()) return Error{file + ": header attribute digitize:models is missing"};
  const char* p = text.data();
  const char* end = text.data() + text.size();
  int64_t sum = 0;
  for (int m = 0; m < kReflectanceModelCount; ++m) {
    const std::string key =
        std::string(m > 0 ? "," : "") + ToString(static_cast<ReflectanceModel>(m)) + "=";
    if (std::string_view(p, end - p).rfind(key, 0) != 0) return Error{bad};
    p += key.size();
    const auto r = std::from_chars(p, end, counts[m]);
    if (r.ec != std::errc() || counts[m] < 0 || counts[m] > texels) return Error{bad};
    p = r.ptr;
    sum += counts[m];
  }
  if (p != end) return Error{bad};
  if (sum != texels)
    return Error{file + ": digitize:models counts " + std::to_string(sum) +
                 " texels, the pack has " + std::to_string(texels)};
  return Status::Ok();
}

// Tiles over every level of a version 3 pack (rows of its checksums part, less the boxes row).
int64_t TileCount(const PackSummary& s) {
  int64_t n = 0;
  for (const auto& [w, h] : s.levels)
    n += int64_t{(w + s.tile_size - 1) / s.tile_size} * ((h + s.tile_size - 1) / s.tile_size);
  return n;
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
  if (*version > kTiledPackVersion)
    return Error{file + ": pack version " + FormatNumber(*version) +
                 " is newer than this reader (" + std::to_string(kTiledPackVersion) +
                 "); update digitize"};
  s.version = static_cast<int>(*version);
  s.width = spec.width;
  s.height = spec.height;
  if (spec.width != raw->at(0).width || spec.height != raw->at(0).height)
    return Error{file + ": part sizes disagree between the raw header and the reader"};
  if (s.version == 1) {  // before models: every texel Lafortune
    s.texels_by_model[static_cast<size_t>(ReflectanceModel::kLafortune)] =
        int64_t{s.width} * s.height;
  } else if (Status st = ParseModelCounts(file, spec.get_string_attribute("digitize:models"),
                                          int64_t{s.width} * s.height, s.texels_by_model);
             !st.ok()) {
    return Error{st.message()};
  }

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
    return Error{file + ": digitize:box_count " + FormatNumber(*box_count, kRoundTripDigits) +
                 " exceeds the " + std::to_string(h.cells_x) + "x" + std::to_string(h.cells_y) +
                 " cells"};
  s.box_count = static_cast<size_t>(*box_count);

  const bool tiled = s.version >= kTiledPackVersion;
  const size_t parts = tiled ? kTiledParts : kParts;
  if (raw->size() != parts)
    return Error{file + ": " + std::to_string(raw->size()) + " parts; a version " +
                 std::to_string(s.version) + " pack has " + std::to_string(parts)};
  for (size_t part = 0; part < parts; ++part)
    if ((raw->at(part).tile_mode >= 0) != (tiled && part < 2))
      return Error{file + ": part " + std::to_string(part) + " is " +
                   (raw->at(part).tile_mode >= 0 ? "tiled" : "not tiled") + "; a version " +
                   std::to_string(s.version) + " pack's " +
                   (tiled ? "surface and reflectance parts alone are tiled" : "parts are not")};
  if (tiled) {
    s.tile_size = raw->at(0).tile_x;
    if (raw->at(1).tile_x != s.tile_size)
      return Error{file + ": the surface and reflectance parts have different tile sizes"};
    auto tile_attr = ParseNumber(file, spec, "digitize:tile_size");
    if (!tile_attr.ok()) return tile_attr.error();
    if (*tile_attr != s.tile_size)
      return Error{file + ": digitize:tile_size " + FormatNumber(*tile_attr) + " but the parts' " +
                   "tiles are " + std::to_string(s.tile_size)};
    s.levels = PyramidLevelSizes(s.width, s.height);
    auto levels_attr = ParseNumber(file, spec, "digitize:levels");
    if (!levels_attr.ok()) return levels_attr.error();
    if (*levels_attr != static_cast<double>(s.levels.size()))
      return Error{file + ": digitize:levels " + FormatNumber(*levels_attr) + ", a " +
                   std::to_string(s.width) + "x" + std::to_string(s.height) + " pyramid has " +
                   std::to_string(s.levels.size())};
    for (int part = 0; part < 2; ++part) {
      for (size_t level = 0; level < s.levels.size(); ++level) {
        if (!in->seek_subimage(part, static_cast<int>(level)))
          return Error{file + ": part " + kPartNames[part] + " lacks level " +
                       std::to_string(level) + " of " + std::to_string(s.levels.size())};
        const OIIO::ImageSpec& ls = in->spec();
        if (ls.width != s.levels[level][0] || ls.height != s.levels[level][1] ||
            ls.tile_width != s.tile_size || ls.tile_height != s.tile_size || ls.x != 0 || ls.y != 0)
          return Error{file + ": part " + kPartNames[part] + " level " + std::to_string(level) +
                       " is " + std::to_string(ls.width) + "x" + std::to_string(ls.height) +
                       ", expected " + std::to_string(s.levels[level][0]) + "x" +
                       std::to_string(s.levels[level][1])};
      }
      if (in->seek_subimage(part, static_cast<int>(s.levels.size())))
        return Error{file + ": part " + kPartNames[part] + " has more levels than " +
                     std::to_string(s.levels.size())};
    }
  }
  for (size_t part = 1; part < parts; ++part) {
    if (!in->seek_subimage(static_cast<int>(part), 0))
      return Error{file + ": part " + std::to_string(part) + " (" +
                   (part < kParts ? kPartNames[part] : kChecksumPartName) +
                   ") cannot be read: " + OneLine(in->geterror())};
    const OIIO::ImageSpec& ps = in->spec();
    int64_t want_w = s.width, want_h = s.height;
    if (part == 2) {
      want_w = h.cells_x;
      want_h = h.cells_y;
    } else if (part == 3) {
      want_w = 1;
      want_h = TileCount(s) + 1;
    }
    if (ps.width != want_w || ps.height != want_h || ps.width != raw->at(part).width ||
        ps.height != raw->at(part).height)
      return Error{file + ": part " + (part < kParts ? kPartNames[part] : kChecksumPartName) +
                   " is " + std::to_string(ps.width) + "x" + std::to_string(ps.height) +
                   ", expected " + std::to_string(want_w) + "x" + std::to_string(want_h)};
  }
  for (int part = 0; part < 2; ++part) {
    (void)in->seek_subimage(part, 0);
    s.raw_bytes_per_texel += static_cast<int>(in->spec().pixel_bytes(/*native=*/true));
  }
  if (in->seek_subimage(static_cast<int>(parts), 0))
    return Error{file + ": more than " + std::to_string(parts) + " parts"};
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

// Channel indices of part `part` (canonical order), for the readers.
struct PartChannels {
  std::vector<int> surface, reflectance, boxes;
};
Result<PartChannels> ReadChannels(const std::string& file, OIIO::ImageInput& in) {
  PartChannels c;
  const std::pair<std::vector<int>*, const std::vector<std::string>*> wanted[] = {
      {&c.surface, &kSurfaceChannels},
      {&c.reflectance, &kReflectanceChannels},
      {&c.boxes, &kBoxChannels}};
  for (int part = 0; part < kParts; ++part) {
    if (!in.seek_subimage(part, 0))
      return Error{file + ": cannot read part " + std::to_string(part)};
    auto idx = ChannelIndices(file, in.spec(), kPartNames[part], *wanted[part].second);
    if (!idx.ok()) return idx.error();
    *wanted[part].first = *idx;
  }
  return c;
}

// Into the writer's channel order (the file's order is EXR's, sorted by name), so the checksum
// and the decoding index by the canonical layout.
template <class T>
void Canonical(std::vector<T>& data, const std::vector<int>& ch) {
  const size_t nc = ch.size();
  std::vector<T> out(data.size());
  for (size_t i = 0; i < data.size() / nc; ++i)
    for (size_t k = 0; k < nc; ++k) out[i * nc + k] = data[i * nc + static_cast<size_t>(ch[k])];
  data.swap(out);
}

Status ChecksumMatches(const std::string& file, bool intact, const std::string& what) {
#ifndef FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION
  if (!intact)
    return Error{file + ": checksum mismatch" + what +
                 ": the file was modified or corrupted after writing"};
#else
  // The fuzz build (tests/fuzz/) goes on, so that mutated inputs reach the value checks below.
  (void)intact;
  (void)what;
#endif
  return Status::Ok();
}

PackLevel EmptyLevel(int w, int h, double pitch_mm) {
  PackLevel l;
  l.field.pitch_mm = pitch_mm;
  l.field.height_mm = Grid<float>(w, h);
  l.field.state = Grid<TexelState>(w, h, TexelState::kOutside);
  l.normals = Grid<Vec3f>(w, h);
  l.maps = ReflectanceMaps::Zeros(w, h);
  return l;
}

}  // namespace

namespace pack_exr {

Status DecodeTexels(const std::string& file, int version, const uint16_t* surface,
                    const uint16_t* reflectance, int w, int h, int x0, int y0,
                    const std::string& where, PackLevel& out) {
  const size_t n = static_cast<size_t>(w) * h;
  auto bad = [&](size_t i, const std::string& what) {
    return Error{file + ": texel " + TexelName(x0 + int(i % w), y0 + int(i / w)) + where + ": " +
                 what};
  };
  for (size_t i = 0; i < n; ++i) {
    const uint16_t* sp = &surface[4 * i];
    const uint16_t* rp = &reflectance[9 * i];
    const float height = FromHalfBits(sp[0]);
    const float nx = FromHalfBits(sp[1]), ny = FromHalfBits(sp[2]);
    const float code = FromHalfBits(sp[3]);
    if (!(std::abs(height) <= kMaxPackHeightMm))
      return bad(i, "height " + FormatNumber(height) + " mm is not finite or beyond " +
                        FormatNumber(kMaxPackHeightMm, kRoundTripDigits) + " mm");
    if (!(std::abs(nx) <= 1.001f && std::abs(ny) <= 1.001f && nx * nx + ny * ny <= 1.002f))
      return bad(i, "normal (" + FormatNumber(nx) + ", " + FormatNumber(ny) +
                        ") is not a unit normal's x, y");
    // Version 1: state + 4 x status (below 24); version 2 adds kModelStride x model.
    const bool v1 = version == 1;
    const int stride = v1 ? kStatesPerStatus * kTexelFitStatusCount : kModelStride;
    if (!(code >= 0 && code < (v1 ? stride : 2048) && code == std::floor(code)) ||
        (static_cast<int>(code) % stride) / kStatesPerStatus >= kTexelFitStatusCount)
      return bad(i, "M = " + FormatNumber(code) + " is not a texel state + 4 x fit status" +
                        (v1 ? " (version 1)" : " + 64 x reflectance model"));
    const int c = static_cast<int>(code);
    if (c / stride >= kReflectanceModelCount)
      return bad(i, "M = " + std::to_string(c) + " names reflectance model " +
                        std::to_string(c / stride) + ", which this reader does not know (" +
                        KnownModels() + ")");
    const auto model = static_cast<ReflectanceModel>(c / stride);
    out.field.height_mm.data[i] = height;
    out.field.state.data[i] = static_cast<TexelState>(c % kStatesPerStatus);
    out.maps.status.data[i] = static_cast<TexelFitStatus>((c % stride) / kStatesPerStatus);
    out.maps.model.data[i] = model;
    out.normals.data[i] = NormalFromXY(nx, ny);
    float v[9];
    for (int k = 0; k < 9; ++k) {
      v[k] = FromHalfBits(rp[k]);
      if (!std::isfinite(v[k])) return bad(i, kReflectanceChannels[k] + " is not finite");
    }
    for (int k = 0; k < 6; ++k)
      if (v[k] < 0) return bad(i, kReflectanceChannels[k] + " is negative");
    if (v[8] < 0) return bad(i, "lobe.k is negative");
    out.maps.rho_d.data[i] = Vec3f(v[0], v[1], v[2]);
    out.maps.rho_s.data[i] = Vec3f(v[3], v[4], v[5]);
    out.maps.lobe.data[i] = {v[6], v[7], 1.0f, v[8]};
    if (model == ReflectanceModel::kGgx) {
      if (v[3] > 1 || v[4] > 1 || v[5] > 1) return bad(i, "a GGX texel's F0 (rho_s) exceeds 1");
      if (!(v[8] >= kGgxMinAlpha && v[8] <= kGgxMaxAlpha))
        return bad(i, "a GGX texel's alpha (lobe.k) " + FormatNumber(v[8]) + " is outside [" +
                          FormatNumber(kGgxMinAlpha) + ", " + FormatNumber(kGgxMaxAlpha) + "]");
      if (v[6] != 0 || v[7] != 0) return bad(i, "a GGX texel's lobe.cx, lobe.cy must be 0");
    }
  }
  return Status::Ok();
}

Result<std::vector<ReliefBox>> DecodeBoxCells(const std::string& file, const float* cells, int w,
                                              int h, int cell_px, size_t box_count) {
  const int cells_x = (w + cell_px - 1) / cell_px, cells_y = (h + cell_px - 1) / cell_px;
  std::vector<ReliefBox> boxes;
  for (int cy = 0; cy < cells_y; ++cy)
    for (int cx = 0; cx < cells_x; ++cx) {
      const float* c = &cells[4 * (static_cast<size_t>(cy) * cells_x + cx)];
      const float present = c[0], hmax = c[1], du = c[2], dv = c[3];
      const std::string cell =
          file + ": box cell " + std::to_string(cx) + ", " + std::to_string(cy);
      if (present == 0) continue;
      if (present != 1) return Error{cell + ": present must be 0 or 1"};
      ReliefBox b;
      b.x0 = cx * cell_px;
      b.y0 = cy * cell_px;
      b.width = std::min(cell_px, w - b.x0);
      b.height = std::min(cell_px, h - b.y0);
      if (!(du >= 0 && dv >= 0 && du < b.width && dv < b.height && du == std::floor(du) &&
            dv == std::floor(dv)))
        return Error{cell + ": highest texel offset (" + FormatNumber(du) + ", " +
                     FormatNumber(dv) + ") is not a texel of the cell"};
      if (!(std::abs(hmax) <= kMaxPackHeightMm))
        return Error{cell + ": h_max " + FormatNumber(hmax) + " mm is not finite or beyond " +
                     FormatNumber(kMaxPackHeightMm, kRoundTripDigits) + " mm"};
      b.h_max_mm = hmax;
      b.u_max = b.x0 + static_cast<int>(du);
      b.v_max = b.y0 + static_cast<int>(dv);
      boxes.push_back(b);
    }
  if (boxes.size() != box_count)
    return Error{file + ": " + std::to_string(boxes.size()) + " boxes, the header says " +
                 std::to_string(box_count)};
  return boxes;
}

}  // namespace pack_exr

// --- version 3: tiles ---------------------------------------------------------------------

struct TiledPackReader::Impl {
  std::string file;
  std::unique_ptr<OIIO::ImageInput> in;
  Header header;
  PartChannels channels;
  std::vector<int64_t> first_row;  // checksum row of each level's first tile
  std::vector<uint32_t> digests;   // 5 words per row
  std::vector<ReliefBox> boxes;
  std::mutex mutex;  // one ImageInput: reads are serialised (decoding and checks are not)
};

TiledPackReader::TiledPackReader(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
TiledPackReader::~TiledPackReader() = default;
const PackSummary& TiledPackReader::summary() const { return impl_->header.summary; }
const std::vector<ReliefBox>& TiledPackReader::boxes() const { return impl_->boxes; }
const RigidTransform& TiledPackReader::canvas_from_scan() const {
  return impl_->header.canvas_from_scan;
}

Result<std::unique_ptr<TiledPackReader>> TiledPackReader::Open(const fs::path& path,
                                                               const PackReadOptions& options) {
  auto impl = std::make_unique<Impl>();
  impl->file = path.string();
  const std::string& file = impl->file;
  auto header = ReadHeader(path, options, &impl->in);
  if (!header.ok()) return header.error();
  impl->header = std::move(header).value();
  const PackSummary& s = impl->header.summary;
  if (s.version < kTiledPackVersion)
    return Error{file + ": a version " + std::to_string(s.version) +
                 " pack has one grid, no tiles (read it with ReadPack)"};
  OIIO::ImageInput& in = *impl->in;
  {
    const std::string stored = in.spec().get_string_attribute("digitize:checksum");
    if (stored.empty()) return Error{file + ": header attribute digitize:checksum is missing"};
    const bool intact = PackChecksum(DigitizeAttributes(in.spec()), nullptr, nullptr, 0) == stored;
    if (Status st = ChecksumMatches(file, intact, " of the header attributes"); !st.ok())
      return Error{st.message()};
  }
  auto channels = ReadChannels(file, in);
  if (!channels.ok()) return channels.error();
  impl->channels = *channels;
  if (!in.seek_subimage(3, 0)) return Error{file + ": cannot read part 3"};
  auto sha_ch = ChannelIndices(file, in.spec(), kChecksumPartName, kChecksumChannels);
  if (!sha_ch.ok()) return sha_ch.error();
  const int rows = in.spec().height;
  impl->digests.resize(static_cast<size_t>(rows) * 5);
  if (!in.read_image(3, 0, 0, 5, OIIO::TypeDesc::UINT32, impl->digests.data()))
    return Error{file + ": part checksums is corrupt or truncated (" + OneLine(in.geterror()) +
                 ")"};
  Canonical(impl->digests, *sha_ch);
  int64_t row = 0;
  for (const auto& [w, h] : s.levels) {
    impl->first_row.push_back(row);
    row += int64_t{(w + s.tile_size - 1) / s.tile_size} * ((h + s.tile_size - 1) / s.tile_size);
  }
  // The boxes part, checked against its digest (the last row).
  std::vector<float> cells;
  if (Status st = ReadPart(file, in, 2, OIIO::TypeDesc::FLOAT, cells); !st.ok())
    return Error{st.message()};
  Canonical(cells, impl->channels.boxes);
  {
    uint32_t digest[5];
    OIIO::SHA1(cells.data(), cells.size() * 4).gethash(digest);
    const bool intact =
        std::equal(digest, digest + 5, &impl->digests[5 * static_cast<size_t>(row)]);
    if (Status st = ChecksumMatches(file, intact, " in the boxes part"); !st.ok())
      return Error{st.message()};
  }
  auto boxes = DecodeBoxCells(file, cells.data(), s.width, s.height, s.cell_px, s.box_count);
  if (!boxes.ok()) return boxes.error();
  impl->boxes = std::move(boxes).value();
  PackHeader check;
  check.width = s.width;
  check.height = s.height;
  check.pitch_mm = s.pitch_mm;
  check.delta0_mm = s.delta0_mm;
  check.max_height_mm = s.max_height_mm;
  check.cell_px = s.cell_px;
  check.boxes = impl->boxes;
  check.canvas_from_scan = impl->header.canvas_from_scan;
  if (Status st = CheckHeader(check); !st.ok()) return Error{file + ": " + st.message()};
  return std::unique_ptr<TiledPackReader>(new TiledPackReader(std::move(impl)));
}

Result<PackTile> TiledPackReader::ReadTile(int level, int tile_x, int tile_y) {
  Impl& m = *impl_;
  const PackSummary& s = m.header.summary;
  if (level < 0 || level >= static_cast<int>(s.levels.size()))
    return Error{m.file + ": no level " + std::to_string(level) + " (the pack has " +
                 std::to_string(s.levels.size()) + ")"};
  const int lw = s.levels[level][0], lh = s.levels[level][1], t = s.tile_size;
  const int tiles_x = (lw + t - 1) / t, tiles_y = (lh + t - 1) / t;
  if (tile_x < 0 || tile_y < 0 || tile_x >= tiles_x || tile_y >= tiles_y)
    return Error{m.file + ": level " + std::to_string(level) + " has " + std::to_string(tiles_x) +
                 " x " + std::to_string(tiles_y) + " tiles, no tile " + std::to_string(tile_x) +
                 ", " + std::to_string(tile_y)};
  PackTile tile;
  tile.level = level;
  tile.tile_x = tile_x;
  tile.tile_y = tile_y;
  tile.x0 = tile_x * t;
  tile.y0 = tile_y * t;
  const int w = std::min(t, lw - tile.x0), h = std::min(t, lh - tile.y0);
  const size_t n = static_cast<size_t>(w) * h;
  std::vector<uint16_t> surface(n * 4), reflectance(n * 9);
  {
    const std::lock_guard<std::mutex> lock(m.mutex);
    for (auto [part, data] :
         {std::pair<int, uint16_t*>{0, surface.data()}, {1, reflectance.data()}})
      if (!m.in->read_tiles(part, level, tile.x0, tile.x0 + w, tile.y0, tile.y0 + h, 0, 1, 0,
                            part == 0 ? 4 : 9, OIIO::TypeDesc::HALF, data))
        return Error{m.file + ": part " + kPartNames[part] + " level " + std::to_string(level) +
                     " tile " + std::to_string(tile_x) + ", " + std::to_string(tile_y) +
                     " is corrupt or truncated (" + OneLine(m.in->geterror()) + ")"};
  }
  Canonical(surface, m.channels.surface);
  Canonical(reflectance, m.channels.reflectance);
  const std::string where = level > 0 ? " of level " + std::to_string(level) : std::string();
  {
    OIIO::SHA1 sha;
    sha.append(surface.data(), surface.size() * 2);
    sha.append(reflectance.data(), reflectance.size() * 2);
    uint32_t digest[5];
    sha.gethash(digest);
    const size_t row = static_cast<size_t>(m.first_row[level] + int64_t{tile_y} * tiles_x + tile_x);
    if (Status st = ChecksumMatches(
            m.file, std::equal(digest, digest + 5, &m.digests[5 * row]),
            " in tile " + std::to_string(tile_x) + ", " + std::to_string(tile_y) + where);
        !st.ok())
      return Error{st.message()};
  }
  tile.texels = EmptyLevel(w, h, s.pitch_mm * std::ldexp(1.0, level));
  if (Status st = DecodeTexels(m.file, s.version, surface.data(), reflectance.data(), w, h, tile.x0,
                               tile.y0, where, tile.texels);
      !st.ok())
    return Error{st.message()};
  tile.texels.max_height_mm = tile.texels.field.height_mm;
  return tile;
}

Result<PackSummary> InspectPack(const fs::path& path, const PackReadOptions& options) {
  auto header = ReadHeader(path, options, nullptr);
  if (!header.ok()) return header.error();
  return header->summary;
}

namespace {

// A version 3 pack whole: level 0's tiles, each checked, into one grid.
Result<Pack> ReadTiledPack(const fs::path& path, const PackReadOptions& options) {
  const std::string file = path.string();
  auto reader = TiledPackReader::Open(path, options);
  if (!reader.ok()) return reader.error();
  const PackSummary& s = (*reader)->summary();
  if (int64_t{s.width} * s.height > options.max_texels)
    return Error{file + ": " + std::to_string(s.width) + "x" + std::to_string(s.height) +
                 " texels, more than the " + std::to_string(options.max_texels) +
                 "-texel limit of a whole read (read its tiles instead)"};
  const PackLevel whole = EmptyLevel(s.width, s.height, s.pitch_mm);
  Pack pack;
  pack.field = whole.field;
  pack.normals = whole.normals;
  pack.maps = whole.maps;
  const int t = s.tile_size;
  for (int ty = 0; ty * t < s.height; ++ty)
    for (int tx = 0; tx * t < s.width; ++tx) {
      auto tile = (*reader)->ReadTile(0, tx, ty);
      if (!tile.ok()) return tile.error();
      const PackLevel& l = tile->texels;
      for (int y = 0; y < l.field.height(); ++y)
        for (int x = 0; x < l.field.width(); ++x) {
          const int X = tile->x0 + x, Y = tile->y0 + y;
          pack.field.height_mm(X, Y) = l.field.height_mm(x, y);
          pack.field.state(X, Y) = l.field.state(x, y);
          pack.normals(X, Y) = l.normals(x, y);
          pack.maps.rho_d(X, Y) = l.maps.rho_d(x, y);
          pack.maps.rho_s(X, Y) = l.maps.rho_s(x, y);
          pack.maps.lobe(X, Y) = l.maps.lobe(x, y);
          pack.maps.status(X, Y) = l.maps.status(x, y);
          pack.maps.model(X, Y) = l.maps.model(x, y);
        }
    }
  pack.delta0_mm = s.delta0_mm;
  pack.max_height_mm = s.max_height_mm;
  pack.cell_px = s.cell_px;
  pack.boxes = (*reader)->boxes();
  pack.provenance = s.provenance;
  pack.canvas_from_scan = (*reader)->canvas_from_scan();
  if (const auto counts = CountModels(pack.maps); counts != s.texels_by_model)
    return Error{file + ": the texels are " + ModelCountsText(counts) +
                 ", the header's digitize:models says " + ModelCountsText(s.texels_by_model)};
  if (Status st = pack.Validate(); !st.ok()) return Error{file + ": " + st.message()};
  return pack;
}

}  // namespace

Result<Pack> ReadPack(const fs::path& path, const PackReadOptions& options) {
  const std::string file = path.string();
  std::unique_ptr<OIIO::ImageInput> in;
  auto header = ReadHeader(path, options, &in);
  if (!header.ok()) return header.error();
  const PackSummary& s = header->summary;
  if (s.version >= kTiledPackVersion) {
    in.reset();
    return ReadTiledPack(path, options);
  }
  const int w = s.width, h = s.height;
  auto channels = ReadChannels(file, *in);
  if (!channels.ok()) return channels.error();
  if (!in->seek_subimage(0, 0)) return Error{file + ": cannot read part 0"};
  const OIIO::ImageSpec meta = in->spec();
  std::vector<uint16_t> surface, reflectance;
  std::vector<float> cells;
  if (Status st = ReadPart(file, *in, 0, OIIO::TypeDesc::HALF, surface); !st.ok())
    return Error{st.message()};
  if (Status st = ReadPart(file, *in, 1, OIIO::TypeDesc::HALF, reflectance); !st.ok())
    return Error{st.message()};
  if (Status st = ReadPart(file, *in, 2, OIIO::TypeDesc::FLOAT, cells); !st.ok())
    return Error{st.message()};
  Canonical(surface, channels->surface);
  Canonical(reflectance, channels->reflectance);
  Canonical(cells, channels->boxes);
  {
    const void* data[kParts] = {surface.data(), reflectance.data(), cells.data()};
    const size_t data_bytes[kParts] = {surface.size() * 2, reflectance.size() * 2,
                                       cells.size() * 4};
    const std::string stored = meta.get_string_attribute("digitize:checksum");
    if (stored.empty()) return Error{file + ": header attribute digitize:checksum is missing"};
    const bool intact = PackChecksum(DigitizeAttributes(meta), data, data_bytes, kParts) == stored;
    if (Status st = ChecksumMatches(file, intact, ""); !st.ok()) return Error{st.message()};
  }
  PackLevel texels = EmptyLevel(w, h, s.pitch_mm);
  if (Status st =
          DecodeTexels(file, s.version, surface.data(), reflectance.data(), w, h, 0, 0, "", texels);
      !st.ok())
    return Error{st.message()};
  Pack pack;
  pack.field = std::move(texels.field);
  pack.normals = std::move(texels.normals);
  pack.maps = std::move(texels.maps);
  pack.delta0_mm = s.delta0_mm;
  pack.max_height_mm = s.max_height_mm;
  pack.cell_px = s.cell_px;
  pack.canvas_from_scan = header->canvas_from_scan;
  pack.provenance = s.provenance;
  if (const auto counts = CountModels(pack.maps); counts != s.texels_by_model)
    return Error{file + ": the texels are " + ModelCountsText(counts) +
                 ", the header's digitize:models says " + ModelCountsText(s.texels_by_model)};
  auto boxes = DecodeBoxCells(file, cells.data(), w, h, s.cell_px, s.box_count);
  if (!boxes.ok()) return boxes.error();
  pack.boxes = std::move(boxes).value();
  if (Status st = pack.Validate(); !st.ok()) return Error{file + ": " + st.message()};
  return pack;
}

std::string PackSummaryJson(const std::string& file, const PackSummary& s) {
  json j = {{"file", file},
            {"format", kPackFormatName},
            {"version", s.version},
            {"size_texels", {s.width, s.height}},
            {"pitch_mm", s.pitch_mm},
            {"size_mm", {s.width * s.pitch_mm, s.height * s.pitch_mm}},
            {"delta0_mm", s.delta0_mm},
            {"max_height_mm", s.max_height_mm},
            {"cell_px", s.cell_px},
            {"boxes", s.box_count},
            {"encoding", ToString(s.encoding)},
            {"file_bytes", s.file_bytes},
            {"bytes_per_texel", s.BytesPerTexel()},
            {"raw_bytes_per_texel", s.raw_bytes_per_texel},
            {"gauge", s.gauge},
            {"models", json::object()},
            {"provenance", ProvenanceToJson(s.provenance)}};
  for (int m = 0; m < kReflectanceModelCount; ++m)
    j["models"][ToString(static_cast<ReflectanceModel>(m))] = s.texels_by_model[m];
  if (s.encoding == PackEncoding::kQuantised)
    j["mantissa_bits"] = ToJson(PackWriteOptions{s.encoding, s.quantisation})["mantissa_bits"];
  if (s.tile_size > 0) {
    j["tile_size"] = s.tile_size;
    j["levels"] = s.levels;
  }
  return j.dump(2, ' ', /*ensure_ascii=*/true, json::error_handler_t::replace);
}

}  // namespace digitize
