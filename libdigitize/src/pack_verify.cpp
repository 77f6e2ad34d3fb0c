// Texture packs: `digitize verify` (pack.h, VerifyPack): ReadPack plus the consistency a reader
// does not need but a keeper wants.
#include <cmath>
#include <limits>

#include "digitize/image_io.h"
#include "digitize/pack.h"
#include "digitize/pack_tiled.h"
#include "pack_exr.h"

namespace digitize {

namespace fs = std::filesystem;
using pack_exr::TexelName;

Result<PackVerification> VerifyPack(const fs::path& path, const PackReadOptions& options) {
  const std::string file = path.string();
  auto summary = InspectPack(path, options);
  if (!summary.ok()) return summary.error();
  auto pack = ReadPack(path, options);
  if (!pack.ok()) return pack.error();
  PackVerification v;
  v.summary = *summary;
  const Pack& p = *pack;
  const bool tiled = v.summary.version >= kTiledPackVersion;
  v.checks.push_back("container: OpenEXR, " + std::to_string(tiled ? 4 : 3) + " parts, version " +
                     std::to_string(v.summary.version) + ", " + ToString(v.summary.encoding) +
                     " encoding");
  if (tiled) {
    // ReadPack read level 0; the levels below are what a streaming viewer reads far away.
    auto reader = TiledPackReader::Open(path, options);
    if (!reader.ok()) return reader.error();
    const int t = v.summary.tile_size;
    int64_t tiles = 0;
    for (size_t l = 0; l < v.summary.levels.size(); ++l)
      for (int ty = 0; ty * t < v.summary.levels[l][1]; ++ty)
        for (int tx = 0; tx * t < v.summary.levels[l][0]; ++tx, ++tiles) {
          auto tile = (*reader)->ReadTile(static_cast<int>(l), tx, ty);
          if (!tile.ok()) return tile.error();
        }
    v.checks.push_back("tiles: " + std::to_string(tiles) + " tiles of " + std::to_string(t) +
                       " texels over " + std::to_string(v.summary.levels.size()) +
                       " levels, each matching its SHA-1, every value checked");
  }
  v.checks.push_back(
      "geometry: pitch " + FormatNumber(p.field.pitch_mm, kRoundTripDigits) + " mm, " +
      FormatNumber(p.width_mm(), kRoundTripDigits) + " x " +
      FormatNumber(p.height_mm(), kRoundTripDigits) + " mm (as digitize:size_mm, within " +
      FormatNumber(kMaxPackExtentMm / 1000, kRoundTripDigits) +
      " m), heights, H and delta0 within " + FormatNumber(kMaxPackHeightMm, kRoundTripDigits) +
      " mm, canvas_from_scan a rotation within " +
      FormatNumber(kMaxPackTranslationMm / 1000, kRoundTripDigits) + " m");
  // ReadPack refused the file unless its checksum matched; verify's output says it was checked.
  v.checks.push_back(
      "checksum: digitize:checksum (SHA-1) matches every digitize:* attribute and "
      "every decoded value");
  v.checks.push_back("values: " + std::to_string(p.width()) + "x" + std::to_string(p.height()) +
                     " texels, every value finite, rho >= 0, k >= 0, unit normals, states and "
                     "statuses known");
  // ReadPack refused the file unless the texels' models add up to digitize:models.
  std::string models;
  for (int m = 0; m < kReflectanceModelCount; ++m)
    models += std::string(m > 0 ? ", " : "") + std::to_string(v.summary.texels_by_model[m]) + " " +
              ToString(static_cast<ReflectanceModel>(m));
  v.checks.push_back(
      "models: " + models + " texels" +
      (v.summary.version == 1 ? " (version 1: every texel Lafortune)" : " (as digitize:models)") +
      "; GGX texels with F0 <= 1 and alpha in [" + FormatNumber(kGgxMinAlpha) + ", " +
      FormatNumber(kGgxMaxAlpha) + "]");
  // Heights are stored in half (or fewer bits): compare within that rounding.
  const double rel = std::ldexp(
      1.0,
      -(v.summary.encoding == PackEncoding::kQuantised ? v.summary.quantisation.height_bits : 10));
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

}  // namespace digitize
