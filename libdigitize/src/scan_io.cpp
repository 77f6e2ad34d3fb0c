// Scan files: float XYZ / depth images and 16-bit height images through OpenImageIO (image_io),
// PLY point grids through OpenMesh.
#include "digitize/scan_io.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>
#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "digitize/image_io.h"

namespace digitize {
namespace {

namespace fs = std::filesystem;

// 16-bit integer samples reach us normalised to [0, 1] by OpenImageIO.
constexpr double kMaxCount16 = 65535.0;
// A PLY header longer than this is not a point grid header but garbage.
constexpr size_t kMaxPlyHeaderLines = 4096;
// Rows of an XYZ scan image decoded at a time: a few MB of floats at scanner widths, and enough
// rows that both cores have work converting each band.
constexpr int kScanBandRows = 256;

std::string Size(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

// A grid whose samples the caller writes in parallel: Eigen's default constructor leaves them
// untouched, so the pages are first touched by the writing threads, not by a serial fill.
Grid<Vec3f> UnfilledGrid(int width, int height) {
  Grid<Vec3f> grid;
  grid.width = width;
  grid.height = height;
  grid.data.resize(static_cast<size_t>(width) * static_cast<size_t>(height));
  return grid;
}

template <class F>
void ParallelRows(int height, const F& f) {
  tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y != rows.end(); ++y) f(y);
  });
}

// Index of the channel called `axis` ("X", or a layer's "P.X"), or -1.
int FindChannel(const std::vector<std::string>& names, const std::string& axis) {
  for (size_t i = 0; i < names.size(); ++i) {
    const std::string& n = names[i];
    if (n == axis || (n.size() > axis.size() && n.ends_with("." + axis)))
      return static_cast<int>(i);
  }
  return -1;
}

}  // namespace

std::array<int, 3> XyzChannels(const std::vector<std::string>& names) {
  std::array<int, 3> channel = {FindChannel(names, "X"), FindChannel(names, "Y"),
                                FindChannel(names, "Z")};
  if (std::find(channel.begin(), channel.end(), -1) != channel.end()) channel = {0, 1, 2};
  return channel;
}

