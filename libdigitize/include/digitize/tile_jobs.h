// Running a tile plan (tile_plan.h): fit tiles, say which are done, merge them into the fit folder
// and the pack, and write the Slurm scripts that do the same on a cluster (docs/cluster.md).
//
// Layer: pipeline (tile_plan.h, reflectance_fit.h, pack.h).
//
// WORK FOLDER (the plan's `work`), written only by these functions:
//   .digitize-tiles     marks the folder as a tile plan's (never written into a folder without it
//                       that is not empty: a folder of the user's is not used)
//   tile_NNNNN/         one tile's result: the fit folder files (WriteReflectanceOutputs) of the
//                       tile's texels, and tile.json (the plan id, the index, the rectangle);
//                       written atomically (WriteDirectoryAtomically), so a tile is either there
//                       whole or not at all, whenever the job is killed
//   fit/                the merged fit folder (report.json alone when the pack is tiled)
//   photo_cache/        tiled copies of the PNG / JPEG photos (CachePlanPhotos), which the
//                       tile jobs read instead while they are current (photo_tile_cache.h)
//   run.log             one line per tile fitted, and per merge
//   slurm/              tiles.sbatch, merge.sbatch, submit.sh (WriteSlurmScripts)
//   logs/               the Slurm jobs' output (tile_<index>.log, merge.log)
// A tile is DONE when its folder is complete and its tile.json names this plan's id, its index
// and its rectangle: so runs resume where they stopped, and a re-cut plan never takes an old
// tile for its own.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize/pack.h"
#include "digitize/photo_tile_cache.h"
#include "digitize/tile_plan.h"

namespace digitize {

inline constexpr const char* kTileWorkMarker = ".digitize-tiles";

struct TilesStatus {
  size_t tiles = 0;
  std::vector<size_t> done, pending;  // indices, ascending
  bool merged = false;                // fit/ is there and the pack exists
  std::string Brief() const;          // "12 of 16 tiles done; pending: 3, 7, 8, 15"
};
Result<TilesStatus> StatusOfTiles(const TilePlan& plan);

// Makes the tiled copies of the plan's PNG and JPEG photos the tile jobs read (the work
// folder's photo_cache/; `tiles plan` runs it): once per plan, before its jobs, so no two jobs
// race to make them. Copies already there and current are kept.
Result<PhotoTileCacheSummary> CachePlanPhotos(const TilePlan& plan,
                                              const ProgressCallback& progress = nullptr);

struct TileRunOptions {
  std::vector<size_t> indices;  // tiles to fit; empty: every tile not done
  int threads = 0;              // worker threads (0 = all cores)
  bool redo = false;            // fit tiles that are done again
  // Bound of the image cache the canvas windows and the photo parts are read through (MB).
  size_t cache_mb = 1024;
};

struct TileRunReport {
  std::vector<size_t> fitted;   // this run
  std::vector<size_t> skipped;  // done already
  double seconds = 0;
  size_t peak_cache_bytes = 0;  // the most the image cache held
  std::string Brief() const;    // "fitted 4 tiles (3, 5, 6, 9), 12 done already; 41.2 s"
};

// Fits the chosen tiles (in index order), one at a time, each from its own inputs: the window of
// the canvas that holds the tile and a halo wide enough for every ray that can shadow or hide a
// tile texel (from the plan's height range and the flattest light or camera over the tile), and
// of each photo the pixels the tile projects to, read through one bounded image cache
// (ImageRegionReader); so a job's memory follows the tile, not the canvas or the photo set. The
// set-wide checks and counts are of the whole set's headers (SharedFitInputs). Each tile's folder
// is written as soon as it is fitted. Checks first: the plan's inputs still there, the canvas the
// plan's size, the work folder the plan's (created with its marker when missing), every index in
// range. Errors name the plan, the tile or the input.
Result<TileRunReport> RunTiles(const TilePlan& plan, const TileRunOptions& options,
                               const ProgressCallback& progress = nullptr);

// The halo (texels) a job reads around `tile`: as far as a ray from a tile texel towards a light
// or camera of `set` can run under the relief's top, (highest - lowest height) / tan(flattest
// elevation over the tile's corners) + 2; the whole canvas when a light or camera is within 1
// degree of the canvas plane. Fixed in mm, so it grows in texels as the pitch shrinks.
int TileHaloTexels(const TilePlan& plan, const TexelRect& tile, const PhotoSet& set,
                   const RigidTransform& canvas_from_scan, double pitch);
// The largest halo over the plan's tiles (the photo set's headers and the canvas's transform are
// read): `tiles plan` says it, since a tile side under ~4x it makes the jobs read more window
// than tile.
Result<int> LargestTileHalo(const TilePlan& plan);

struct TileMergeReport {
  ReflectanceFitReport fit;  // the tiles' reports summed (times: summed over the tiles)
  PackSummary pack;          // of the written pack
};

// Every tile done (else an error naming how many are pending and the first of them): their
// reports summed into work/fit/report.json, then the pack at plan.out (provenance, atomic, never
// over an input). A single-grid pack (plan.pack.tile_size 0) is written from the whole maps,
// assembled into work/fit as `digitize fit` writes them (PackFromFolders). A tiled pack streams:
// each tile's maps are read and checked once to count its models, then level 0 is fed to
// WriteTiledPack a band of rows at a time from the canvas folder (read by window) and the tiles the
// band crosses, so no whole-canvas map is ever held; work/fit holds report.json alone and the
// pack's provenance hashes every tile folder's files. Both give the same texels as `digitize pack`
// of an untiled fit with the same options.
Result<TileMergeReport> MergeTiles(const TilePlan& plan,
                                   const ProgressCallback& progress = nullptr);

struct SlurmScriptOptions {
  std::string digitize;   // the `digitize` executable the jobs run (absolute)
  int cpus_per_task = 2;  // each tile job's cores (passed on as --threads)
  int mem_mb = 0;         // each job's memory request; 0: the cluster's default
  std::string partition;  // empty: the default partition
  std::string time;       // each job's limit ("2:00:00"); empty: the partition's
  int max_running = 0;    // at most this many tiles at once (--array=...%N); 0: no limit
  Status Validate() const;
};

struct SlurmScripts {
  std::filesystem::path tiles, merge, submit;  // work/slurm/...
};

// Writes work/slurm/tiles.sbatch (a job array, one task per tile: `digitize tiles run PLAN
// --index $SLURM_ARRAY_TASK_ID`), merge.sbatch (`digitize tiles merge PLAN`) and submit.sh, which
// submits the array and then the merge with --dependency=afterok on it, and prints both job ids.
// Paths are quoted for the shell; a path with a newline or a NUL is refused.
Result<SlurmScripts> WriteSlurmScripts(const TilePlan& plan, const SlurmScriptOptions& options);

}  // namespace digitize
