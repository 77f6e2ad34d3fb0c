// Image files through OpenImageIO, and atomic replacement of output files.
#include "digitize/image_io.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagecache.h>
#include <OpenImageIO/imageio.h>
#include <signal.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <fstream>
#include <mutex>
#include <new>
#include <sstream>
#include <string>
#include <system_error>

#include "checked_output.h"

namespace digitize {
namespace {

namespace fs = std::filesystem;

static_assert(sizeof(Vec3f) == 3 * sizeof(float), "Grid<Vec3f> must be interleaved floats");
static_assert(sizeof(std::array<uint8_t, 3>) == 3, "Grid<RGB8> must be interleaved bytes");

// "name.exr" -> ".name.exr.tmp-<pid>-<n>.exr": hidden, unique per process and call, and still
// ending in the real extension for any writer that picks the format from the name.
fs::path TempPathFor(const fs::path& path) {
  static std::atomic<uint64_t> counter{0};
  const std::string name = path.filename().string();
  const std::string temp_name = "." + name + ".tmp-" + std::to_string(::getpid()) + "-" +
                                std::to_string(counter.fetch_add(1)) + path.extension().string();
  return path.parent_path() / temp_name;
}

// "No space left on device" -> "no space left on device": the cause, inside a sentence.
std::string Cause(int error) {
  std::string text = std::generic_category().message(error);
  if (!text.empty()) text[0] = static_cast<char>(std::tolower(static_cast<unsigned char>(text[0])));
  return text;
}

// The file an OpenImageIO writer writes through: every short write is recorded (its errno) and
// reported to the writer as complete, so that no codec library gives up halfway in its own way;
// FinishFile reports the failure.
class CheckedFile final : public OIIO::Filesystem::IOFile {
 public:
  explicit CheckedFile(FILE* file) : IOFile(file, IOProxy::Write) {}
  // Not "file": writers that see a file proxy take its FILE* and write past these checks.
  const char* proxytype() const override { return "checked-file"; }
  size_t write(const void* buf, size_t size) override {
    const int64_t at = tell();
    errno = 0;
    return Checked(IOFile::write(buf, size), size, at);
  }
  size_t pwrite(const void* buf, size_t size, int64_t offset) override {
    errno = 0;
    return Checked(IOFile::pwrite(buf, size, offset), size, offset);
  }
  int error() const { return error_; }
  uint64_t extent() const { return extent_; }

