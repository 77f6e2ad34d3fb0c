// Synthetic painting: a continuous, band-limited height function of the canvas-frame position,
// evaluated with its exact gradient (automatic differentiation with ceres::Jet) at every texel
// centre. Heights come from the grid; normals from the gradient of the continuous function, so
// ground-truth normals do not depend on how the grid is differentiated.
//
// Composition (mm, canvas frame):
//   h = weave * exp(-paint / kWeaveBurialMm) + paint + craquelure
//   paint = sum of brush strokes and impasto (blobs, palette-knife strokes), all >= 0.
// Thick paint buries the canvas weave, as it does on a real painting.
//
// Band-limiting (the grid must be able to represent what it carries):
//   - periodic features (weave, bristle striations, blob swirls) are multiplied by a fade that is
//     0 below kFadeStartTexels texels per wavelength and 1 above kFadeEndTexels;
//   - isolated narrow features (cracks, ridges) are Gaussian profiles whose sigma is widened by
//     kBlurTexels texels in quadrature, with the amplitude scaled to keep their cross-section
//     area (what a Gaussian low-pass filter does to a Gaussian): at coarse resolutions cracks
//     get wider and shallower rather than aliased;
//   - steps (stroke and impasto walls) rise over a width of at least kWallTexels texels (still
//     steep: a 2.5 mm blob wall at 0.39 mm pitch slopes at ~70 deg).
// Texel-level finite differences agree with the normals to a few hundredths of a degree on the
// smooth parts (tests/synth_test.cpp); on walls they cannot, by construction.
//
// Determinism: every random choice is drawn up front from std::mt19937_64 streams seeded from the
// options' seed (one stream per feature family, so switching one family off leaves the others
// unchanged); per-texel evaluation is a pure function of the position, so the result does not
// depend on thread scheduling.
#include "digitize_synth/painting.h"

#include <ceres/jet.h>
#include <tbb/blocked_range2d.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <random>

namespace digitize::synth {
namespace {

using J = ceres::Jet<double, 2>;  // value and d/dX, d/dY
constexpr double kPi = std::numbers::pi;

constexpr double kFadeStartTexels = 8;   // periodic features vanish below this many texels/period
constexpr double kFadeEndTexels = 16;    // ... and are at full amplitude above this
constexpr double kWallTexels = 4;        // steps rise over at least this many texels
constexpr double kBlurTexels = 2;        // Gaussian features widened by this sigma (texels)
constexpr double kWeaveBurialMm = 0.15;  // paint this thick hides ~63 % of the weave
constexpr int kTilePx = 64;              // feature binning tile

// ---------------------------------------------------------------------------------------------
// Small helpers

uint64_t SplitMix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// Independent stream per feature family (see header comment).
std::mt19937_64 Stream(uint64_t seed, uint64_t family) {
  return std::mt19937_64(SplitMix64(SplitMix64(seed) ^ (family * 0xD6E8FEB86659FD93ull)));
}

double Uniform(std::mt19937_64& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}

// Uniform [0, 1) from a hash, for per-cell jitter evaluated on the fly.
double HashUnit(uint64_t h) { return static_cast<double>(h >> 11) * 0x1.0p-53; }

double SmoothStep01(double t) {
  t = std::clamp(t, 0.0, 1.0);
  return t * t * t * (t * (t * 6 - 15) + 10);
}

// Quintic smoothstep on [0, 1] (C2, so normals of walls are continuous); flat outside.
J SmoothStep01(const J& t) {
  if (t.a <= 0) return J(0.0);
  if (t.a >= 1) return J(1.0);
  return t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
}

// Amplitude factor for a periodic feature of wavelength_mm on a grid of pitch_mm.
double Fade(double wavelength_mm, double pitch_mm) {
  double texels = wavelength_mm / pitch_mm;
  return SmoothStep01((texels - kFadeStartTexels) / (kFadeEndTexels - kFadeStartTexels));
}

// A Gaussian of nominal sigma after the band-limiting blur: wider, lower, same area.
struct BlurredGaussian {
  double sigma = 1, scale = 1;
  BlurredGaussian() = default;
  BlurredGaussian(double sigma_mm, double pitch_mm) {
    double blur = kBlurTexels * pitch_mm;
    sigma = std::sqrt(sigma_mm * sigma_mm + blur * blur);
    scale = sigma_mm / sigma;
  }
  J operator()(const J& d) const { return scale * exp(-(d * d) / (2 * sigma * sigma)); }
};

// Width of a wall (mm) after band-limiting.
double WallWidth(double nominal_mm, double pitch_mm) {
  double min_mm = kWallTexels * pitch_mm;
  return std::sqrt(nominal_mm * nominal_mm + min_mm * min_mm);
}

// Per-tile table of a Waves field at the texel centres: sin(k.p + phase) splits into a column
// factor and a row factor (angle addition), so a texel costs a few multiplications instead of a
// sine per term (the fields are evaluated at every texel several times).
struct WaveTable {
  int nx = 0, ny = 0;
  std::vector<double> amp, kx, ky;
  std::vector<double> col_sin, col_cos, row_sin, row_cos;  // [term * n + i]

