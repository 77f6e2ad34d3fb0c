// A painting's fit as tiles: a job plan (`digitize tiles plan`) that cuts the canvas into square
// tiles, each fitted on its own -- by one process after another, by every core of one machine
// (`tiles run --all`), or as the tasks of a Slurm job array (`tiles sbatch`) -- and merged into
// the fit folder and the pack (`tiles merge`). Format: docs/formats.md, "Tile plans".
//
// Layer: pipeline (reflectance_fit.h, pack.h; tile_jobs.h runs what this describes).
//
// A plan names its inputs (a canvas folder, a calibration JSON) and its outputs (the pack; the
// work folder with one result folder per tile, and the merged fit folder) by absolute path, so a
// job started from any folder on any node that mounts them finds them; and it carries every
// option of the fit, so every tile is fitted alike. Its `id` (a SHA-1 of its content) stamps each
// tile result: a result of another plan (the options changed, the canvas re-cut) is never taken
// for this one's.
//
// Each tile's texels are fitted exactly as the whole canvas's fit would fit them
// (FitReflectanceRegions), so the merged maps equal an untiled `digitize fit` bit for bit.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize/pack.h"
#include "digitize/photo_set.h"
#include "digitize/reflectance_fit.h"

namespace digitize {

inline constexpr const char* kTilePlanFormat = "digitize.tile_plan";
inline constexpr int kTilePlanVersion = 1;
inline constexpr int kMinTileSize = 16;     // texels a side: smaller tiles are all overhead
inline constexpr int kMaxTileSize = 16384;  // a tile's maps alone would be 5 GB
inline constexpr size_t kMaxPlanTiles = 1 << 20;

struct TilePlan {
  std::filesystem::path file;    // the plan file itself (absolute; not stored in it)
  std::filesystem::path canvas;  // canvas folder (`digitize preprocess`)
  std::filesystem::path photos;  // calibration JSON
  std::filesystem::path out;     // the pack `tiles merge` writes
  std::filesystem::path work;    // tile results (tile_NNNNN/) and the merged fit (fit/)
  int canvas_width = 0, canvas_height = 0;
  int tile_size = 0;  // texels a side (the last column and row of tiles may be smaller)
  // Lowest and highest height of the whole canvas (height.exr, mm): how far a shadow or view ray
  // of a tile can travel below the relief's top, so how wide a halo each tile job reads.
  double min_height_mm = 0, max_height_mm = 0;
  PhotoSetOptions photo;
  ReflectanceFitOptions fit;  // num_threads are the machine's: not stored (tiles run --threads)
  PackWriteOptions pack;
  std::vector<TexelRect> tiles;  // row by row, left to right (TileGrid)
  std::string id;                // SHA-1 of the plan's content

  std::filesystem::path TileFolder(size_t index) const;  // work / "tile_00012"
  std::filesystem::path FitFolder() const { return work / "fit"; }
  // Tiled copies of the PNG / JPEG photos (photo_tile_cache.h), made by CachePlanPhotos.
  std::filesystem::path PhotoCacheFolder() const { return work / "photo_cache"; }
};

// The tiles of a width x height canvas cut into tile_size squares, row by row.
std::vector<TexelRect> TileGrid(int width, int height, int tile_size);

struct TilePlanOptions {
  std::string canvas;  // canvas folder
  std::string photos;  // calibration JSON (an RTI .lp is fitted untiled: `digitize fit`)
  PhotoSetOptions photo;
  ReflectanceFitOptions fit;
  PackWriteOptions pack;
  int tile_size = 1024;
  std::string out;   // the pack file merge writes
  std::string plan;  // the plan file to write
  std::string work;  // empty: beside the plan, PLAN minus ".json" plus ".tiles"
};

// Checks the options and the inputs (the canvas folder complete, its size from height.exr's
// header, the calibration readable without its pixels), then writes the plan file atomically
// (WriteTilePlan) and returns it. The plan, the work folder and the pack must not be, lie in or
// hold an input; an existing file at `plan` is replaced only when it is a tile plan.
Result<TilePlan> MakeTilePlan(const TilePlanOptions& options);

// The plan as JSON text (docs/formats.md), and its inverse. ReadTilePlan treats the file as
// untrusted: every field is checked (format, version, paths absolute, sizes and tile count in
// bounds, the tiles exactly TileGrid's, the options valid, the id matching the content); errors
// name the plan file and the field.
std::string TilePlanJson(const TilePlan& plan);
Result<TilePlan> ReadTilePlan(const std::filesystem::path& file);

}  // namespace digitize
