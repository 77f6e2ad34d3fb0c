// Texture packs: `digitize verify` (pack.h, VerifyPack): ReadPack plus the consistency a reader
// does not need but a keeper wants.
#include <array>
#include <cmath>
#include <limits>
#include <optional>

#include "digitize/image_io.h"
#include "digitize/pack.h"
#include "digitize/pack_tiled.h"
#include "pack_exr.h"

namespace digitize {

namespace fs = std::filesystem;
using pack_exr::TexelName;

namespace {

// What the box and height checks need of level 0, gathered from one grid (a single-grid pack)
// or a tile at a time (a tiled one), each texel once.
struct HeightExtremes {
  float highest = -std::numeric_limits<float>::infinity();  // over texels with a height
  std::vector<float> box_max;                               // per box: its cell's highest height
  std::vector<float> at_peak;                               // per box: the height at (u_max, v_max)

  HeightExtremes(const std::vector<ReliefBox>& boxes, int width, int height, int cell_px)
      : box_max(boxes.size(), -std::numeric_limits<float>::infinity()),
        at_peak(boxes.size(), std::numeric_limits<float>::quiet_NaN()),
        cell_px_(cell_px),
        cells_x_((width + cell_px - 1) / cell_px),
        box_of_cell_(static_cast<size_t>(cells_x_) * ((height + cell_px - 1) / cell_px), -1) {
    // Boxes are cells of cell_px (DecodeBoxCells): a texel finds its box through its cell.
    for (size_t i = 0; i < boxes.size(); ++i)
      box_of_cell_[Cell(boxes[i].x0, boxes[i].y0)] = static_cast<int>(i);
  }

  // The texels of `field`, whose first texel is (x0, y0) of level 0; `boxes` as constructed.
  void Add(const std::vector<ReliefBox>& boxes, const HeightField& field, int x0, int y0) {
    for (int y = 0; y < field.height(); ++y)
      for (int x = 0; x < field.width(); ++x) {
        const int X = x0 + x, Y = y0 + y;
        const float hgt = field.height_mm(x, y);
        const int box = box_of_cell_[Cell(X, Y)];
        if (box >= 0 && X == boxes[box].u_max && Y == boxes[box].v_max) at_peak[box] = hgt;
        if (!HasHeight(field.state(x, y))) continue;
        highest = std::max(highest, hgt);
        if (box >= 0) box_max[box] = std::max(box_max[box], hgt);
      }
  }

 private:
  size_t Cell(int x, int y) const {
    return static_cast<size_t>(y / cell_px_) * cells_x_ + x / cell_px_;
  }
  int cell_px_, cells_x_;
  std::vector<int> box_of_cell_;
};

// A version 3 pack verified a tile at a time: ReadPack would hold level 0 whole, which a pack
// larger than one machine's memory (or than PackReadOptions::max_texels) cannot be. Every tile of
// every level is checked against its SHA-1 and value by value; level 0's tiles also give the
// heights the boxes are checked against and the model counts the header states.
Result<HeightExtremes> VerifyTiles(const fs::path& path, TiledPackReader& reader,
                                   std::vector<std::string>& checks) {
  const std::string file = path.string();
  const PackSummary& s = reader.summary();
  HeightExtremes e(reader.boxes(), s.width, s.height, s.cell_px);
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
        const auto counts = pack_exr::CountModels(texels.maps);
        for (int m = 0; m < kReflectanceModelCount; ++m) models[m] += counts[m];
        e.Add(reader.boxes(), texels.field, tile->x0, tile->y0);
      }
  if (models != s.texels_by_model)
    return Error{file + ": the texels are " + pack_exr::ModelCountsText(models) +
                 ", the header's digitize:models says " +
                 pack_exr::ModelCountsText(s.texels_by_model)};
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
  std::optional<HeightExtremes> extremes;
  if (tiled) {
    auto reader = TiledPackReader::Open(path, options);
    if (!reader.ok()) return reader.error();
    auto e = VerifyTiles(path, **reader, v.checks);
    if (!e.ok()) return e.error();
    boxes = (*reader)->boxes();
    extremes = std::move(e).value();
  } else {
    auto pack = ReadPack(path, options);
    if (!pack.ok()) return pack.error();
    boxes = pack->boxes;
    extremes.emplace(boxes, s.width, s.height, s.cell_px);
    extremes->Add(boxes, pack->field, 0, 0);
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
  if (std::isfinite(extremes->highest) &&
      extremes->highest > s.max_height_mm + tol(s.max_height_mm))
    return Error{file + ": a height of " + FormatNumber(extremes->highest) +
                 " mm exceeds max_height_mm " + FormatNumber(s.max_height_mm)};
  for (size_t i = 0; i < boxes.size(); ++i) {
    const ReliefBox& b = boxes[i];
    const float cell_max = extremes->box_max[i], at_peak = extremes->at_peak[i];
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
