// Pixels of a photo set as linear RGB (docs/formats.md, "Pixels: linearisation, NaN and
// saturation"): the image headers checked against the cameras first (cheap), then every image
// decoded, linearised and flagged, in parallel.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#ifdef __linux__
#include <sys/mman.h>
#endif

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <mutex>
#include <new>
#include <string>
#include <type_traits>
#include <vector>

#include "digitize/image_io.h"
#include "digitize/photo_set.h"
#include "photo_set_internal.h"

namespace digitize {

using namespace photo_detail;
namespace fs = std::filesystem;

namespace {

double SrgbToLinearD(double c) {
  const double a = std::abs(c);
  const double linear = a <= 0.04045 ? a / 12.92 : std::pow((a + 0.055) / 1.055, 2.4);
  return c < 0 ? -linear : linear;
}

// Linear value of every integer code, for 8-bit (256 entries) or 16-bit (65536) images.
const std::vector<float>& SrgbLut(int max_code) {
  static const auto make = [](int n) {
    std::vector<float> lut(static_cast<size_t>(n) + 1);
    for (int i = 0; i <= n; ++i) lut[i] = static_cast<float>(SrgbToLinearD(double(i) / n));
    return lut;
  };
  static const std::vector<float> lut8 = make(255);
  static const std::vector<float> lut16 = make(65535);
  return max_code == 255 ? lut8 : lut16;
}
// code / max_code, for integer images declared linear.
const std::vector<float>& LinearLut(int max_code) {
  static const auto make = [](int n) {
    std::vector<float> lut(static_cast<size_t>(n) + 1);
    for (int i = 0; i <= n; ++i) lut[i] = static_cast<float>(double(i) / n);
    return lut;
  };
  static const std::vector<float> lut8 = make(255);
  static const std::vector<float> lut16 = make(65535);
  return max_code == 255 ? lut8 : lut16;
}

// Decoded samples -> linear RGB + flags. Rows in parallel (nested inside the per-photo tasks,
// which TBB composes) so that a single large photo also keeps every core busy.
struct Converted {
  Grid<Vec3f> rgb;
  Grid<uint8_t> flags;
  size_t non_finite = 0, saturated = 0;
};

struct RowCounts {
  size_t non_finite = 0, saturated = 0;
};

// Integer samples: a code table gives their linear value (sRGB EOTF or code / max_code). Codes
// come as stored (CodeImage) or, from a region read, as code / max_code floats, which rounding
// turns back into the code exactly. C is the stride: 1 (grey), 3 (RGB) or 4 (RGBA: alpha dropped,
// the colour is what was photographed).
template <int C, class T>
RowCounts IntegerRow(const T* src, int w, float max_code, int sat_code, const float* lut,
                     Vec3f* dst, uint8_t* flags) {
  RowCounts n;
  const int top = static_cast<int>(max_code);
  for (int x = 0; x < w; ++x, src += C) {
    int code[3];
    for (int k = 0; k < std::min(C, 3); ++k) {
      if constexpr (std::is_floating_point_v<T>)
        code[k] = std::max(std::min(static_cast<int>(src[k] * max_code + 0.5f), top), 0);
      else
        code[k] = src[k];
    }
    if constexpr (C == 1) code[1] = code[2] = code[0];
    dst[x] = Vec3f(lut[code[0]], lut[code[1]], lut[code[2]]);
    if (std::max({code[0], code[1], code[2]}) >= sat_code) {
      flags[x] = kPixelSaturated;
      ++n.saturated;
    }
  }
  return n;
}

// Float samples (EXR, float TIFF): finite check, optional sRGB curve, saturation level. C is the
// stride, as for IntegerRow (4: alpha dropped).
template <int C>
RowCounts FloatRow(const float* src, int w, bool srgb, float sat_level, Vec3f* dst,
                   uint8_t* flags) {
  RowCounts n;
  for (int x = 0; x < w; ++x, src += C) {
    Vec3f v =
        C == 1 ? Vec3f::Constant(src[0]) : Vec3f(src[0], src[C > 1 ? 1 : 0], src[C > 2 ? 2 : 0]);
    if (srgb) v = Vec3f(SrgbToLinear(v.x()), SrgbToLinear(v.y()), SrgbToLinear(v.z()));
    if (!v.allFinite()) {
      dst[x] = Vec3f::Zero();
      flags[x] = kPixelNonFinite;
      ++n.non_finite;
      continue;
    }
    dst[x] = v;
    if (v.maxCoeff() >= sat_level) {
      flags[x] = kPixelSaturated;
      ++n.saturated;
    }
  }
  return n;
}

// The smallest code at or above the saturation threshold.
int SaturationCode(const PhotoSetOptions& o, int max_code) {
  return static_cast<int>(std::ceil(static_cast<double>(o.saturation_encoded) * max_code - 1e-9));
}

const std::vector<float>& CodeLut(bool srgb, int max_code) {
  return srgb ? SrgbLut(max_code) : LinearLut(max_code);
}

// Photos are the largest buffers of a fit (12 bytes a pixel, GBs for a set) and are written once
// as they are decoded: with 4 KB pages that first write costs a page fault per 4 KB (measured on
// 64 photos of 1.7 Mpx: 27 % of the load's time in the kernel's page faults, load 3.7 s -> 2.3 s
// with this). Transparent huge pages, where the kernel offers them on request, take one fault
// per 2 MB. Advice only: nothing changes where it is refused.
void AdviseHugePages(void* data, size_t bytes) {
#ifdef __linux__
  constexpr uintptr_t kHuge = uintptr_t{2} << 20;
  const uintptr_t begin = (reinterpret_cast<uintptr_t>(data) + kHuge - 1) & ~(kHuge - 1);
  const uintptr_t end = (reinterpret_cast<uintptr_t>(data) + bytes) & ~(kHuge - 1);
  if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
#else
  (void)data, (void)bytes;
#endif
}

// Rows in parallel: row(y, dst, flags) converts row y and returns its counts.
template <class RowFn>
Converted ConvertRows(int w, int h, const RowFn& row) {
  Converted out;
  out.rgb.width = w;
  out.rgb.height = h;
  out.rgb.data.resize(static_cast<size_t>(w) * h);  // Eigen leaves it unset: written below
  AdviseHugePages(out.rgb.data.data(), out.rgb.data.size() * sizeof(Vec3f));
  out.flags = Grid<uint8_t>(w, h, 0);
  std::atomic<size_t> non_finite{0}, saturated{0};
  tbb::parallel_for(tbb::blocked_range<int>(0, h, 16), [&](const tbb::blocked_range<int>& rows) {
    RowCounts total;
    for (int y = rows.begin(); y != rows.end(); ++y) {
      const RowCounts n = row(y, out.rgb.Row(y), out.flags.Row(y));
      total.non_finite += n.non_finite;
      total.saturated += n.saturated;
    }
    non_finite += total.non_finite;
    saturated += total.saturated;
  });
  out.non_finite = non_finite;
  out.saturated = saturated;
  if (out.non_finite == 0 && out.saturated == 0) out.flags = Grid<uint8_t>();
  return out;
}

Converted Convert(const FloatImage& image, ColourEncoding encoding, const PhotoSetOptions& o) {
  const int w = image.width, c = image.channels;
  const bool srgb = encoding == ColourEncoding::kSrgb;
  // 8-bit and 16-bit codes go through a table; deeper integers (rare) through the float path,
  // which is exact for them too.
  const int max_code = !image.integer_samples        ? 0
                       : image.bits_per_sample <= 8  ? 255
                       : image.bits_per_sample <= 16 ? 65535
                                                     : 0;
  const float* lut = max_code == 0 ? nullptr : CodeLut(srgb, max_code).data();
  const int sat_code = SaturationCode(o, max_code);
  // Integer images beyond 16 bits: the threshold applies to the encoded value as for the others.
  const float sat_level = image.integer_samples
                              ? (srgb ? SrgbToLinear(o.saturation_encoded) : o.saturation_encoded)
                              : o.float_saturation_level;
  return ConvertRows(w, image.height, [&](int y, Vec3f* dst, uint8_t* flags) {
    const float* src = image.pixels.data() + static_cast<size_t>(y) * w * c;
    const float top = static_cast<float>(max_code);
    if (lut)
      return c == 1   ? IntegerRow<1>(src, w, top, sat_code, lut, dst, flags)
             : c == 3 ? IntegerRow<3>(src, w, top, sat_code, lut, dst, flags)
                      : IntegerRow<4>(src, w, top, sat_code, lut, dst, flags);
    return c == 1   ? FloatRow<1>(src, w, srgb, sat_level, dst, flags)
           : c == 3 ? FloatRow<3>(src, w, srgb, sat_level, dst, flags)
                    : FloatRow<4>(src, w, srgb, sat_level, dst, flags);
  });
}

Converted Convert(const CodeImage& image, ColourEncoding encoding, const PhotoSetOptions& o) {
  const int w = image.width, c = image.channels;
  const float* lut = CodeLut(encoding == ColourEncoding::kSrgb, image.max_code).data();
  const int sat_code = SaturationCode(o, image.max_code);
  const float top = static_cast<float>(image.max_code);
  const auto rows = [&](const auto* codes) {
    return ConvertRows(w, image.height, [&](int y, Vec3f* dst, uint8_t* flags) {
      const auto* src = codes + static_cast<size_t>(y) * w * c;
      return c == 1   ? IntegerRow<1>(src, w, top, sat_code, lut, dst, flags)
             : c == 3 ? IntegerRow<3>(src, w, top, sat_code, lut, dst, flags)
                      : IntegerRow<4>(src, w, top, sat_code, lut, dst, flags);
    });
  };
  return image.max_code == 255 ? rows(image.codes8.data()) : rows(image.codes16.data());
}

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

}  // namespace

Result<ImageHeader> photo_detail::ReadHeader(const fs::path& path) {
  const std::string name = path.string();
  auto read = ReadImageHeader(path);
  if (!read.ok()) return read.error();
  const ImageHeader header = *read;
  if (header.channels != 1 && header.channels != 3 && header.channels != 4) {
    return Error{name + ": " + std::to_string(header.channels) +
                 " channels; photos must be 1-channel (grey), 3-channel (RGB) or RGBA"};
  }
  return header;
}

ColourEncoding photo_detail::Resolve(ColourEncoding declared, bool integer_samples) {
  if (declared != ColourEncoding::kAuto) return declared;
  return integer_samples ? ColourEncoding::kSrgb : ColourEncoding::kLinear;
}

namespace {

// Checks the header of a photo's image against its camera and resolves its encoding.
Status ProbePhoto(Photo& photo) {
  auto header = ReadHeader(photo.path);
  if (!header) return Error{photo.entry + ": " + header.error().message};
  if (header->width != photo.camera.width || header->height != photo.camera.height) {
    return Error{photo.entry + ": " + photo.path.string() + ": image is " +
                 Size(header->width, header->height) + ", its camera says " +
                 Size(photo.camera.width, photo.camera.height)};
  }
  photo.encoding = Resolve(photo.encoding, header->integer_samples);
  return Status::Ok();
}

}  // namespace

Status photo_detail::ProbeAll(PhotoSet& set) {
  for (Photo& photo : set.photos) {
    if (Status s = ProbePhoto(photo); !s) return s;
  }
  return Status::Ok();
}

const char* ToString(ColourEncoding encoding) {
  switch (encoding) {
    case ColourEncoding::kSrgb:
      return "srgb";
    case ColourEncoding::kLinear:
      return "linear";
    case ColourEncoding::kAuto:
      break;
  }
  return "auto";
}

float SrgbToLinear(float encoded) { return static_cast<float>(SrgbToLinearD(encoded)); }

float LinearToSrgb(float linear) {
  const double a = std::abs(static_cast<double>(linear));
  const double e = a <= 0.0031308 ? 12.92 * a : 1.055 * std::pow(a, 1.0 / 2.4) - 0.055;
  return static_cast<float>(linear < 0 ? -e : e);
}

std::string PhotoLoadSummary::Brief() const {
  char buf[256];
  const double mpx = pixels / 1e6;
  const double sat_pct = pixels ? 100.0 * saturated_pixels / pixels : 0.0;
  std::snprintf(buf, sizeof buf,
                "%d photos (%d sRGB, %d linear), %.1f Mpx, %zu NaN/Inf px, %zu saturated px "
                "(%.2f %%); %.2f s",
                photos_loaded, srgb_photos, linear_photos, mpx, non_finite_pixels, saturated_pixels,
                sat_pct, seconds);
  return buf;
}

namespace {

// The image converted (Convert) into photo.rgb / flags / counts, after the NaN/Inf check.
template <class Image>
Status ConvertInto(Photo& photo, const Image& image, ColourEncoding encoding,
                   const PhotoSetOptions& options) {
  Converted c;
  try {
    c = Convert(image, encoding, options);
  } catch (const std::bad_alloc&) {
    return Error{photo.entry + ": " + photo.path.string() + ": not enough memory for " +
                 Size(image.width, image.height) + " float RGB pixels"};
  }
  const size_t pixels = c.rgb.size();
  if (c.non_finite > options.max_non_finite_fraction * static_cast<double>(pixels)) {
    return Error{photo.entry + ": " + photo.path.string() + ": " + std::to_string(c.non_finite) +
                 " of " + std::to_string(pixels) + " pixels are NaN/Inf (more than " +
                 FormatNumber(100 * options.max_non_finite_fraction, kShownDigits) +
                 " %): corrupt image"};
  }
  photo.encoding = encoding;
  photo.rgb = std::move(c.rgb);
  photo.flags = std::move(c.flags);
  photo.non_finite_pixels = c.non_finite;
  photo.saturated_pixels = c.saturated;
  return Status::Ok();
}

Status BadChannels(const Photo& photo, int channels) {
  return Error{photo.entry + ": " + photo.path.string() + ": " + std::to_string(channels) +
               " channels; photos must be 1-channel (grey), 3-channel (RGB) or RGBA"};
}

// The decoded pixels of `photo` (the whole image or a rectangle of it) into photo.rgb / flags /
// counts: RGBA and grey handled, colour linearised, NaN/Inf and saturation flagged.
Status TakePixels(Photo& photo, const FloatImage& image, const PhotoSetOptions& options) {
  if (image.channels != 1 && image.channels != 3 && image.channels != 4)
    return BadChannels(photo, image.channels);
  return ConvertInto(photo, image, Resolve(photo.encoding, image.integer_samples), options);
}

Status TakePixels(Photo& photo, const CodeImage& image, const PhotoSetOptions& options) {
  if (image.channels != 1 && image.channels != 3 && image.channels != 4)
    return BadChannels(photo, image.channels);
  return ConvertInto(photo, image, Resolve(photo.encoding, true), options);
}

// A decode buffer from a pool shared by all threads and given back when done, so that a set's
// photos reuse a few buffers rather than each writing fresh memory (a page fault per 4 KB). Not
// thread_local: while a photo's rows convert in parallel, TBB may start another photo's load on
// the same thread. Buffers of large images are not kept (the pool would hold their memory).
class CodeBuffer {
 public:
  CodeBuffer() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!free_.empty()) {
      image_ = std::move(free_.back());
      free_.pop_back();
    } else {
      image_ = std::make_unique<CodeImage>();
    }
  }
  ~CodeBuffer() {
    constexpr size_t kMaxKeptBytes = size_t{64} << 20;
    constexpr size_t kMaxKept = 8;
    if (image_->codes8.capacity() + 2 * image_->codes16.capacity() > kMaxKeptBytes) return;
    std::lock_guard<std::mutex> lock(mutex_);
    if (free_.size() < kMaxKept) free_.push_back(std::move(image_));
  }
  CodeBuffer(const CodeBuffer&) = delete;
  CodeBuffer& operator=(const CodeBuffer&) = delete;
  CodeImage* operator->() const { return image_.get(); }
  CodeImage& operator*() const { return *image_; }

