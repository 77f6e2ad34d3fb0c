// Texture packs: `digitize verify` (pack.h, VerifyPack): ReadPack plus the consistency a reader
// does not need but a keeper wants.
#include <array>
#include <cmath>
#include <limits>

#include "digitize/image_io.h"
#include "digitize/pack.h"
#include "digitize/pack_tiled.h"
#include "pack_exr.h"

namespace digitize {

namespace fs = std::filesystem;
using pack_exr::TexelName;

namespace {

// What the box and height checks need of level 0, gathered from one grid or tile by tile.
struct HeightExtremes {
  float highest = -std::numeric_limits<float>::infinity();  // over texels with a height
  std::vector<float> box_max;                               // per box: its cell's highest height
  std::vector<float> at_peak;                               // per box: the height at (u_max, v_max)
};

HeightExtremes ExtremesOf(const Pack& p) {
  HeightExtremes e;
  for (int y = 0; y < p.height(); ++y)
    for (int x = 0; x < p.width(); ++x)
      if (HasHeight(p.field.state(x, y))) e.highest = std::max(e.highest, p.field.height_mm(x, y));
  for (const ReliefBox& b : p.boxes) {
    float cell_max = -std::numeric_limits<float>::infinity();
    for (int y = b.y0; y < b.y0 + b.height; ++y)
      for (int x = b.x0; x < b.x0 + b.width; ++x)
        if (HasHeight(p.field.state(x, y))) cell_max = std::max(cell_max, p.field.height_mm(x, y));
    e.box_max.push_back(cell_max);
    e.at_peak.push_back(p.field.height_mm(b.u_max, b.v_max));
  }
  return e;
}

// A version 3 pack verified a tile at a time: ReadPack would hold level 0 whole, which a pack
// larger than one machine's memory (or than PackReadOptions::max_texels) cannot be. Every tile of
// every level is checked against its SHA-1 and value by value; level 0's tiles also give the
// heights the boxes are checked against and the model counts the header states.
Result<HeightExtremes> VerifyTiles(const fs::path& path, TiledPackReader& reader,
                                   std::vector<std::string>& checks) {
  const std::string file = path.string();
  const PackSummary& s = reader.summary();
  const std::vector<ReliefBox>& boxes = reader.boxes();
  HeightExtremes e;
  e.box_max.assign(boxes.size(), -std::numeric_limits<float>::infinity());
  e.at_peak.assign(boxes.size(), std::numeric_limits<float>::quiet_NaN());
  // Boxes are cells of cell_px (DecodeBoxCells): a texel finds its box through its cell.
  const int cells_x = (s.width + s.cell_px - 1) / s.cell_px;
  const int cells_y = (s.height + s.cell_px - 1) / s.cell_px;
  std::vector<int> box_of_cell(static_cast<size_t>(cells_x) * cells_y, -1);
  for (size_t i = 0; i < boxes.size(); ++i)
    box_of_cell[static_cast<size_t>(boxes[i].y0 / s.cell_px) * cells_x + boxes[i].x0 / s.cell_px] =
        static_cast<int>(i);
  std::array<int64_t, kReflectanceModelCount> models{};
  const int t = s.tile_size;
  int64_t tiles = 0;
  for (size_t l = 0; l < s.levels.size(); ++l)
    for (int ty = 0; ty * t < s.levels[l][1]; ++ty)
      for (int tx = 0; tx * t < s.levels[l][0]; ++tx, ++tiles) {
        auto tile = reader.ReadTile(static_cast<int>(l), tx, ty);
        if (!tile.ok()) return tile.error();
        if (l > 0) continue;  // prefiltered: ReadTile checked every value
        const PackLevel& texels = tile->texels;
        if (Status st = texels.maps.Validate(); !st.ok())
          return Error{file + ": tile " + std::to_string(tx) + ", " + std::to_string(ty) + ": " +
                       st.message()};
        for (int y = 0; y < texels.field.height(); ++y)
          for (int x = 0; x < texels.field.width(); ++x) {
            const int X = tile->x0 + x, Y = tile->y0 + y;
            ++models[static_cast<int>(texels.maps.model(x, y))];
            const float hgt = texels.field.height_mm(x, y);
            const int box =
                box_of_cell[static_cast<size_t>(Y / s.cell_px) * cells_x + X / s.cell_px];
            if (box >= 0 && X == boxes[box].u_max && Y == boxes[box].v_max) e.at_peak[box] = hgt;
            if (!HasHeight(texels.field.state(x, y))) continue;
            e.highest = std::max(e.highest, hgt);
            if (box >= 0) e.box_max[box] = std::max(e.box_max[box], hgt);
          }
      }
  if (models != s.texels_by_model) {
    auto text = [](const std::array<int64_t, kReflectanceModelCount>& counts) {
      std::string out;
      for (int k = 0; k < kReflectanceModelCount; ++k)
        out += std::string(k > 0 ? ", " : "") + std::to_string(counts[k]) + " " +
               ToString(static_cast<ReflectanceModel>(k));
      return out;
    };
    return Error{file + ": the texels are " + text(models) +
                 ", the header's digitize:models says " + text(s.texels_by_model)};
  }
  checks.push_back("tiles: " + std::to_string(tiles) + " tiles of " + std::to_string(t) +
                   " texels over " + std::to_string(s.levels.size()) +
                   " levels, each matching its SHA-1, every value checked, read a tile at a time");
  return e;
}

}  // namespace

Result<PackVerification> VerifyPack(const fs::path& path, const PackReadOptions& options) {
  const std::string file = path.string();
  auto summary = InspectPack(path, options);
  if (!summary.ok()) return summary.error();
  PackVerification v;
  v.summary = *summary;
  const PackSummary& s = v.summary;
  const bool tiled = s.version >= kTiledPackVersion;
  v.checks.push_back("container: OpenEXR, " + std::to_string(tiled ? 4 : 3) + " parts, version " +
                     std::to_string(s.version) + ", " + ToString(s.encoding) + " encoding");
  std::vector<ReliefBox> boxes;
  HeightExtremes extremes;
  if (tiled) {
    auto reader = TiledPackReader::Open(path, options);
    if (!reader.ok()) return reader.error();
    auto e = VerifyTiles(path, **reader, v.checks);
    if (!e.ok()) return e.error();
    extremes = std::move(e).value();
    boxes = (*reader)->boxes();
  } else {
    auto pack = ReadPack(path, options);
    if (!pack.ok()) return pack.error();
    extremes = ExtremesOf(*pack);
    boxes = pack->boxes;
  }
  v.checks.push_back(
      "geometry: pitch " + FormatNumber(s.pitch_mm, kRoundTripDigits) + " mm, " +
      FormatNumber(s.width * s.pitch_mm, kRoundTripDigits) + " x " +
      FormatNumber(s.height * s.pitch_mm, kRoundTripDigits) + " mm (as digitize:size_mm, within " +
      FormatNumber(kMaxPackExtentMm / 1000, kRoundTripDigits) +
      " m), heights, H and delta0 within " + FormatNumber(kMaxPackHeightMm, kRoundTripDigits) +
      " mm, canvas_from_scan a rotation within " +
      FormatNumber(kMaxPackTranslationMm / 1000, kRoundTripDigits) + " m");
  // The reader refused the file unless its checksums matched; verify's output says so.
  v.checks.push_back(
      "checksum: digitize:checksum (SHA-1) matches every digitize:* attribute and "
      "every decoded value");
  v.checks.push_back("values: " + std::to_string(s.width) + "x" + std::to_string(s.height) +
                     " texels, every value finite, rho >= 0, k >= 0, unit normals, states and "
                     "statuses known");
  // The reader refused the file unless the texels' models add up to digitize:models.
  std::string models;
  for (int m = 0; m < kReflectanceModelCount; ++m)
    models += std::string(m > 0 ? ", " : "") + std::to_string(s.texels_by_model[m]) + " " +
              ToString(static_cast<ReflectanceModel>(m));
  v.checks.push_back(
      "models: " + models + " texels" +
      (s.version == 1 ? " (version 1: every texel Lafortune)" : " (as digitize:models)") +
      "; GGX texels with F0 <= 1 and alpha in [" + FormatNumber(kGgxMinAlpha) + ", " +
      FormatNumber(kGgxMaxAlpha) + "]");
  // Heights are stored in half (or fewer bits): compare within that rounding.
  const double rel =
      std::ldexp(1.0, -(s.encoding == PackEncoding::kQuantised ? s.quantisation.height_bits : 10));
  auto tol = [&](double hgt) { return rel * std::abs(hgt) + 1e-6; };
  if (std::isfinite(extremes.highest) && extremes.highest > s.max_height_mm + tol(s.max_height_mm))
    return Error{file + ": a height of " + FormatNumber(extremes.highest) +
                 " mm exceeds max_height_mm " + FormatNumber(s.max_height_mm)};
  for (size_t i = 0; i < boxes.size(); ++i) {
    const ReliefBox& b = boxes[i];
    const float cell_max = extremes.box_max[i], at_peak = extremes.at_peak[i];
    if (!std::isfinite(cell_max) || std::abs(cell_max - b.h_max_mm) > tol(b.h_max_mm) ||
        !(std::abs(at_peak - b.h_max_mm) <= tol(b.h_max_mm)))
      return Error{file + ": box " + std::to_string(i) + " (cell at texel " +
                   TexelName(b.x0, b.y0) + "): h_max " + FormatNumber(b.h_max_mm) +
                   " mm is not its cell's highest height (" + FormatNumber(cell_max) + " mm; " +
                   FormatNumber(at_peak) + " mm at (u_max, v_max))"};
  }
  v.checks.push_back("boxes: " + std::to_string(boxes.size()) + " of " +
                     std::to_string(((s.width + s.cell_px - 1) / s.cell_px) *
                                    ((s.height + s.cell_px - 1) / s.cell_px)) +
                     " cells; each h_max is its cell's highest height, at (u_max, v_max)");
  v.checks.push_back("heights: all <= max_height_mm " + FormatNumber(s.max_height_mm) + " mm");
  if (s.provenance.tool_version.empty()) return Error{file + ": provenance has no tool_version"};
  v.checks.push_back("provenance: " + EscapeForTerminal(s.provenance.tool_version) + ", " +
                     std::to_string(s.provenance.inputs.size()) + " inputs");
  return v;
}

}  // namespace digitize
