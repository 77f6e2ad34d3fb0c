// Preprocess in tiles (preprocess_tiled.h).
#include "digitize/preprocess_tiled.h"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <memory>

#include "digitize/image_io.h"
#include "digitize/scan_io.h"
#include "preprocess_internal.h"

namespace digitize {
namespace {

namespace fs = std::filesystem;
using preprocess_internal::Clock;

constexpr size_t kCanvasPassSamples = size_t{1} << 24;

using preprocess_internal::Format;
using preprocess_internal::MaskPngCode;
using preprocess_internal::SecondsSince;

Result<std::array<int, 3>> XyzOf(const fs::path& path, const FloatImage& image) {
  if (image.channels != 3 || image.integer_samples)
    return Error{path.string() +
                 ": a tiled preprocess reads 3-channel float XYZ scans (EXR or TIFF, mm); this "
                 "file has " +
                 std::to_string(image.channels) + (image.integer_samples ? " integer" : "") +
                 " channel(s): preprocess it whole, or write it as XYZ first"};
  return XyzChannels(image.channel_names);
}

// Every stride-th sample of every stride-th row, read a band at a time, and the 3D distance of
// each to the full-resolution sample right of it (NaN where either is missing): the scan's
// spacing, which the strided samples alone see stride times over.
struct StridedScan {
  Scan scan;
  Grid<float> next_mm;
};

Result<StridedScan> ReadStridedScan(const fs::path& path, int stride, size_t max_samples) {
  StridedScan out;
  Scan& scan = out.scan;
  std::vector<float>& next = out.next_mm.data;
  scan.source = path.string();
  std::array<int, 3> channel{};
  const Status read =
      ReadImageInBands(path, max_samples, 256, [&](const FloatImage& band, int y0) -> Status {
        if (y0 == 0) {
          auto xyz = XyzOf(path, band);
          if (!xyz.ok()) return xyz.error();
          channel = *xyz;
          scan.xyz_mm.width = (band.width + stride - 1) / stride;
        }
        for (int y = (stride - y0 % stride) % stride; y < band.height; y += stride) {
          const float* in = band.pixels.data() + static_cast<size_t>(y) * band.width * 3;
          for (int x = 0; x < band.width; x += stride) {
            const float* p = in + static_cast<size_t>(x) * 3;
            const Vec3f here(p[channel[0]], p[channel[1]], p[channel[2]]);
            scan.xyz_mm.data.push_back(here);
            float d = std::numeric_limits<float>::quiet_NaN();
            if (x + 1 < band.width) {
              const float* q = p + 3;
              d = (Vec3f(q[channel[0]], q[channel[1]], q[channel[2]]) - here).norm();
            }
            next.push_back(d);
          }
          ++scan.xyz_mm.height;
        }
        return Status::Ok();
      });
  if (!read.ok()) return Error{read.message()};
  out.next_mm.width = scan.xyz_mm.width;
  out.next_mm.height = scan.xyz_mm.height;
  return out;
}

// The median of the canvas samples' distances to their right neighbours (as the whole
// preprocess measures the spacing on its full-resolution scan), over at most ~10^6 of them.
double StridedSpacing(const StridedScan& s, const Grid<uint8_t>& mask) {
  size_t count = 0;
  for (size_t i = 0; i < mask.data.size(); ++i) count += mask.data[i] != 0;
  const size_t step = std::max<size_t>(1, count / 1000000);
  std::vector<float> d;
  for (size_t i = 0, k = 0; i < mask.data.size(); ++i) {
    if (!mask.data[i] || k++ % step != 0) continue;
    const float v = s.next_mm.data[i];
    if (std::isfinite(v) && v > 0 && v < 1e6f) d.push_back(v);
  }
  if (d.empty()) return 0;
  const auto mid = d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2);
  std::nth_element(d.begin(), mid, d.end());
  return *mid;
}

// Full-resolution samples [x0, x0 + w) x [y0, y0 + h) of the scan, through the cache.
Result<Scan> ReadScanRect(const fs::path& path, ImageRegionReader& reader, int x0, int y0, int w,
                          int h) {
  auto image = reader.Read(path, x0, y0, w, h);
  if (!image.ok()) return image.error();
  auto xyz = XyzOf(path, *image);
  if (!xyz.ok()) return xyz.error();
  const std::array<int, 3> c = *xyz;
  Scan scan;
  scan.source = path.string();
  scan.xyz_mm = Grid<Vec3f>(w, h);
  for (size_t i = 0; i < scan.xyz_mm.data.size(); ++i) {
    const float* p = image->pixels.data() + 3 * i;
    scan.xyz_mm.data[i] = Vec3f(p[c[0]], p[c[1]], p[c[2]]);
  }
  return scan;
}

// The canvas pass's mask at a full-resolution sample: its nearest strided sample.
uint8_t StridedMask(const Grid<uint8_t>& mask, int stride, int x, int y) {
  const int sx = std::min(mask.width - 1, (x + stride / 2) / stride);
  const int sy = std::min(mask.height - 1, (y + stride / 2) / stride);
  return mask(sx, sy);
}

struct Tile {
  int cx0, cy0, cx1, cy1;  // core [cx0, cx1) x [cy0, cy1), canvas texels
  int wx0, wy0, wx1, wy1;  // window: the core and its halo, inside the grid
  int sx0 = std::numeric_limits<int>::max(), sy0 = std::numeric_limits<int>::max();
  int sx1 = -1, sy1 = -1;  // scan samples reaching the window (inclusive bounds), from the pass
};

struct TileGrid {
  int w = 0, h = 0, core = 0, halo = 0, nx = 0, ny = 0;
  std::vector<Tile> tiles;  // row-major
};

TileGrid CutTiles(int w, int h, int core, int halo) {
  TileGrid grid{w, h, core, halo, (w + core - 1) / core, (h + core - 1) / core, {}};
  for (int iy = 0; iy < grid.ny; ++iy)
    for (int ix = 0; ix < grid.nx; ++ix) {
      Tile t{};
      t.cx0 = ix * core, t.cy0 = iy * core;
      t.cx1 = std::min(w, t.cx0 + core), t.cy1 = std::min(h, t.cy0 + core);
      t.wx0 = std::max(0, t.cx0 - halo), t.wy0 = std::max(0, t.cy0 - halo);
      t.wx1 = std::min(w, t.cx1 + halo), t.wy1 = std::min(h, t.cy1 + halo);
      t.sx0 = t.sy0 = std::numeric_limits<int>::max();
      t.sx1 = t.sy1 = -1;
      grid.tiles.push_back(t);
    }
  return grid;
}

// Which scan samples each tile's window needs: the bounding rectangle of the strided canvas
// samples landing within `margin` texels of the window, grown by a stride and a quad.
void FindScanRects(const Scan& strided, const Grid<uint8_t>& mask, int stride,
                   const RigidTransform& canvas_from_scan, double pitch, double margin, int scan_w,
                   int scan_h, TileGrid& grid) {
  const Mat3d& r = canvas_from_scan.rotation;
  const Vec3d& t = canvas_from_scan.translation;
  const int reach = grid.halo + static_cast<int>(std::ceil(margin));
  for (int y = 0; y < strided.xyz_mm.height; ++y)
    for (int x = 0; x < strided.xyz_mm.width; ++x) {
      const Vec3f& p = strided.xyz_mm(x, y);
      if (!mask(x, y) || !p.allFinite()) continue;
      const Vec3d q = r * p.cast<double>() + t;
      const double tx = q.x() / pitch - 0.5, ty = grid.h - q.y() / pitch - 0.5;
      const int ix0 = std::max(0, static_cast<int>(std::floor((tx - reach) / grid.core)));
      const int ix1 = std::min(grid.nx - 1, static_cast<int>(std::floor((tx + reach) / grid.core)));
      const int iy0 = std::max(0, static_cast<int>(std::floor((ty - reach) / grid.core)));
      const int iy1 = std::min(grid.ny - 1, static_cast<int>(std::floor((ty + reach) / grid.core)));
      for (int iy = iy0; iy <= iy1; ++iy)
        for (int ix = ix0; ix <= ix1; ++ix) {
          Tile& tile = grid.tiles[static_cast<size_t>(iy) * grid.nx + ix];
          if (tx < tile.wx0 - margin || tx > tile.wx1 - 1 + margin || ty < tile.wy0 - margin ||
              ty > tile.wy1 - 1 + margin)
            continue;
          tile.sx0 = std::min(tile.sx0, x * stride), tile.sx1 = std::max(tile.sx1, x * stride);
          tile.sy0 = std::min(tile.sy0, y * stride), tile.sy1 = std::max(tile.sy1, y * stride);
        }
    }
  for (Tile& tile : grid.tiles) {
    if (tile.sx1 < 0) continue;
    tile.sx0 = std::max(0, tile.sx0 - stride - 1), tile.sy0 = std::max(0, tile.sy0 - stride - 1);
    tile.sx1 = std::min(scan_w - 1, tile.sx1 + stride + 1);
    tile.sy1 = std::min(scan_h - 1, tile.sy1 + stride + 1);
  }
}

// The canvas of a tile's window: the same rotation, the origin moved so the window's texels are
// the grid's, an extent of exactly its texels; the mask over the scan rectangle `xyz`: the
// canvas pass's where its strided samples around agree; where they do not (the outline, within
// a stride of it), a sample is canvas when it lies inside the outline rectangle and below half
// the frame's lowest side (a frame sample grazed at the edge is no canvas), as the whole
// preprocess's outline mask decides (canvas_outline.cpp); a missing one takes the nearest.
CanvasResult TileCanvas(const CanvasResult& canvas, int stride, const Tile& tile, int grid_h,
                        double pitch, const Grid<Vec3f>& xyz) {
  CanvasResult c;
  const int ww = tile.wx1 - tile.wx0, wh = tile.wy1 - tile.wy0;
  c.canvas_from_scan.rotation = canvas.canvas_from_scan.rotation;
  c.canvas_from_scan.translation =
      canvas.canvas_from_scan.translation -
      Vec3d(tile.wx0 * pitch, static_cast<double>(grid_h - tile.wy0 - wh) * pitch, 0);
  c.extent_mm = Eigen::Vector2d((ww - 0.5) * pitch, (wh - 0.5) * pitch);
  const int rw = tile.sx1 - tile.sx0 + 1, rh = tile.sy1 - tile.sy0 + 1;
  c.mask_scan = Grid<uint8_t>(rw, rh);
  const Grid<uint8_t>& m = canvas.mask_scan;
  double frame_z = std::numeric_limits<double>::infinity();
  for (int side = 0; side < 4; ++side)
    if (canvas.frame.raise_mm[side] > 0)
      frame_z = std::min(frame_z, 0.5 * canvas.frame.raise_mm[side]);
  const Mat3d& r = canvas.canvas_from_scan.rotation;
  const Vec3d& t = canvas.canvas_from_scan.translation;
  const Eigen::Vector2d extent = canvas.extent_mm;
  for (int y = 0; y < rh; ++y)
    for (int x = 0; x < rw; ++x) {
      const int gx = tile.sx0 + x, gy = tile.sy0 + y;
      const int sx = std::min(m.width - 1, gx / stride), sy = std::min(m.height - 1, gy / stride);
      const int sx1 = std::min(m.width - 1, sx + 1), sy1 = std::min(m.height - 1, sy + 1);
      const int sum = (m(sx, sy) != 0) + (m(sx1, sy) != 0) + (m(sx, sy1) != 0) + (m(sx1, sy1) != 0);
      const Vec3f& p = xyz(x, y);
      if (stride == 1 || sum == 0 || sum == 4 || !canvas.outline_fitted || !p.allFinite()) {
        c.mask_scan(x, y) = StridedMask(m, stride, gx, gy);
        continue;
      }
      const Vec3d q = r * p.cast<double>() + t;
      c.mask_scan(x, y) = q.x() >= 0 && q.x() <= extent.x() && q.y() >= 0 && q.y() <= extent.y() &&
                          std::fabs(q.z()) < frame_z;
    }
  return c;
}

// A row of tiles' cores.
struct Strip {
  int rows = 0;
  std::vector<float> height, normals;
  std::vector<TexelState> state;
  std::vector<uint8_t> mask;  // mask.png's codes
};

// The canvas's heights and states between the two passes: a raw file beside the outputs, gone
// when the store is, so a tile's window of them costs its rows' reads, not the decoding of the
// compressed maps around it (read back through the image cache, the pass took 69 s instead of
// 49 s at 16k texels).
class FieldStore {
 public:
  FieldStore(fs::path path, int w, int h) : path_(std::move(path)), w_(w), h_(h) {
    file_ = std::fopen(path_.c_str(), "w+b");
  }
  ~FieldStore() {
    if (file_) std::fclose(file_);
    std::error_code ec;
    fs::remove(path_, ec);
  }
  FieldStore(const FieldStore&) = delete;
  FieldStore& operator=(const FieldStore&) = delete;
  bool ok() const { return file_ != nullptr; }