 private:
  static inline std::mutex mutex_;
  static inline std::vector<std::unique_ptr<CodeImage>> free_;
  std::unique_ptr<CodeImage> image_;
};

Status CheckSize(const Photo& photo, int width, int height) {
  if (width == photo.camera.width && height == photo.camera.height) return Status::Ok();
  return Error{photo.entry + ": " + photo.path.string() + ": image is " + Size(width, height) +
               ", its camera says " + Size(photo.camera.width, photo.camera.height)};
}

}  // namespace

Status LoadPhoto(Photo& photo, const PhotoSetOptions& options) {
  if (Status s = options.Validate(); !s) return s;
  // 8/16-bit files (PNG, JPEG, most TIFF) as their codes: a quarter of the float image's memory
  // (8-bit) and one table lookup per sample; float and deeper files through ReadImage.
  const CodeBuffer codes;
  if (Status s = ReadImageCodes(photo.path, options.max_pixels_per_image, *codes); !s)
    return Error{photo.entry + ": " + s.message()};
  if (codes->max_code > 0) {
    if (Status s = CheckSize(photo, codes->width, codes->height); !s) return s;
    return TakePixels(photo, *codes, options);
  }
  auto image = ReadImage(photo.path, options.max_pixels_per_image);
  if (!image) return Error{photo.entry + ": " + image.error().message};
  if (Status s = CheckSize(photo, image->width, image->height); !s) return s;
  return TakePixels(photo, *image, options);
}

