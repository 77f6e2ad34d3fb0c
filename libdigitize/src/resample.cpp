// Resampling onto the canvas grid (resample.h).
//
// 1. Canvas samples (mask & usable) go to continuous texel coordinates of the canvas frame
//    (texel centres at integers; height_field.h's row flip), per chunk of a row when drawn.
// 2. Per scan quad: which of its (at most two) triangles are drawn. Four valid corners: split
//    along the shorter 3D diagonal; three: the one triangle they make; any edge longer than the
//    edge limit: that triangle is skipped (it spans a step or a gap).
// 3. Rasterisation, race-free: the output rows are cut into bands; every chunk of kChunk quads of
//    a scan row is listed in the bands its texel-row range meets, and each band (one task) draws
//    only its own rows. Linear (barycentric) interpolation; overlaps keep the highest.
// 4. Holes. The canvas outline is the footprint of the mask's quads (a missing corner predicted
//    from its quad's parallelogram or a quadratic pixel -> texel map) plus everything it
//    encloses; uncovered texels inside are holes. A connected hole up to max_hole_area_mm2 is
//    small; a larger one is split: texels farther from measured ones than the radius of a disc
//    of that area are cores of large holes, and everything within that radius of a core is
//    large (kUnfilled), the rest small (kFilled). Every hole is filled by push-pull interpolation
//    relaxed towards a membrane (harmonic) fill, one component per task.
#include "digitize/resample.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "resample_holes.h"

