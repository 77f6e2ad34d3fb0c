// Version 3 texture packs: tiled and multi-resolution (issue 14), for paintings whose pack does
// not fit in memory and for a viewer that loads only the tiles it sees, at the level it needs.
// Layer: pack. Format: docs/formats.md, "Tiled, multi-resolution packs (version 3)".
//
// The same multi-part OpenEXR file as a version 2 pack, with the surface and reflectance parts
// tiled (tile_size x tile_size) and mip-mapped (OpenEXR MIPMAP_LEVELS, ROUND_UP: level l is
// ceil(w / 2^l) x ceil(h / 2^l), down to 1 x 1), each level the PrefilterLevel of the one above
// (pack_pyramid.h), and a fourth part holding the SHA-1 of every tile, so a reader that reads one
// tile can check that tile. Level 0 holds exactly the values a version 2 pack of the same options
// holds; ReadPack reads it like any pack.
//
// Writing streams: level 0 is asked for in bands of tile_size rows, each level keeps at most two
// bands of its own rows (the pair the next level is filtered from), and every tile is written as
// soon as its rows are there (OpenEXR writes tiles of any level in any order). Memory: about
// 4 x tile_size x width texels of PackLevel (~70 bytes each) in all, whatever the height.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <vector>

#include "digitize/pack.h"
#include "digitize/pack_pyramid.h"

namespace digitize {

inline constexpr int kTiledPackVersion = 3;
// A tile below 64 texels makes OpenEXR's offset tables large against the pixels; above 4096 one
// tile is 200 MB of floats to decode. Powers of two only, so a level's tile maps onto whole tiles
// of the next.
inline constexpr int kMinPackTileSize = 64;
inline constexpr int kMaxPackTileSize = 4096;
Status CheckPackTileSize(int tile_size);  // a power of two in [64, 4096]

// Level sizes of the pyramid over w x h: level 0 is w x h, each next ceil(w / 2) x ceil(h / 2),
// the last 1 x 1.
std::vector<std::array<int, 2>> PyramidLevelSizes(int w, int h);

// Everything of a pack but its texel grids: what the streamed writer needs before the first texel.
struct PackHeader {
  int width = 0, height = 0;
  double pitch_mm = 0;
  double delta0_mm = 0, max_height_mm = 0;
  int cell_px = 0;
  std::vector<ReliefBox> boxes;
  RigidTransform canvas_from_scan;
  PackProvenance provenance;
  // Level 0's texels per reflectance model (the header states them before any texel is written);
  // Finish refuses a pack whose texels say otherwise.
  std::array<int64_t, kReflectanceModelCount> texels_by_model{};
};
PackHeader HeaderOf(const Pack& pack);

// Level 0's rows [y0, y0 + rows) of the painting: header.width x rows texels (max_height_mm is
// not read). Called top to bottom, each row once, tile_size rows at a time (fewer for the last).
using PackBandSource = std::function<Result<PackLevel>(int y0, int rows)>;

// Writes a version 3 pack at `path`, atomically (a temporary file beside it, renamed into place
// only when everything succeeded). Each band is checked like a pack (Pack::Validate: finite
// values, unit normals, ...; values within half's range) and each level's tiles are written as
// soon as their rows are there. Errors name the file, the level and the rows; an error of `band`
// is passed on. Afterwards the texels per model must equal header.texels_by_model.
Status WriteTiledPack(const std::filesystem::path& path, const PackHeader& header,
                      const PackWriteOptions& options, const PackBandSource& band);

// Rows [y0, y0 + rows) of a pack's grids, as a level-0 band (what WritePack hands WriteTiledPack).
PackLevel PackRows(const Pack& pack, int y0, int rows);

// One tile of one level, as read and checked.
struct PackTile {
  int level = 0, tile_x = 0, tile_y = 0;
  int x0 = 0, y0 = 0;  // its first texel in the level's grid
  PackLevel texels;    // field.pitch_mm the level's; max_height_mm = height (not stored)
};

// Reads the tiles of a version 3 pack, at any level, without reading the rest: the header is
// checked as ReadPack checks it (InspectPack's summary), each tile against its SHA-1 and then
// value by value as ReadPack checks texels. ReadTile may be called from several threads.
class TiledPackReader {
 public:
  static Result<std::unique_ptr<TiledPackReader>> Open(const std::filesystem::path& path,
                                                       const PackReadOptions& options = {});
  ~TiledPackReader();
  const PackSummary& summary() const;           // tile_size > 0, levels from level 0
  const std::vector<ReliefBox>& boxes() const;  // level 0's, checked
  const RigidTransform& canvas_from_scan() const;
  Result<PackTile> ReadTile(int level, int tile_x, int tile_y);

  TiledPackReader(const TiledPackReader&) = delete;
  TiledPackReader& operator=(const TiledPackReader&) = delete;

 private:
  struct Impl;
  explicit TiledPackReader(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace digitize