 private:
  size_t Checked(size_t written, size_t size, int64_t at) {
    std::lock_guard<std::mutex> lock(checked_mutex_);
    if (written != size && error_ == 0) error_ = errno != 0 ? errno : EIO;
    extent_ = std::max<uint64_t>(extent_, static_cast<uint64_t>(std::max<int64_t>(at, 0)) + size);
    return size;
  }
  std::mutex checked_mutex_;
  int error_ = 0;
  uint64_t extent_ = 0;
};

// Flushes, syncs (a full disk may only show here) and closes `file`, then checks that `temp`
// holds `bytes` bytes. `error` is a write failure seen before; the first failure is reported.
Status FinishFile(FILE* file, const fs::path& temp, const fs::path& path, int error,
                  uint64_t bytes) {
  if (std::fflush(file) != 0 && error == 0) error = errno;
  if (::fsync(::fileno(file)) != 0 && error == 0 && errno != EINVAL) error = errno;
  if (std::fclose(file) != 0 && error == 0) error = errno;
  if (error != 0) return Error{path.string() + ": write failed: " + Cause(error)};
  std::error_code ec;
  const uintmax_t size = fs::file_size(temp, ec);
  if (ec) return Error{path.string() + ": write failed: " + ec.message()};
  if (size != bytes)
    return Error{path.string() + ": write failed: the file holds " + std::to_string(size) +
                 " bytes of " + std::to_string(bytes) + " written"};
  return Status::Ok();
}

// Writes interleaved pixels of one type through the OIIO writer named by `format`.
Status WritePixels(const fs::path& path, const char* format, const OIIO::ImageSpec& spec,
                   const void* pixels) {
  if (spec.width <= 0 || spec.height <= 0) {
    return Error{path.string() + ": cannot write an empty image (" + std::to_string(spec.width) +
                 "x" + std::to_string(spec.height) + ")"};
  }
  auto write = [&](OIIO::ImageOutput& out, const std::string& temp) -> Status {
    if (!out.open(temp, spec))
      return Error{path.string() + ": cannot open for writing: " + OneLine(out.geterror())};
    const bool wrote = out.write_image(spec.format, pixels);
    const bool closed = out.close();
    if (!wrote || !closed)
      return Error{path.string() + ": write failed: " + OneLine(out.geterror())};
    return Status::Ok();
  };
  return WriteImageAtomically(path, format, write);
}

OIIO::ImageSpec ExrSpec(int width, int height, const std::vector<std::string>& channels,
                        const ImageMetadata& metadata) {
  OIIO::ImageSpec spec(width, height, static_cast<int>(channels.size()), OIIO::TypeDesc::FLOAT);
  spec.channelnames = channels;
  spec.alpha_channel = -1;
  spec.attribute("compression", "zip");
  for (const auto& [key, value] : metadata) spec.attribute(key, value);
  return spec;
}

template <class T>
void CheckStorage(const Grid<T>& image) {
  DIGITIZE_CHECK(image.data.size() == static_cast<size_t>(image.width) * image.height,
                 "image grid storage does not match its " + std::to_string(image.width) + "x" +
                     std::to_string(image.height) + " size");
}

bool IsIntegerType(OIIO::TypeDesc type) {
  return type.basetype != OIIO::TypeDesc::FLOAT && type.basetype != OIIO::TypeDesc::HALF &&
         type.basetype != OIIO::TypeDesc::DOUBLE;
}

std::string JoinNames(const std::vector<std::string>& names) {
  std::string joined;
  for (const auto& n : names) joined += (joined.empty() ? "" : ",") + n;
  return joined;
}

}  // namespace

void RemoveStaleTemporaries(const fs::path& dir, const std::string& prefix) {
  const fs::path where = dir.empty() ? fs::path(".") : dir;
  std::error_code ec;
  // Removed after the listing: removing entries while iterating is unspecified.
  std::vector<fs::path> stale;
  for (fs::directory_iterator it(where, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.rfind(prefix, 0) != 0) continue;
    const std::string rest = name.substr(prefix.size());  // "<pid>-<n>..."
    char* after = nullptr;
    const long pid = std::strtol(rest.c_str(), &after, 10);
    if (pid <= 0 || after == rest.c_str() || *after != '-') continue;
    if (::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;  // alive, or unknown
    stale.push_back(it->path());
  }
  for (const fs::path& p : stale) fs::remove_all(p, ec);
}

Status WriteAtomically(const fs::path& path,
                       const std::function<Status(const fs::path& temp_path)>& write) {
  if (path.filename().empty()) return Error{path.string() + ": not a file name"};
  const fs::path dir = path.parent_path().empty() ? fs::path(".") : path.parent_path();
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    return Error{path.string() + ": cannot write, directory " + dir.string() + " does not exist"};
  }
  if (fs::is_directory(path, ec)) return Error{path.string() + ": is a directory"};

  const fs::path temp = TempPathFor(path);
  Status status;
  try {
    status = write(temp);
  } catch (const std::exception& e) {
    status = Error{path.string() + ": write failed: " + e.what()};
  } catch (...) {
    status = Error{path.string() + ": write failed with an unknown exception"};
  }
  if (status.ok() && !fs::is_regular_file(temp, ec)) {
    status = Error{path.string() + ": the writer reported success but produced no file"};
  }
  if (status.ok()) {
    fs::rename(temp, path, ec);
    if (ec)
      status = Error{path.string() + ": cannot move the finished file into place: " + ec.message()};
  }
  if (!status.ok()) fs::remove(temp, ec);  // best effort; the error already says what failed
  // A writer killed mid-write (SIGKILL, power loss) leaves its temporary file behind.
  RemoveStaleTemporaries(dir, "." + path.filename().string() + ".tmp-");
  return status;
}

Status WriteImageAtomically(
    const fs::path& path, const char* format,
    const std::function<Status(OIIO::ImageOutput& out, const std::string& temp)>& write) {
  return WriteAtomically(path, [&](const fs::path& temp) -> Status {
    auto out = OIIO::ImageOutput::create(format);
    if (!out)
      return Error{path.string() + ": no " + format + " writer: " + OneLine(OIIO::geterror())};
    if (!out->supports("ioproxy"))
      return Error{path.string() + ": the " + format +
                   " writer cannot write through a checked file"};
    FILE* file = std::fopen(temp.c_str(), "wb");
    if (file == nullptr) return Error{path.string() + ": cannot open for writing: " + Cause(errno)};
    CheckedFile proxy(file);
    Status status = out->set_ioproxy(&proxy)
                        ? write(*out, temp.string())
                        : Status(Error{path.string() + ": cannot write through a checked file"});
    out.reset();  // a writer left open by a failed write closes here, before its file does
    Status finished = FinishFile(file, temp, path, proxy.error(), proxy.extent());
    if (finished.ok() && status.ok() && proxy.extent() == 0)
      return Error{path.string() + ": the " + format + " writer wrote nothing"};
    // The cause (a full disk) says more than the codec's view of it.
    return proxy.error() != 0 || status.ok() ? finished : status;
  });
}

Status WithDiskFull(Status status, const fs::path& path) {
  if (status.ok()) return status;
  const fs::path dir = path.parent_path().empty() ? fs::path(".") : path.parent_path();
  struct statvfs disk {};
  if (::statvfs(dir.c_str(), &disk) == 0 && disk.f_bavail == 0)
    return Error{status.message() + " (" + Cause(ENOSPC) + ")"};
  return status;
}

Result<std::string> OutputFormatFor(const fs::path& path) {
  std::string ext = path.extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".png") return std::string("png");
  if (ext == ".jpg" || ext == ".jpeg") return std::string("jpeg");
  if (ext == ".tif" || ext == ".tiff") return std::string("tiff");
  if (ext == ".exr") return std::string("openexr");
  return Error{path.string() + ": unknown image extension '" + path.extension().string() +
               "'; write .png, .jpg, .tif or .exr"};
}