namespace digitize {
namespace {

constexpr float kMaxAbsCoordinateMm = 1e6f;  // as canvas_steps.h: beyond is garbage
constexpr int kChunk = 32;                   // quads per chunk of a scan row (rasteriser lists)
constexpr int kBandRows = 32;                // output rows per rasteriser task
constexpr float kBaryEps = 1e-5f;            // texel centres on a shared edge go to both sides
constexpr size_t kStatSamples = 50000;       // subsample size for the median spacing
constexpr size_t kMapSamples = 20000;        // samples fitting the pixel -> texel map
constexpr float kLowest = std::numeric_limits<float>::lowest();

inline bool Usable(const Vec3f& p) {
  return std::fabs(p.x()) <= kMaxAbsCoordinateMm && std::fabs(p.y()) <= kMaxAbsCoordinateMm &&
         std::fabs(p.z()) <= kMaxAbsCoordinateMm;
}

struct TexelPoint {
  float x, y, h;  // continuous texel column, row; height (mm)
  bool ok() const { return x == x; }
};

// Triangles of a quad with corners A = (x, y), B = (x+1, y), C = (x, y+1), D = (x+1, y+1).
enum : uint8_t { kABD = 1, kADC = 2, kABC = 4, kBDC = 8 };
constexpr uint8_t kBits[16] = {0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4};  // popcount

struct Counts {
  size_t drawn = 0, skipped = 0;
};

// Median 3D distance between 4-neighbours (dx, dy) that are both usable canvas samples.
double MedianSpacing(const Grid<Vec3f>& xyz, const Grid<uint8_t>& mask, int dx, int dy,
                     size_t count) {
  const int stride =
      std::max(1, static_cast<int>(std::sqrt(static_cast<double>(count) / kStatSamples)));
  std::vector<float> d;
  for (int y = 0; y + dy < xyz.height; y += stride)
    for (int x = 0; x + dx < xyz.width; x += stride) {
      if (!mask(x, y) || !mask(x + dx, y + dy)) continue;
      const Vec3f& p = xyz(x, y);
      const Vec3f& q = xyz(x + dx, y + dy);
      if (Usable(p) && Usable(q)) d.push_back((q - p).norm());
    }
  if (d.empty()) return 0;
  const size_t mid = d.size() / 2;
  std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(mid), d.end());
  return d[mid];
}

// canvas texel coordinates of a scan sample: m (p - ref) + t.
struct TexelTransform {
  Eigen::Vector3f ref = Eigen::Vector3f::Zero();
  Eigen::Matrix3f m = Eigen::Matrix3f::Identity();
  Eigen::Vector3f t = Eigen::Vector3f::Zero();
};

// Texel points of n consecutive samples of a scan row; NaN where not a usable canvas sample.
inline void TexelRow(const Vec3f* in, const uint8_t* mask, int n, const TexelTransform& tf,
                     TexelPoint* out) {
  const float nanf = std::numeric_limits<float>::quiet_NaN();
  for (int k = 0; k < n; ++k) {
    if (mask[k] && Usable(in[k])) {
      const Eigen::Vector3f p = tf.m * (in[k] - tf.ref) + tf.t;
      out[k] = {p.x(), p.y(), p.z()};
    } else {
      out[k] = {nanf, nanf, nanf};
    }
  }
}

// floor / ceil of v >= -2 by truncation (the callers clamp): no libm call, no branch.
inline int FloorFrom(float v) { return static_cast<int>(v + 2.f) - 2; }
inline int CeilFrom(float v) {
  const int f = FloorFrom(v);
  return f + (static_cast<float>(f) < v);
}

// Texel rectangle [i0, i1] x [j0, j1] of a bounding box (texel coordinates) inside the band of
// rows row0..row1 of a grid w wide. Clamped to just outside the band first, so the integer
// conversions are plain truncations. False when nothing is left.
struct TexelRect {
  int i0 = 0, i1 = -1, j0 = 0, j1 = -1;
};
inline bool ClampToBand(float minx, float maxx, float miny, float maxy, int w, int row0, int row1,
                        TexelRect& rect) {
  minx = std::max(minx, -1.f), maxx = std::min(maxx, static_cast<float>(w));
  miny = std::max(miny, static_cast<float>(row0 - 1));
  maxy = std::min(maxy, static_cast<float>(row1 + 1));
  if (!(minx <= maxx && miny <= maxy)) return false;
  rect.i0 = std::max(0, CeilFrom(minx)), rect.i1 = std::min(w - 1, FloorFrom(maxx));
  rect.j0 = std::max(row0, CeilFrom(miny)), rect.j1 = std::min(row1, FloorFrom(maxy));
  return rect.i0 <= rect.i1 && rect.j0 <= rect.j1;
}

// Linear interpolation over one triangle at texel centres. Edge functions relative to vertex a
// in float: differences of nearby coordinates are exact. At() gives kLowest outside.
struct TriangleSetup {
  float ax = 0, ay = 0, ah = 0, e1x = 0, e1y = 0, e2x = 0, e2y = 0, inv = 0, dh1 = 0, dh2 = 0;
  TriangleSetup() = default;
  TriangleSetup(const TexelPoint& a, const TexelPoint& b, const TexelPoint& c)
      : ax(a.x),
        ay(a.y),
        ah(a.h),
        e1x(b.x - a.x),
        e1y(b.y - a.y),
        e2x(c.x - a.x),
        e2y(c.y - a.y),
        dh1(b.h - a.h),
        dh2(c.h - a.h) {
    const float area = e1x * e2y - e2x * e1y;
    inv = std::fabs(area) > 1e-12f ? 1.0f / area : 0.f;  // degenerate: never inside
  }
  float At(int i, int j) const {
    const float px = static_cast<float>(i) - ax, py = static_cast<float>(j) - ay;
    const float wb = (px * e2y - e2x * py) * inv;
    const float wc = (e1x * py - px * e1y) * inv;
    const bool in =
        (wb >= -kBaryEps) & (wc >= -kBaryEps) & (wb + wc <= 1.0f + kBaryEps) & (inv != 0.f);
    const float value = ah + wb * dh1 + wc * dh2;
    return in ? value : kLowest;
  }
};

// Marks in `grid` (width w, rows row0..row1) the texels inside the triangles that a quad's
// mask corners make (both triangles with four, the one triangle with three); missing corners
// (NaN) are predicted: the parallelogram of the three others when they are valid, else
// predict(pixel x, pixel y).
template <class Predict>
void DrawFootprint(TexelPoint a, TexelPoint b, TexelPoint c, TexelPoint d, int ma, int mb, int mc,
                   int md, int x, int y, const Predict& predict, int w, int row0, int row1,
                   uint8_t* grid) {
  const int nvalid = a.ok() + b.ok() + c.ok() + d.ok();
  auto fill = [&](TexelPoint& p, const TexelPoint& q, const TexelPoint& r, const TexelPoint& o,
                  int px, int py) {
    if (p.ok()) return;
    if (nvalid == 3) {  // p = q + r - o, o the corner opposite p
      p = {q.x + r.x - o.x, q.y + r.y - o.y, 0.f};
    } else {
      p = predict(px, py);
    }
  };
  fill(a, b, c, d, x, y);
  fill(b, a, d, c, x + 1, y);
  fill(c, a, d, b, x, y + 1);
  fill(d, b, c, a, x + 1, y + 1);
  const TexelPoint* tri[2][3];
  int ntri = 0;
  if (ma + mb + mc + md == 4) {
    tri[0][0] = &a, tri[0][1] = &b, tri[0][2] = &d;
    tri[1][0] = &a, tri[1][1] = &d, tri[1][2] = &c;
    ntri = 2;
  } else {
    tri[0][0] = ma ? &a : &b, tri[0][1] = md ? &d : &b, tri[0][2] = mc ? &c : &b;
    if (!mb) tri[0][0] = &a, tri[0][1] = &d, tri[0][2] = &c;
    ntri = 1;
  }
  for (int t = 0; t < ntri; ++t) {
    const TexelPoint &p = *tri[t][0], &q = *tri[t][1], &r = *tri[t][2];
    TexelRect rect;
    if (!ClampToBand(std::min({p.x, q.x, r.x}), std::max({p.x, q.x, r.x}),
                     std::min({p.y, q.y, r.y}), std::max({p.y, q.y, r.y}), w, row0, row1, rect))
      continue;
    const TriangleSetup setup(p, q, r);
    for (int j = rect.j0; j <= rect.j1; ++j)
      for (int i = rect.i0; i <= rect.i1; ++i)
        if (setup.At(i, j) > kLowest) grid[static_cast<size_t>(j) * w + i] = 255;
  }
}

// ---- 1. Per scan row and chunk of kChunk + 1 vertices: the canvas-Y range (mm) of its canvas
// samples, so every chunk of quads can be listed in the output bands it reaches.
struct ChunkRanges {
  int chunks_per_row = 1;
  std::vector<float> row_ylo, row_yhi;  // [row * chunks_per_row + chunk]
  size_t count = 0;                     // canvas samples (mask and usable)
};

ChunkRanges MeasureChunkRanges(const Grid<Vec3f>& xyz, const Grid<uint8_t>& mask,
                               const RigidTransform& canvas_from_scan) {
  const int sw = xyz.width, sh = xyz.height;
  const Mat3d& rot = canvas_from_scan.rotation;
  const Vec3d& trans = canvas_from_scan.translation;
  const int qw = std::max(0, sw - 1);
  const int chunks_per_row = std::max(1, (qw + kChunk - 1) / kChunk);
  const float flt_max = std::numeric_limits<float>::max();
  std::vector<float> row_ylo(static_cast<size_t>(chunks_per_row) * sh, flt_max);
  std::vector<float> row_yhi(row_ylo.size(), kLowest);
  const Eigen::Vector3d rot_y = rot.row(1).transpose();
  const size_t count = tbb::parallel_reduce(
      tbb::blocked_range<int>(0, sh), size_t{0},
      [&](const tbb::blocked_range<int>& rows, size_t n) {
        for (int y = rows.begin(); y < rows.end(); ++y) {
          const Vec3f* in = xyz.Row(y);
          const uint8_t* m = mask.Row(y);
          float* lo = row_ylo.data() + static_cast<size_t>(y) * chunks_per_row;
          float* hi = row_yhi.data() + static_cast<size_t>(y) * chunks_per_row;
          for (int x = 0; x < sw; ++x) {
            if (!m[x] || !Usable(in[x])) continue;
            ++n;
            const float cy = static_cast<float>(rot_y.dot(in[x].cast<double>()) + trans.y());
            // Vertex x belongs to chunk x / kChunk and, as its last vertex, to the one before.
            const int c = std::min(x / kChunk, chunks_per_row - 1);
            lo[c] = std::min(lo[c], cy);
            hi[c] = std::max(hi[c], cy);
            if (x % kChunk == 0 && c > 0) {
              lo[c - 1] = std::min(lo[c - 1], cy);
              hi[c - 1] = std::max(hi[c - 1], cy);
            }
          }
        }
        return n;
      },
      [](size_t a, size_t b) { return a + b; });
  ChunkRanges out;
  out.chunks_per_row = chunks_per_row;
  out.row_ylo = std::move(row_ylo);
  out.row_yhi = std::move(row_yhi);
  out.count = count;
  return out;
}

// The output grid: pitch (the scan spacing unless given), size, and the edge limit of the
// triangles. 3D distances do not depend on the frame: the spacing is measured on the raw
// samples. Errors: too few samples, no spacing to measure, too many texels.
struct GridPlan {
  double spacing = 0, pitch = 0;  // mm
  int w = 1, h = 1;               // texels
  double edge_limit = 0;          // mm
  float edge_limit2 = 0;          // mm^2
};

Result<GridPlan> PlanGrid(const Grid<Vec3f>& xyz, const Grid<uint8_t>& mask, size_t count,
                          const Eigen::Vector2d& extent, const ResampleOptions& options,
                          const std::string& src) {
  if (count < 3)
    return Error{src + ": the canvas mask holds " + std::to_string(count) +
                 " valid samples, too few to resample"};
  double spacing = options.scan_spacing_mm;
  if (!(spacing > 0)) spacing = MedianSpacing(xyz, mask, 1, 0, count);
  if (!(spacing > 0)) spacing = MedianSpacing(xyz, mask, 0, 1, count);
  const double pitch = options.pitch_mm > 0 ? options.pitch_mm : spacing;
  if (!(pitch > 0) || !std::isfinite(pitch))
    return Error{src +
                 ": no two adjacent canvas samples to measure the scan spacing; give pitch_mm"};
  if (!(spacing > 0)) spacing = pitch;
  const double gw = std::ceil(extent.x() / pitch), gh = std::ceil(extent.y() / pitch);
  if (gw > options.max_texels_per_side || gh > options.max_texels_per_side)
    return Error{src + ": a " + std::to_string(extent.x()) + " x " + std::to_string(extent.y()) +
                 " mm canvas at pitch " + std::to_string(pitch) + " mm needs " +
                 std::to_string(static_cast<long long>(gw)) + " x " +
                 std::to_string(static_cast<long long>(gh)) + " texels, more than " +
                 std::to_string(options.max_texels_per_side) +
                 " per side (max_texels_per_side); raise pitch_mm"};
  const int w = std::max(1, static_cast<int>(gw)), h = std::max(1, static_cast<int>(gh));
  // Edges are judged against the coarser of the output pitch and the scan spacing, so a fine
  // output pitch does not discard every triangle.
  const double edge_limit = options.max_edge_factor * std::max(pitch, spacing);
  const float edge_limit2 = static_cast<float>(edge_limit * edge_limit);
  return GridPlan{spacing, pitch, w, h, edge_limit, edge_limit2};
}

// ---- 2. Chunks of quads listed in the output bands (kBandRows texel rows) they reach. Frees
// the ranges, which are not needed after.
struct BandLists {
  int bands = 0;
  std::vector<std::vector<uint32_t>> band_chunks;  // per band: chunk indices
  std::vector<int> first_band;  // per chunk: the band that counts its triangles (-1: none)
};

BandLists ListChunksInBands(ChunkRanges& ranges, const GridPlan& plan, int qh) {
  const int chunks_per_row = ranges.chunks_per_row, h = plan.h;
  const double spacing = plan.spacing, pitch = plan.pitch;
  std::vector<float>& row_ylo = ranges.row_ylo;
  std::vector<float>& row_yhi = ranges.row_yhi;
  const double margin_rows = 1.0 + spacing / pitch;
  const int bands = (h + kBandRows - 1) / kBandRows;
  const size_t chunk_count = static_cast<size_t>(chunks_per_row) * qh;
  std::vector<std::vector<uint32_t>> band_chunks(static_cast<size_t>(bands));
  std::vector<int> first_band(chunk_count, -1);  // the band that counts the chunk's triangles
  for (int y = 0; y < qh; ++y)
    for (int c = 0; c < chunks_per_row; ++c) {
      const size_t i0 = static_cast<size_t>(y) * chunks_per_row + c, i1 = i0 + chunks_per_row;
      const float ylo = std::min(row_ylo[i0], row_ylo[i1]);
      const float yhi = std::max(row_yhi[i0], row_yhi[i1]);
      if (!(ylo <= yhi)) continue;
      // Texel rows: ty = h - Y / pitch - 0.5 (height_field.h), so Y's maximum gives the first.
      // The margin covers the outline's predicted positions of missing samples (about one
      // sample spacing from their valid neighbours).
      const double j0 = std::max(0.0, std::ceil(h - yhi / pitch - 0.5 - margin_rows));
      const double j1 = std::min(double(h - 1), std::floor(h - ylo / pitch - 0.5 + margin_rows));
      if (j0 > j1) continue;
      const size_t ci = static_cast<size_t>(y) * chunks_per_row + c;
      first_band[ci] = static_cast<int>(j0) / kBandRows;
      for (int b = static_cast<int>(j0) / kBandRows; b <= static_cast<int>(j1) / kBandRows; ++b)
        band_chunks[static_cast<size_t>(b)].push_back(static_cast<uint32_t>(ci));
    }
  std::vector<float>().swap(row_ylo);
  std::vector<float>().swap(row_yhi);

  return BandLists{bands, std::move(band_chunks), std::move(first_band)};
}

// ---- 3. Texel coordinates: texel = (R p + t) scaled: x = X / pitch - 0.5,
// y = h - Y / pitch - 0.5; in float about a reference sample so the products stay small.
TexelTransform MakeTexelTransform(const Grid<Vec3f>& xyz, const Grid<uint8_t>& mask,
                                  const RigidTransform& canvas_from_scan, double pitch, int h) {
  const Mat3d& rot = canvas_from_scan.rotation;
  const Vec3d& trans = canvas_from_scan.translation;
  TexelTransform tf;
  Mat3d to_texel = rot;
  to_texel.row(0) /= pitch;
  to_texel.row(1) /= -pitch;
  const Vec3d offset(trans.x() / pitch - 0.5, h - trans.y() / pitch - 0.5, trans.z());
  Vec3d ref = Vec3d::Zero();
  for (size_t i = xyz.size() / 2, k = 0; k < xyz.size(); ++k) {
    const size_t j = (i + k) % xyz.size();
    if (mask.data[j] && Usable(xyz.data[j])) {
      ref = xyz.data[j].cast<double>();
      break;
    }
  }
  tf.ref = ref.cast<float>();
  tf.m = to_texel.cast<float>();
  tf.t = (to_texel * tf.ref.cast<double>() + offset).cast<float>();
  return tf;
}

// Texel position of a missing canvas sample (for the outline only): a quadratic map of the
// scan pixel fitted to the valid ones, unless the parallelogram of a quad's three valid
// corners gives it.
struct PixelMap {
  int sw = 0, sh = 0;  // scan size
  Eigen::Matrix<double, 6, 2> coefficients = Eigen::Matrix<double, 6, 2>::Zero();
  bool ok = false;
  Eigen::Matrix<double, 6, 1> Basis(int x, int y) const {
    const double u = (x - 0.5 * sw) / std::max(sw, 1), v = (y - 0.5 * sh) / std::max(sh, 1);
    Eigen::Matrix<double, 6, 1> b;
    b << 1, u, v, u * u, u * v, v * v;
    return b;
  }
  TexelPoint operator()(int x, int y) const {
    const Eigen::Matrix<double, 6, 1> b = Basis(x, y);
    return TexelPoint{static_cast<float>(b.dot(coefficients.col(0))),
                      static_cast<float>(b.dot(coefficients.col(1))), 0.f};
  }
};

PixelMap FitPixelMap(const Grid<Vec3f>& xyz, const Grid<uint8_t>& mask, const TexelTransform& tf,
                     size_t count) {
  const int sw = xyz.width, sh = xyz.height;
  PixelMap map;
  map.sw = sw;
  map.sh = sh;
  const int stride =
      std::max(1, static_cast<int>(std::sqrt(static_cast<double>(count) / kMapSamples)));
  Eigen::Matrix<double, 6, 6> ata = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 2> atb = Eigen::Matrix<double, 6, 2>::Zero();
  size_t n = 0;
  for (int y = 0; y < sh; y += stride)
    for (int x = 0; x < sw; x += stride) {
      if (!mask(x, y) || !Usable(xyz(x, y))) continue;
      const Eigen::Vector3f t = tf.m * (xyz(x, y) - tf.ref) + tf.t;
      const Eigen::Matrix<double, 6, 1> b = map.Basis(x, y);
      ata += b * b.transpose();
      atb.col(0) += b * t.x();
      atb.col(1) += b * t.y();
      ++n;
    }
  if (n >= 12) {
    map.coefficients = ata.completeOrthogonalDecomposition().solve(atb);
    map.ok = map.coefficients.allFinite();
  }
  return map;
}

// Per band (one task each, so no two write the same texel): the chunk's two vertex rows in
// texel coordinates, the quads' triangles chosen and drawn into the band's rows of `out`
// (highest wins), and the footprints of mask quads whose triangles were not drawn.
Counts RasteriseBands(const Grid<Vec3f>& xyz, const Grid<uint8_t>& mask, const TexelTransform& tf,
                      const PixelMap& predict, const BandLists& lists, const GridPlan& plan,
                      int chunks_per_row, float* out, Grid<uint8_t>* footprint) {
  const int qw = std::max(0, xyz.width - 1);
  const int w = plan.w, h = plan.h, bands = lists.bands;
  const bool have_map = predict.ok;
  const float edge_limit2 = plan.edge_limit2;
  const std::vector<std::vector<uint32_t>>& band_chunks = lists.band_chunks;
  const std::vector<int>& first_band = lists.first_band;
  // Edge lengths from the scan's own samples (a rigid transform keeps them): the triangles chosen
  // do not depend on the float rounding of the texel transform, so a tile of the canvas
  // (preprocess_tiled.h), whose transform is the whole's moved, draws the same ones.
  auto dist2 = [](const Vec3f& p, const Vec3f& q) { return (p - q).squaredNorm(); };
  return tbb::parallel_reduce(
      tbb::blocked_range<int>(0, bands, 1), Counts{},
      [&](const tbb::blocked_range<int>& br, Counts cnt) {
        TexelPoint r0[kChunk + 1], r1[kChunk + 1];
        for (int b = br.begin(); b < br.end(); ++b) {
          const int row0 = b * kBandRows, row1 = std::min(h, row0 + kBandRows) - 1;
          for (uint32_t ci : band_chunks[static_cast<size_t>(b)]) {
            const int y = static_cast<int>(ci / chunks_per_row);
            const int x0 = static_cast<int>(ci % chunks_per_row) * kChunk;
            const int x1 = std::min(qw, x0 + kChunk);  // quads x0 .. x1 - 1
            const bool count_here = first_band[ci] == b;
            const uint8_t* m0 = mask.Row(y) + x0;
            const uint8_t* m1 = mask.Row(y + 1) + x0;
            for (int r = 0; r < 2; ++r)
              TexelRow(xyz.Row(y + r) + x0, mask.Row(y + r) + x0, x1 - x0 + 1, tf,
                       r == 0 ? r0 : r1);
            for (int x = x0; x < x1; ++x) {
              const TexelPoint &A = r0[x - x0], &B = r0[x - x0 + 1], &C = r1[x - x0],
                               &D = r1[x - x0 + 1];
              const Vec3f *pa = xyz.Row(y) + x, *pc = xyz.Row(y + 1) + x;
              const Vec3f &PA = pa[0], &PB = pa[1], &PC = pc[0], &PD = pc[1];
              const int va = A.ok(), vb = B.ok(), vc = C.ok(), vd = D.ok();
              const int nvalid = va + vb + vc + vd;
              const int k = x - x0;
              const int ma = m0[k] != 0, mb = m0[k + 1] != 0, mc = m1[k] != 0, md = m1[k + 1] != 0;
              const int nmask = ma + mb + mc + md;
              if (nvalid < 3) {
                if (nmask >= 3 && have_map)
                  DrawFootprint(A, B, C, D, ma, mb, mc, md, x, y, predict, w, row0, row1,
                                footprint->data.data());
                continue;
              }
              uint8_t cand = 0;
              if (nvalid == 4)
                cand = dist2(PA, PD) <= dist2(PB, PC) ? (kABD | kADC) : (kABC | kBDC);
              else
                cand = !va ? kBDC : !vb ? kADC : !vc ? kABD : kABC;
              auto short_edge = [&](const Vec3f& p, const Vec3f& q) {
                return dist2(p, q) <= edge_limit2;
              };
              uint8_t keep = 0;
              if ((cand & kABD) && short_edge(PA, PB) && short_edge(PB, PD) && short_edge(PA, PD))
                keep |= kABD;
              if ((cand & kADC) && short_edge(PA, PD) && short_edge(PD, PC) && short_edge(PA, PC))
                keep |= kADC;
              if ((cand & kABC) && short_edge(PA, PB) && short_edge(PB, PC) && short_edge(PA, PC))
                keep |= kABC;
              if ((cand & kBDC) && short_edge(PB, PD) && short_edge(PD, PC) && short_edge(PB, PC))
                keep |= kBDC;
              if (count_here) {
                const int ncand = kBits[cand], nkeep = kBits[keep];
                cnt.drawn += nkeep;
                cnt.skipped += ncand - nkeep;
              }
              if (kBits[keep] < 2 && nmask >= 3 && (nvalid == 3 || have_map))
                DrawFootprint(A, B, C, D, ma, mb, mc, md, x, y, predict, w, row0, row1,
                              footprint->data.data());
              if (!keep) continue;
              // Texel centres inside the quad's box (usually one or two), then per triangle.
              const TexelPoint* tri[2][3];
              int ntri = 0;
              if (keep & kABD) tri[ntri][0] = &A, tri[ntri][1] = &B, tri[ntri++][2] = &D;
              if (keep & kADC) tri[ntri][0] = &A, tri[ntri][1] = &D, tri[ntri++][2] = &C;
              if (keep & kABC) tri[ntri][0] = &A, tri[ntri][1] = &B, tri[ntri++][2] = &C;
              if (keep & kBDC) tri[ntri][0] = &B, tri[ntri][1] = &D, tri[ntri++][2] = &C;
              float minx = tri[0][0]->x, maxx = minx, miny = tri[0][0]->y, maxy = miny;
              for (int t = 0; t < ntri; ++t)
                for (int k = 0; k < 3; ++k) {
                  minx = std::min(minx, tri[t][k]->x), maxx = std::max(maxx, tri[t][k]->x);
                  miny = std::min(miny, tri[t][k]->y), maxy = std::max(maxy, tri[t][k]->y);
                }
              TexelRect rect;
              if (!ClampToBand(minx, maxx, miny, maxy, w, row0, row1, rect)) continue;
              TriangleSetup setup[2];
              for (int t = 0; t < ntri; ++t)
                setup[t] = TriangleSetup(*tri[t][0], *tri[t][1], *tri[t][2]);
              for (int j = rect.j0; j <= rect.j1; ++j) {
                float* row = out + static_cast<size_t>(j) * w;
                for (int i = rect.i0; i <= rect.i1; ++i) {
                  float value = kLowest;
                  for (int t = 0; t < ntri; ++t) value = std::max(value, setup[t].At(i, j));
                  row[i] = std::max(row[i], value);
                }
              }
            }
          }
        }
        return cnt;
      },
      [](Counts a, const Counts& b) {
        a.drawn += b.drawn;
        a.skipped += b.skipped;
        return a;
      });
}

}  // namespace