  J Eval(int ix, int iy) const {
    double v = 0, gx = 0, gy = 0;
    for (size_t t = 0; t < amp.size(); ++t) {
      double sx = col_sin[t * nx + ix], cx = col_cos[t * nx + ix];
      double sy = row_sin[t * ny + iy], cy = row_cos[t * ny + iy];
      double s = sx * cy + cx * sy, c = cx * cy - sx * sy;
      v += amp[t] * s;
      gx += amp[t] * kx[t] * c;
      gy += amp[t] * ky[t] * c;
    }
    J r(v);
    r.v[0] = gx;
    r.v[1] = gy;
    return r;
  }
  double Value(int ix, int iy) const {
    double v = 0;
    for (size_t t = 0; t < amp.size(); ++t)
      v += amp[t] * (col_sin[t * nx + ix] * row_cos[t * ny + iy] +
                     col_cos[t * nx + ix] * row_sin[t * ny + iy]);
    return v;
  }
};

// Where a texel-centre evaluation happens: the tile's tables and the texel's place in the tile.
struct At {
  const WaveTable* tables = nullptr;
  int ix = 0, iy = 0;
};

// Sum of a few plane waves: a cheap smooth random field with an exact gradient.
struct Waves {
  struct Term {
    double amplitude, kx, ky, phase;
  };
  std::vector<Term> terms;

  static Waves Random(std::mt19937_64& rng, int count, double amplitude, double min_wavelength_mm,
                      double max_wavelength_mm) {
    Waves w;
    for (int i = 0; i < count; ++i) {
      double angle = Uniform(rng, 0, 2 * kPi);
      double k = 2 * kPi / Uniform(rng, min_wavelength_mm, max_wavelength_mm);
      w.terms.push_back({amplitude / std::sqrt(static_cast<double>(count)) * Uniform(rng, 0.6, 1.4),
                         k * std::cos(angle), k * std::sin(angle), Uniform(rng, 0, 2 * kPi)});
    }
    return w;
  }
  int slot = -1;  // index of its WaveTable in a tile (assigned when the model is complete)

  J operator()(const At& at) const { return at.tables[slot].Eval(at.ix, at.iy); }
  double Value(const At& at) const { return at.tables[slot].Value(at.ix, at.iy); }

  WaveTable Tabulate(const std::vector<double>& xs, const std::vector<double>& ys) const {
    WaveTable w;
    w.nx = static_cast<int>(xs.size());
    w.ny = static_cast<int>(ys.size());
    for (const Term& t : terms) {
      w.amp.push_back(t.amplitude);
      w.kx.push_back(t.kx);
      w.ky.push_back(t.ky);
      for (double x : xs) {
        w.col_sin.push_back(std::sin(t.kx * x));
        w.col_cos.push_back(std::cos(t.kx * x));
      }
      for (double y : ys) {
        w.row_sin.push_back(std::sin(t.ky * y + t.phase));
        w.row_cos.push_back(std::cos(t.ky * y + t.phase));
      }
    }
    return w;
  }

  double MaxAbs() const {
    double sum = 0;
    for (const Term& t : terms) sum += std::abs(t.amplitude);
    return sum;
  }
};

struct Box2 {
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // mm
  bool Contains(double x, double y) const { return x >= x0 && x <= x1 && y >= y0 && y <= y1; }
};

// ---------------------------------------------------------------------------------------------
// Weave: plain weave as two crossing thread families (over/under term + thread cross-sections),
// with slowly wandering threads and a slowly varying amplitude.

struct Weave {
  double period_mm = 1, amplitude_mm = 0;
  double fade_cross = 0, fade_threads = 0;  // over/under term (wavelength P/sqrt2), threads (P/2)
  Waves wander_x, wander_y, amplitude_mod;

  J operator()(const J& x, const J& y, const At& at) const {
    if (amplitude_mm == 0 || (fade_cross == 0 && fade_threads == 0)) return J(0.0);
    J u = x + wander_x(at), v = y + wander_y(at);
    double k = 2 * kPi / period_mm;
    J over_under = sin(k * u) * sin(k * v);
    J threads = 0.5 * (cos(2 * k * u) + cos(2 * k * v));
    J amplitude = amplitude_mm * (1.0 + amplitude_mod(at));
    return amplitude * (0.75 * fade_cross * over_under + 0.25 * fade_threads * threads);
  }
};

// ---------------------------------------------------------------------------------------------
// Strokes along circular arcs: elongated, gently curved, with an exact (along, across) frame.

enum class StrokeKind { kBrush, kKnife };

struct Stroke {
  StrokeKind kind = StrokeKind::kBrush;
  double cx = 0, cy = 0, radius = 0;  // arc centre and radius (mm)
  double theta_mid = 0, half_angle = 0;
  double turn = 1;  // +1 / -1: direction of travel along the arc
  double length_mm = 0, half_width_mm = 0;
  double wobble = 0, wobble_cycles = 0, wobble_phase = 0;  // width variation along the stroke
  double height_mm = 0;
  double edge_mm = 0;               // wall width after band-limiting
  double end_mm = 0, start_mm = 0;  // taper lengths at the ends
  BlurredGaussian ridge;            // brush: ridges of paint pushed to the stroke's edges
  double ridge_inset_mm = 0;
  double stria_period_mm = 1, stria_amp = 0, stria_phase = 0;  // bristle marks (faded)
  double knife_tilt = 0;  // knife: top tilted across the stroke
  BlurredGaussian pile;   // knife: paint piled up at the end of the stroke
  uint8_t region = 0;
  Box2 bounds;

