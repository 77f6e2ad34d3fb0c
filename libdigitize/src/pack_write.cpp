// Texture packs: the writer (pack.h, WritePack), a multi-part half-float OpenEXR file through
// OpenImageIO.
#include <OpenImageIO/imageio.h>

#include <nlohmann/json.hpp>

#include "checked_output.h"
#include "digitize/image_io.h"
#include "digitize/pack.h"
#include "options_json.h"
#include "pack_exr.h"

namespace digitize {
namespace {

namespace fs = std::filesystem;
using namespace pack_exr;

constexpr const char* kGauge =
    "lafortune1: f = rho_d + rho_s max(0, cx vx lx + cy vy ly + vz lz)^k, "
    "cz = 1, v and l in the texel's tangent frame (tangent_frame.h); "
    "ggx (M model 1): f = rho_d + F D G1(v) G1(l) / (4 vz lz), GGX D and Smith G1 of roughness "
    "alpha = lobe.k, Schlick F of F0 = rho_s, lobe.cx = lobe.cy = 0 (ggx.h)";

std::string QuantisationText(const PackQuantisation& q) {
  return "height=" + std::to_string(q.height_bits) + ",normal=" + std::to_string(q.normal_bits) +
         ",rho=" + std::to_string(q.rho_bits) + ",lobe=" + std::to_string(q.lobe_bits);
}

}  // namespace

namespace pack_exr {

Attributes PackAttributes(const PackHeader& header, const PackWriteOptions& options) {
  const bool tiled = options.tile_size > 0;
  Attributes a = {{"digitize:format", kPackFormatName},
                  {"digitize:version", std::to_string(tiled ? kTiledPackVersion : kPackVersion)},
                  {"digitize:encoding", ToString(options.encoding)}};
  if (options.encoding == PackEncoding::kQuantised)
    a.emplace_back("digitize:quantisation", QuantisationText(options.quantisation));
  a.emplace_back("digitize:gauge", kGauge);
  a.emplace_back(
      "digitize:units",
      "H mm above the canvas plane; NX NY unit normal (nz = sqrt(1 - nx^2 - ny^2)); "
      "M = texel state + 4 x fit status + 64 x reflectance model (0 lafortune, 1 ggx); rho_d "
      "1/sr; rho_s 1/sr (lafortune) or F0 in [0, 1] (ggx); lobe.k exponent (lafortune) or GGX "
      "alpha (ggx); boxes: h_max mm, u/v_max texels from the cell corner");
  a.emplace_back("digitize:models", ModelCountsText(header.texels_by_model));
  a.emplace_back("digitize:pitch_mm", FormatNumber(header.pitch_mm, kRoundTripDigits));
  a.emplace_back("digitize:size_mm",
                 FormatNumber(header.width * header.pitch_mm, kRoundTripDigits) + " x " +
                     FormatNumber(header.height * header.pitch_mm, kRoundTripDigits));
  a.emplace_back("digitize:delta0_mm", FormatNumber(header.delta0_mm, kRoundTripDigits));
  a.emplace_back("digitize:max_height_mm", FormatNumber(header.max_height_mm, kRoundTripDigits));
  a.emplace_back("digitize:cell_px", std::to_string(header.cell_px));
  a.emplace_back("digitize:box_count", std::to_string(header.boxes.size()));
  a.emplace_back("digitize:canvas_from_scan", ToJson(header.canvas_from_scan).dump());
  // File names are bytes, not always UTF-8 (a capture machine's Latin-1 names): replaced, not
  // thrown on.
  a.emplace_back("digitize:provenance",
                 ProvenanceToJson(header.provenance)
                     .dump(-1, ' ', false, nlohmann::json::error_handler_t::replace));
  if (tiled) {
    a.emplace_back("digitize:tile_size", std::to_string(options.tile_size));
    a.emplace_back("digitize:levels",
                   std::to_string(PyramidLevelSizes(header.width, header.height).size()));
  }
  return a;
}

}  // namespace pack_exr

Status WritePack(const fs::path& path, const Pack& pack, const PackWriteOptions& options) {
  const std::string file = path.string();
  if (Status s = options.Validate(); !s.ok()) return Error{file + ": " + s.message()};
  if (Status s = pack.Validate(); !s.ok()) return Error{file + ": " + s.message()};
  // Values must survive half: a texel beyond its range would read back as Inf.
  if (Status s = CheckHalfRange(pack); !s.ok()) return Error{file + ": " + s.message()};
  if (options.tile_size > 0)
    return WriteTiledPack(
        path, HeaderOf(pack), options,
        [&](int y0, int rows) -> Result<PackLevel> { return PackRows(pack, y0, rows); });
  const int w = pack.width(), h = pack.height();
  const Pack enc = EncodePackValues(pack, options);
  const size_t n = static_cast<size_t>(w) * h;

  std::vector<uint16_t> surface(n * 4), reflectance(n * 9);
  for (size_t i = 0; i < n; ++i)
    EncodeTexel(enc.field, enc.normals, enc.maps, i, &surface[4 * i], &reflectance[9 * i]);
  const int cells_x = (w + pack.cell_px - 1) / pack.cell_px,
            cells_y = (h + pack.cell_px - 1) / pack.cell_px;
  const std::vector<float> cells = BoxCells(pack.boxes, w, h, pack.cell_px);

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
  const Attributes attributes = PackAttributes(HeaderOf(pack), options);
  for (const auto& [name, value] : attributes) meta.attribute(name, value);
  const void* data[kParts] = {surface.data(), reflectance.data(), cells.data()};
  const size_t data_bytes[kParts] = {surface.size() * 2, reflectance.size() * 2, cells.size() * 4};
  meta.attribute("digitize:checksum", PackChecksum(attributes, data, data_bytes, kParts));
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

}  // namespace digitize