std::string OneLine(std::string text) {
  while (!text.empty() && (text.back() == '\n' || text.back() == ' ')) text.pop_back();
  for (size_t pos; (pos = text.find('\n')) != std::string::npos;) text.replace(pos, 1, "; ");
  return text;
}

std::string EscapeForTerminal(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  auto hex = [&](unsigned v, const char* format) {
    char buf[16];
    std::snprintf(buf, sizeof buf, format, v);
    out += buf;
  };
  const auto byte = [&](size_t i) { return static_cast<unsigned char>(text[i]); };
  for (size_t i = 0; i < text.size();) {
    const unsigned char c = byte(i);
    if (c < 0x80) {
      if (c == '\\')
        out += "\\\\";
      else if (c == '\n')
        out += "\\n";
      else if (c == '\r')
        out += "\\r";
      else if (c == '\t')
        out += "\\t";
      else if (c < 0x20 || c == 0x7f)
        hex(c, "\\x%02x");
      else
        out += static_cast<char>(c);
      ++i;
      continue;
    }
    // A well-formed UTF-8 sequence (shortest form, no surrogates, at most U+10FFFF), or one byte.
    const int length = c >= 0xc2 && c <= 0xdf   ? 2
                       : c >= 0xe0 && c <= 0xef ? 3
                       : c >= 0xf0 && c <= 0xf4 ? 4
                                                : 0;
    uint32_t cp = length == 2 ? c & 0x1fu : length == 3 ? c & 0x0fu : c & 0x07u;
    bool valid = length > 0 && i + length <= text.size();
    for (int k = 1; valid && k < length; ++k) {
      valid = (byte(i + k) & 0xc0) == 0x80;
      cp = (cp << 6) | (byte(i + k) & 0x3fu);
    }
    if (valid) {
      valid = !(length == 3 && (cp < 0x800 || (cp >= 0xd800 && cp <= 0xdfff))) &&
              !(length == 4 && (cp < 0x10000 || cp > 0x10ffff));
    }
    if (!valid) {
      hex(c, "\\x%02x");
      ++i;
      continue;
    }
    const bool control = cp <= 0x9f ||                    // C1 (U+0080-U+009F)
                         cp == 0x2028 || cp == 0x2029 ||  // line and paragraph separators
                         (cp >= 0x200e && cp <= 0x200f) || (cp >= 0x202a && cp <= 0x202e) ||
                         (cp >= 0x2066 && cp <= 0x2069);  // bidirectional marks and overrides
    if (control)
      hex(cp, "\\u{%04x}");
    else
      out.append(text.substr(i, static_cast<size_t>(length)));
    i += static_cast<size_t>(length);
  }
  return out;
}

Status WriteTextFile(const fs::path& path, const std::string& text) {
  return WriteAtomically(path, [&](const fs::path& temp) -> Status {
    FILE* file = std::fopen(temp.c_str(), "wb");
    if (file == nullptr) return Error{path.string() + ": cannot open for writing: " + Cause(errno)};
    errno = 0;
    const size_t wrote = std::fwrite(text.data(), 1, text.size(), file);
    const int error = wrote == text.size() ? 0 : (errno != 0 ? errno : EIO);
    return FinishFile(file, temp, path, error, text.size());
  });
}

Result<std::string> ReadTextFile(const fs::path& path, const std::string& what,
                                 uintmax_t max_bytes) {
  std::error_code ec;
  const auto status = fs::status(path, ec);
  if (!fs::exists(status)) return Error{path.string() + ": no such file"};
  if (fs::is_directory(status)) return Error{path.string() + ": is a directory, not a " + what};
  const uintmax_t bytes = fs::file_size(path, ec);
  if (!ec && bytes > max_bytes) {
    return Error{path.string() + ": " + std::to_string(bytes) + " bytes, too large for a " + what};
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{path.string() + ": cannot open for reading"};
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) return Error{path.string() + ": read failed"};
  return text.str();
}