Result<Photo> LoadPhotoRegion(const Photo& photo, const PixelRect& region,
                              ImageRegionReader& reader, const PhotoSetOptions& options,
                              const std::filesystem::path& tiled_copy) {
  if (Status s = options.Validate(); !s) return Error{s.message()};
  const Camera& c = photo.camera;
  if (region.width <= 0 || region.height <= 0 || region.x < 0 || region.y < 0 ||
      region.x > c.width - region.width || region.y > c.height - region.height)
    return Error{photo.entry + ": region (" + std::to_string(region.x) + ", " +
                 std::to_string(region.y) + ", " + Size(region.width, region.height) +
                 ") is not inside the " + Size(c.width, c.height) + " image"};
  auto image = reader.Read(tiled_copy.empty() ? photo.path : tiled_copy, region.x, region.y,
                           region.width, region.height);
  if (!image) return Error{photo.entry + ": " + image.error().message};
  Photo part;
  part.path = photo.path;
  part.entry = photo.entry;
  part.light = photo.light;
  part.encoding = photo.encoding;
  part.camera = c;
  part.camera.width = region.width;
  part.camera.height = region.height;
  part.camera.origin_x = c.origin_x + region.x;  // pixel (u, v) of the part is (u + x, v + y)
  part.camera.origin_y = c.origin_y + region.y;
  if (Status s = TakePixels(part, *image, options); !s.ok()) return Error{s.message()};
  return part;
}

