#include "digitize_viewer/tonal_art_map.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <string>

namespace digitize::viewer {
namespace {

struct Stroke {
  double cx = 0, cy = 0;  // centre, texture coordinates in [0, 1)
  double angle = 0;       // radians
  double length = 0;      // relative to the texture side
};

// A stroke's coverage at one level: (texel index, coverage) pairs, texels wrapped (tiling).
struct Footprint {
  std::vector<int> texel;
  std::vector<float> coverage;
};

// The stroke as a segment `width_px` wide at `side` x `side` texels: coverage is the box-filtered
// line, clamp(width / 2 + 1/2 - distance, 0, 1), distance in texels from the texel centre to the
// segment (its ends included, so strokes have round caps).
void Rasterise(const Stroke& s, int side, double width_px, Footprint& out) {
  out.texel.clear();
  out.coverage.clear();
  const double ux = std::cos(s.angle), uy = std::sin(s.angle);
  const double half = 0.5 * s.length * side;
  const double cx = s.cx * side, cy = s.cy * side;
  const double ax = cx - half * ux, ay = cy - half * uy, bx = cx + half * ux, by = cy + half * uy;
  const double reach = 0.5 * width_px + 0.5;
  const int x0 = static_cast<int>(std::floor(std::min(ax, bx) - reach));
  const int x1 = static_cast<int>(std::ceil(std::max(ax, bx) + reach));
  const int y0 = static_cast<int>(std::floor(std::min(ay, by) - reach));
  const int y1 = static_cast<int>(std::ceil(std::max(ay, by) + reach));
  const double len2 = (bx - ax) * (bx - ax) + (by - ay) * (by - ay);
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x) {
      const double px = x + 0.5, py = y + 0.5;
      double t = len2 > 0 ? ((px - ax) * (bx - ax) + (py - ay) * (by - ay)) / len2 : 0.0;
      t = std::clamp(t, 0.0, 1.0);
      const double dx = px - (ax + t * (bx - ax)), dy = py - (ay + t * (by - ay));
      const double c = std::clamp(reach - std::sqrt(dx * dx + dy * dy), 0.0, 1.0);
      if (c <= 0.0) continue;
      const int wx = ((x % side) + side) % side, wy = ((y % side) + side) % side;
      out.texel.push_back(wy * side + wx);
      out.coverage.push_back(static_cast<float>(c));
    }
}

// Ink added by drawing `f` over `ink` (over-compositing: 1 - (1 - a)(1 - c)), and the ink it
// lands on (the seed's dot product of the stroke with the image).
struct Effect {
  double added = 0, overlap = 0, area = 0;
};
Effect Measure(const Footprint& f, const Grid<float>& ink) {
  Effect e;
  for (size_t i = 0; i < f.texel.size(); ++i) {
    const double a = ink.data[f.texel[i]], c = f.coverage[i];
    e.added += c * (1.0 - a);
    e.overlap += c * a;
    e.area += c;
  }
  return e;
}

void Draw(const Footprint& f, Grid<float>& ink) {
  for (size_t i = 0; i < f.texel.size(); ++i) {
    float& a = ink.data[f.texel[i]];
    a = 1.0f - (1.0f - a) * (1.0f - f.coverage[i]);
  }
}

bool PowerOfTwo(int n) { return n > 0 && (n & (n - 1)) == 0; }

}  // namespace

Status TonalArtMapOptions::Validate() const {
  if (!PowerOfTwo(size) || size < TonalArtMap::kFirstStrokeLevel || size > 4096)
    return Error{"size must be a power of two in [" +
                 std::to_string(TonalArtMap::kFirstStrokeLevel) + ", 4096], got " +
                 std::to_string(size)};
  if (tone_ink.empty() || tone_ink.size() > 16)
    return Error{"tone_ink must hold 1 to 16 tones, got " + std::to_string(tone_ink.size())};
  for (size_t t = 0; t < tone_ink.size(); ++t)
    if (!(tone_ink[t] > (t ? tone_ink[t - 1] : 0.0) && tone_ink[t] < 1.0))
      return Error{"tone_ink must increase within (0, 1); tone " + std::to_string(t) + " is " +
                   FormatNumber(tone_ink[t])};
  if (!(stroke_width_px >= 0.5 && stroke_width_px <= 8))
    return Error{"stroke_width_px must be in [0.5, 8], got " + FormatNumber(stroke_width_px)};
  if (!(min_length > 0 && max_length >= min_length && max_length <= 1))
    return Error{"lengths must satisfy 0 < min_length <= max_length <= 1, got " +
                 FormatNumber(min_length) + " and " + FormatNumber(max_length)};
  if (!(std::isfinite(angle_deg) && std::isfinite(angle_jitter_deg) && angle_jitter_deg >= 0))
    return Error{"angle_deg and angle_jitter_deg (>= 0) must be finite"};
  if (candidates < 1 || candidates > 10000)
    return Error{"candidates must be in [1, 10000], got " + std::to_string(candidates)};
  return Status::Ok();
}

