// Version 3 texture packs: the streamed writer (pack_tiled.h, WriteTiledPack). Through OpenEXR
// itself, not OpenImageIO: OpenImageIO writes one mip level after the other, so a level could
// only be written once the whole level above it was in memory; OpenEXR's tiled parts take any
// tile of any level in any order (RANDOM_Y), which is what lets each level follow its band.
#include "digitize/pack_tiled.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfMultiPartOutputFile.h>
#include <OpenEXR/ImfOutputPart.h>
#include <OpenEXR/ImfPartType.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfThreading.h>
#include <OpenEXR/ImfTiledOutputPart.h>
#include <OpenImageIO/hash.h>

#include <algorithm>
#include <bit>
#include <cstring>

#include "checked_output.h"
#include "digitize/image_io.h"
#include "pack_exr.h"

namespace digitize {

namespace fs = std::filesystem;
using namespace pack_exr;

Status CheckPackTileSize(int tile_size) {
  if (tile_size < kMinPackTileSize || tile_size > kMaxPackTileSize ||
      !std::has_single_bit(static_cast<unsigned>(tile_size)))
    return Error{"tile_size must be a power of two in [" + std::to_string(kMinPackTileSize) + ", " +
                 std::to_string(kMaxPackTileSize) + "], got " + std::to_string(tile_size)};
  return Status::Ok();
}

std::vector<std::array<int, 2>> PyramidLevelSizes(int w, int h) {
  std::vector<std::array<int, 2>> levels;
  if (w <= 0 || h <= 0) return levels;
  levels.push_back({w, h});
  while (w > 1 || h > 1) {
    w = (w + 1) / 2;
    h = (h + 1) / 2;
    levels.push_back({w, h});
  }
  return levels;
}

namespace {

// Texels [x0, x0 + w) x [y0, y0 + h) of a grid.
template <class T>
Grid<T> GridBlock(const Grid<T>& g, int x0, int y0, int w, int h) {
  Grid<T> out;
  out.width = w;
  out.height = h;
  out.data.reserve(static_cast<size_t>(w) * static_cast<size_t>(h));
  for (int y = y0; y < y0 + h; ++y) {
    const auto row = g.data.begin() + static_cast<ptrdiff_t>(static_cast<size_t>(y) * g.width + x0);
    out.data.insert(out.data.end(), row, row + w);
  }
  return out;
}

// A block of a pack's grids (the pitch with them) into `field`, `normals`, `maps`.
void CopyPackBlock(const Pack& pack, int x0, int y0, int w, int h, HeightField& field,
                   Grid<Vec3f>& normals, ReflectanceMaps& maps) {
  field.pitch_mm = pack.field.pitch_mm;
  field.height_mm = GridBlock(pack.field.height_mm, x0, y0, w, h);
  field.state = GridBlock(pack.field.state, x0, y0, w, h);
  normals = GridBlock(pack.normals, x0, y0, w, h);
  maps.rho_d = GridBlock(pack.maps.rho_d, x0, y0, w, h);
  maps.rho_s = GridBlock(pack.maps.rho_s, x0, y0, w, h);
  maps.lobe = GridBlock(pack.maps.lobe, x0, y0, w, h);
  maps.fit_error = GridBlock(pack.maps.fit_error, x0, y0, w, h);
  maps.status = GridBlock(pack.maps.status, x0, y0, w, h);
  maps.model = GridBlock(pack.maps.model, x0, y0, w, h);
}

template <class T>
void AppendRows(Grid<T>& to, const Grid<T>& rows) {
  if (to.data.empty()) to.width = rows.width;
  to.height += rows.height;
  to.data.insert(to.data.end(), rows.data.begin(), rows.data.end());
}

// Every grid of a level, for the row operations.
template <class F>
void ForEachGrid(PackLevel& a, const PackLevel& b, F&& f) {
  f(a.field.height_mm, b.field.height_mm);
  f(a.field.state, b.field.state);
  f(a.max_height_mm, b.max_height_mm);
  f(a.normals, b.normals);
  f(a.maps.rho_d, b.maps.rho_d);
  f(a.maps.rho_s, b.maps.rho_s);
  f(a.maps.lobe, b.maps.lobe);
  f(a.maps.fit_error, b.maps.fit_error);
  f(a.maps.status, b.maps.status);
  f(a.maps.model, b.maps.model);
}

std::string Rows(int level, int y0, int rows) {
  return "level " + std::to_string(level) + ", rows " + std::to_string(y0) + ".." +
         std::to_string(y0 + rows - 1);
}

Imf::Header PartHeader(int w, int h, int display_w, int display_h, const char* name, int tile) {
  const Imath::Box2i display(Imath::V2i(0, 0), Imath::V2i(display_w - 1, display_h - 1));
  const Imath::Box2i data(Imath::V2i(0, 0), Imath::V2i(w - 1, h - 1));
  Imf::Header header(display, data, 1.0f, Imath::V2f(0, 0), 1.0f,
                     tile > 0 ? Imf::RANDOM_Y : Imf::INCREASING_Y, Imf::ZIP_COMPRESSION);
  header.setName(name);
  if (tile > 0) {
    header.setType(Imf::TILEDIMAGE);
    header.setTileDescription(Imf::TileDescription(tile, tile, Imf::MIPMAP_LEVELS, Imf::ROUND_UP));
  } else {
    header.setType(Imf::SCANLINEIMAGE);
  }
  return header;
}

// One frame buffer slice per channel over an interleaved block whose first pixel is (x0, y0).
template <class T>
Imf::FrameBuffer Interleaved(Imf::PixelType type, T* data, const std::vector<std::string>& names,
                             int x0, int y0, int w, int h) {
  Imf::FrameBuffer fb;
  const size_t nc = names.size();
  const Imath::Box2i box(Imath::V2i(x0, y0), Imath::V2i(x0 + w - 1, y0 + h - 1));
  for (size_t c = 0; c < nc; ++c)
    fb.insert(names[c], Imf::Slice::Make(type, data + c, box, nc * sizeof(T), nc * sizeof(T) * w));
  return fb;
}

// Columns [x0, x0 + w) of a pack's grids, with its scalars.
Pack PackColumns(const Pack& pack, int x0, int w) {
  Pack out;
  CopyPackBlock(pack, x0, 0, w, pack.height(), out.field, out.normals, out.maps);
  out.delta0_mm = pack.delta0_mm;
  out.max_height_mm = pack.max_height_mm;
  out.cell_px = pack.cell_px;
  out.canvas_from_scan = pack.canvas_from_scan;
  return out;
}

// The pyramid, level by level: each level writes the tiles of the band it is given, filters it
// into rows of the next level at once, and gathers those until they make a band (Feed).
class PyramidWriter {
 public:
  PyramidWriter(Imf::MultiPartOutputFile& file, const PackHeader& header,
                const PackWriteOptions& options)
      : surface_(file, 0),
        reflectance_(file, 1),
        header_(header),
        options_(options),
        sizes_(PyramidLevelSizes(header.width, header.height)),
        pending_(sizes_.size()),
        rows_in_(sizes_.size(), 0) {
    int64_t row = 0;
    for (const auto& [w, h] : sizes_) {
      first_row_.push_back(row);
      row += int64_t{TilesX(w)} * TilesX(h);
    }
    digests_.assign(static_cast<size_t>(row + 1) * 5, 0);  // + the boxes part's
  }