  // Paint thickness (mm, >= 0) at (x, y).
  J operator()(const J& x, const J& y) const {
    J dx = x - cx, dy = y - cy;
    double rho_scalar = std::hypot(dx.a, dy.a);
    double reach = half_width_mm * (1 + wobble) + edge_mm;
    if (std::abs(rho_scalar - radius) > reach) return J(0.0);
    J rho = sqrt(dx * dx + dy * dy);
    J theta = atan2(dy, dx);
    double wrap = 2 * kPi * std::round((theta.a - theta_mid) / (2 * kPi));
    J along = (turn * (theta - theta_mid - wrap) + half_angle) * radius;  // 0 .. length_mm
    if (along.a < -edge_mm || along.a > length_mm + edge_mm) return J(0.0);
    J across = rho - radius;

    // Half-width: wobbles with brush pressure, narrows as the brush lifts at the end.
    J width = half_width_mm *
              (1.0 + wobble * sin(2 * kPi * wobble_cycles * along / length_mm + wobble_phase)) *
              (1.0 - 0.4 * SmoothStep01((along - 0.75 * length_mm) / (0.25 * length_mm)));
    // Smooth |across| (its kink at the centre line would put a crease in the normals).
    J dist = sqrt(across * across + 0.01 * edge_mm * edge_mm);
    J lateral = SmoothStep01((width - dist) / edge_mm);
    if (lateral.a == 0) return J(0.0);
    J ends = SmoothStep01(along / start_mm) * SmoothStep01((length_mm - along) / end_mm);

    if (kind == StrokeKind::kBrush) {
      J load = 1.0 - 0.35 * along / length_mm;  // the brush runs out of paint
      J profile = 0.5 + 0.5 * ridge(dist - (width - ridge_inset_mm));
      J stria = 1.0 + stria_amp * sin(2 * kPi * across / stria_period_mm + stria_phase +
                                      0.6 * sin(along / (4 * stria_period_mm)));
      return height_mm * lateral * ends * load * profile * stria;
    }
    J top = 0.75 + knife_tilt * across / half_width_mm + 0.35 * pile(along - 0.93 * length_mm);
    J stria = 1.0 + stria_amp * sin(2 * kPi * across / stria_period_mm + stria_phase);
    return height_mm * lateral * ends * top * stria;
  }
};

// ---------------------------------------------------------------------------------------------
// Impasto blobs: irregular (harmonic-perturbed, elliptical) domes with walls from soft to steep.

struct Blob {
  double cx = 0, cy = 0, cos_a = 1, sin_a = 0, aspect = 1;
  double radius_mm = 1;
  std::array<double, 3> harmonic_amp{}, harmonic_phase{};  // k = 2, 3, 5
  double height_mm = 0, wall_mm = 0, dome = 0;
  double swirl_period_mm = 1, swirl_amp = 0;
  uint8_t region = 0;
  Box2 bounds;

  J operator()(const J& x, const J& y) const {
    J dx = x - cx, dy = y - cy;
    J u = cos_a * dx + sin_a * dy;
    J v = (-sin_a * dx + cos_a * dy) * aspect;
    J r2 = u * u + v * v;
    if (r2.a < 1e-18) u += 1e-9;  // atan2 and sqrt have no derivative at the very centre
    r2 = u * u + v * v;
    J r = sqrt(r2);
    double max_r = radius_mm * (1 + harmonic_amp[0] + harmonic_amp[1] + harmonic_amp[2]);
    if (r.a > max_r + wall_mm) return J(0.0);
    J theta = atan2(v, u);
    J boundary = radius_mm * (1.0 + harmonic_amp[0] * cos(2.0 * theta + harmonic_phase[0]) +
                              harmonic_amp[1] * cos(3.0 * theta + harmonic_phase[1]) +
                              harmonic_amp[2] * cos(5.0 * theta + harmonic_phase[2]));
    J wall = SmoothStep01((boundary - r) / wall_mm);
    if (wall.a == 0) return J(0.0);
    J rel = r / boundary;
    J shape = 1.0 - dome * rel * rel;
    J swirl = 1.0 + swirl_amp * sin(2 * kPi * r / swirl_period_mm + 3.0 * theta);
    return height_mm * wall * shape * swirl;
  }
};

// ---------------------------------------------------------------------------------------------
// Craquelure: a (domain-warped) Voronoi network; the groove depth follows the distance to the
// boundary of the texel's cell (smooth minimum over the bisectors with its neighbours, exact for
// the convex cell and without creases at junctions).

struct CrackLevel {
  double cell_mm = 8, jitter = 0.85;
  double depth_mm = 0;
  BlurredGaussian groove, lip;
  double lip_share = 0.15;  // cupping: paint islands curl up beside the crack
  double smin_mm = 0.05;
  Waves warp_x, warp_y;
  double max_warp_mm = 0;  // bound on |warp| per axis
  Waves presence;          // > 0 where this level's cracks exist
  bool use_presence = false;
  uint64_t seed = 0;

  // Beyond this distance from a cell boundary the groove and lip are negligible (< 1e-3 of the
  // depth); smooth-min terms more than kSminCut softenings above the minimum change the result by
  // less than 0.3 % of the softening.
  double Reach() const { return 3.8 * std::max(groove.sigma, lip.sigma); }
  static constexpr double kSminCut = 6;

  Eigen::Vector2d Site(int64_t i, int64_t j) const {
    uint64_t h = SplitMix64(seed ^ SplitMix64(static_cast<uint64_t>(i) * 0x9E3779B1ull +
                                              static_cast<uint64_t>(j) * 0x85EBCA77ull));
    double jx = HashUnit(h), jy = HashUnit(SplitMix64(h));
    return {(static_cast<double>(i) + 0.5 + jitter * (jx - 0.5)) * cell_mm,
            (static_cast<double>(j) + 0.5 + jitter * (jy - 0.5)) * cell_mm};
  }

  // The sites of every cell a warped point of box b can look at (its cell and the 8 around).
  struct Sites {
    int64_t i0 = 0, j0 = 0;
    int nx = 0, ny = 0;
    std::vector<Eigen::Vector2d> site;
  };
  Sites CacheSites(const Box2& b) const {
    Sites c;
    double m = max_warp_mm + cell_mm;
    c.i0 = static_cast<int64_t>(std::floor((b.x0 - m) / cell_mm));
    c.j0 = static_cast<int64_t>(std::floor((b.y0 - m) / cell_mm));
    c.nx = static_cast<int>(std::floor((b.x1 + m) / cell_mm) - c.i0) + 1;
    c.ny = static_cast<int>(std::floor((b.y1 + m) / cell_mm) - c.j0) + 1;
    for (int j = 0; j < c.ny; ++j)
      for (int i = 0; i < c.nx; ++i) c.site.push_back(Site(c.i0 + i, c.j0 + j));
    return c;
  }
  Eigen::Vector2d Lookup(const Sites& c, int64_t i, int64_t j) const {
    int64_t li = i - c.i0, lj = j - c.j0;
    if (li < 0 || lj < 0 || li >= c.nx || lj >= c.ny) return Site(i, j);  // not expected
    return c.site[static_cast<size_t>(lj * c.nx + li)];
  }

