// Image and file output through OpenImageIO, and the atomic-write rule: everything the toolkit
// writes goes to a temporary file beside the target and is renamed into place only when complete,
// so a failure or a kill leaves the old file or none, never a partial one.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "digitize/core.h"

namespace digitize {

// Calls write(temp_path), then renames temp_path to path. On failure removes the temporary file
// and returns the error. The temporary file sits in path's directory (same file system).
Status WriteAtomically(const std::filesystem::path& path,
                       const std::function<Status(const std::filesystem::path& temp_path)>& write);

// Removes the entries of `dir` (files or folders) named prefix + "<pid>-..." whose process is
// gone: the temporaries of a writer killed mid-write. Those of a live process stay.
void RemoveStaleTemporaries(const std::filesystem::path& dir, const std::string& prefix);

// Every writer below checks each write, flush and sync of the file and its final size: a full
// disk is "PATH: write failed: no space left on device", and the previous file stays.
Status WriteTextFile(const std::filesystem::path& path, const std::string& text);

// Text files larger than this are not what the toolkit reads (a wrong file given).
inline constexpr uintmax_t kMaxTextFileBytes = uintmax_t{64} << 20;
// The whole file, as bytes. Errors name the file: "no such file", "is a directory, not a WHAT",
// "N bytes, too large for a WHAT" (over max_bytes), "cannot open for reading", "read failed".
Result<std::string> ReadTextFile(const std::filesystem::path& path, const std::string& what,
                                 uintmax_t max_bytes = kMaxTextFileBytes);

// A library's multi-line error text as one line ("; " between lines, no trailing newline), so
// every message the toolkit prints stays one line.
std::string OneLine(std::string text);

// Text from a file (a pack's provenance, a shared capture's names) made safe to print on a
// terminal: C0 controls (newline and ESC included), DEL and the C1 controls (U+0080-U+009F, and
// raw bytes 0x80-0x9F, which some terminals read as CSI) become \n, \r, \t or \xNN / \u{NNNN};
// Unicode line separators and bidirectional overrides (which reorder what is shown) become
// \u{NNNN}; bytes that are not UTF-8 become \xNN; a backslash becomes \\, so an escaped text
// cannot pose as another. Printable UTF-8 is kept as it is. One line out, always.
std::string EscapeForTerminal(std::string_view text);

// String metadata stored in the image header (EXR attributes), e.g. {"digitize:units", "mm"}.
using ImageMetadata = std::map<std::string, std::string>;

// Float images (EXR, 32-bit float, ZIP compression), channels named as given
// (e.g. {"Y"} or {"X","Y","Z"}).
Status WriteFloatExr(const std::filesystem::path& path, const Grid<float>& image,
                     const std::string& channel, const ImageMetadata& metadata = {});
Status WriteFloatExr(const std::filesystem::path& path, const Grid<Vec3f>& image,
                     const std::array<std::string, 3>& channels,
                     const ImageMetadata& metadata = {});
Status WriteFloatExr(const std::filesystem::path& path, const Grid<std::array<float, 4>>& image,
                     const std::array<std::string, 4>& channels,
                     const ImageMetadata& metadata = {});
// 8-bit single-channel PNG (masks), values written as they are.
Status WritePng8(const std::filesystem::path& path, const Grid<uint8_t>& image);
// 8-bit RGB PNG (previews).
Status WritePngRgb8(const std::filesystem::path& path, const Grid<std::array<uint8_t, 3>>& image);
// RGB PNG of 8- or 16-bit sRGB codes as given (`bits`; photos), tagged sRGB, zlib level
// `zlib_level` (0-9).
Status WriteSrgbPng(const std::filesystem::path& path, int width, int height, int bits,
                    const void* codes, int zlib_level = 6);
// The OpenImageIO format an output file's extension names (case-insensitive): .png "png",
// .jpg/.jpeg "jpeg", .tif/.tiff "tiff", .exr "openexr"; any other is an error naming the file.
Result<std::string> OutputFormatFor(const std::filesystem::path& path);
// 8-bit sRGB RGB image (screenshots) in the format its extension names (OutputFormatFor): PNG,
// JPEG (quality 95), TIFF as 8-bit sRGB; OpenEXR as the linear values of those codes (float).
Status WriteRgb8(const std::filesystem::path& path, const Grid<std::array<uint8_t, 3>>& image);

// Reads any 1-, 3- or 4-channel image OpenImageIO opens, converted to float (callers check the
// channel count they need).
struct FloatImage {
  int width = 0, height = 0, channels = 0;
  std::vector<float> pixels;     // interleaved
  std::string format;            // "openexr", "tiff", "png", ...
  int bits_per_sample = 0;       // 8, 16, 32 (for integer formats: the original depth)
  bool integer_samples = false;  // stored as integers: OIIO mapped 0..2^bits-1 onto [0, 1]
  std::vector<std::string> channel_names;  // as stored: {"X","Y","Z"}, {"R","G","B"}, {"Y"}, ...
  ImageMetadata metadata;
};
// Errors name the file: missing, unreadable, truncated, zero-sized or larger than max_pixels.
// The header alone (cheap: nothing is decoded), with the same file checks as ReadImage.
struct ImageHeader {
  int width = 0, height = 0, channels = 0;
  bool integer_samples = false;  // 8/16-bit integers (not float or half)
  std::string format;            // "openexr", "png", ...
  int bits_per_sample = 0;       // 8, 16, 32 (integer formats: the depth stored, e.g. 4 or 12)
  bool tiled = false;            // stored in tiles (TIFF, OpenEXR), so a region reads alone
  // Physical pixel size from the resolution tags (XResolution + ResolutionUnit: TIFF, EXIF,
  // JFIF, PNG pHYs), e.g. 300 per inch -> 25.4 / 300 mm. 0 when there is none, or no unit
  // (an aspect ratio only); resolution_tag says what was read ("300 per inch").
  double mm_per_pixel = 0;
  std::string resolution_tag;
};
Result<ImageHeader> ReadImageHeader(const std::filesystem::path& path);

// A tiled TIFF of an image file's samples exactly as stored: 1 or 3 channels of 8 or 16 bits
// (the types PNG and JPEG decode to), `tile` pixels a side, zip level 1. For files that cannot be
// read from the middle (a PNG or JPEG region costs decoding every row above it), so that a region
// of the copy costs its own tiles. Read and written a row of tiles at a time, written atomically;
// errors name the file (other channel counts or depths are refused).
Status WriteTiledCopy(const std::filesystem::path& from, const std::filesystem::path& to,
                      int tile = 256);

// Rectangles of image files, read through one OpenImageIO ImageCache whose memory is bounded
// (`max_cache_mb`): tiled TIFF/OpenEXR files are read tile by tile, scanline files (PNG, JPEG)
// in 256 x 256 pieces the cache decodes once and keeps while they fit; so the fit of a part of a
// painting holds the part of each photo it needs, not the photos. Thread-safe.
class ImageRegionReader {
 public:
  explicit ImageRegionReader(size_t max_cache_mb = 1024);
  ~ImageRegionReader();
  ImageRegionReader(const ImageRegionReader&) = delete;
  ImageRegionReader& operator=(const ImageRegionReader&) = delete;