  // Rows [rows_in_[level], + band height) of `level`: its tiles are written, and the band is
  // filtered at once into rows of the next level, which gathers them until it has a row of
  // tiles. A band starts on an even row (a whole number of tiles down), so filtering it alone
  // gives the rows filtering the whole level would (the filter is 2 x 2, texel by texel). So a
  // level holds one band of its own and less than a row of tiles of the next: the merge's memory
  // is about two bands of level 0. The band is taken, not copied.
  Status Feed(int level, PackLevel band) {
    const int y0 = rows_in_[level], rows = band.field.height();
    if (Status s = WriteTiles(level, y0, band); !s.ok()) return s;
    rows_in_[level] += rows;
    if (level + 1 == static_cast<int>(sizes_.size())) return Status::Ok();
    PackLevel coarse = PrefilterLevel(band);
    band = PackLevel{};
    PackLevel& pending = pending_[level + 1];
    if (pending.field.height() == 0) {
      pending = std::move(coarse);
    } else {
      ForEachGrid(pending, coarse, [](auto& to, const auto& from) { AppendRows(to, from); });
      coarse = PackLevel{};
    }
    const int next_rows = rows_in_[level + 1] + pending.field.height();
    if (pending.field.height() < options_.tile_size && next_rows < sizes_[level + 1][1])
      return Status::Ok();
    PackLevel next = std::move(pending);
    pending = PackLevel{};
    return Feed(level + 1, std::move(next));
  }

