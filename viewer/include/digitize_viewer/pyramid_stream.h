// Streaming a tiled pack's pyramid (pack_tiled.h, version 3) into the viewer: per frame, the tiles
// the view needs at the level it needs, loaded in the background, handed to the GPU a few at a
// time, within a memory budget -- so a painting of a Gtexel hangs in the gallery in bounded GPU
// memory, and walking up to it never stalls a frame on a file read (issue 14, part 4).
//
// Layer: viewer (libdigitize only, no GL: Renderer does the uploads, tests run this without GL).
//
// SELECTION. The pyramid is a quadtree: tile (l, tx, ty) covers tiles (l - 1, 2 tx .. 2 tx + 1,
// 2 ty .. 2 ty + 1) (power-of-two tiles, ROUND_UP levels). From the root (the finest level that is
// one tile) a tile is refined while a texel of its level, seen from the eye at the tile's nearest
// point (its box from the lowest to the highest height), covers more than max_texel_px pixels:
// the screen-space error. Tiles whose box lies outside the view frustum are skipped.
// RESIDENCY. A needed tile that is not on the GPU is queued for the loader threads (nearest
// first; TiledPackReader checks each tile's SHA-1 and values) and, until it is, the nearest
// resident ancestor is drawn in its place; the root is always resident. Decoded tiles are handed
// over max_uploads_per_frame at a time (the frame-time bound); before each upload the least
// recently drawn tiles not drawn this frame are evicted while the resident bytes would exceed
// budget_bytes. A tile that fails to read is reported once and never asked for again (its
// ancestor stays).
#pragma once

#include <array>
#include <compare>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize/pack.h"
#include "digitize_viewer/view.h"

namespace digitize::viewer {

struct StreamOptions {
  // Refine while a texel covers more pixels than this. 0.5: a pixel shades a few texels of the
  // level it gets (renderer.h's filter over that level), which matches the whole pack's image at
  // level 0 (docs/benchmarks.md); 1 needs a quarter of the tiles and aliases edges.
  double max_texel_px = 0.5;
  int64_t budget_bytes = int64_t{512} << 20;  // resident tiles' GPU memory, at most
  int max_uploads_per_frame = 4;              // tiles handed to the GPU per frame, at most
  int max_decoded = 16;                       // decoded tiles waiting for upload, at most
  int loader_threads = 2;
  // Finite max_texel_px > 0, budget >= 1 MB, uploads and decoded >= 1, loader threads in [1, 16].
  Status Validate() const;
};

struct TileKey {
  int level = 0, tx = 0, ty = 0;
  auto operator<=>(const TileKey&) const = default;
};

// A tile ready for the GPU: four RGBA float images, laid out as Renderer::AddPainting lays out a
// pack (surface: normal xyz, height mm; rho_d: rgb, 1 where shaded; rho_s: rgb, model; lobe: cx,
// cy, cz, k), of the tile and an apron of one texel from each neighbour of its level there is,
// so the bilinear heights and normals are continuous across its edges. Texels outside the canvas
// or fitted from too few samples take the reflectance of the nearest fitted texel of the images
// (ShadingSource).
struct GpuTile {
  TileKey key;
  int x0 = 0, y0 = 0, width = 0, height = 0;  // the images, in its level's texels (apron included)
  int own_x0 = 0, own_y0 = 0, own_width = 0, own_height = 0;  // the tile itself (what is drawn)
  double pitch_mm = 0;                                        // its level's texel
  float min_height_mm = 0, max_height_mm = 0;
  std::array<std::vector<float>, 4> rgba;
  int64_t Bytes() const { return int64_t{width} * height * 4 * 4 * 2; }  // as RGBA16F
};

struct StreamFrame {
  // Resident tiles covering the part of the canvas in view once: each at the level the view needs,
  // or a coarser resident ancestor while that one loads.
  std::vector<TileKey> draw;
  std::vector<GpuTile> upload;      // to upload now (before drawing `draw`, which may hold them)
  std::vector<TileKey> evict;       // to free now
  int needed = 0;                   // tiles at the level the view needs
  int missing = 0;                  // of them not resident: an ancestor drawn instead
  int loading = 0;                  // queued or being read
  int64_t resident_bytes = 0;       // after this frame's uploads and evictions
  std::vector<std::string> errors;  // tiles that failed to read since the last frame
};

class PyramidStream {
 public:
  // Opens a version 3 pack (TiledPackReader: header checked as ReadPack checks it), reads its root
  // tile (so there is always something to draw: the first frame uploads it) and starts the
  // loaders. Errors name the file: not a tiled pack, a header or root tile that fails its checks.
  static Result<std::unique_ptr<PyramidStream>> Open(const std::filesystem::path& path,
                                                     const StreamOptions& options = {});
  ~PyramidStream();  // stops the loaders
  PyramidStream(const PyramidStream&) = delete;
  PyramidStream& operator=(const PyramidStream&) = delete;

  const PackSummary& summary() const;
  double width_mm() const;  // the canvas's extent (level 0: texels x pitch)
  double height_mm() const;
  int root_level() const;

  // The tiles this view needs (selection only, whatever is resident), and the frame: what to draw,
  // upload and evict. Call once per drawn frame; the camera and placement as drawn.
  std::vector<TileKey> Needed(const ViewCamera& camera,
                              const RigidTransform& world_from_canvas) const;
  StreamFrame Frame(const ViewCamera& camera, const RigidTransform& world_from_canvas);
  // Waits until the loaders are idle or hold max_decoded tiles (for screenshots and tests), at most
  // `seconds`; whether they were.
  bool WaitForLoads(double seconds);

  // A level's texel grid: its size and the tiles along each side.
  std::array<int, 2> LevelSize(int level) const;
  std::array<int, 2> LevelTiles(int level) const;

 private:
  struct Impl;
  explicit PyramidStream(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace digitize::viewer