  J operator()(const J& x, const J& y, const Sites& cache, const At& at) const {
    if (depth_mm == 0) return J(0.0);
    if (use_presence && presence.Value(at) / 0.3 + 0.5 <= 0) return J(0.0);
    // Scalar pass: nearest site and distances to its bisectors; most texels stop here.
    const double qx_s = x.a + warp_x.Value(at), qy_s = y.a + warp_y.Value(at);
    const int64_t ci = static_cast<int64_t>(std::floor(qx_s / cell_mm));
    const int64_t cj = static_cast<int64_t>(std::floor(qy_s / cell_mm));
    const Eigen::Vector2d q(qx_s, qy_s);
    std::array<Eigen::Vector2d, 9> sites;
    int nearest = 0;
    double best = 1e300;
    for (int k = 0; k < 9; ++k) {
      sites[k] = Lookup(cache, ci + k % 3 - 1, cj + k / 3 - 1);
      double d2 = (sites[k] - q).squaredNorm();
      if (d2 < best) best = d2, nearest = k;
    }
    const Eigen::Vector2d& a = sites[nearest];
    std::array<Eigen::Vector2d, 9> normal, mid;
    std::array<double, 9> dist{};
    double dmin = 1e300;
    for (int k = 0; k < 9; ++k) {
      if (k == nearest) continue;
      normal[k] = (sites[k] - a).normalized();
      mid[k] = 0.5 * (sites[k] + a);
      dist[k] = -(q - mid[k]).dot(normal[k]);  // >= 0 on a's side
      dmin = std::min(dmin, dist[k]);
    }
    if (dmin > Reach()) return J(0.0);

    // Jet pass near a crack.
    J strength(1.0);
    if (use_presence) strength = SmoothStep01(presence(at) / 0.3 + 0.5);
    J qx = x + warp_x(at), qy = y + warp_y(at);
    J sum(0.0), dmin_j(0.0);
    std::array<J, 9> near;
    int count = 0;
    for (int k = 0; k < 9; ++k) {
      if (k == nearest || dist[k] > dmin + kSminCut * smin_mm) continue;
      near[count++] = -((qx - mid[k].x()) * normal[k].x() + (qy - mid[k].y()) * normal[k].y());
    }
    J d = near[0];
    if (count > 1) {
      for (int k = 0; k < count; ++k) sum += exp(-(near[k] - dmin) / smin_mm);
      d = dmin - smin_mm * log(sum);
    }
    return strength * depth_mm * (lip_share * lip(d) - groove(d));
  }
};

// ---------------------------------------------------------------------------------------------
// Paint regions: warped Voronoi patches; strokes and blobs paint their own region on top.

struct Regions {
  std::vector<Eigen::Vector2d> sites;
  std::vector<uint8_t> label;
  Waves warp_x, warp_y;
  double max_warp_mm = 0;  // bound on |warp| per axis

  // Sites that can be nearest to some warped point of the box b: all those whose distance to
  // the (warp-expanded) box is at most the smallest farthest-distance of any site to it.
  std::vector<int> Candidates(const Box2& b) const {
    Box2 e{b.x0 - max_warp_mm, b.y0 - max_warp_mm, b.x1 + max_warp_mm, b.y1 + max_warp_mm};
    auto min_d2 = [&](const Eigen::Vector2d& s) {
      double dx = std::max({e.x0 - s.x(), 0.0, s.x() - e.x1});
      double dy = std::max({e.y0 - s.y(), 0.0, s.y() - e.y1});
      return dx * dx + dy * dy;
    };
    auto max_d2 = [&](const Eigen::Vector2d& s) {
      double dx = std::max(std::abs(s.x() - e.x0), std::abs(s.x() - e.x1));
      double dy = std::max(std::abs(s.y() - e.y0), std::abs(s.y() - e.y1));
      return dx * dx + dy * dy;
    };
    double bound = 1e300;
    for (const auto& s : sites) bound = std::min(bound, max_d2(s));
    std::vector<int> out;
    for (size_t i = 0; i < sites.size(); ++i)
      if (min_d2(sites[i]) <= bound) out.push_back(static_cast<int>(i));
    return out;
  }

  uint8_t operator()(double x, double y, const std::vector<int>& candidates, const At& at) const {
    Eigen::Vector2d q(x + warp_x.Value(at), y + warp_y.Value(at));
    int best = candidates.front();
    double best_d2 = 1e300;
    for (int i : candidates) {
      double d2 = (sites[static_cast<size_t>(i)] - q).squaredNorm();
      if (d2 < best_d2) best_d2 = d2, best = i;
    }
    return label[static_cast<size_t>(best)];
  }
};

// A stroke or blob claims the region of the texels where it is at least this share of its height.
constexpr double kRegionCoverShare = 0.3;

// ---------------------------------------------------------------------------------------------
// Feature generation

struct Model {
  double pitch_mm = 1;
  bool weave_on = false, craquelure_on = false;
  Weave weave;
  std::vector<Stroke> strokes;  // painting order: strokes first ...
  std::vector<Blob> blobs;      // ... then impasto on top
  std::vector<CrackLevel> cracks;
  Regions regions;
  std::vector<Waves*> waves;  // every field, in slot order (see AssignSlots)