  Status WriteRows(int y0, const Strip& strip) {
    const size_t n = static_cast<size_t>(w_) * strip.rows;
    if (!Seek(HeightOffset(0, y0)) ||
        std::fwrite(strip.height.data(), sizeof(float), n, file_) != n ||
        !Seek(StateOffset(0, y0)) || std::fwrite(strip.state.data(), 1, n, file_) != n)
      return Failed("write");
    return Status::Ok();
  }

  // The window [x0, x0 + ww) x [y0, y0 + wh) into `into`'s grids.
  Status ReadWindow(int x0, int y0, int ww, int wh, HeightField& into) {
    into.height_mm = Grid<float>(ww, wh);
    into.state = Grid<TexelState>(ww, wh);
    for (int y = 0; y < wh; ++y) {
      const size_t n = static_cast<size_t>(ww);
      if (!Seek(HeightOffset(x0, y0 + y)) ||
          std::fread(into.height_mm.Row(y), sizeof(float), n, file_) != n ||
          !Seek(StateOffset(x0, y0 + y)) || std::fread(into.state.Row(y), 1, n, file_) != n)
        return Failed("read");
    }
    return Status::Ok();
  }

 private:
  off_t HeightOffset(int x, int y) const {
    return static_cast<off_t>((static_cast<int64_t>(y) * w_ + x) * 4);
  }
  off_t StateOffset(int x, int y) const {
    return static_cast<off_t>(static_cast<int64_t>(w_) * h_ * 4 + static_cast<int64_t>(y) * w_ + x);
  }
  bool Seek(off_t at) { return fseeko(file_, at, SEEK_SET) == 0; }
  Status Failed(const char* what) {
    return Error{path_.string() + ": " + what + " failed (" + std::strerror(errno) +
                 "): the tiled preprocess keeps 5 bytes a texel there between its passes"};
  }

