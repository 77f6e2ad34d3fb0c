// Tiled copies of a photo set's PNG and JPEG files, made once for the tile jobs (tile_jobs.h).
//
// A tile job reads, of each photo, the part its tile projects to. PNG and JPEG cannot be read
// from the middle: a region costs decoding every row above it, so every job would decode most of
// every photo it uses, again and again. The copies are tiled TIFFs of the same samples
// (WriteTiledCopy: 8 or 16 bits, zip), read tile by tile; tiled TIFF and OpenEXR photos, and
// scanline files of other kinds (read by strip), are read as they are.
//
// Layer: photos (photo_set.h, image_io.h).
//
// FOLDER (written only by WritePhotoTileCache; docs/formats.md "Photo tile cache"):
//   index.json   {"format": "digitize.photo_tile_cache", "version": 1, "copies": [{"photo":
//                index in the set, "source": the photo's file (absolute), "bytes": its size and
//                "mtime_ns": its modification time when copied, "copy": "NNNNN.tif"}, ...]}
//   NNNNN.tif    the copy of the photo with that index
// A copy is used only while its photo's file has the size and time it had when copied and the
// copy is the photo's size: a photo replaced since is read from its own file (the same result,
// slower). The index is untrusted input (a copy name other than NNNNN.tif, an unknown format):
// the whole cache is then ignored, and the reason said.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize/photo_set.h"

namespace digitize {

inline constexpr const char* kPhotoTileCacheFormat = "digitize.photo_tile_cache";

struct PhotoTileCacheSummary {
  size_t photos = 0;   // in the set
  size_t copied = 0;   // copies written by this call
  size_t kept = 0;     // copies already there and current
  size_t direct = 0;   // read as they are (tiled already, or not a kind that is copied)
  uint64_t bytes = 0;  // of every current copy on disk
  double seconds = 0;
  std::string Brief()
      const;  // "64 photos: 64 copied tiled (0 kept, 0 read as they are), 255 MB; 9.1 s"
};

// Copies every photo of `set` (headers read, pixels not needed) that is a PNG or JPEG of 1 or 3
// channels of 8 or 16 bits into `dir` (created), keeping the copies that are current, and writes
// the index. On every core; `progress` per photo. Errors name the file and leave the index of the
// copies made before them.
Result<PhotoTileCacheSummary> WritePhotoTileCache(const PhotoSet& set,
                                                  const std::filesystem::path& dir,
                                                  const ProgressCallback& progress = nullptr);

// Per photo of `set`, its current copy in `dir`, or an empty path (read the photo itself). No
// folder or no index: every path empty, `note` empty. An index that cannot be used: every path
// empty, `note` says why.
std::vector<std::filesystem::path> FindPhotoTileCopies(const PhotoSet& set,
                                                       const std::filesystem::path& dir,
                                                       std::string* note = nullptr);

}  // namespace digitize