  // Called once the model is complete (the vectors above no longer move).
  void AssignSlots() {
    waves = {&weave.wander_x, &weave.wander_y, &weave.amplitude_mod, &regions.warp_x,
             &regions.warp_y};
    for (CrackLevel& c : cracks) {
      waves.push_back(&c.warp_x);
      waves.push_back(&c.warp_y);
      waves.push_back(&c.presence);
    }
    for (size_t i = 0; i < waves.size(); ++i) waves[i]->slot = static_cast<int>(i);
  }
};

Box2 ArcBounds(const Stroke& s) {
  Box2 b{1e300, 1e300, -1e300, -1e300};
  for (int i = 0; i <= 32; ++i) {
    double t = s.theta_mid + s.half_angle * (2.0 * i / 32 - 1);
    double px = s.cx + s.radius * std::cos(t), py = s.cy + s.radius * std::sin(t);
    b.x0 = std::min(b.x0, px), b.y0 = std::min(b.y0, py);
    b.x1 = std::max(b.x1, px), b.y1 = std::max(b.y1, py);
  }
  // The chord sampling misses at most radius*(1-cos(half_angle/32)); a wide margin covers it.
  double margin = s.half_width_mm * (1 + s.wobble) + 2 * s.edge_mm + 1.0;
  b.x0 -= margin, b.y0 -= margin, b.x1 += margin, b.y1 += margin;
  return b;
}

// An arc of given length through a random point with a random heading; radius from gentle to
// moderately curved.
void PlaceArc(std::mt19937_64& rng, double w, double h, double length_mm, Stroke& s) {
  double px = Uniform(rng, 0, w), py = Uniform(rng, 0, h);
  double heading = Uniform(rng, 0, 2 * kPi);
  s.radius = length_mm * Uniform(rng, 0.6, 4.0);
  s.turn = Uniform(rng, 0, 1) < 0.5 ? -1 : 1;
  // Centre on the left (turn +1: counter-clockwise travel) of the heading at the midpoint.
  double nx = -std::sin(heading) * s.turn, ny = std::cos(heading) * s.turn;
  s.cx = px + nx * s.radius;
  s.cy = py + ny * s.radius;
  s.theta_mid = std::atan2(py - s.cy, px - s.cx);
  s.length_mm = length_mm;
  s.half_angle = 0.5 * length_mm / s.radius;
}

Model BuildModel(const PaintingOptions& o, double w, double h, double pitch) {
  Model m;
  m.pitch_mm = pitch;
  double area_cm2 = w * h / 100.0;
  double long_mm = std::max(w, h), short_mm = std::min(w, h);
  int regions = o.region_count;
  auto region_of = [&](std::mt19937_64& rng) {
    return static_cast<uint8_t>(std::uniform_int_distribution<int>(0, regions - 1)(rng));
  };

  {  // Weave
    auto rng = Stream(o.seed, 1);
    m.weave.period_mm = o.weave_period_mm;
    m.weave.amplitude_mm = o.weave ? o.weave_amplitude_mm : 0;
    m.weave.fade_cross = Fade(o.weave_period_mm / std::sqrt(2.0), pitch);
    m.weave.fade_threads = Fade(o.weave_period_mm / 2, pitch);
    m.weave.wander_x = Waves::Random(rng, 3, 0.08 * o.weave_period_mm, 20, 80);
    m.weave.wander_y = Waves::Random(rng, 3, 0.08 * o.weave_period_mm, 20, 80);
    m.weave.amplitude_mod = Waves::Random(rng, 3, 0.2, 30, 150);
    m.weave_on =
        o.weave && m.weave.amplitude_mm > 0 && (m.weave.fade_cross > 0 || m.weave.fade_threads > 0);
  }

  {  // Regions (always drawn so later streams do not shift when features are switched)
    auto rng = Stream(o.seed, 2);
    int sites = std::max(8, 2 * regions);
    for (int i = 0; i < sites; ++i) {
      m.regions.sites.emplace_back(Uniform(rng, 0, w), Uniform(rng, 0, h));
      m.regions.label.push_back(static_cast<uint8_t>(i % regions));
    }
    std::shuffle(m.regions.label.begin(), m.regions.label.end(), rng);
    m.regions.warp_x = Waves::Random(rng, 3, 0.04 * long_mm, 0.15 * long_mm, 0.5 * long_mm);
    m.regions.warp_y = Waves::Random(rng, 3, 0.04 * long_mm, 0.15 * long_mm, 0.5 * long_mm);
    m.regions.max_warp_mm = std::max(m.regions.warp_x.MaxAbs(), m.regions.warp_y.MaxAbs());
  }

  if (o.strokes) {
    auto rng = Stream(o.seed, 3);
    int count = o.stroke_count > 0 ? o.stroke_count
                                   : std::max(1, static_cast<int>(std::lround(area_cm2 / 20)));
    for (int i = 0; i < count; ++i) {
      Stroke s;
      s.kind = StrokeKind::kBrush;
      double length = std::min(Uniform(rng, 15, 120), 0.8 * long_mm);
      PlaceArc(rng, w, h, length, s);
      s.half_width_mm = std::min(Uniform(rng, 1.5, 8.0), 0.25 * short_mm);
      s.wobble = Uniform(rng, 0.05, 0.2);
      s.wobble_cycles = Uniform(rng, 0.5, 2.5);
      s.wobble_phase = Uniform(rng, 0, 2 * kPi);
      s.height_mm = Uniform(rng, o.stroke_min_mm, o.stroke_max_mm);
      s.edge_mm = WallWidth(Uniform(rng, 0.2, 0.6), pitch);
      s.start_mm = std::max(s.half_width_mm * 0.6, s.edge_mm);
      s.end_mm = std::max(s.length_mm * 0.25, s.edge_mm);
      double ridge_sigma = Uniform(rng, 0.15, 0.5) * std::min(1.0, s.half_width_mm / 3);
      s.ridge = BlurredGaussian(ridge_sigma, pitch);
      s.ridge_inset_mm = s.edge_mm + 1.5 * ridge_sigma;
      s.stria_period_mm = Uniform(rng, 0.3, 1.2);
      s.stria_amp = 0.25 * Fade(s.stria_period_mm, pitch);
      s.stria_phase = Uniform(rng, 0, 2 * kPi);
      s.region = region_of(rng);
      s.bounds = ArcBounds(s);
      m.strokes.push_back(s);
    }
  }

  if (o.impasto && o.impasto_max_mm > 0) {
    auto rng = Stream(o.seed, 4);
    int count = o.impasto_count > 0 ? o.impasto_count
                                    : std::max(1, static_cast<int>(std::lround(area_cm2 / 60)));
    for (int i = 0; i < count; ++i) {
      bool knife = Uniform(rng, 0, 1) < 0.4;
      double height = o.impasto_max_mm * Uniform(rng, 0.35, 1.0);
      // Some walls nearly vertical (knife cuts), others soft (slumped paint).
      double wall = Uniform(rng, 0, 1) < 0.5 ? Uniform(rng, 0.03, 0.15) : Uniform(rng, 0.5, 2.0);
      if (knife) {
        Stroke s;
        s.kind = StrokeKind::kKnife;
        double length = std::min(Uniform(rng, 10, 45), 0.5 * long_mm);
        PlaceArc(rng, w, h, length, s);
        s.radius *= 2;  // knife strokes are straighter than brush strokes
        s.half_angle = 0.5 * s.length_mm / s.radius;
        s.half_width_mm = std::min(Uniform(rng, 3, 9), 0.25 * short_mm);
        s.wobble = Uniform(rng, 0.02, 0.1);
        s.wobble_cycles = Uniform(rng, 0.3, 1.5);
        s.wobble_phase = Uniform(rng, 0, 2 * kPi);
        s.height_mm = height;
        s.edge_mm = WallWidth(wall, pitch);
        s.start_mm = std::max(Uniform(rng, 1, 4), s.edge_mm);
        s.end_mm = s.edge_mm;  // the knife lifts off sharply
        s.knife_tilt = Uniform(rng, -0.2, 0.2);
        s.pile = BlurredGaussian(0.04 * length, pitch);
        s.stria_period_mm = Uniform(rng, 1.5, 4);
        s.stria_amp = 0.08 * Fade(s.stria_period_mm, pitch);
        s.stria_phase = Uniform(rng, 0, 2 * kPi);
        s.region = region_of(rng);
        // Re-centre the arc after the radius change: keep the midpoint where it was drawn.
        double mx = s.cx + (s.radius / 2) * std::cos(s.theta_mid);
        double my = s.cy + (s.radius / 2) * std::sin(s.theta_mid);
        s.cx = mx - s.radius * std::cos(s.theta_mid);
        s.cy = my - s.radius * std::sin(s.theta_mid);
        s.bounds = ArcBounds(s);
        m.strokes.push_back(s);  // drawn after every brush stroke (same painting order)
      } else {
        Blob b;
        b.cx = Uniform(rng, 0, w);
        b.cy = Uniform(rng, 0, h);
        double angle = Uniform(rng, 0, 2 * kPi);
        b.cos_a = std::cos(angle), b.sin_a = std::sin(angle);
        b.aspect = Uniform(rng, 1.0, 2.2);
        b.radius_mm = std::min(Uniform(rng, 2.5, 12), 0.2 * short_mm);
        for (int k = 0; k < 3; ++k) {
          b.harmonic_amp[k] = Uniform(rng, 0, 0.12);
          b.harmonic_phase[k] = Uniform(rng, 0, 2 * kPi);
        }
        b.height_mm = height;
        b.wall_mm = WallWidth(wall, pitch);
        b.dome = Uniform(rng, 0.1, 0.6);
        b.swirl_period_mm = Uniform(rng, 0.8, 2.5);
        b.swirl_amp = 0.06 * Fade(b.swirl_period_mm, pitch);
        b.region = region_of(rng);
        double reach =
            b.radius_mm * (1 + b.harmonic_amp[0] + b.harmonic_amp[1] + b.harmonic_amp[2]) +
            b.wall_mm + 1.0;
        b.bounds = {b.cx - reach, b.cy - reach, b.cx + reach, b.cy + reach};
        m.blobs.push_back(b);
      }
    }
  }

  if (o.craquelure && o.crack_depth_mm > 0) {
    auto rng = Stream(o.seed, 5);
    // Primary network (islands of ~8 mm) and a partial secondary one inside the islands.
    for (int level = 0; level < 2; ++level) {
      CrackLevel c;
      c.cell_mm = level == 0 ? Uniform(rng, 6, 10) : Uniform(rng, 2.5, 4);
      double width = o.crack_width_mm * (level == 0 ? 1.0 : 0.6);
      double fade = Fade(c.cell_mm, pitch);
      c.depth_mm = o.crack_depth_mm * (level == 0 ? 1.0 : 0.5) * fade;
      c.groove = BlurredGaussian(width / 2.5, pitch);
      c.lip = BlurredGaussian(1.2 * width, pitch);
      c.smin_mm = 0.3 * c.groove.sigma;
      c.warp_x = Waves::Random(rng, 3, 0.12 * c.cell_mm, 2 * c.cell_mm, 5 * c.cell_mm);
      c.warp_y = Waves::Random(rng, 3, 0.12 * c.cell_mm, 2 * c.cell_mm, 5 * c.cell_mm);
      c.max_warp_mm = std::max(c.warp_x.MaxAbs(), c.warp_y.MaxAbs());
      c.use_presence = level == 1;
      c.presence = Waves::Random(rng, 4, 1.0, 3 * c.cell_mm, 10 * c.cell_mm);
      c.seed = rng();
      if (c.depth_mm > 0) m.cracks.push_back(c);
    }
    m.craquelure_on = !m.cracks.empty();
  }
  m.AssignSlots();
  return m;
}

}  // namespace

Status PaintingOptions::Validate() const {
  auto fail = [](const std::string& what) { return Status(Error{"painting options: " + what}); };
  if (!(std::isfinite(width_mm) && width_mm > 0 && width_mm <= 1e5))
    return fail("width_mm must be in (0, 100000], got " + FormatNumber(width_mm));
  if (!(std::isfinite(height_mm) && height_mm > 0 && height_mm <= 1e5))
    return fail("height_mm must be in (0, 100000], got " + FormatNumber(height_mm));
  if (resolution_px < 64 || resolution_px > 16384)
    return fail("resolution_px must be in [64, 16384], got " + std::to_string(resolution_px));
  if (std::max(width_mm, height_mm) / std::min(width_mm, height_mm) > resolution_px)
    return fail("canvas aspect ratio " +
                FormatNumber(std::max(width_mm, height_mm) / std::min(width_mm, height_mm)) +
                " leaves less than one texel on the short side at resolution_px " +
                std::to_string(resolution_px));
  if (!(std::isfinite(weave_period_mm) && weave_period_mm > 0))
    return fail("weave_period_mm must be > 0, got " + FormatNumber(weave_period_mm));
  if (!(std::isfinite(weave_amplitude_mm) && weave_amplitude_mm >= 0 && weave_amplitude_mm <= 10))
    return fail("weave_amplitude_mm must be in [0, 10], got " + FormatNumber(weave_amplitude_mm));
  if (stroke_count < 0 || stroke_count > 100000)
    return fail("stroke_count must be in [0, 100000], got " + std::to_string(stroke_count));
  if (!(std::isfinite(stroke_min_mm) && stroke_min_mm >= 0))
    return fail("stroke_min_mm must be >= 0, got " + FormatNumber(stroke_min_mm));
  if (!(std::isfinite(stroke_max_mm) && stroke_max_mm >= stroke_min_mm && stroke_max_mm <= 100))
    return fail("stroke_max_mm must be in [stroke_min_mm, 100], got " +
                FormatNumber(stroke_max_mm));
  if (impasto_count < 0 || impasto_count > 100000)
    return fail("impasto_count must be in [0, 100000], got " + std::to_string(impasto_count));
  if (!(std::isfinite(impasto_max_mm) && impasto_max_mm >= 0 && impasto_max_mm <= 100))
    return fail("impasto_max_mm must be in [0, 100], got " + FormatNumber(impasto_max_mm));
  if (!(std::isfinite(crack_depth_mm) && crack_depth_mm >= 0 && crack_depth_mm <= 100))
    return fail("crack_depth_mm must be in [0, 100], got " + FormatNumber(crack_depth_mm));
  if (!(std::isfinite(crack_width_mm) && crack_width_mm > 0 && crack_width_mm <= 100))
    return fail("crack_width_mm must be in (0, 100], got " + FormatNumber(crack_width_mm));
  if (region_count < 1 || region_count > 256)
    return fail("region_count must be in [1, 256], got " + std::to_string(region_count));
  if (!(std::isfinite(bow_mm) && std::abs(bow_mm) <= 100))
    return fail("bow_mm must be in [-100, 100], got " + FormatNumber(bow_mm));
  return Status::Ok();
}

Painting MakePainting(const PaintingOptions& options) {
  Status valid = options.Validate();
  DIGITIZE_CHECK(valid.ok(), "MakePainting: " + valid.message());

  // Grid: resolution_px texels on the long side; the canvas is exactly the grid's extent.
  double long_mm = std::max(options.width_mm, options.height_mm);
  double pitch = long_mm / options.resolution_px;
  int w_px = std::max(1, static_cast<int>(std::lround(options.width_mm / pitch)));
  int h_px = std::max(1, static_cast<int>(std::lround(options.height_mm / pitch)));

  Painting p;
  p.options = options;
  p.width_mm = w_px * pitch;
  p.height_mm = h_px * pitch;
  p.truth.pitch_mm = pitch;
  p.truth.height_mm = Grid<float>(w_px, h_px, 0.0f);
  p.truth.state = Grid<TexelState>(w_px, h_px, TexelState::kMeasured);
  p.normals = Grid<Vec3f>(w_px, h_px, Vec3f(0, 0, 1));
  p.region = Grid<uint8_t>(w_px, h_px, 0);

  Model model = BuildModel(options, p.width_mm, p.height_mm, pitch);

  // Bin strokes and blobs into tiles so each texel only looks at the few that can reach it.
  int tiles_x = (w_px + kTilePx - 1) / kTilePx, tiles_y = (h_px + kTilePx - 1) / kTilePx;
  std::vector<std::vector<int>> tile_strokes(static_cast<size_t>(tiles_x) * tiles_y);
  std::vector<std::vector<int>> tile_blobs(tile_strokes.size());
  auto bin = [&](const Box2& b, int index, std::vector<std::vector<int>>& bins) {
    // Texel x covers X in [x*pitch, (x+1)*pitch]; rows are flipped (row 0 = top).
    int x0 = std::max(0, static_cast<int>(std::floor(b.x0 / pitch)));
    int x1 = std::min(w_px - 1, static_cast<int>(std::floor(b.x1 / pitch)));
    int y0 = std::max(0, static_cast<int>(std::floor((p.height_mm - b.y1) / pitch)));
    int y1 = std::min(h_px - 1, static_cast<int>(std::floor((p.height_mm - b.y0) / pitch)));
    if (x0 > x1 || y0 > y1) return;
    for (int ty = y0 / kTilePx; ty <= y1 / kTilePx; ++ty)
      for (int tx = x0 / kTilePx; tx <= x1 / kTilePx; ++tx)
        bins[static_cast<size_t>(ty) * tiles_x + tx].push_back(index);
  };
  for (size_t i = 0; i < model.strokes.size(); ++i)
    bin(model.strokes[i].bounds, static_cast<int>(i), tile_strokes);
  for (size_t i = 0; i < model.blobs.size(); ++i)
    bin(model.blobs[i].bounds, static_cast<int>(i), tile_blobs);

  tbb::parallel_for(tbb::blocked_range2d<int>(0, tiles_y, 1, 0, tiles_x, 1),
                    [&](const tbb::blocked_range2d<int>& range) {
                      for (int ty = range.rows().begin(); ty < range.rows().end(); ++ty) {
                        for (int tx = range.cols().begin(); tx < range.cols().end(); ++tx) {
                          size_t tile = static_cast<size_t>(ty) * tiles_x + tx;
                          const std::vector<int>& strokes = tile_strokes[tile];
                          const std::vector<int>& blobs = tile_blobs[tile];
                          int y_end = std::min(h_px, (ty + 1) * kTilePx);
                          int x_end = std::min(w_px, (tx + 1) * kTilePx);
                          const Box2 tile_mm{tx * kTilePx * pitch, p.height_mm - y_end * pitch,
                                             x_end * pitch, p.height_mm - ty * kTilePx * pitch};
                          const std::vector<int> region_sites = model.regions.Candidates(tile_mm);
                          std::vector<CrackLevel::Sites> crack_sites;
                          for (const CrackLevel& crack : model.cracks)
                            crack_sites.push_back(crack.CacheSites(tile_mm));
                          std::vector<double> xs, ys;
                          for (int x = tx * kTilePx; x < x_end; ++x)
                            xs.push_back((x + 0.5) * pitch);
                          for (int y = ty * kTilePx; y < y_end; ++y)
                            ys.push_back(p.height_mm - (y + 0.5) * pitch);
                          std::vector<WaveTable> tables;
                          for (const Waves* w : model.waves) tables.push_back(w->Tabulate(xs, ys));
                          for (int y = ty * kTilePx; y < y_end; ++y) {
                            for (int x = tx * kTilePx; x < x_end; ++x) {
                              const Eigen::Vector2d c(xs[x - tx * kTilePx], ys[y - ty * kTilePx]);
                              const At at{tables.data(), x - tx * kTilePx, y - ty * kTilePx};
                              J X(c.x(), 0), Y(c.y(), 1);
                              uint8_t region = model.regions(c.x(), c.y(), region_sites, at);
                              J paint(0.0);
                              for (int i : strokes) {
                                const Stroke& s = model.strokes[static_cast<size_t>(i)];
                                if (!s.bounds.Contains(c.x(), c.y())) continue;
                                J t = s(X, Y);
                                paint += t;
                                if (t.a >= kRegionCoverShare * s.height_mm && t.a > 0)
                                  region = s.region;
                              }
                              for (int i : blobs) {
                                const Blob& b = model.blobs[static_cast<size_t>(i)];
                                if (!b.bounds.Contains(c.x(), c.y())) continue;
                                J t = b(X, Y);
                                paint += t;
                                if (t.a >= kRegionCoverShare * b.height_mm && t.a > 0)
                                  region = b.region;
                              }
                              J h = paint;
                              if (model.weave_on)
                                h += model.weave(X, Y, at) * exp(-paint / kWeaveBurialMm);
                              for (size_t k = 0; k < model.cracks.size(); ++k)
                                h += model.cracks[k](X, Y, crack_sites[k], at);
                              if (options.bow_mm != 0) {
                                const J u = 2.0 * X / p.width_mm - 1.0,
                                        v = 2.0 * Y / p.height_mm - 1.0;
                                h += options.bow_mm * (1.0 - u * u) * (1.0 - v * v);
                              }
                              p.truth.height_mm(x, y) = static_cast<float>(h.a);
                              Vec3d n(-h.v[0], -h.v[1], 1.0);
                              p.normals(x, y) = n.normalized().cast<float>();
                              p.region(x, y) = region;
                            }
                          }
                        }
                      }
                    });
  // The bare canvas's plane: least squares of the bow over the texel centres (X', Y' centred, so
  // the normal equations separate: offset = mean, slopes = sum(X' bow) / sum(X'^2)).
  if (options.bow_mm != 0) {
    double s = 0, sx = 0, sy = 0, xx = 0, yy = 0;
    for (int y = 0; y < h_px; ++y)
      for (int x = 0; x < w_px; ++x) {
        const double X = (x + 0.5) * pitch, Y = p.height_mm - (y + 0.5) * pitch;
        const double u = 2 * X / p.width_mm - 1, v = 2 * Y / p.height_mm - 1;
        const double b = options.bow_mm * (1 - u * u) * (1 - v * v);
        const double dx = X - 0.5 * p.width_mm, dy = Y - 0.5 * p.height_mm;
        s += b, sx += dx * b, sy += dy * b, xx += dx * dx, yy += dy * dy;
      }
    const double n = static_cast<double>(w_px) * h_px;
    p.bare_plane_offset_mm = s / n;
    p.bare_plane_slope = Eigen::Vector2d(xx > 0 ? sx / xx : 0, yy > 0 ? sy / yy : 0);
    p.bare_plane_normal = Vec3d(-p.bare_plane_slope.x(), -p.bare_plane_slope.y(), 1).normalized();
  }
  return p;
}

}  // namespace digitize::synth