namespace {

// Read a band at a time into the scan's grid: the file's float copy would be as large as the
// scan (12 bytes a sample: 1.4 GB for the scan of an 8192-texel canvas).
Result<Scan> ReadXyzImageScan(const fs::path& path, const ImageHeader& header, size_t max_samples) {
  Scan scan;
  scan.source = path.string();
  std::array<int, 3> channel{};
  const Status read = ReadImageInBands(
      path, max_samples, kScanBandRows, [&](const FloatImage& band, int y0) -> Status {
        if (y0 == 0) {
          if (band.integer_samples)
            return Error{path.string() + ": 3-channel " + std::to_string(band.bits_per_sample) +
                         "-bit integer image; an XYZ scan must be float (EXR or TIFF, mm)"};
          // OpenEXR stores channels sorted by name and OpenImageIO may reorder them: map by name
          // when the file names its axes, else take the stored order (R, G, B = X, Y, Z).
          channel = XyzChannels(band.channel_names);
          // Allocated once the reader has checked the size against max_samples.
          scan.xyz_mm = UnfilledGrid(header.width, header.height);
        }
        if (band.width != scan.xyz_mm.width || y0 + band.height > scan.xyz_mm.height)
          return Error{path.string() + ": changed while it was read"};
        ParallelRows(band.height, [&](int y) {
          const float* in = band.pixels.data() + static_cast<size_t>(y) * band.width * 3;
          Vec3f* out = scan.xyz_mm.Row(y0 + y);
          for (int x = 0; x < band.width; ++x, in += 3)
            out[x] = Vec3f(in[channel[0]], in[channel[1]], in[channel[2]]);
        });
        return Status::Ok();
      });
  if (!read.ok()) return Error{read.message()};
  return scan;
}

// Orthographic grid looking along +Z, centred on the optical axis, rows downwards = +Y.
template <class DepthAt>  // float(size_t sample_index), NaN = missing
Scan ScanFromDepth(const fs::path& path, int width, int height, double pitch_mm,
                   const DepthAt& depth_mm_at) {
  Scan scan;
  scan.source = path.string();
  scan.xyz_mm = UnfilledGrid(width, height);
  const double cx = 0.5 * (width - 1), cy = 0.5 * (height - 1);
  ParallelRows(height, [&](int y) {
    Vec3f* out = scan.xyz_mm.Row(y);
    const auto py = static_cast<float>((y - cy) * pitch_mm);
    for (int x = 0; x < width; ++x) {
      const float z = depth_mm_at(scan.xyz_mm.Index(x, y));
      out[x] = std::isnan(z) ? Vec3f::Constant(kMissing)
                             : Vec3f(static_cast<float>((x - cx) * pitch_mm), py, z);
    }
  });
  return scan;
}

Result<Scan> ScanFromDepthImage(const fs::path& path, const FloatImage& image,
                                const ScanReadOptions& options) {
  const std::string name = path.string();
  if (image.integer_samples && image.bits_per_sample <= 8) {
    return Error{name + ": " + std::to_string(image.bits_per_sample) +
                 "-bit image cannot hold a height map (too few levels); use a 16-bit PNG/TIFF "
                 "with height_scale_mm or a float EXR/TIFF"};
  }
  if (image.integer_samples && image.bits_per_sample != 16) {
    return Error{name + ": " + std::to_string(image.bits_per_sample) +
                 "-bit integer depth is not supported; use 16-bit PNG/TIFF or float EXR/TIFF"};
  }
  if (options.pixel_pitch_mm <= 0) {
    return Error{name + ": 1-channel depth image needs pixel_pitch_mm (mm between samples)"};
  }
  if (!image.integer_samples) {
    return ScanFromDepth(path, image.width, image.height, options.pixel_pitch_mm,
                         [&](size_t i) { return image.pixels[i]; });
  }
  if (options.height_scale_mm <= 0) {
    return Error{name + ": 16-bit depth image needs height_scale_mm (mm per count)"};
  }
  return ScanFromDepth(path, image.width, image.height, options.pixel_pitch_mm, [&](size_t i) {
    const double count = std::round(static_cast<double>(image.pixels[i]) * kMaxCount16);
    if (count == 0) return kMissing;  // 0 = missing sample, by convention of these files
    return static_cast<float>(count * options.height_scale_mm + options.height_offset_mm);
  });
}

struct PlyHeader {
  std::string format;  // "ascii", "binary_little_endian" or "binary_big_endian"
  size_t vertices = 0;
  bool has_vertices = false;
  size_t lines_before_vertices = 0;  // ASCII: lines of the elements stored before the vertices
  std::vector<std::string> vertex_properties;  // in stored order
  bool vertex_has_list = false;
  std::streamoff body_offset = 0;
  int grid_width = 0, grid_height = 0;  // from "comment grid W H"; 0 = absent
};

// Reads just the header lines: OpenMesh does not expose comments, and the vertex count must be
// checked against the limits before anything is allocated.
Result<PlyHeader> ReadPlyHeader(const fs::path& path) {
  const std::string name = path.string();
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{name + ": unreadable, cannot open"};
  PlyHeader header;
  std::string line, element;
  for (size_t n = 0; n < kMaxPlyHeaderLines && std::getline(in, line); ++n) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (n == 0) {
      if (line != "ply") return Error{name + ": not a PLY file (no 'ply' magic line)"};
      continue;
    }
    std::istringstream words(line);
    std::string keyword, what;
    words >> keyword >> what;
    if (keyword == "end_header") {
      if (!header.has_vertices) return Error{name + ": PLY header has no 'element vertex' line"};
      if (header.format.empty()) return Error{name + ": PLY header has no 'format' line"};
      header.body_offset = in.tellg();
      return header;
    }
    if (keyword == "format") {
      if (what != "ascii" && what != "binary_little_endian" && what != "binary_big_endian") {
        return Error{name + ": unknown PLY format '" + what + "'"};
      }
      header.format = what;
    } else if (keyword == "comment" && what == "grid") {
      long long w = 0, h = 0;
      if (!(words >> w >> h) || w <= 0 || h <= 0 || w > (1 << 30) || h > (1 << 30)) {
        return Error{name + ": malformed '" + line + "' (expected 'comment grid WIDTH HEIGHT')"};
      }
      header.grid_width = static_cast<int>(w);
      header.grid_height = static_cast<int>(h);
    } else if (keyword == "element") {
      long long count = -1;
      if (!(words >> count) || count < 0) {
        return Error{name + ": malformed '" + line + "' in the PLY header"};
      }
      element = what;
      if (element == "vertex") {
        header.vertices = static_cast<size_t>(count);
        header.has_vertices = true;
      } else if (!header.has_vertices) {
        header.lines_before_vertices += static_cast<size_t>(count);
      }
    } else if (keyword == "property" && element == "vertex") {
      std::string property;
      if (what == "list") {
        header.vertex_has_list = true;
        std::string count_type, item_type;
        words >> count_type >> item_type;
      }
      words >> property;
      header.vertex_properties.push_back(property);
    }
  }
  return Error{name + ": truncated or corrupt PLY header (no 'end_header')"};
}

// One token of an ASCII PLY as a float; "nan" and "inf" are numbers here.
bool ParsePlyNumber(std::string_view token, float& value) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  const auto [end, error] = std::from_chars(token.data(), token.data() + token.size(), value);
  return error == std::errc() && end == token.data() + token.size();
}