Status WriteFloatExr(const fs::path& path, const Grid<float>& image, const std::string& channel,
                     const ImageMetadata& metadata) {
  CheckStorage(image);
  const auto spec = ExrSpec(image.width, image.height, {channel}, metadata);
  return WritePixels(path, "openexr", spec, image.data.data());
}

Status WriteFloatExr(const fs::path& path, const Grid<Vec3f>& image,
                     const std::array<std::string, 3>& channels, const ImageMetadata& metadata) {
  CheckStorage(image);
  const auto spec =
      ExrSpec(image.width, image.height, {channels[0], channels[1], channels[2]}, metadata);
  return WritePixels(path, "openexr", spec, image.data.data());
}

Status WriteFloatExr(const fs::path& path, const Grid<std::array<float, 4>>& image,
                     const std::array<std::string, 4>& channels, const ImageMetadata& metadata) {
  CheckStorage(image);
  const auto spec = ExrSpec(image.width, image.height,
                            {channels[0], channels[1], channels[2], channels[3]}, metadata);
  return WritePixels(path, "openexr", spec, image.data.data());
}

Status WritePng8(const fs::path& path, const Grid<uint8_t>& image) {
  CheckStorage(image);
  const OIIO::ImageSpec spec(image.width, image.height, 1, OIIO::TypeDesc::UINT8);
  return WritePixels(path, "png", spec, image.data.data());
}

Status WritePngRgb8(const fs::path& path, const Grid<std::array<uint8_t, 3>>& image) {
  CheckStorage(image);
  const OIIO::ImageSpec spec(image.width, image.height, 3, OIIO::TypeDesc::UINT8);
  return WritePixels(path, "png", spec, image.data.data());
}

Status WriteSrgbPng(const fs::path& path, int width, int height, int bits, const void* codes,
                    int zlib_level) {
  if (bits != 8 && bits != 16)
    return Error{path.string() + ": PNG codes are 8 or 16 bits, got " + std::to_string(bits)};
  OIIO::ImageSpec spec(width, height, 3,
                       bits == 8 ? OIIO::TypeDesc::UINT8 : OIIO::TypeDesc::UINT16);
  spec.attribute("oiio:ColorSpace", "sRGB");
  spec.attribute("png:compressionLevel", zlib_level);
  return WritePixels(path, "png", spec, codes);
}

Status WriteRgb8(const fs::path& path, const Grid<std::array<uint8_t, 3>>& image) {
  CheckStorage(image);
  auto format = OutputFormatFor(path);
  if (!format.ok()) return Status(format.error());
  OIIO::ImageSpec spec(image.width, image.height, 3, OIIO::TypeDesc::UINT8);
  // Not for TIFF: its colour space goes into an Exif directory, which libtiff links by reading
  // the file back, and the checked file is write-only (the result would not open).
  if (*format != "tiff") spec.attribute("oiio:ColorSpace", "sRGB");
  if (*format == "jpeg") spec.attribute("Compression", "jpeg:95");
  if (*format != "openexr") return WritePixels(path, format->c_str(), spec, image.data.data());
  // OpenEXR holds linear values: the sRGB codes decoded.
  std::vector<float> linear(image.data.size() * 3);
  for (size_t i = 0; i < linear.size(); ++i) {
    const double c = image.data[i / 3][i % 3] / 255.0;
    linear[i] = static_cast<float>(c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4));
  }
  OIIO::ImageSpec exr(image.width, image.height, 3, OIIO::TypeDesc::FLOAT);
  exr.attribute("compression", "zip");
  return WritePixels(path, "openexr", exr, linear.data());
}

namespace {

// The checks every reader makes before decoding: the file exists, is not empty, OpenImageIO
// opens it, and it is a 2D image. Errors name the file.
Result<std::unique_ptr<OIIO::ImageInput>> OpenImage(const fs::path& path) {
  const std::string name = path.string();
  std::error_code ec;
  const auto file_status = fs::status(path, ec);
  if (!fs::exists(file_status)) return Error{name + ": no such file"};
  if (fs::is_directory(file_status)) return Error{name + ": is a directory, not an image"};
  if (fs::is_regular_file(file_status) && fs::file_size(path, ec) == 0 && !ec) {
    return Error{name + ": empty file (0 bytes)"};
  }
  // Colour as stored: OpenImageIO would otherwise premultiply a PNG's RGB by its alpha, and a
  // photo saved with a transparent alpha would read black.
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto in = OIIO::ImageInput::open(name, &config);
  if (!in) {
    return Error{name + ": unreadable, not an image OpenImageIO can open (" +
                 OneLine(OIIO::geterror()) + ")"};
  }
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.depth != 1) {
    return Error{name + ": zero-sized or volume image (" + std::to_string(spec.width) + "x" +
                 std::to_string(spec.height) + "x" + std::to_string(spec.depth) + ")"};
  }
  return in;
}

}  // namespace

