// ClassifyRelief against independent brute-force answers on hand-made and random height fields.
#include "digitize/relief.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <queue>
#include <random>
#include <string>
#include <vector>

#include "digitize/height_field.h"
#include "digitize_synth/painting.h"
#include "test_support.h"

namespace digitize {
namespace {

ReliefOptions Options(int cell_px, double min_area_mm2 = 0.0, double fraction = 0.3,
                      double margin_mm = 0.0) {
  ReliefOptions o;
  o.cell_px = cell_px;
  o.min_component_area_mm2 = min_area_mm2;
  o.delta0_fraction = fraction;
  o.noise_margin_mm = margin_mm;
  o.cover_px = 0;  // exact paper semantics: a cell is boxed iff it holds an Mv texel
  return o;
}

// Independent answer: Mv from the definition, then 8-connected components by breadth-first
// search, specks (area < min) removed.
Grid<uint8_t> ExpectedValid(const HeightField& f, const ReliefOptions& o, double* delta0_out) {
  float H = -std::numeric_limits<float>::infinity();
  for (size_t i = 0; i < f.height_mm.size(); ++i)
    if (HasHeight(f.state.data[i])) H = std::max(H, f.height_mm.data[i]);
  Grid<uint8_t> mv(f.width(), f.height(), 0);
  *delta0_out = 0;
  if (!(H > 0)) return mv;
  const double delta0 = o.delta0_fraction * H;
  *delta0_out = delta0;
  for (size_t i = 0; i < mv.size(); ++i)
    mv.data[i] = HasHeight(f.state.data[i]) &&
                 f.height_mm.data[i] > delta0 - std::min(o.noise_margin_mm, 0.5 * delta0);
  Grid<int> label(f.width(), f.height(), 0);
  int next = 0;
  for (int y = 0; y < f.height(); ++y)
    for (int x = 0; x < f.width(); ++x) {
      if (!mv(x, y) || label(x, y)) continue;
      std::vector<std::pair<int, int>> members{{x, y}};
      label(x, y) = ++next;
      for (size_t k = 0; k < members.size(); ++k) {
        const auto [u, v] = members[k];
        for (int dv = -1; dv <= 1; ++dv)
          for (int du = -1; du <= 1; ++du)
            if (mv.Contains(u + du, v + dv) && mv(u + du, v + dv) && !label(u + du, v + dv)) {
              label(u + du, v + dv) = next;
              members.push_back({u + du, v + dv});
            }
      }
      if (members.size() * f.pitch_mm * f.pitch_mm < o.min_component_area_mm2)
        for (const auto& [u, v] : members) mv(u, v) = 0;
    }
  return mv;
}

// Every structural property of a result, checked against the brute-force answer.
void CheckAgainstBruteForce(const HeightField& f, const ReliefOptions& o, const ReliefResult& r) {
  double delta0 = 0;
  const Grid<uint8_t> expected = ExpectedValid(f, o, &delta0);
  EXPECT_DOUBLE_EQ(r.delta0_mm, delta0);
  ASSERT_EQ(r.valid.width, f.width());
  ASSERT_EQ(r.valid.height, f.height());
  ASSERT_EQ(r.valid.data, expected.data);
  size_t above = 0;
  for (uint8_t v : expected.data) above += v;
  EXPECT_EQ(r.texels_above, above);

  // Boxes: on the cell grid, in row-major cell order, each holding valid relief, with the peak
  // of its cell among texels with height (first in row-major order on ties).
  const int n = o.cell_px;
  Grid<int> covered(f.width(), f.height(), 0);
  long previous = -1;
  const long cells_x = (f.width() + static_cast<long>(n) - 1) / n;
  for (const ReliefBox& b : r.boxes) {
    ASSERT_EQ(b.x0 % n, 0);
    ASSERT_EQ(b.y0 % n, 0);
    const long index = (b.y0 / n) * cells_x + b.x0 / n;
    ASSERT_GT(index, previous) << "boxes out of row-major order";
    previous = index;
    ASSERT_EQ(b.width, std::min(n, f.width() - b.x0));
    ASSERT_EQ(b.height, std::min(n, f.height() - b.y0));
    bool any_valid = false;
    float peak = -std::numeric_limits<float>::infinity();
    int pu = -1, pv = -1;
    for (int y = b.y0; y < b.y0 + b.height; ++y)
      for (int x = b.x0; x < b.x0 + b.width; ++x) {
        ++covered(x, y);
        if (HasHeight(f.state(x, y)) && f.height_mm(x, y) > peak) {
          peak = f.height_mm(x, y);
          pu = x;
          pv = y;
        }
      }
    // With cover_px > 0 a box may hold no Mv texel itself but one within cover_px of its cell.
    const int c = o.cover_px;
    for (int y = std::max(0, b.y0 - c); y < std::min(f.height(), b.y0 + b.height + c); ++y)
      for (int x = std::max(0, b.x0 - c); x < std::min(f.width(), b.x0 + b.width + c); ++x)
        any_valid |= expected(x, y) != 0;
    EXPECT_TRUE(any_valid) << "box at " << b.x0 << "," << b.y0 << " holds no relief";
    EXPECT_EQ(b.h_max_mm, peak);
    EXPECT_EQ(b.u_max, pu);
    EXPECT_EQ(b.v_max, pv);
    EXPECT_LE(b.h_max_mm, r.max_height_mm);
  }
  // Completeness: every valid texel lies in exactly one box (the paper: the segmented relief
  // is entirely contained in the boxes).
  for (int y = 0; y < f.height(); ++y)
    for (int x = 0; x < f.width(); ++x) {
      if (expected(x, y)) {
        ASSERT_EQ(covered(x, y), 1) << "valid texel " << x << "," << y;
      }
      ASSERT_LE(covered(x, y), 1);
    }
}

void ExpectNoRelief(const ReliefResult& r, const HeightField& f) {
  EXPECT_TRUE(r.boxes.empty());
  EXPECT_EQ(r.texels_above, 0u);
  EXPECT_EQ(r.valid.width, f.width());
  EXPECT_EQ(r.valid.height, f.height());
  for (uint8_t v : r.valid.data) EXPECT_EQ(v, 0);
}

TEST(ReliefOptions, DefaultsAreValid) { EXPECT_TRUE(ReliefOptions{}.Validate().ok()); }

TEST(ReliefOptions, EachBadValueIsNamed) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  struct Case {
    ReliefOptions o;
    std::string expected;
  };
  std::vector<Case> cases;
  cases.push_back({Options(0), "cell_px must be >= 1, got 0"});
  cases.push_back({Options(-3), "cell_px must be >= 1, got -3"});
  cases.push_back({Options(16, -1.0), "min_component_area_mm2 must be"});
  cases.push_back({Options(16, nan), "min_component_area_mm2 must be"});
  cases.push_back({Options(16, 0.5, 1.5), "delta0_fraction must be in [0, 1]"});
  cases.push_back({Options(16, 0.5, -0.1), "delta0_fraction must be in [0, 1]"});
  cases.push_back({Options(16, 0.5, nan), "delta0_fraction must be in [0, 1]"});
  cases.push_back({Options(16, 0.5, 0.3, -0.01), "noise_margin_mm must be"});
  cases.push_back(
      {Options(16, 0.5, 0.3, std::numeric_limits<double>::infinity()), "noise_margin_mm must be"});
  for (const Case& c : cases) {
    const Status s = c.o.Validate();
    ASSERT_FALSE(s.ok()) << c.expected;
    EXPECT_NE(s.message().find(c.expected), std::string::npos) << s.message();
  }
  EXPECT_NE(Options(16, -1.0).Validate().message().find("mm^2"), std::string::npos);
  EXPECT_NE(Options(16, 0.5, 0.3, -0.01).Validate().message().find("got -0.01"), std::string::npos);
}

TEST(Relief, InvalidOptionsOrBrokenFieldThrow) {
  const HeightField f = test::MakeFlatField(4, 4, 0.1, 1.0f);
  EXPECT_THROW(ClassifyRelief(f, Options(0)), InvariantError);
  HeightField bad_pitch = f;
  bad_pitch.pitch_mm = 0;
  EXPECT_THROW(ClassifyRelief(bad_pitch, Options(4)), InvariantError);
  HeightField bad_size = f;
  bad_size.state = Grid<TexelState>(4, 3, TexelState::kMeasured);
  EXPECT_THROW(ClassifyRelief(bad_size, Options(4)), InvariantError);
}

TEST(Relief, EmptyGrid) {
  const HeightField f = test::MakeFlatField(0, 0, 0.1);
  const ReliefResult r = ClassifyRelief(f, ReliefOptions{});
  ExpectNoRelief(r, f);
  EXPECT_EQ(r.delta0_mm, 0.0);
}

TEST(Relief, FlatCanvasHasNoBoxes) {
  const HeightField f = test::MakeFlatField(64, 48, 0.1);
  const ReliefResult r = ClassifyRelief(f, ReliefOptions{});
  ExpectNoRelief(r, f);
  EXPECT_EQ(r.delta0_mm, 0.0);
  EXPECT_EQ(r.max_height_mm, 0.0);
  EXPECT_EQ(r.components_kept + r.components_removed, 0u);
}

TEST(Relief, ConcaveCanvasHasNoBoxes) {
  HeightField f = test::MakeFlatField(32, 32, 0.1, -0.5f);
  f.height_mm(10, 10) = -0.1f;
  const ReliefResult r = ClassifyRelief(f, ReliefOptions{});
  ExpectNoRelief(r, f);
  EXPECT_EQ(r.delta0_mm, 0.0);
  EXPECT_FLOAT_EQ(static_cast<float>(r.max_height_mm), -0.1f);
}

// Only texels with height take part: a tall texel marked kOutside or kUnfilled (its height is
// inpainted for continuity, not measured) neither sets H nor becomes relief.
TEST(Relief, TexelsWithoutHeightAreIgnored) {
  HeightField all_out = test::MakeFlatField(16, 16, 0.1, 3.0f);
  for (auto& s : all_out.state.data) s = TexelState::kOutside;
  ExpectNoRelief(ClassifyRelief(all_out, Options(4)), all_out);

  HeightField f = test::MakeFlatField(16, 16, 0.1);
  for (int y = 4; y < 8; ++y)
    for (int x = 4; x < 8; ++x) f.height_mm(x, y) = 1.0f;
  f.height_mm(13, 13) = 50.0f;
  f.state(13, 13) = TexelState::kOutside;
  f.height_mm(1, 13) = 40.0f;
  f.state(1, 13) = TexelState::kUnfilled;
  f.state(5, 5) = TexelState::kFilled;  // filled texels do count
  const ReliefResult r = ClassifyRelief(f, Options(4));
  EXPECT_FLOAT_EQ(static_cast<float>(r.max_height_mm), 1.0f);
  EXPECT_EQ(r.texels_above, 16u);
  ASSERT_EQ(r.boxes.size(), 1u);
  CheckAgainstBruteForce(f, Options(4), r);
}

// A lone spike below the minimum area is noise: removed, even when it is the highest point
// (H and delta0 still come from it, as in the paper: thresholds before cleaning).
TEST(Relief, SingleSpikeBelowMinAreaIsRemoved) {
  HeightField f = test::MakeFlatField(64, 64, 0.1);
  f.height_mm(20, 30) = 5.0f;
  const ReliefOptions o = Options(8, 0.5);
  ReliefResult r = ClassifyRelief(f, o);
  ExpectNoRelief(r, f);
  EXPECT_DOUBLE_EQ(r.max_height_mm, 5.0);
  EXPECT_DOUBLE_EQ(r.delta0_mm, 1.5);
  EXPECT_EQ(r.components_removed, 1u);
  EXPECT_EQ(r.components_kept, 0u);

  // Beside a real blob (10 x 10 texels = 1 mm^2) the spike goes and the blob stays.
  for (int y = 40; y < 50; ++y)
    for (int x = 40; x < 50; ++x) f.height_mm(x, y) = 2.0f;
  r = ClassifyRelief(f, o);
  EXPECT_EQ(r.components_kept, 1u);
  EXPECT_EQ(r.components_removed, 1u);
  EXPECT_EQ(r.valid(20, 30), 0);
  EXPECT_EQ(r.texels_above, 100u);
  for (const ReliefBox& b : r.boxes) EXPECT_GE(b.x0, 40);
  CheckAgainstBruteForce(f, o, r);
}

// Area threshold on the boundary, and 8-connectivity: texels 0.5 mm apart (0.25 mm^2 each).
// A component exactly at the minimum area is kept ("smaller than" removes).
TEST(Relief, MinAreaBoundaryAndEightConnectivity) {
  HeightField f = test::MakeFlatField(20, 20, 0.5);
  f.height_mm(2, 2) = 1.0f;  // diagonal pair: one 8-connected component of 0.5 mm^2
  f.height_mm(3, 3) = 1.0f;
  f.height_mm(10, 10) = 1.0f;  // two texels two apart: two components of 0.25 mm^2
  f.height_mm(12, 10) = 1.0f;
  const ReliefOptions o = Options(4, 0.5);
  const ReliefResult r = ClassifyRelief(f, o);
  EXPECT_EQ(r.components_kept, 1u);
  EXPECT_EQ(r.components_removed, 2u);
  EXPECT_EQ(r.valid(2, 2), 1);
  EXPECT_EQ(r.valid(3, 3), 1);
  EXPECT_EQ(r.valid(10, 10), 0);
  ASSERT_EQ(r.boxes.size(), 1u);
  EXPECT_EQ(r.boxes[0].x0, 0);
  EXPECT_EQ(r.boxes[0].y0, 0);
  CheckAgainstBruteForce(f, o, r);
}

// The box's peak is taken among all texels of the cell with height, not only valid ones: here a
// removed speck is higher than the kept blob sharing its cell.
TEST(Relief, PeakIsTheCellMaximumAmongTexelsWithHeight) {
  HeightField f = test::MakeFlatField(16, 16, 0.25);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) f.height_mm(x, y) = 1.0f + 0.01f * x;  // kept, peak (3, *)
  f.height_mm(6, 6) = 1.5f;  // speck (0.0625 mm^2), same 8x8 cell
  f.height_mm(7, 7) = 9.0f;  // higher still, but no height: ignored
  f.state(7, 7) = TexelState::kOutside;
  const ReliefOptions o = Options(8, 0.5);
  const ReliefResult r = ClassifyRelief(f, o);
  ASSERT_EQ(r.boxes.size(), 1u);
  EXPECT_EQ(r.valid(6, 6), 0);
  EXPECT_FLOAT_EQ(r.boxes[0].h_max_mm, 1.5f);
  EXPECT_EQ(r.boxes[0].u_max, 6);
  EXPECT_EQ(r.boxes[0].v_max, 6);
  // Ties: the first texel in row-major order.
  HeightField g = test::MakeFlatField(8, 8, 0.25);
  for (int y = 2; y < 6; ++y)
    for (int x = 2; x < 6; ++x) g.height_mm(x, y) = 1.0f;
  const ReliefResult t = ClassifyRelief(g, o);
  ASSERT_EQ(t.boxes.size(), 1u);
  EXPECT_EQ(t.boxes[0].u_max, 2);
  EXPECT_EQ(t.boxes[0].v_max, 2);
  CheckAgainstBruteForce(f, o, r);
  CheckAgainstBruteForce(g, o, t);
}