  fs::path path_;
  int w_, h_;
  std::FILE* file_ = nullptr;
};

}  // namespace

Status TiledPreprocessOptions::Validate() const {
  if (tile_texels < 64 || tile_texels > 16384)
    return Error{"tile_texels must be in [64, 16384], got " + std::to_string(tile_texels)};
  if (halo_texels < 0 || halo_texels > 4096)
    return Error{"halo_texels must be in [0, 4096] (0 = from the options), got " +
                 std::to_string(halo_texels)};
  if (canvas_stride < 0 || canvas_stride > 64)
    return Error{"canvas_stride must be in [0, 64] (0 = automatic), got " +
                 std::to_string(canvas_stride)};
  if (cache_mb < 64) return Error{"cache_mb must be >= 64, got " + std::to_string(cache_mb)};
  return Status::Ok();
}

int TiledPreprocessHalo(const PreprocessOptions& options, double pitch_mm) {
  const double hole_diameter = 2.0 * std::sqrt(options.resample.max_hole_area_mm2 / kPi);
  const double speck_diameter = 2.0 * std::sqrt(options.relief.min_component_area_mm2 / kPi);
  const double texels = 2.0 * std::max(hole_diameter, speck_diameter) / pitch_mm;
  const int n = std::max(1, options.relief.cell_px);
  const int halo = std::max(32, static_cast<int>(std::ceil(std::min(texels, 4096.0))));
  return (halo + n - 1) / n * n;
}