  int64_t texels_done(int level) const { return rows_in_[level]; }
  std::vector<uint32_t>& digests() { return digests_; }
  const std::array<int64_t, kReflectanceModelCount>& models() const { return models_; }

 private:
  int TilesX(int w) const { return (w + options_.tile_size - 1) / options_.tile_size; }

  // The band's grids are lent to a Pack (validated as one) and given back.
  Status WriteTiles(int level, int y0, PackLevel& band) {
    Pack pack;
    pack.field = std::move(band.field);
    pack.normals = std::move(band.normals);
    pack.maps = std::move(band.maps);
    Status s = WritePackTiles(level, y0, pack);
    band.field = std::move(pack.field);
    band.normals = std::move(pack.normals);
    band.maps = std::move(pack.maps);
    return s;
  }

  Status WritePackTiles(int level, int y0, Pack& pack) {
    const int t = options_.tile_size, w = pack.field.width(), rows = pack.field.height();
    pack.delta0_mm = header_.delta0_mm;
    pack.max_height_mm = header_.max_height_mm;
    pack.cell_px = header_.cell_px;
    pack.canvas_from_scan = header_.canvas_from_scan;
    if (Status s = pack.Validate(); !s.ok())
      return Error{Rows(level, y0, rows) +
                   " (texel rows counted from the band's first): " + s.message()};
    if (Status s = CheckHalfRange(pack, y0); !s.ok())
      return Error{Rows(level, y0, rows) + ": " + s.message()};
    if (level == 0)
      for (const ReflectanceModel m : pack.maps.model.data) ++models_[static_cast<size_t>(m)];
    const int ty = y0 / t;
    std::vector<uint16_t> surface, reflectance;
    for (int tx = 0; tx * t < w; ++tx) {
      const int x0 = tx * t, tw = std::min(t, w - x0);
      // Encoded a tile at a time (the encoding is per texel), not the whole band at once.
      const Pack enc = EncodePackValues(PackColumns(pack, x0, tw), options_);
      surface.assign(static_cast<size_t>(tw) * rows * 4, 0);
      reflectance.assign(static_cast<size_t>(tw) * rows * 9, 0);
      for (int y = 0; y < rows; ++y)
        for (int x = 0; x < tw; ++x) {
          const size_t o = static_cast<size_t>(y) * tw + x;
          EncodeTexel(enc.field, enc.normals, enc.maps, enc.field.height_mm.Index(x, y),
                      &surface[4 * o], &reflectance[9 * o]);
        }
      OIIO::SHA1 sha;
      sha.append(surface.data(), surface.size() * 2);
      sha.append(reflectance.data(), reflectance.size() * 2);
      const size_t row =
          static_cast<size_t>(first_row_[level] + int64_t{ty} * TilesX(sizes_[level][0]) + tx);
      sha.gethash(&digests_[5 * row]);
      surface_.setFrameBuffer(
          Interleaved(Imf::HALF, surface.data(), kSurfaceChannels, x0, y0, tw, rows));
      surface_.writeTile(tx, ty, level, level);
      reflectance_.setFrameBuffer(
          Interleaved(Imf::HALF, reflectance.data(), kReflectanceChannels, x0, y0, tw, rows));
      reflectance_.writeTile(tx, ty, level, level);
    }
    return Status::Ok();
  }