// Random Gaussian blobs, noise specks and holes on a non-square grid whose size is not a
// multiple of the cell: everything checked against the brute-force answer.
HeightField RandomPainting(int w, int h, double pitch, uint32_t seed) {
  HeightField f = test::MakeFlatField(w, h, pitch);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> ux(0, w), uy(0, h), amp(0.2, 2.5), rad(1.0, 6.0);
  std::normal_distribution<float> noise(0.0f, 0.02f);
  std::uniform_int_distribution<int> pick(0, 99);
  struct Blob {
    double x, y, a, r;
  };
  std::vector<Blob> blobs;
  blobs.reserve(12);
  for (int i = 0; i < 12; ++i) blobs.push_back({ux(rng), uy(rng), amp(rng), rad(rng)});
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double v = noise(rng);
      for (const Blob& b : blobs)
        v += b.a * std::exp(-((x - b.x) * (x - b.x) + (y - b.y) * (y - b.y)) / (2 * b.r * b.r));
      const int p = pick(rng);
      if (p == 0) v += 1.5;  // spike
      f.height_mm(x, y) = static_cast<float>(v);
      if (p == 1) f.state(x, y) = TexelState::kOutside;
      if (p == 2) f.state(x, y) = TexelState::kFilled;
      if (p == 3) f.state(x, y) = TexelState::kUnfilled;
    }
  return f;
}