Result<PreprocessResult> PreprocessScanTiled(const fs::path& scan_path,
                                             const PreprocessOptions& options,
                                             const TiledPreprocessOptions& tiled,
                                             const fs::path& dir,
                                             const std::vector<std::string>& inputs,
                                             const ProgressCallback& progress) {
  const std::string src = scan_path.string();
  if (Status s = options.Validate(); !s.ok()) return Error{s.message()};
  if (Status s = tiled.Validate(); !s.ok()) return Error{"tiled preprocess: " + s.message()};
  const auto start = Clock::now();
  PreprocessResult result;
  auto step = [&](const char* name, Clock::time_point t0, std::string line) {
    result.steps.push_back({name, SecondsSince(t0), std::move(line)});
  };
  auto header = ReadImageHeader(scan_path);
  if (!header.ok()) return header.error();
  const int sw = header->width, sh = header->height;
  if (header->channels != 3 || header->integer_samples)
    return Error{src +
                 ": a tiled preprocess reads 3-channel float XYZ scans (EXR or TIFF, mm); "
                 "preprocess it whole, or write it as XYZ first"};
  const uint64_t samples = static_cast<uint64_t>(sw) * static_cast<uint64_t>(sh);
  const int stride = tiled.canvas_stride > 0
                         ? tiled.canvas_stride
                         : std::max(1, static_cast<int>(std::ceil(std::sqrt(
                                           static_cast<double>(samples) / kCanvasPassSamples))));

  // ---- 1. The canvas from every stride-th sample.
  auto t0 = Clock::now();
  ReportProgress(progress, "canvas", 0.0);
  CanvasResult canvas;
  double spacing = 0;
  auto strided = ReadStridedScan(scan_path, stride, size_t{1} << 36);
  if (!strided.ok()) return strided.error();
  result.sanitize = SanitizeScan(strided->scan, options.sanitize);
  result.merge.exposures = 1;
  {
    auto found = ExtractCanvas(strided->scan, options.canvas);
    if (!found.ok()) return found.error();
    canvas = std::move(found).value();
  }
  spacing = StridedSpacing(*strided, canvas.mask_scan);
  const double pitch = options.resample.pitch_mm > 0 ? options.resample.pitch_mm : spacing;
  if (!(pitch > 0) || !std::isfinite(pitch))
    return Error{src +
                 ": no two adjacent canvas samples to measure the scan spacing; give "
                 "pitch_mm"};
  const double gw = std::ceil(canvas.extent_mm.x() / pitch);
  const double gh = std::ceil(canvas.extent_mm.y() / pitch);
  if (gw > options.resample.max_texels_per_side || gh > options.resample.max_texels_per_side ||
      gw < 1 || gh < 1)
    return Error{src + ": a " + FormatNumber(canvas.extent_mm.x()) + " x " +
                 FormatNumber(canvas.extent_mm.y()) + " mm canvas at pitch " + FormatNumber(pitch) +
                 " mm needs " + FormatNumber(gw) + " x " + FormatNumber(gh) +
                 " texels, more than " + std::to_string(options.resample.max_texels_per_side) +
                 " per side (max_texels_per_side); raise pitch_mm"};
  const int w = static_cast<int>(gw), h = static_cast<int>(gh);
  const int cell = options.relief.cell_px;
  const int core = (tiled.tile_texels + cell - 1) / cell * cell;
  int halo = tiled.halo_texels > 0 ? tiled.halo_texels : TiledPreprocessHalo(options, pitch);
  halo = (halo + cell - 1) / cell * cell;
  TileGrid grid = CutTiles(w, h, core, halo);
  FindScanRects(strided->scan, canvas.mask_scan, stride, canvas.canvas_from_scan, pitch,
                stride * std::max(spacing, pitch) / pitch + 2.0, sw, sh, grid);
  strided = StridedScan{};  // the tiles read their own samples
  step(
      "canvas", t0,
      Format("canvas (%s): %.1f x %.1f mm, plane RMS %.4f mm, noise sigma "
             "%.4f mm; %s; %dx%d texels at %.4f mm in %d tile(s) of %d + %d halo",
             stride == 1 ? "every scan sample"
                         : Format("one scan sample in %d x %d", stride, stride).c_str(),
             canvas.extent_mm.x(), canvas.extent_mm.y(), canvas.plane_rms_mm, canvas.noise_sigma_mm,
             canvas.outline_fitted ? "axes and mask from the canvas outline"
                                   : ("outline not used (" + canvas.outline_note + ")").c_str(),
             w, h, pitch, static_cast<int>(grid.tiles.size()), core, halo) +
          [&] {
            std::string text;
            for (const std::string& warning : canvas.warnings) text += "; WARNING: " + warning;
            return text;
          }());

  const double tiles_total = static_cast<double>(grid.tiles.size());

  // ---- 2. Resample, tile by tile; height.exr and mask.png a row of tiles at a time.
  t0 = Clock::now();
  float max_h = -std::numeric_limits<float>::infinity();
  size_t empty_tiles = 0;
  double read_seconds = 0;                // of the scan's rectangles, through the cache
  size_t state_counts[4] = {0, 0, 0, 0};  // by TexelState
  // The scan's parts, cached while the tiles of a row share them; gone before the second pass.
  auto reader = std::make_unique<ImageRegionReader>(tiled.cache_mb);
  FieldStore store(dir / ".field.tmp", w, h);
  if (!store.ok())
    return Error{(dir / ".field.tmp").string() + ": cannot create (" + std::strerror(errno) + ")"};
  {
    auto height_out = BandImageWriter::Open(dir / "height.exr", w, h, {"Y"},
                                            preprocess_internal::HeightMapMetadata(pitch));
    if (!height_out.ok()) return height_out.error();
    auto mask_out = BandImageWriter::Open(dir / "mask.png", w, h, {});
    if (!mask_out.ok()) return mask_out.error();
    Strip strip;
    for (int iy = 0; iy < grid.ny; ++iy) {
      const Tile& first = grid.tiles[static_cast<size_t>(iy) * grid.nx];
      strip.rows = first.cy1 - first.cy0;
      strip.height.assign(static_cast<size_t>(w) * strip.rows, 0.f);
      strip.state.assign(static_cast<size_t>(w) * strip.rows, TexelState::kOutside);
      for (int ix = 0; ix < grid.nx; ++ix) {
        const Tile& tile = grid.tiles[static_cast<size_t>(iy) * grid.nx + ix];
        ReportProgress(progress, "resample", (0.1 + 0.6 * (iy * grid.nx + ix) / tiles_total));
        if (tile.sx1 < 0) {  // no canvas sample reaches it: outside, as the whole's grid there
          ++empty_tiles;
          continue;
        }
        const auto read_start = Clock::now();
        auto sub = ReadScanRect(scan_path, *reader, tile.sx0, tile.sy0, tile.sx1 - tile.sx0 + 1,
                                tile.sy1 - tile.sy0 + 1);
        if (!sub.ok()) return sub.error();
        read_seconds += SecondsSince(read_start);
        SanitizeScan(*sub, options.sanitize);
        ResampleOptions ro = options.resample;
        ro.pitch_mm = pitch;
        ro.scan_spacing_mm = spacing;
        ResampleStats rs;
        CanvasResult tile_canvas = TileCanvas(canvas, stride, tile, h, pitch, sub->xyz_mm);
        auto field = ResampleToCanvasGrid(std::move(*sub), tile_canvas, ro, &rs);
        if (!field.ok()) {  // no triangle in reach: nothing measured there
          ++empty_tiles;
          continue;
        }
        result.resample.holes_filled += rs.holes_filled;
        result.resample.holes_unfilled += rs.holes_unfilled;
        result.resample.triangles_drawn += rs.triangles_drawn;
        result.resample.triangles_skipped += rs.triangles_skipped;
        for (int y = tile.cy0; y < tile.cy1; ++y) {
          const float* hr = field->height_mm.Row(y - tile.wy0) + (tile.cx0 - tile.wx0);
          const TexelState* sr = field->state.Row(y - tile.wy0) + (tile.cx0 - tile.wx0);
          const size_t o = static_cast<size_t>(y - tile.cy0) * w + tile.cx0;
          for (int x = 0; x < tile.cx1 - tile.cx0; ++x) {
            strip.height[o + x] = hr[x];
            strip.state[o + x] = sr[x];
            if (HasHeight(sr[x]) && std::isfinite(hr[x])) max_h = std::max(max_h, hr[x]);
          }
        }
      }
      strip.mask.resize(strip.state.size());
      for (size_t i = 0; i < strip.state.size(); ++i) {
        strip.mask[i] = MaskPngCode(strip.state[i]);
        ++state_counts[static_cast<int>(strip.state[i])];
      }
      if (Status s = store.WriteRows(first.cy0, strip); !s.ok()) return Error{s.message()};
      if (Status s = (*height_out)->Write(strip.height.data(), strip.rows); !s.ok())
        return Error{s.message()};
      if (Status s = (*mask_out)->Write(strip.mask.data(), strip.rows); !s.ok())
        return Error{s.message()};
    }
    if (Status s = (*height_out)->Close(); !s.ok()) return Error{s.message()};
    if (Status s = (*mask_out)->Close(); !s.ok()) return Error{s.message()};
  }
  reader.reset();
  result.resample.texels = static_cast<size_t>(w) * h;
  result.resample.outside = state_counts[static_cast<int>(TexelState::kOutside)];
  result.resample.measured = state_counts[static_cast<int>(TexelState::kMeasured)];
  result.resample.filled = state_counts[static_cast<int>(TexelState::kFilled)];
  result.resample.unfilled = state_counts[static_cast<int>(TexelState::kUnfilled)];
  if (result.resample.measured == 0)
    return Error{src +
                 ": no canvas texel could be measured (every tile's triangles were skipped "
                 "or missing)"};
  const ResampleStats& rs = result.resample;
  step("resample", t0,
       Format("resample: %dx%d texels at %.4f mm in %d tile(s) (%zu without canvas samples; "
              "%.1f s reading the scan); %zu measured, %zu filled, %zu unfilled",
              w, h, pitch, static_cast<int>(grid.tiles.size()), empty_tiles, read_seconds,
              rs.measured, rs.filled, rs.unfilled));

  // ---- 3. Relief with the canvas's H, and normals: each tile's window read back.
  t0 = Clock::now();
  const ReliefOptions relief_options = PreprocessReliefOptions(options, canvas.noise_sigma_mm);
  ReliefResult& relief = result.relief;
  relief.cell_px = cell;
  relief.max_height_mm = max_h;
  {
    auto normals_out = BandImageWriter::Open(dir / "normals.exr", w, h, {"R", "G", "B"},
                                             preprocess_internal::NormalMapMetadata(pitch));
    if (!normals_out.ok()) return normals_out.error();
    Strip strip;
    for (int iy = 0; iy < grid.ny; ++iy) {
      const Tile& first = grid.tiles[static_cast<size_t>(iy) * grid.nx];
      strip.rows = first.cy1 - first.cy0;
      strip.normals.assign(static_cast<size_t>(w) * strip.rows * 3, 0.f);
      for (int ix = 0; ix < grid.nx; ++ix) {
        const Tile& tile = grid.tiles[static_cast<size_t>(iy) * grid.nx + ix];
        ReportProgress(progress, "relief and normals",
                       (0.7 + 0.3 * (iy * grid.nx + ix) / tiles_total));
        const int ww = tile.wx1 - tile.wx0, wh = tile.wy1 - tile.wy0;
        HeightField win;
        win.pitch_mm = pitch;
        win.frame = canvas.frame;
        win.window = TexelWindow{tile.wx0, tile.wy0, w, h, max_h};
        if (Status s = store.ReadWindow(tile.wx0, tile.wy0, ww, wh, win); !s.ok())
          return Error{s.message()};
        // The window takes the canvas's H, so every tile's delta0 is the canvas's (0 for a flat
        // canvas, and in a window with no height at all).
        const ReliefResult r = ClassifyRelief(win, relief_options);
        relief.delta0_mm = std::max(relief.delta0_mm, r.delta0_mm);
        for (ReliefBox b : r.boxes) {
          b.x0 += tile.wx0, b.y0 += tile.wy0, b.u_max += tile.wx0, b.v_max += tile.wy0;
          if (b.x0 >= tile.cx0 && b.x0 < tile.cx1 && b.y0 >= tile.cy0 && b.y0 < tile.cy1)
            relief.boxes.push_back(b);
        }
        for (int y = tile.cy0; y < tile.cy1; ++y)
          for (int x = tile.cx0; x < tile.cx1; ++x)
            relief.texels_above += r.valid(x - tile.wx0, y - tile.wy0);
        relief.components_kept += r.components_kept;
        relief.components_removed += r.components_removed;
        const Grid<Vec3f> normals = ComputeNormals(win);
        for (int y = tile.cy0; y < tile.cy1; ++y) {
          const Vec3f* in = normals.Row(y - tile.wy0) + (tile.cx0 - tile.wx0);
          float* out =
              strip.normals.data() + (static_cast<size_t>(y - tile.cy0) * w + tile.cx0) * 3;
          for (int x = 0; x < tile.cx1 - tile.cx0; ++x)
            for (int k = 0; k < 3; ++k) out[3 * x + k] = in[x][k];
        }
      }
      if (Status s = (*normals_out)->Write(strip.normals.data(), strip.rows); !s.ok())
        return Error{s.message()};
    }
    if (Status s = (*normals_out)->Close(); !s.ok()) return Error{s.message()};
  }
  std::sort(relief.boxes.begin(), relief.boxes.end(), [](const ReliefBox& a, const ReliefBox& b) {
    return a.y0 != b.y0 ? a.y0 < b.y0 : a.x0 < b.x0;
  });
  step("relief", t0,
       Format("relief and normals: max height %.3f mm, delta0 %.3f mm; %zu texels above; %zu "
              "boxes of %dx%d texels",
              relief.max_height_mm, relief.delta0_mm, relief.texels_above, relief.boxes.size(),
              cell, cell));

  // ---- 4. The rest of the folder.
  result.tiled = PreprocessResult::Tiled{
      core,   halo, stride, static_cast<int>(grid.tiles.size()), static_cast<int>(empty_tiles),
      spacing};
  result.canvas = std::move(canvas);
  result.field.pitch_mm = pitch;
  result.field.frame = result.canvas.frame;
  result.field.window = TexelWindow{0, 0, w, h, max_h};
  result.total_seconds = SecondsSince(start);
  if (Status s = WritePreprocessSideFiles(dir, result, options, inputs); !s.ok())
    return Error{s.message()};
  ReportProgress(progress, "done", 1.0);
  return result;
}

}  // namespace digitize