Status LoadPhotoPixels(PhotoSet& set, const PhotoSetOptions& options,
                       const ProgressCallback& progress) {
  if (Status s = options.Validate(); !s) return s;
  const auto start = std::chrono::steady_clock::now();
  const size_t n = set.photos.size();
  std::vector<Status> status(n);
  std::atomic<bool> failed{false};
  std::atomic<size_t> done{0};
  std::mutex progress_mutex;
  ReportProgress(progress, "load photos", 0.0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (failed.load(std::memory_order_relaxed)) return;  // the set is refused anyway
      status[i] = LoadPhoto(set.photos[i], options);
      if (!status[i].ok()) failed = true;
      const size_t finished = ++done;
      if (progress) {
        std::lock_guard<std::mutex> lock(progress_mutex);
        progress("load photos", static_cast<double>(finished) / static_cast<double>(n));
      }
    }
  });
  if (failed) {
    for (Photo& photo : set.photos) {  // no partial state
      photo.rgb = Grid<Vec3f>();
      photo.flags = Grid<uint8_t>();
      photo.non_finite_pixels = photo.saturated_pixels = 0;
    }
    set.summary = PhotoLoadSummary{};
    for (const Status& s : status) {
      if (!s.ok()) return s;
    }
  }
  PhotoLoadSummary summary;
  for (const Photo& photo : set.photos) {
    ++summary.photos_loaded;
    summary.pixels += photo.rgb.size();
    summary.non_finite_pixels += photo.non_finite_pixels;
    summary.saturated_pixels += photo.saturated_pixels;
    (photo.encoding == ColourEncoding::kSrgb ? summary.srgb_photos : summary.linear_photos) += 1;
  }
  summary.seconds = Seconds(start);
  set.summary = summary;
  return Status::Ok();
}

}  // namespace digitize