TEST(Relief, RandomBlobsAllInsideBoxes) {
  for (uint32_t seed : {1u, 2u, 3u}) {
    const HeightField f = RandomPainting(101, 67, 0.2, seed);
    for (int n : {1, 5, 16, 64}) {
      const ReliefOptions o = Options(n, 0.3, 0.3, 0.0);
      SCOPED_TRACE("seed " + std::to_string(seed) + " cell_px " + std::to_string(n));
      const ReliefResult r = ClassifyRelief(f, o);
      EXPECT_GT(r.components_kept, 0u);
      EXPECT_GT(r.components_removed, 0u);
      CheckAgainstBruteForce(f, o, r);
    }
  }
}

TEST(Relief, CellOfOneTexel) {
  const HeightField f = RandomPainting(40, 30, 0.2, 9);
  const ReliefOptions o = Options(1, 0.2);
  const ReliefResult r = ClassifyRelief(f, o);
  EXPECT_EQ(r.boxes.size(), r.texels_above);
  for (const ReliefBox& b : r.boxes) {
    EXPECT_EQ(b.width, 1);
    EXPECT_EQ(b.height, 1);
    EXPECT_EQ(b.u_max, b.x0);
    EXPECT_EQ(b.v_max, b.y0);
    EXPECT_EQ(b.h_max_mm, f.height_mm(b.x0, b.y0));
  }
  CheckAgainstBruteForce(f, o, r);
}