  Imf::TiledOutputPart surface_, reflectance_;
  const PackHeader& header_;
  const PackWriteOptions& options_;
  std::vector<std::array<int, 2>> sizes_;
  std::vector<PackLevel> pending_;
  std::vector<int> rows_in_;
  std::vector<int64_t> first_row_;
  std::vector<uint32_t> digests_;
  std::array<int64_t, kReflectanceModelCount> models_{};
};

}  // namespace

PackLevel PackRows(const Pack& pack, int y0, int rows) {
  DIGITIZE_CHECK(y0 >= 0 && rows >= 0 && y0 + rows <= pack.height(), "PackRows: rows outside");
  PackLevel band;
  CopyPackBlock(pack, 0, y0, pack.width(), rows, band.field, band.normals, band.maps);
  band.max_height_mm = band.field.height_mm;
  return band;
}

Status WriteTiledPack(const fs::path& path, const PackHeader& header,
                      const PackWriteOptions& options, const PackBandSource& band) {
  const std::string file = path.string();
  if (Status s = options.Validate(); !s.ok()) return Error{file + ": " + s.message()};
  if (options.tile_size <= 0) return Error{file + ": a tiled pack needs tile_size > 0"};
  if (Status s = CheckHeader(header); !s.ok()) return Error{file + ": " + s.message()};
  const int w = header.width, h = header.height;
  const int cells_x = (w + header.cell_px - 1) / header.cell_px,
            cells_y = (h + header.cell_px - 1) / header.cell_px;
  std::vector<float> cells = BoxCells(header.boxes, w, h, header.cell_px);
  const int64_t tiles = [&] {
    int64_t n = 0;
    for (const auto& [lw, lh] : PyramidLevelSizes(w, h))
      n += int64_t{(lw + options.tile_size - 1) / options.tile_size} *
           ((lh + options.tile_size - 1) / options.tile_size);
    return n;
  }();

  std::vector<Imf::Header> parts = {
      PartHeader(w, h, w, h, kPartNames[0], options.tile_size),
      PartHeader(w, h, w, h, kPartNames[1], options.tile_size),
      PartHeader(cells_x, cells_y, w, h, kPartNames[2], 0),
      PartHeader(1, static_cast<int>(tiles + 1), w, h, kChecksumPartName, 0)};
  for (const std::string& c : kSurfaceChannels)
    parts[0].channels().insert(c, Imf::Channel(Imf::HALF));
  for (const std::string& c : kReflectanceChannels)
    parts[1].channels().insert(c, Imf::Channel(Imf::HALF));
  for (const std::string& c : kBoxChannels) parts[2].channels().insert(c, Imf::Channel(Imf::FLOAT));
  for (const std::string& c : kChecksumChannels)
    parts[3].channels().insert(c, Imf::Channel(Imf::UINT));
  // The header is written before the first tile, so the checksum covers the attributes alone;
  // each tile, and the boxes part, has its own digest in the checksums part.
  const Attributes attributes = PackAttributes(header, options);
  for (const auto& [name, value] : attributes) parts[0].insert(name, Imf::StringAttribute(value));
  parts[0].insert("digitize:checksum",
                  Imf::StringAttribute(PackChecksum(attributes, nullptr, nullptr, 0)));

  return WriteAtomically(path, [&](const fs::path& temp) -> Status {
    try {
      Imf::MultiPartOutputFile out(temp.c_str(), parts.data(), static_cast<int>(parts.size()),
                                   false, Imf::globalThreadCount());
      PyramidWriter pyramid(out, header, options);
      for (int y0 = 0; y0 < h; y0 += options.tile_size) {
        const int rows = std::min(options.tile_size, h - y0);
        auto b = band(y0, rows);
        if (!b.ok()) return b.error();
        if (b->field.width() != w || b->field.height() != rows || b->normals.width != w ||
            b->normals.height != rows || b->maps.width() != w || b->maps.height() != rows)
          return Error{file + ": " + Rows(0, y0, rows) + ": the band is " +
                       std::to_string(b->field.width()) + "x" + std::to_string(b->field.height()) +
                       " texels, expected " + std::to_string(w) + "x" + std::to_string(rows)};
        if (b->max_height_mm.size() != b->field.height_mm.size())
          b->max_height_mm = b->field.height_mm;
        b->field.pitch_mm = header.pitch_mm;
        if (Status s = pyramid.Feed(0, std::move(*b)); !s.ok())
          return Error{file + ": " + s.message()};
      }
      if (pyramid.models() != header.texels_by_model)
        return Error{file + ": the texels are " + ModelCountsText(pyramid.models()) +
                     ", the header said " + ModelCountsText(header.texels_by_model)};
      Imf::OutputPart boxes(out, 2);
      boxes.setFrameBuffer(
          Interleaved(Imf::FLOAT, cells.data(), kBoxChannels, 0, 0, cells_x, cells_y));
      boxes.writePixels(cells_y);
      std::vector<uint32_t>& digests = pyramid.digests();
      OIIO::SHA1(cells.data(), cells.size() * 4).gethash(&digests[5 * static_cast<size_t>(tiles)]);
      Imf::OutputPart sums(out, 3);
      sums.setFrameBuffer(Interleaved(Imf::UINT, digests.data(), kChecksumChannels, 0, 0, 1,
                                      static_cast<int>(tiles + 1)));
      sums.writePixels(static_cast<int>(tiles + 1));
    } catch (const std::exception& e) {
      return WithDiskFull(Error{file + ": write failed: " + OneLine(e.what())}, path);
    }
    return Status::Ok();
  });
}

}  // namespace digitize