Status ResampleOptions::Validate() const {
  auto fail = [](const std::string& what) { return Status(Error{"resample options: " + what}); };
  if (!(pitch_mm >= 0) || !std::isfinite(pitch_mm))
    return fail("pitch_mm must be >= 0 (0 = the scan spacing), got " + std::to_string(pitch_mm));
  if (!(max_edge_factor > 0) || !std::isfinite(max_edge_factor))
    return fail("max_edge_factor must be > 0, got " + std::to_string(max_edge_factor));
  if (!(max_hole_area_mm2 >= 0) || !std::isfinite(max_hole_area_mm2))
    return fail("max_hole_area_mm2 must be >= 0, got " + std::to_string(max_hole_area_mm2));
  if (!(scan_spacing_mm >= 0) || !std::isfinite(scan_spacing_mm))
    return fail("scan_spacing_mm must be >= 0 (0 = measured), got " +
                std::to_string(scan_spacing_mm));
  if (max_texels_per_side < 1)
    return fail("max_texels_per_side must be >= 1, got " + std::to_string(max_texels_per_side));
  return Status::Ok();
}

namespace {

// consumed: the scan to free once its triangles are drawn (null: the caller keeps it).
Result<HeightField> Resample(const Scan& scan, const CanvasResult& canvas,
                             const ResampleOptions& options, ResampleStats* stats, Scan* consumed) {
  using resample_detail::HoleMap;
  using resample_detail::HoleSizes;
  using resample_detail::StateCounts;
  const std::string src = scan.source.empty() ? "scan" : scan.source;
  if (Status st = options.Validate(); !st.ok()) return Error{src + ": " + st.message()};
  const Grid<Vec3f>& xyz = scan.xyz_mm;
  const int sw = xyz.width, sh = xyz.height;
  if (xyz.empty()) return Error{src + ": empty scan"};
  if (canvas.mask_scan.width != sw || canvas.mask_scan.height != sh)
    return Error{src + ": canvas mask is " + std::to_string(canvas.mask_scan.width) + "x" +
                 std::to_string(canvas.mask_scan.height) + ", scan is " + std::to_string(sw) + "x" +
                 std::to_string(sh)};
  const Mat3d& rot = canvas.canvas_from_scan.rotation;
  const Vec3d& trans = canvas.canvas_from_scan.translation;
  if (!rot.allFinite() || !trans.allFinite() ||
      !(rot.transpose() * rot).isApprox(Mat3d::Identity(), 1e-6) || !(rot.determinant() > 0))
    return Error{src + ": canvas_from_scan is not a rigid transform"};
  const Eigen::Vector2d extent = canvas.extent_mm;
  if (!extent.allFinite() || extent.x() < 0 || extent.y() < 0)
    return Error{src + ": invalid canvas extent"};

  ChunkRanges ranges = MeasureChunkRanges(xyz, canvas.mask_scan, canvas.canvas_from_scan);
  const Result<GridPlan> planned =
      PlanGrid(xyz, canvas.mask_scan, ranges.count, extent, options, src);
  if (!planned.ok()) return planned.error();
  const GridPlan& plan = *planned;
  const int w = plan.w, h = plan.h;
  const BandLists lists = ListChunksInBands(ranges, plan, std::max(0, sh - 1));

  HeightField field;
  field.pitch_mm = plan.pitch;
  field.height_mm = Grid<float>(w, h, kLowest);
  field.state = Grid<TexelState>(w, h, TexelState::kOutside);
  float* out = field.height_mm.data.data();
  const TexelTransform tf =
      MakeTexelTransform(xyz, canvas.mask_scan, canvas.canvas_from_scan, plan.pitch, h);
  const PixelMap predict = FitPixelMap(xyz, canvas.mask_scan, tf, ranges.count);
  Grid<uint8_t> footprint(w, h, 0);  // texels inside mask quads whose triangles were not drawn
  const Counts counts = RasteriseBands(xyz, canvas.mask_scan, tf, predict, lists, plan,
                                       ranges.chunks_per_row, out, &footprint);
  if (consumed) consumed->xyz_mm = Grid<Vec3f>();  // xyz is not read from here on

  cv::Mat height_mat(h, w, CV_32F, out);
  cv::Mat covered;
  cv::compare(height_mat, kLowest, covered, cv::CMP_GT);  // 255 / 0
  if (cv::countNonZero(covered) == 0)
    return Error{src + ": no canvas triangle could be drawn (" + std::to_string(counts.skipped) +
                 " skipped for edges longer than " + std::to_string(plan.edge_limit) +
                 " mm; a scan one sample wide has none)"};
  if (!options.find_holes) {
    size_t measured = 0;
    for (size_t i = 0; i < field.state.data.size(); ++i) {
      if (covered.data[i]) {
        field.state.data[i] = TexelState::kMeasured;
        ++measured;
      } else {
        out[i] = 0;
      }
    }
    if (stats) {
      *stats = ResampleStats{};
      stats->texels = static_cast<size_t>(w) * h;
      stats->measured = measured;
      stats->outside = stats->texels - measured;
      stats->triangles_drawn = counts.drawn;
      stats->triangles_skipped = counts.skipped;
    }
    return field;
  }
  HoleMap holes = resample_detail::FindHoles(covered, &footprint);
  const HoleSizes sizes = resample_detail::SplitLargeHoles(holes, plan.pitch, options);
  holes.holes.release();
  resample_detail::FillHoles(holes, sizes, out);
  const StateCounts sc = resample_detail::AssignStates(holes, sizes.large, &field);
  if (stats) {
    stats->texels = static_cast<size_t>(w) * h;
    stats->measured = sc.measured;
    stats->filled = sc.filled;
    stats->unfilled = sc.unfilled;
    stats->outside = sc.outside;
    stats->holes_filled = sizes.holes_filled;
    stats->holes_unfilled = sizes.holes_unfilled;
    stats->triangles_drawn = counts.drawn;
    stats->triangles_skipped = counts.skipped;
  }
  return field;
}

}  // namespace

Result<HeightField> ResampleToCanvasGrid(const Scan& scan, const CanvasResult& canvas,
                                         const ResampleOptions& options, ResampleStats* stats) {
  return Resample(scan, canvas, options, stats, nullptr);
}

Result<HeightField> ResampleToCanvasGrid(Scan&& scan, const CanvasResult& canvas,
                                         const ResampleOptions& options, ResampleStats* stats) {
  return Resample(scan, canvas, options, stats, &scan);
}

}  // namespace digitize