// ASCII bodies are read here rather than by OpenMesh: its ASCII reader turns "nan" (our missing
// sample) and any malformed number into silent zeros for the rest of the file.
Status ReadAsciiPlyVertices(const fs::path& path, const PlyHeader& header, Grid<Vec3f>& xyz) {
  const std::string name = path.string();
  if (header.vertex_has_list) return Error{name + ": list properties on PLY vertices unsupported"};
  std::array<int, 3> column = {-1, -1, -1};
  for (size_t i = 0; i < header.vertex_properties.size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      if (header.vertex_properties[i] == std::string(1, static_cast<char>('x' + c))) {
        column[c] = static_cast<int>(i);
      }
    }
  }
  if (std::find(column.begin(), column.end(), -1) != column.end()) {
    return Error{name + ": PLY vertices have no x, y and z properties"};
  }
  std::ifstream in(path, std::ios::binary);
  in.seekg(header.body_offset);
  std::string line;
  for (size_t i = 0; i < header.lines_before_vertices; ++i) {
    if (!std::getline(in, line)) return Error{name + ": truncated PLY (elements before vertices)"};
  }
  const size_t columns = header.vertex_properties.size();
  for (size_t v = 0; v < xyz.size(); ++v) {
    if (!std::getline(in, line)) {
      return Error{name + ": truncated PLY, " + std::to_string(v) + " of " +
                   std::to_string(xyz.size()) + " vertices"};
    }
    std::string_view rest = line;
    size_t token_index = 0;
    while (true) {
      const size_t begin = rest.find_first_not_of(" \t\r");
      if (begin == std::string_view::npos) break;
      rest.remove_prefix(begin);
      const std::string_view token = rest.substr(0, rest.find_first_of(" \t\r"));
      rest.remove_prefix(token.size());
      for (int c = 0; c < 3; ++c) {
        if (static_cast<size_t>(column[c]) != token_index) continue;
        if (!ParsePlyNumber(token, xyz.data[v][c])) {
          return Error{name + ": corrupt PLY, vertex " + std::to_string(v) + ": '" +
                       std::string(token) + "' is not a number"};
        }
      }
      ++token_index;
    }
    if (token_index < columns) {
      return Error{name + ": corrupt PLY, vertex " + std::to_string(v) + " has " +
                   std::to_string(token_index) + " values, " + std::to_string(columns) +
                   " expected"};
    }
  }
  return Status::Ok();
}

Status ReadBinaryPlyVertices(const fs::path& path, Grid<Vec3f>& xyz) {
  const std::string name = path.string();
  OpenMesh::PolyMesh_ArrayKernelT<> cloud;
  bool read = false;
  try {
    OpenMesh::IO::Options io_options;
    read = OpenMesh::IO::read_mesh(cloud, name, io_options);
  } catch (const std::exception& e) {
    return Error{name + ": unreadable PLY (" + e.what() + ")"};
  }
  if (!read) return Error{name + ": unreadable or truncated PLY (OpenMesh could not read it)"};
  if (cloud.n_vertices() != xyz.size()) {
    return Error{name + ": wrong vertex count, read " + std::to_string(cloud.n_vertices()) +
                 " vertices for a " + Size(xyz.width, xyz.height) + " grid (truncated file?)"};
  }
  for (size_t i = 0; i < xyz.size(); ++i) {
    const auto& p = cloud.point(OpenMesh::VertexHandle(static_cast<int>(i)));
    xyz.data[i] = Vec3f(p[0], p[1], p[2]);
  }
  return Status::Ok();
}

Result<Scan> ReadPlyScan(const fs::path& path, const ScanReadOptions& options) {
  const std::string name = path.string();
  std::error_code ec;
  if (!fs::exists(path, ec)) return Error{name + ": no such file"};
  if (fs::is_regular_file(path, ec) && fs::file_size(path, ec) == 0 && !ec) {
    return Error{name + ": empty file (0 bytes)"};
  }
  auto header = ReadPlyHeader(path);
  if (!header.ok()) return header.error();

  int width = header->grid_width, height = header->grid_height;
  if (options.grid_width > 0 || options.grid_height > 0) {
    if (width > 0 && (width != options.grid_width || height != options.grid_height)) {
      return Error{name + ": grid " + Size(width, height) +
                   " in the file's 'comment grid' line "
                   "disagrees with the requested grid " +
                   Size(options.grid_width, options.grid_height)};
    }
    width = options.grid_width;
    height = options.grid_height;
  }
  if (width <= 0 || height <= 0) {
    return Error{name +
                 ": unknown grid size; add a 'comment grid WIDTH HEIGHT' header line or "
                 "give grid_width and grid_height"};
  }
  const auto samples = static_cast<uint64_t>(width) * static_cast<uint64_t>(height);
  if (samples > options.max_samples) {
    return Error{name + ": too large, grid " + Size(width, height) + " = " +
                 std::to_string(samples) + " samples exceeds the limit of " +
                 std::to_string(options.max_samples)};
  }
  if (header->vertices != samples) {
    return Error{name + ": wrong vertex count, " + std::to_string(header->vertices) +
                 " vertices for a " + Size(width, height) + " grid (" + std::to_string(samples) +
                 " expected)"};
  }

  Scan scan;
  scan.source = name;
  scan.xyz_mm = Grid<Vec3f>(width, height, Vec3f::Constant(kMissing));
  const Status read = header->format == "ascii" ? ReadAsciiPlyVertices(path, *header, scan.xyz_mm)
                                                : ReadBinaryPlyVertices(path, scan.xyz_mm);
  if (!read.ok()) return Error{read.message()};
  return scan;
}

