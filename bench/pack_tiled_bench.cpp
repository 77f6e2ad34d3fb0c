// Tiled packs (version 3) against single-grid packs (version 2) as the painting grows: time to
// write, peak memory, file size, and the error of what is read back against the texels written.
// One size and one form per process, so the peak RSS (getrusage) is that write's alone;
// bench/pack_tiled_bench.sh runs the table (docs/benchmarks.md, "Tiled packs").
//
//   pack_tiled_bench --size N [--tile T]   T = 0: single grid (the whole Pack in memory first)
//
// The painting is procedural (height waves, normals from their gradient, Lafortune texels with
// a GGX gilded band), computed band by band for the tiled writer, so nothing but the writer's own
// buffers holds texels. Read back: every level-0 tile of a tiled pack (the whole pack for a single
// grid), each texel against the procedural texel encoded, and the coarsest level against the mean.
#include <sys/resource.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>

#include "digitize/pack.h"
#include "digitize/pack_tiled.h"

namespace fs = std::filesystem;
using namespace digitize;

namespace {

constexpr double kPitchMm = 0.1;

// Rows [y0, y0 + rows) of the N x N procedural painting.
PackLevel Band(int n, int y0, int rows) {
  PackLevel b;
  b.field.pitch_mm = kPitchMm;
  b.field.height_mm = Grid<float>(n, rows);
  b.field.state = Grid<TexelState>(n, rows, TexelState::kMeasured);
  b.normals = Grid<Vec3f>(n, rows);
  b.maps = ReflectanceMaps::Zeros(n, rows);
  const double f = 2 * M_PI / 97.0, g = 2 * M_PI / 61.0;
  for (int r = 0; r < rows; ++r)
    for (int x = 0; x < n; ++x) {
      const int y = y0 + r;
      const double h = 0.3 * std::sin(f * x) * std::cos(g * y);
      const double hx = 0.3 * f * std::cos(f * x) * std::cos(g * y) / kPitchMm;
      const double hy = -0.3 * g * std::sin(f * x) * std::sin(g * y) / kPitchMm;
      b.field.height_mm(x, r) = static_cast<float>(0.5 + h);
      b.normals(x, r) = Vec3f(float(-hx), float(-hy), 1.0f).normalized();
      b.maps.rho_d(x, r) = Vec3f(0.2f + 0.1f * float(x % 7) / 7, 0.3f, 0.25f);
      b.maps.status(x, r) = TexelFitStatus{};
      if ((y / 256) % 4 == 1) {
        GgxParams p;
        p.rho_d = Vec3f::Zero();
        p.f0 = Vec3f(1.0f, 0.78f, 0.34f);
        p.alpha = 0.1f + 0.2f * float(x % 13) / 13;
        b.maps.SetGgx(x, r, p);
      } else {
        b.maps.rho_s(x, r) = Vec3f(0.5f, 0.5f, 0.5f);
        b.maps.lobe(x, r) = {0.05f, -0.03f, 1.0f, 20.0f + float(y % 50)};
      }
    }
  b.max_height_mm = b.field.height_mm;
  return b;
}

PackHeader Header(int n) {
  PackHeader h;
  h.width = h.height = n;
  h.pitch_mm = kPitchMm;
  h.max_height_mm = 1.0;
  h.cell_px = 16;
  h.provenance.tool_version = "pack_tiled_bench";
  for (int y0 = 0; y0 < n; y0 += 256) {
    const PackLevel b = Band(n, y0, std::min(256, n - y0));
    for (const ReflectanceModel m : b.maps.model.data) ++h.texels_by_model[static_cast<size_t>(m)];
  }
  return h;
}

double PeakRssMb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;  // kB on Linux
}

// Largest |read - written| over the level-0 texels `read` holds, at (x0, y0) of the band of
// rows `want` (what was written there).
double MaxError(const PackLevel& read, int x0, const PackLevel& want) {
  double e = 0;
  for (int y = 0; y < read.field.height(); ++y)
    for (int x = 0; x < read.field.width(); ++x) {
      e = std::max<double>(e,
                           std::abs(read.field.height_mm(x, y) - want.field.height_mm(x0 + x, y)));
      e = std::max<double>(
          e, (read.maps.rho_d(x, y) - want.maps.rho_d(x0 + x, y)).cwiseAbs().maxCoeff());
      e = std::max<double>(e, std::abs(read.maps.lobe(x, y)[3] - want.maps.lobe(x0 + x, y)[3]) /
                                  std::max(1.0f, want.maps.lobe(x0 + x, y)[3]));
    }
  return e;
}

}  // namespace

int main(int argc, char** argv) {
  int n = 0, tile = 256;
  bool keep = false;  // --keep 1: leave the pack (viewer_stream_bench streams it)
  std::string out = "/tmp/pack_tiled_bench.pack.exr";
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--keep"))
      keep = std::atoi(argv[i + 1]) != 0;
    else if (!std::strcmp(argv[i], "--size"))
      n = std::atoi(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--tile"))
      tile = std::atoi(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--out"))
      out = argv[i + 1];
  }
  if (n < 2) {
    std::fprintf(
        stderr,
        "usage: pack_tiled_bench --size N [--tile T (0: single grid)] [--out F] [--keep 1]\n");
    return 2;
  }
  const PackHeader header = Header(n);
  PackWriteOptions o;
  o.tile_size = tile;
  const auto t0 = std::chrono::steady_clock::now();
  Status written;
  if (tile > 0) {
    written = WriteTiledPack(
        out, header, o, [&](int y0, int rows) -> Result<PackLevel> { return Band(n, y0, rows); });
  } else {
    Pack p;
    const PackLevel all = Band(n, 0, n);
    p.field = all.field;
    p.normals = all.normals;
    p.maps = all.maps;
    p.max_height_mm = header.max_height_mm;
    p.cell_px = header.cell_px;
    p.provenance = header.provenance;
    written = WritePack(out, p, o);
  }
  const double write_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double write_rss = PeakRssMb();
  if (!written.ok()) {
    std::fprintf(stderr, "%s\n", written.message().c_str());
    return 1;
  }
  double error = 0;
  int levels = 1;
  if (tile > 0) {
    auto reader = TiledPackReader::Open(out);
    if (!reader.ok()) return std::fprintf(stderr, "%s\n", reader.error().message.c_str()), 1;
    levels = static_cast<int>((*reader)->summary().levels.size());
    for (int ty = 0; ty * tile < n; ++ty) {
      // The row's reference band once (made per tile, it was most of a 16384 run's time).
      const PackLevel want = Band(n, ty * tile, std::min(tile, n - ty * tile));
      for (int tx = 0; tx * tile < n; ++tx) {
        auto t = (*reader)->ReadTile(0, tx, ty);
        if (!t.ok()) return std::fprintf(stderr, "%s\n", t.error().message.c_str()), 1;
        error = std::max(error, MaxError(t->texels, t->x0, want));
      }
    }
  } else {
    auto p = ReadPack(out, PackReadOptions{int64_t{1} << 30});
    if (!p.ok()) return std::fprintf(stderr, "%s\n", p.error().message.c_str()), 1;
    PackLevel l{p->field, p->field.height_mm, p->normals, p->maps};
    error = MaxError(l, 0, Band(n, 0, n));
  }
  // size, tile, levels, write s, peak RSS after writing, file MB, max relative error read back
  std::printf("%d,%d,%d,%.2f,%.0f,%.1f,%.2e\n", n, tile, levels, write_s, write_rss,
              fs::file_size(out) / 1e6, error);
  if (!keep) fs::remove(out);
  return 0;
}