double TonalArtMap::Mean(const Grid<float>& g) {
  double sum = 0;
  for (float v : g.data) sum += v;
  return g.data.empty() ? 0.0 : sum / static_cast<double>(g.data.size());
}

TonalArtMap BuildTonalArtMap(const TonalArtMapOptions& o) {
  const Status valid = o.Validate();
  DIGITIZE_CHECK(valid.ok(), "BuildTonalArtMap: " + valid.message());
  TonalArtMap map;
  map.tones = static_cast<int>(o.tone_ink.size());
  map.levels = 1 + static_cast<int>(std::lround(std::log2(o.size)));
  map.target = o.tone_ink;
  const auto side_of = [&](int level) { return o.size >> level; };
  // The coarsest level that gets strokes; coarser ones are filtered from it.
  const int stroked =
      static_cast<int>(std::lround(std::log2(o.size / TonalArtMap::kFirstStrokeLevel)));
  for (int t = 0; t < map.tones; ++t)
    for (int l = 0; l < map.levels; ++l) map.ink.emplace_back(side_of(l), side_of(l), 0.0f);
  map.strokes.resize(map.ink.size());

  std::mt19937_64 rng(o.seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const double base = o.angle_deg * std::numbers::pi / 180.0;
  const double jitter = o.angle_jitter_deg * std::numbers::pi / 180.0;
  uint32_t next_id = 0;
  std::vector<Stroke> candidates(o.candidates);
  std::vector<Effect> effects(o.candidates);
  Footprint f;
  for (int t = 0; t < map.tones; ++t) {
    for (int l = stroked; l >= 0; --l) {  // coarse to fine
      Grid<float>& ink = map.ink[t * map.levels + l];
      const double texels = static_cast<double>(ink.data.size());
      const double target_sum = o.tone_ink[t] * texels;
      double sum = TonalArtMap::Mean(ink) * texels;
      while (sum < target_sum) {
        for (int c = 0; c < o.candidates; ++c) {
          Stroke& s = candidates[c];
          s.cx = unit(rng);
          s.cy = unit(rng);
          s.length = o.min_length + (o.max_length - o.min_length) * unit(rng);
          const bool cross = t >= o.cross_hatch_from_tone && unit(rng) < 0.5;
          s.angle = base + (cross ? 0.5 * std::numbers::pi : 0.0) + jitter * (2 * unit(rng) - 1);
          Rasterise(s, side_of(l), o.stroke_width_px, f);
          effects[c] = Measure(f, ink);
        }
        const double deficit = target_sum - sum;
        // The stroke that lands on the least ink (per unit of its area), unless it would
        // finish the texture: then the one whose ink lands nearest the target, or none.
        int best = 0;
        for (int c = 1; c < o.candidates; ++c)
          if (effects[c].overlap * effects[best].area < effects[best].overlap * effects[c].area)
            best = c;
        if (effects[best].added >= deficit) {
          int closest = 0;
          for (int c = 1; c < o.candidates; ++c)
            if (std::abs(effects[c].added - deficit) < std::abs(effects[closest].added - deficit))
              closest = c;
          if (std::abs(effects[closest].added - deficit) >= deficit) break;  // nearer without
          best = closest;
        }
        if (!(effects[best].added > 0.0)) break;  // nothing can add ink (not expected)
        // Into this texture, every darker tone and every finer level.
        const uint32_t id = next_id++;
        for (int level = l; level >= 0; --level) {
          Rasterise(candidates[best], side_of(level), o.stroke_width_px, f);
          for (int tone = t; tone < map.tones; ++tone) {
            Draw(f, map.ink[tone * map.levels + level]);
            map.strokes[tone * map.levels + level].push_back(id);
          }
        }
        sum += effects[best].added;
      }
    }
    // Coarser levels: 2 x 2 box filter of the next finer one (mean and tone order kept).
    for (int l = stroked + 1; l < map.levels; ++l) {
      const Grid<float>& fine = map.ink[t * map.levels + l - 1];
      Grid<float>& coarse = map.ink[t * map.levels + l];
      for (int y = 0; y < coarse.height; ++y)
        for (int x = 0; x < coarse.width; ++x)
          coarse(x, y) = 0.25f * (fine(2 * x, 2 * y) + fine(2 * x + 1, 2 * y) +
                                  fine(2 * x, 2 * y + 1) + fine(2 * x + 1, 2 * y + 1));
    }
  }
  return map;
}

}  // namespace digitize::viewer
