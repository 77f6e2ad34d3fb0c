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
    surface[4 * i + 3] = ToHalfBits(static_cast<float>(
        TexelCode(pack.field.state.data[i], pack.maps.status.data[i], pack.maps.model.data[i])));
    uint16_t* r = &reflectance[9 * i];
    for (int c = 0; c < 3; ++c) {
      r[c] = ToHalfBits(enc.maps.rho_d.data[i][c]);
      r[3 + c] = ToHalfBits(enc.maps.rho_s.data[i][c]);
    }
    r[6] = ToHalfBits(enc.maps.lobe.data[i][0]);
    r[7] = ToHalfBits(enc.maps.lobe.data[i][1]);
    r[8] = ToHalfBits(enc.maps.lobe.data[i][3]);
  }
  const int cells_x = (w + pack.cell_px - 1) / pack.cell_px,
            cells_y = (h + pack.cell_px - 1) / pack.cell_px;
  std::vector<float> cells(static_cast<size_t>(cells_x) * cells_y * 4, 0.0f);
  for (const ReliefBox& b : pack.boxes) {
    float* c =
        &cells[4 * (static_cast<size_t>(b.y0 / pack.cell_px) * cells_x + b.x0 / pack.cell_px)];
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
  meta.attribute(
      "digitize:units",
      "H mm above the canvas plane; NX NY unit normal (nz = sqrt(1 - nx^2 - ny^2)); "
      "M = texel state + 4 x fit status + 64 x reflectance model (0 lafortune, 1 ggx); rho_d "
      "1/sr; rho_s 1/sr (lafortune) or F0 in [0, 1] (ggx); lobe.k exponent (lafortune) or GGX "
      "alpha (ggx); boxes: h_max mm, u/v_max texels from the cell corner");
  meta.attribute("digitize:models", ModelCountsText(CountModels(pack.maps)));
  meta.attribute("digitize:pitch_mm", FormatNumber(pack.field.pitch_mm, kRoundTripDigits));
  meta.attribute("digitize:size_mm", FormatNumber(pack.width_mm(), kRoundTripDigits) + " x " +
                                         FormatNumber(pack.height_mm(), kRoundTripDigits));
  meta.attribute("digitize:delta0_mm", FormatNumber(pack.delta0_mm, kRoundTripDigits));
  meta.attribute("digitize:max_height_mm", FormatNumber(pack.max_height_mm, kRoundTripDigits));
  meta.attribute("digitize:cell_px", std::to_string(pack.cell_px));
  meta.attribute("digitize:box_count", std::to_string(pack.boxes.size()));
  meta.attribute("digitize:canvas_from_scan", ToJson(pack.canvas_from_scan).dump());
  // File names are bytes, not always UTF-8 (a capture machine's Latin-1 names): replaced, not
  // thrown on.
  meta.attribute("digitize:provenance",
                 ProvenanceToJson(pack.provenance)
                     .dump(-1, ' ', false, nlohmann::json::error_handler_t::replace));
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

}  // namespace digitize