TEST(Relief, CellLargerThanGridIsOneBox) {
  const HeightField f = RandomPainting(40, 30, 0.2, 4);
  for (int n : {41, 1000, std::numeric_limits<int>::max()}) {
    const ReliefOptions o = Options(n, 0.2);
    const ReliefResult r = ClassifyRelief(f, o);
    ASSERT_EQ(r.boxes.size(), 1u);
    EXPECT_EQ(r.boxes[0].width, 40);
    EXPECT_EQ(r.boxes[0].height, 30);
    EXPECT_FLOAT_EQ(r.boxes[0].h_max_mm, static_cast<float>(r.max_height_mm));
    CheckAgainstBruteForce(f, o, r);
  }
}

TEST(Relief, EdgeCellsAreSmaller) {
  HeightField f = test::MakeFlatField(50, 37, 0.1);
  f.height_mm(49, 36) = 1.0f;  // bottom-right corner texel, in a 2 x 5 cell
  const ReliefOptions o = Options(16, 0.0);
  const ReliefResult r = ClassifyRelief(f, o);
  ASSERT_EQ(r.boxes.size(), 1u);
  EXPECT_EQ(r.boxes[0].x0, 48);
  EXPECT_EQ(r.boxes[0].y0, 32);
  EXPECT_EQ(r.boxes[0].width, 2);
  EXPECT_EQ(r.boxes[0].height, 5);
  CheckAgainstBruteForce(f, o, r);
}

