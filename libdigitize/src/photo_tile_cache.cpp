// Tiled copies of a photo set's PNG and JPEG files (photo_tile_cache.h).
#include "digitize/photo_tile_cache.h"

#include <tbb/parallel_for.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>

#include "digitize/image_io.h"

namespace digitize {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

constexpr const char* kIndexFile = "index.json";
constexpr int kCopyTile = 256;  // the image cache's own tile side (ImageRegionReader)

// What a photo's file was when it was copied: a copy is current while the file still is.
struct FileStamp {
  uintmax_t bytes = 0;
  int64_t mtime_ns = 0;
  bool operator==(const FileStamp&) const = default;
};

std::optional<FileStamp> StampOf(const fs::path& path) {
  std::error_code ec;
  const uintmax_t bytes = fs::file_size(path, ec);
  if (ec) return std::nullopt;
  const auto time = fs::last_write_time(path, ec);
  if (ec) return std::nullopt;
  const auto unix_time = std::chrono::file_clock::to_sys(time);  // readable in the index
  return FileStamp{
      bytes,
      std::chrono::duration_cast<std::chrono::nanoseconds>(unix_time.time_since_epoch()).count()};
}

std::string CopyName(size_t index) {
  char name[32];
  std::snprintf(name, sizeof name, "%05zu.tif", index);
  return name;
}

struct IndexEntry {
  size_t photo = 0;
  std::string source;
  FileStamp stamp;
  std::string copy;
};

// The index's entries, or why it cannot be used. Untrusted: every field checked, a copy is a
// plain NNNNN.tif name of its photo's index, so nothing outside the folder is ever read.
Result<std::vector<IndexEntry>> ReadIndex(const fs::path& dir) {
  const fs::path file = dir / kIndexFile;
  auto text = ReadTextFile(file, "photo tile cache index", 16u << 20);
  if (!text.ok()) return text.error();
  const json doc = json::parse(*text, nullptr, false);
  if (doc.is_discarded() || !doc.is_object()) return Error{file.string() + ": not a JSON object"};
  if (doc.value("format", "") != kPhotoTileCacheFormat || doc.value("version", 0) != 1)
    return Error{file.string() + ": not a version 1 " + kPhotoTileCacheFormat + " index"};
  const auto copies = doc.find("copies");
  if (copies == doc.end() || !copies->is_array())
    return Error{file.string() + ": no \"copies\" list"};
  std::vector<IndexEntry> entries;
  for (const json& c : *copies) {
    if (!c.is_object() || !c.contains("photo") || !c["photo"].is_number_unsigned() ||
        !c.contains("source") || !c["source"].is_string() || !c.contains("bytes") ||
        !c["bytes"].is_number_unsigned() || !c.contains("mtime_ns") ||
        !c["mtime_ns"].is_number_integer() || !c.contains("copy") || !c["copy"].is_string())
      return Error{file.string() + ": an entry without photo, source, bytes, mtime_ns and copy"};
    IndexEntry e;
    e.photo = c["photo"].get<size_t>();
    e.source = c["source"].get<std::string>();
    e.stamp = {c["bytes"].get<uintmax_t>(), c["mtime_ns"].get<int64_t>()};
    e.copy = c["copy"].get<std::string>();
    if (e.photo > (size_t{1} << 24) || e.copy != CopyName(e.photo))
      return Error{file.string() + ": copy \"" + e.copy + "\" is not the copy of photo " +
                   std::to_string(e.photo) + " (" + CopyName(e.photo) + ")"};
    entries.push_back(std::move(e));
  }
  return entries;
}

// The entry of photo `index` whose copy is current: same file, same stamp, and the copy there
// with the photo's size and channels.
bool IsCurrent(const IndexEntry& e, const Photo& photo, const fs::path& dir, int channels) {
  if (e.source != photo.path.string()) return false;
  const auto stamp = StampOf(photo.path);
  if (!stamp || !(*stamp == e.stamp)) return false;
  auto header = ReadImageHeader(dir / e.copy);
  return header.ok() && header->tiled && header->width == photo.camera.width &&
         header->height == photo.camera.height && header->channels == channels;
}

// Whether a photo's file is copied: a PNG or JPEG (read from the top only) of samples the copy
// holds exactly.
bool IsCopied(const ImageHeader& h) {
  return !h.tiled && (h.format == "png" || h.format == "jpeg") &&
         (h.channels == 1 || h.channels == 3) && h.integer_samples &&
         (h.bits_per_sample == 8 || h.bits_per_sample == 16);
}

}  // namespace