Result<Scan> ReadImageScan(const fs::path& path, const ScanReadOptions& options) {
  const auto header = ReadImageHeader(path);
  if (!header.ok()) return header.error();
  if (header->channels == 3) return ReadXyzImageScan(path, *header, options.max_samples);
  auto image = ReadImage(path, options.max_samples);
  if (!image.ok()) return image.error();
  if (image->channels == 1) return ScanFromDepthImage(path, *image, options);
  return Error{path.string() + ": " + std::to_string(image->channels) +
               " channels, expected 3 (X, Y, Z in mm) or 1 (depth in mm)"};
}

Status ApplyMask(const fs::path& mask_path, Scan& scan, size_t max_samples) {
  auto mask = ReadImage(mask_path, max_samples);
  if (!mask.ok()) return mask.error();
  if (mask->width != scan.xyz_mm.width || mask->height != scan.xyz_mm.height) {
    return Error{mask_path.string() + ": wrong size, mask is " + Size(mask->width, mask->height) +
                 " but scan " + scan.source + " is " + Size(scan.xyz_mm.width, scan.xyz_mm.height)};
  }
  const int channels = mask->channels;
  ParallelRows(scan.xyz_mm.height, [&](int y) {
    const float* m = mask->pixels.data() + scan.xyz_mm.Index(0, y) * channels;
    Vec3f* p = scan.xyz_mm.Row(y);
    for (int x = 0; x < scan.xyz_mm.width; ++x, m += channels) {
      if (*std::max_element(m, m + channels) <= 0) p[x] = Vec3f::Constant(kMissing);
    }
  });
  return Status::Ok();
}

bool IsPly(const fs::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == ".ply";
}

std::string CheckNonNegative(const char* name, double value) {
  if (std::isfinite(value) && value >= 0) return {};
  return std::string(name) + " must be finite and >= 0, got " + std::to_string(value);
}

}  // namespace

Status ScanReadOptions::Validate() const {
  for (const std::string& problem : {CheckNonNegative("pixel_pitch_mm", pixel_pitch_mm),
                                     CheckNonNegative("height_scale_mm", height_scale_mm)}) {
    if (!problem.empty()) return Error{problem};
  }
  if (!std::isfinite(height_offset_mm)) {
    return Error{"height_offset_mm must be finite, got " + std::to_string(height_offset_mm)};
  }
  if (grid_width < 0 || grid_height < 0 || (grid_width > 0) != (grid_height > 0)) {
    return Error{"grid_width and grid_height must both be > 0 or both 0, got " +
                 std::to_string(grid_width) + " and " + std::to_string(grid_height)};
  }
  if (max_samples == 0) return Error{"max_samples must be > 0"};
  return Status::Ok();
}

Result<Scan> ReadScan(const fs::path& path, const ScanReadOptions& options) {
  if (const Status valid = options.Validate(); !valid.ok()) {
    return Error{path.string() + ": " + valid.message()};
  }
  Result<Scan> scan = IsPly(path) ? ReadPlyScan(path, options) : ReadImageScan(path, options);
  if (!scan.ok() || options.mask.empty()) return scan;
  if (const Status masked = ApplyMask(options.mask, *scan, options.max_samples); !masked.ok()) {
    return Error{masked.message()};
  }
  return scan;
}

Status WriteScanExr(const fs::path& path, const Scan& scan) {
  if (scan.xyz_mm.empty()) return Error{path.string() + ": cannot write an empty scan"};
  ImageMetadata metadata = {
      {"digitize:content", "scan xyz"}, {"digitize:units", "mm"}, {"digitize:frame", "scan"}};
  if (!scan.source.empty()) metadata["digitize:source"] = scan.source;
  return WriteFloatExr(path, scan.xyz_mm, {"X", "Y", "Z"}, metadata);
}

}  // namespace digitize