TEST(Relief, OneByNAndNByOne) {
  for (const auto& [w, h] : {std::pair{1, 1}, std::pair{1, 97}, std::pair{97, 1}}) {
    HeightField f = test::MakeFlatField(w, h, 0.5);
    for (int i = 0; i < w * h; ++i) f.height_mm.data[i] = (i % 7 < 3) ? 1.0f + 0.1f * i : 0.0f;
    for (int n : {1, 4, 200}) {
      const ReliefOptions o = Options(n, 0.5);
      SCOPED_TRACE(std::to_string(w) + "x" + std::to_string(h) + " n " + std::to_string(n));
      CheckAgainstBruteForce(f, o, ClassifyRelief(f, o));
    }
  }
}

// Hostile magnitudes: 1e6 mm heights and a 1e-4 mm pitch (texel area 1e-8 mm^2).
TEST(Relief, HugeHeightsAndTinyPitchStayFinite) {
  HeightField f = test::MakeFlatField(32, 32, 1e-4);
  for (int y = 8; y < 16; ++y)
    for (int x = 8; x < 16; ++x) f.height_mm(x, y) = 1e6f;
  f.height_mm(30, 30) = std::numeric_limits<float>::max();
  const ReliefOptions o = Options(4, 0.0);
  const ReliefResult r = ClassifyRelief(f, o);
  EXPECT_TRUE(std::isfinite(r.max_height_mm));
  EXPECT_TRUE(std::isfinite(r.delta0_mm));
  EXPECT_EQ(r.texels_above, 1u);  // only the FLT_MAX texel is above 0.3 FLT_MAX
  CheckAgainstBruteForce(f, o, r);
  // Any area at this pitch is far below 0.5 mm^2: everything is a speck.
  ExpectNoRelief(ClassifyRelief(f, Options(4, 0.5)), f);
}