std::string PhotoTileCacheSummary::Brief() const {
  char text[256];
  std::snprintf(text, sizeof text,
                "%zu photos: %zu copied tiled (%zu kept from before, %zu read as they are), "
                "%.0f MB; %.1f s",
                photos, copied, kept, direct, static_cast<double>(bytes) / (1 << 20), seconds);
  return text;
}

Result<PhotoTileCacheSummary> WritePhotoTileCache(const PhotoSet& set, const fs::path& dir,
                                                  const ProgressCallback& progress) {
  const auto start = std::chrono::steady_clock::now();
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Error{dir.string() + ": cannot create the photo tile cache: " + ec.message()};
  std::vector<IndexEntry> before;
  if (fs::exists(dir / kIndexFile, ec)) {
    auto read = ReadIndex(dir);
    if (read.ok()) before = std::move(read).value();  // else: every copy is made again
  }
  const size_t n = set.photos.size();
  PhotoTileCacheSummary summary;
  summary.photos = n;
  std::vector<std::optional<IndexEntry>> entries(n);
  std::vector<Status> status(n);
  std::vector<uint8_t> kept(n, 0);
  std::atomic<size_t> done{0};
  std::atomic<bool> failed{false};
  std::mutex progress_mutex;
  ReportProgress(progress, "photo tile cache", 0.0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (failed.load(std::memory_order_relaxed)) return;
      const Photo& photo = set.photos[i];
      auto header = ReadImageHeader(photo.path);
      if (!header.ok()) {
        status[i] = Error{photo.entry + ": " + header.error().message};
        failed = true;
        return;
      }
      if (IsCopied(*header)) {
        for (const IndexEntry& e : before)
          if (e.photo == i && IsCurrent(e, photo, dir, header->channels)) {
            entries[i] = e;
            kept[i] = 1;
          }
        if (!entries[i]) {
          const auto stamp = StampOf(photo.path);
          Status s = stamp ? WriteTiledCopy(photo.path, dir / CopyName(i), kCopyTile)
                           : Status(Error{photo.path.string() + ": cannot stat"});
          if (!s.ok()) {
            status[i] = Error{photo.entry + ": " + s.message()};
            failed = true;
            return;
          }
          entries[i] = IndexEntry{i, photo.path.string(), *stamp, CopyName(i)};
        }
      }
      const size_t finished = ++done;
      if (progress) {
        std::lock_guard<std::mutex> lock(progress_mutex);
        progress("photo tile cache", static_cast<double>(finished) / static_cast<double>(n));
      }
    }
  });
  // The index lists every copy made, also when a later photo failed: they are kept next time.
  json copies = json::array();
  for (size_t i = 0; i < n; ++i) {
    if (!entries[i]) {
      summary.direct += status[i].ok();
      continue;
    }
    const IndexEntry& e = *entries[i];
    copies.push_back({{"photo", e.photo},
                      {"source", e.source},
                      {"bytes", e.stamp.bytes},
                      {"mtime_ns", e.stamp.mtime_ns},
                      {"copy", e.copy}});
    (kept[i] ? summary.kept : summary.copied) += 1;
    summary.bytes += fs::file_size(dir / e.copy, ec);
  }
  const json index = {{"format", kPhotoTileCacheFormat}, {"version", 1}, {"copies", copies}};
  if (Status s = WriteTextFile(dir / kIndexFile, index.dump(1) + "\n"); !s.ok())
    return Error{s.message()};
  for (const Status& s : status)
    if (!s.ok()) return Error{s.message()};
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

std::vector<fs::path> FindPhotoTileCopies(const PhotoSet& set, const fs::path& dir,
                                          std::string* note) {
  std::vector<fs::path> copies(set.photos.size());
  if (note) note->clear();
  std::error_code ec;
  if (!fs::exists(dir / kIndexFile, ec)) return copies;
  auto entries = ReadIndex(dir);
  if (!entries.ok()) {
    if (note) *note = entries.error().message + ": the photos are read from their own files";
    return copies;
  }
  for (const IndexEntry& e : *entries) {
    if (e.photo >= set.photos.size()) continue;
    const Photo& photo = set.photos[e.photo];
    auto header = ReadImageHeader(photo.path);
    if (header.ok() && IsCopied(*header) && IsCurrent(e, photo, dir, header->channels))
      copies[e.photo] = dir / e.copy;
  }
  return copies;
}

}  // namespace digitize