  // Pixels [x, x + width) x [y, y + height) of the file's first image as float (integer samples
  // mapped onto [0, 1] as ReadImage does), every channel, and the file's header fields (format,
  // bits, integer_samples, channel names); FloatImage::width/height are the rectangle's. Errors
  // name the file: unreadable, truncated, or a rectangle that is not inside the image.
  Result<FloatImage> Read(const std::filesystem::path& path, int x, int y, int width, int height);
  // Bytes the cache holds now, and the most it held.
  size_t cache_bytes() const;
  size_t peak_cache_bytes() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

Result<FloatImage> ReadImage(const std::filesystem::path& path,
                             size_t max_pixels = size_t{1} << 28);

// An 8- or 16-bit integer image's samples as stored (codes 0..max_code, not mapped onto
// [0, 1]), for callers that look codes up in a table (photos): a quarter (8-bit) or half of the
// float image's memory and no conversion on the way. max_code is 255 or 65535; an image whose
// samples are float, half or deeper integers comes back with max_code 0 and no samples (read it
// with ReadImage). `into`'s buffers are reused: a caller decoding many images keeps a few
// CodeImages, so each image is not fresh memory (a page fault per 4 KB). Errors: ReadImage's.
struct CodeImage {
  int width = 0, height = 0, channels = 0;
  int max_code = 0;
  std::vector<uint8_t> codes8;    // interleaved, max_code 255
  std::vector<uint16_t> codes16;  // interleaved, max_code 65535
};
Status ReadImageCodes(const std::filesystem::path& path, size_t max_pixels, CodeImage& into);

// An image written a band of rows at a time, top to bottom, for maps too large to hold whole
// (a tiled preprocess's height, normals and mask): float EXR as WriteFloatExr (channels as
// named) or 8-bit single-channel PNG (no channel names). Written in place, not renamed: for
// files inside a folder that is itself written atomically (WriteDirectoryAtomically). Errors
// name the file; Close() checks the file holds every row.
class BandImageWriter {
 public:
  static Result<std::unique_ptr<BandImageWriter>> Open(const std::filesystem::path& path, int width,
                                                       int height,
                                                       const std::vector<std::string>& channels,
                                                       const ImageMetadata& metadata = {});
  ~BandImageWriter();
  BandImageWriter(const BandImageWriter&) = delete;
  BandImageWriter& operator=(const BandImageWriter&) = delete;
  // The next `rows` rows: float (EXR, channels interleaved) or uint8_t (PNG).
  Status Write(const void* pixels, int rows);
  Status Close();

 private:
  struct Impl;
  explicit BandImageWriter(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// The image a band of rows at a time, in order: `consume(band, y0)` gets rows [y0, y0 +
// band.height) as ReadImage would give them (band.width and the header fields are the file's).
// For readers that convert as they go, so that the float copy of a whole large image (12 bytes
// a pixel for a scan's XYZ) never exists beside what they convert it to. Bands of tiled files
// are whole rows of tiles. Errors: ReadImage's, or the first one `consume` returns.
Status ReadImageInBands(const std::filesystem::path& path, size_t max_pixels, int band_rows,
                        const std::function<Status(const FloatImage& band, int y0)>& consume);

}  // namespace digitize

namespace digitize {

// 8-bit RGB JPEG at `quality` (1-100) with full-resolution chroma (4:4:4): for images whose
// channels are independent data (RTI coefficient planes), which chroma subsampling would blur
// into each other. Values written as they are, no colour space.
Status WriteJpegRgb8(const std::filesystem::path& path, const Grid<std::array<uint8_t, 3>>& image,
                     int quality);

}  // namespace digitize