// Mv is strictly above delta0: a texel exactly on the bump plane is not relief (exact in float
// and double: 0.25 x 10).
TEST(Relief, TexelExactlyAtDelta0IsNotRelief) {
  HeightField f = test::MakeFlatField(8, 8, 0.5);
  f.height_mm(1, 1) = 10.0f;
  f.height_mm(6, 6) = 2.5f;
  const ReliefResult r = ClassifyRelief(f, Options(4, 0.0, 0.25));
  EXPECT_EQ(r.delta0_mm, 2.5);
  EXPECT_EQ(r.valid(6, 6), 0);
  EXPECT_EQ(r.texels_above, 1u);
}

// The noise margin lowers the classification threshold, not the reported bump plane.
TEST(Relief, NoiseMarginLowersTheThresholdOnly) {
  HeightField f = test::MakeFlatField(16, 16, 0.25);
  f.height_mm(2, 2) = 10.0f;    // H; delta0 = 3
  f.height_mm(10, 10) = 2.99f;  // just below delta0
  ReliefResult r = ClassifyRelief(f, Options(4, 0.0, 0.3, 0.0));
  EXPECT_DOUBLE_EQ(r.delta0_mm, 3.0);
  EXPECT_EQ(r.texels_above, 1u);
  r = ClassifyRelief(f, Options(4, 0.0, 0.3, 0.02));
  EXPECT_DOUBLE_EQ(r.delta0_mm, 3.0);
  EXPECT_EQ(r.texels_above, 2u);
  EXPECT_EQ(r.valid(10, 10), 1);
  CheckAgainstBruteForce(f, Options(4, 0.0, 0.3, 0.02), r);
  // A margin above delta0 is capped at delta0 / 2 (threshold 1.5 mm here): a noisy scan must not
  // turn the whole canvas into relief.
  r = ClassifyRelief(f, Options(4, 0.0, 0.3, 3.5));
  EXPECT_EQ(r.texels_above, 2u);
  EXPECT_EQ(r.boxes.size(), 2u);
}