Result<ImageHeader> ReadImageHeader(const fs::path& path) {
  auto in = OpenImage(path);
  if (!in.ok()) return in.error();
  const OIIO::ImageSpec& spec = (*in)->spec();
  ImageHeader header;
  header.width = spec.width;
  header.height = spec.height;
  header.channels = spec.nchannels;
  header.integer_samples = IsIntegerType(spec.format);
  header.format = (*in)->format_name();
  header.bits_per_sample =
      spec.get_int_attribute("oiio:BitsPerSample", static_cast<int>(spec.format.size() * 8));
  header.tiled = spec.tile_width > 0 && spec.tile_height > 0;
  const float per_unit = spec.get_float_attribute("XResolution", 0.0f);
  const std::string unit = spec.get_string_attribute("ResolutionUnit");
  const double unit_mm = unit == "in" || unit == "inch" ? 25.4
                         : unit == "cm"                 ? 10.0
                         : unit == "mm"                 ? 1.0
                         : unit == "m"                  ? 1000.0
                                                        : 0.0;
  if (std::isfinite(per_unit) && per_unit > 0 && unit_mm > 0) {
    header.mm_per_pixel = unit_mm / per_unit;
    header.resolution_tag = FormatNumber(per_unit) + " per " + (unit == "in" ? "inch" : unit);
  }
  (*in)->close();
  return header;
}

Status WriteTiledCopy(const fs::path& from, const fs::path& to, int tile) {
  if (tile < 16 || tile > 4096 || tile % 16 != 0)
    return Error{to.string() + ": tile side " + std::to_string(tile) +
                 " (TIFF tiles are multiples of 16, here at most 4096)"};
  auto opened = OpenImage(from);
  if (!opened.ok()) return opened.error();
  OIIO::ImageInput& in = **opened;
  const OIIO::ImageSpec& spec = in.spec();
  const OIIO::TypeDesc type = spec.format;
  const int bits = spec.get_int_attribute("oiio:BitsPerSample", static_cast<int>(type.size() * 8));
  if ((type != OIIO::TypeDesc::UINT8 && type != OIIO::TypeDesc::UINT16) ||
      bits != static_cast<int>(type.size() * 8) || (spec.nchannels != 1 && spec.nchannels != 3))
    return Error{from.string() + ": " + std::to_string(spec.nchannels) + " channel(s) of " +
                 std::to_string(bits) + " bits: only 1 or 3 channels of 8 or 16 bits are copied"};
  OIIO::ImageSpec out_spec(spec.width, spec.height, spec.nchannels, type);
  out_spec.channelnames = spec.channelnames;
  out_spec.tile_width = out_spec.tile_height = tile;
  // Level 1: a 64-photo set (290 Mpx) copied in 8.6 s instead of 16.3 s at the default level 6,
  // for 13 % more disk (317 against 281 MB); reading does not depend on the level.
  out_spec.attribute("compression", "zip:1");
  const size_t row_bytes = static_cast<size_t>(spec.width) * spec.nchannels * type.size();
  std::vector<unsigned char> band(row_bytes * static_cast<size_t>(tile));
  auto write = [&](OIIO::ImageOutput& out, const std::string& temp) -> Status {
    if (!out.open(temp, out_spec))
      return Error{to.string() + ": cannot open for writing: " + OneLine(out.geterror())};
    for (int y0 = 0; y0 < spec.height; y0 += tile) {
      const int y1 = std::min(spec.height, y0 + tile);
      if (!in.read_scanlines(0, 0, spec.y + y0, spec.y + y1, 0, 0, spec.nchannels, type,
                             band.data()))
        return Error{from.string() + ": truncated or corrupt pixel data (" +
                     OneLine(in.geterror()) + ")"};
      if (!out.write_tiles(0, spec.width, y0, y1, 0, 1, type, band.data()))
        return Error{to.string() + ": write failed: " + OneLine(out.geterror())};
    }
    if (!out.close()) return Error{to.string() + ": write failed: " + OneLine(out.geterror())};
    return Status::Ok();
  };
  return WriteImageAtomically(to, "tiff", write);
}