TEST(Relief, CoverGrowsBoxesByOneTexelAcrossCellBorders) {
  HeightField f = test::MakeFlatField(16, 16, 0.25);
  f.height_mm(3, 5) = 1.0f;  // last column of cell (0, 1) with 4x4 cells: only that cell is boxed
  ReliefOptions o = Options(4);
  ReliefResult r = ClassifyRelief(f, o);
  ASSERT_EQ(r.boxes.size(), 1u);
  o.cover_px = 1;  // the one-texel ring reaches cells (1, 1), (0, 1)'s neighbours in x only
  r = ClassifyRelief(f, o);
  EXPECT_EQ(r.boxes.size(), 2u);
  EXPECT_EQ(r.texels_above, 1u) << "cover widens the boxes, not Mv";
  for (const ReliefBox& b : r.boxes) EXPECT_EQ(b.y0, 4);
  o.cover_px = -1;
  EXPECT_NE(o.Validate().message().find("cover_px"), std::string::npos);
}

TEST(Relief, FlatCanvasBelowTheReliefFloorHasNoBoxes) {
  HeightField f = test::MakeFlatField(16, 16, 0.25);
  f.height_mm(5, 5) = 0.015f;  // rounding dust, below the default 0.02 mm floor
  ReliefResult r = ClassifyRelief(f, ReliefOptions{});
  EXPECT_TRUE(r.boxes.empty());
  EXPECT_EQ(r.texels_above, 0u);
  ReliefOptions no_floor;
  no_floor.min_relief_mm = 0.0;
  no_floor.min_component_area_mm2 = 0.0;  // one texel is 0.0625 mm^2: not a speck here
  r = ClassifyRelief(f, no_floor);        // without a floor the same dust becomes a box
  EXPECT_EQ(r.boxes.size(), 1u);
  ReliefOptions bad;
  bad.min_relief_mm = -1;
  EXPECT_NE(bad.Validate().message().find("min_relief_mm"), std::string::npos);
}

// The generator's truth height field (weave, strokes, impasto, cracks): every texel above delta0
// outside removed specks lies in a box, peaks exact, for the default options and a fine cell.
TEST(Relief, SyntheticPaintingReliefAllInsideBoxes) {
  synth::PaintingOptions options;
  options.resolution_px = 512;
  options.seed = 2;
  const synth::Painting painting = synth::MakePainting(options);
  for (int n : {16, 5}) {
    ReliefOptions o;
    o.cell_px = n;
    SCOPED_TRACE("cell_px " + std::to_string(n));
    const ReliefResult r = ClassifyRelief(painting.truth, o);
    EXPECT_GT(r.boxes.size(), 0u);
    EXPECT_GT(r.max_height_mm, 0.5);  // impasto is on by default
    CheckAgainstBruteForce(painting.truth, o, r);
  }
}

TEST(Relief, DeterministicAcrossRuns) {
  const HeightField f = RandomPainting(300, 200, 0.1, 5);
  const ReliefOptions o = Options(7, 0.05);
  const ReliefResult a = ClassifyRelief(f, o), b = ClassifyRelief(f, o);
  ASSERT_EQ(a.boxes.size(), b.boxes.size());
  for (size_t i = 0; i < a.boxes.size(); ++i) {
    EXPECT_EQ(a.boxes[i].x0, b.boxes[i].x0);
    EXPECT_EQ(a.boxes[i].y0, b.boxes[i].y0);
    EXPECT_EQ(a.boxes[i].u_max, b.boxes[i].u_max);
  }
  EXPECT_EQ(a.valid.data, b.valid.data);
  CheckAgainstBruteForce(f, o, a);
}

}  // namespace
}  // namespace digitize