namespace {

// OpenImage, then the checks of a reader of pixels (size within max_pixels, before anything is
// allocated: a corrupt header can claim billions; 1, 3 or 4 channels), and the FloatImage's
// header fields filled (its pixels left empty).
Result<std::unique_ptr<OIIO::ImageInput>> OpenForPixels(const fs::path& path, size_t max_pixels,
                                                        FloatImage* image) {
  const std::string name = path.string();
  auto opened = OpenImage(path);
  if (!opened.ok()) return opened.error();
  std::unique_ptr<OIIO::ImageInput> in = std::move(opened).value();
  const OIIO::ImageSpec& spec = in->spec();
  const auto pixels = static_cast<uint64_t>(spec.width) * static_cast<uint64_t>(spec.height);
  if (pixels > max_pixels) {
    return Error{name + ": too large, " + std::to_string(spec.width) + "x" +
                 std::to_string(spec.height) + " = " + std::to_string(pixels) +
                 " pixels exceeds the limit of " + std::to_string(max_pixels)};
  }
  if (spec.nchannels < 1 || spec.nchannels > 4 || spec.nchannels == 2) {
    return Error{name + ": " + std::to_string(spec.nchannels) + " channels (" +
                 JoinNames(spec.channelnames) +
                 "); only 1-channel (height, mask), 3-channel (X,Y,Z or RGB) or 4-channel (RGBA, "
                 "lobe) images are read"};
  }
  image->width = spec.width;
  image->height = spec.height;
  image->channels = spec.nchannels;
  image->format = in->format_name();
  image->integer_samples = IsIntegerType(spec.format);
  image->bits_per_sample =
      spec.get_int_attribute("oiio:BitsPerSample", static_cast<int>(spec.format.size() * 8));
  image->channel_names = spec.channelnames;
  for (const auto& attribute : spec.extra_attribs) {
    if (attribute.type() == OIIO::TypeString) {
      image->metadata[attribute.name().string()] = attribute.get_string();
    }
  }
  return in;
}

bool ResizeFor(FloatImage& image, uint64_t pixels) {
  try {
    image.pixels.resize(pixels * static_cast<uint64_t>(image.channels));
  } catch (const std::bad_alloc&) {
    return false;
  }
  return true;
}

}  // namespace

Result<FloatImage> ReadImage(const fs::path& path, size_t max_pixels) {
  const std::string name = path.string();
  FloatImage image;
  auto opened = OpenForPixels(path, max_pixels, &image);
  if (!opened.ok()) return opened.error();
  const std::unique_ptr<OIIO::ImageInput> in = std::move(opened).value();
  const auto pixels = static_cast<uint64_t>(image.width) * static_cast<uint64_t>(image.height);
  if (!ResizeFor(image, pixels))
    return Error{name + ": not enough memory for " + std::to_string(pixels) + " pixels"};
  if (!in->read_image(0, 0, 0, image.channels, OIIO::TypeDesc::FLOAT, image.pixels.data()) ||
      in->has_error()) {
    return Error{name + ": truncated or corrupt pixel data (" + OneLine(in->geterror()) + ")"};
  }
  in->close();
  return image;
}

Status ReadImageCodes(const fs::path& path, size_t max_pixels, CodeImage& image) {
  const std::string name = path.string();
  image.width = image.height = image.channels = image.max_code = 0;
  FloatImage header;
  auto opened = OpenForPixels(path, max_pixels, &header);
  if (!opened.ok()) return opened.error();
  const std::unique_ptr<OIIO::ImageInput> in = std::move(opened).value();
  const OIIO::TypeDesc format = in->spec().format;
  const bool eight = format == OIIO::TypeDesc::UINT8, sixteen = format == OIIO::TypeDesc::UINT16;
  if (!eight && !sixteen) return Status::Ok();
  const uint64_t samples = static_cast<uint64_t>(header.width) *
                           static_cast<uint64_t>(header.height) *
                           static_cast<uint64_t>(header.channels);
  void* data = nullptr;
  try {
    if (eight) {
      image.codes8.resize(samples);
      data = image.codes8.data();
    } else {
      image.codes16.resize(samples);
      data = image.codes16.data();
    }
  } catch (const std::bad_alloc&) {
    return Error{name + ": not enough memory for " + std::to_string(samples) + " samples"};
  }
  if (!in->read_image(0, 0, 0, header.channels, format, data) || in->has_error()) {
    return Error{name + ": truncated or corrupt pixel data (" + OneLine(in->geterror()) + ")"};
  }
  in->close();
  image.width = header.width;
  image.height = header.height;
  image.channels = header.channels;
  image.max_code = eight ? 255 : 65535;
  return Status::Ok();
}

Status ReadImageInBands(const fs::path& path, size_t max_pixels, int band_rows,
                        const std::function<Status(const FloatImage& band, int y0)>& consume) {
  const std::string name = path.string();
  FloatImage band;
  auto opened = OpenForPixels(path, max_pixels, &band);
  if (!opened.ok()) return Status(opened.error());
  const std::unique_ptr<OIIO::ImageInput> in = std::move(opened).value();
  const OIIO::ImageSpec& spec = in->spec();
  const int height = band.height;
  // A tiled file is read a row of tiles at a time: bands start on tile boundaries.
  int rows = std::max(1, band_rows);
  if (spec.tile_width > 0 && spec.tile_height > 0)
    rows = (rows + spec.tile_height - 1) / spec.tile_height * spec.tile_height;
  rows = std::min(rows, height);
  if (!ResizeFor(band, static_cast<uint64_t>(band.width) * static_cast<uint64_t>(rows)))
    return Error{name + ": not enough memory for a band of " + std::to_string(rows) + " rows"};
  for (int y0 = 0; y0 < height; y0 += rows) {
    band.height = std::min(rows, height - y0);
    band.pixels.resize(static_cast<size_t>(band.width) * static_cast<size_t>(band.height) *
                       static_cast<size_t>(band.channels));
    const int y = spec.y + y0;
    const bool read = spec.tile_width > 0
                          ? in->read_tiles(0, 0, spec.x, spec.x + spec.width, y, y + band.height,
                                           spec.z, spec.z + 1, 0, band.channels,
                                           OIIO::TypeDesc::FLOAT, band.pixels.data())
                          : in->read_scanlines(0, 0, y, y + band.height, spec.z, 0, band.channels,
                                               OIIO::TypeDesc::FLOAT, band.pixels.data());
    if (!read || in->has_error())
      return Error{name + ": truncated or corrupt pixel data (" + OneLine(in->geterror()) + ")"};
    if (Status st = consume(band, y0); !st.ok()) return st;
  }
  in->close();
  return Status::Ok();
}

}  // namespace digitize

namespace digitize {

struct BandImageWriter::Impl {
  fs::path path;
  std::unique_ptr<OIIO::ImageOutput> out;
  OIIO::TypeDesc type;
  int width = 0, height = 0, channels = 0, next_row = 0;
};

BandImageWriter::BandImageWriter(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
BandImageWriter::~BandImageWriter() = default;

Result<std::unique_ptr<BandImageWriter>> BandImageWriter::Open(
    const fs::path& path, int width, int height, const std::vector<std::string>& channels,
    const ImageMetadata& metadata) {
  if (width <= 0 || height <= 0)
    return Error{path.string() + ": cannot write an empty image (" + std::to_string(width) + "x" +
                 std::to_string(height) + ")"};
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  impl->width = width;
  impl->height = height;
  const bool exr = !channels.empty();
  OIIO::ImageSpec spec;
  if (exr) {
    spec = ExrSpec(width, height, channels, metadata);
    impl->type = OIIO::TypeDesc::FLOAT;
    impl->channels = static_cast<int>(channels.size());
  } else {
    spec = OIIO::ImageSpec(width, height, 1, OIIO::TypeDesc::UINT8);
    impl->type = OIIO::TypeDesc::UINT8;
    impl->channels = 1;
  }
  impl->out = OIIO::ImageOutput::create(exr ? "openexr" : "png");
  if (!impl->out) return Error{path.string() + ": no image writer: " + OneLine(OIIO::geterror())};
  if (!impl->out->open(path.string(), spec))
    return Error{path.string() + ": cannot open for writing: " + OneLine(impl->out->geterror())};
  return std::unique_ptr<BandImageWriter>(new BandImageWriter(std::move(impl)));
}

Status BandImageWriter::Write(const void* pixels, int rows) {
  Impl& m = *impl_;
  if (!m.out) return Error{m.path.string() + ": written after it was closed"};
  if (rows <= 0 || rows > m.height - m.next_row)
    return Error{m.path.string() + ": " + std::to_string(rows) + " rows at row " +
                 std::to_string(m.next_row) + " of " + std::to_string(m.height)};
  if (!m.out->write_scanlines(m.next_row, m.next_row + rows, 0, m.type, pixels))
    return WithDiskFull(Error{m.path.string() + ": write failed: " + OneLine(m.out->geterror())},
                        m.path);
  m.next_row += rows;
  return Status::Ok();
}

Status BandImageWriter::Close() {
  Impl& m = *impl_;
  if (!m.out) return Status::Ok();
  const bool complete = m.next_row == m.height;
  const bool closed = m.out->close();
  const std::string error = closed ? "" : OneLine(m.out->geterror());
  m.out.reset();
  if (!closed) return WithDiskFull(Error{m.path.string() + ": write failed: " + error}, m.path);
  if (!complete)
    return Error{m.path.string() + ": closed after " + std::to_string(m.next_row) + " of " +
                 std::to_string(m.height) + " rows"};
  return Status::Ok();
}

struct ImageRegionReader::Impl {
  OIIO::ImageCache* cache = nullptr;
  std::atomic<size_t> peak{0};
};

ImageRegionReader::ImageRegionReader(size_t max_cache_mb) : impl_(std::make_unique<Impl>()) {
  impl_->cache = OIIO::ImageCache::create(/*shared=*/false);
  impl_->cache->attribute("max_memory_MB", static_cast<float>(std::max<size_t>(64, max_cache_mb)));
  // Scanline files are cut into tiles of this size, so a rectangle costs its own rows.
  impl_->cache->attribute("autotile", 256);
  impl_->cache->attribute("autoscanline", 0);
  impl_->cache->attribute("max_open_files", 64);
}

ImageRegionReader::~ImageRegionReader() { OIIO::ImageCache::destroy(impl_->cache, true); }

size_t ImageRegionReader::cache_bytes() const {
  long long used = 0;
  impl_->cache->getattribute("stat:cache_memory_used", OIIO::TypeInt64, &used);
  return static_cast<size_t>(std::max(0LL, used));
}

size_t ImageRegionReader::peak_cache_bytes() const {
  return std::max(impl_->peak.load(), cache_bytes());
}

Result<FloatImage> ImageRegionReader::Read(const fs::path& path, int x, int y, int width,
                                           int height) {
  const std::string name = path.string();
  const OIIO::ustring file(name);
  OIIO::ImageSpec spec;
  if (!impl_->cache->get_imagespec(file, spec)) {
    std::string why = OneLine(impl_->cache->geterror());
    if (!fs::exists(path)) why = "no such file";
    return Error{name + ": cannot read (" + why + ")"};
  }
  if (width <= 0 || height <= 0 || x < 0 || y < 0 || x > spec.width - width ||
      y > spec.height - height)
    return Error{name + ": the region (" + std::to_string(x) + ", " + std::to_string(y) + ", " +
                 std::to_string(width) + " x " + std::to_string(height) + ") is not inside the " +
                 std::to_string(spec.width) + "x" + std::to_string(spec.height) + " image"};
  if (spec.nchannels < 1 || spec.nchannels > 4 || spec.nchannels == 2)
    return Error{name + ": " + std::to_string(spec.nchannels) + " channels (" +
                 JoinNames(spec.channelnames) + "); only 1-, 3- or 4-channel images are read"};
  FloatImage image;
  image.width = width;
  image.height = height;
  image.channels = spec.nchannels;
  // The cache converts as it caches: the file's own sample type is in its native spec.
  OIIO::ImageSpec original;
  impl_->cache->get_imagespec(file, original, 0, 0, /*native=*/true);
  image.format = OIIO::Filesystem::extension(name, false);
  image.integer_samples = IsIntegerType(original.format);
  image.bits_per_sample = original.get_int_attribute("oiio:BitsPerSample",
                                                     static_cast<int>(original.format.size() * 8));
  image.channel_names = spec.channelnames;
  const size_t count = static_cast<size_t>(width) * static_cast<size_t>(height) *
                       static_cast<size_t>(spec.nchannels);
  try {
    image.pixels.resize(count);
  } catch (const std::bad_alloc&) {
    return Error{name + ": not enough memory for a " + std::to_string(width) + "x" +
                 std::to_string(height) + " region"};
  }
  if (!impl_->cache->get_pixels(file, 0, 0, x, x + width, y, y + height, 0, 1, 0, spec.nchannels,
                                OIIO::TypeDesc::FLOAT, image.pixels.data()))
    return Error{name + ": truncated or corrupt pixel data (" + OneLine(impl_->cache->geterror()) +
                 ")"};
  size_t used = cache_bytes(), seen = impl_->peak.load();
  while (used > seen && !impl_->peak.compare_exchange_weak(seen, used)) {
  }
  return image;
}

Status WriteJpegRgb8(const fs::path& path, const Grid<std::array<uint8_t, 3>>& image, int quality) {
  CheckStorage(image);
  if (quality < 1 || quality > 100)
    return Error{path.string() + ": JPEG quality must be 1-100, got " + std::to_string(quality)};
  OIIO::ImageSpec spec(image.width, image.height, 3, OIIO::TypeDesc::UINT8);
  spec.attribute("Compression", "jpeg:" + std::to_string(quality));
  spec.attribute("jpeg:subsampling", "4:4:4");
  return WritePixels(path, "jpeg", spec, image.data.data());
}

}  // namespace digitize
