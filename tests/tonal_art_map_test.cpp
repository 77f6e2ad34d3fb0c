// Tonal art maps (seed 004): the properties the hatching style relies on, texel by texel on the
// generated maps -- tone nesting, level nesting, equal means across levels -- and that the maps
// are deterministic, tile, and reject bad options. Writes a contact sheet (tones across, levels
// down, each magnified to 128 px) to the scratch folder to look at.
#include "digitize_viewer/tonal_art_map.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "digitize/image_io.h"
#include "test_support.h"

namespace digitize::viewer {
namespace {

const TonalArtMap& Default() {
  static const TonalArtMap map = BuildTonalArtMap();
  return map;
}

TEST(TonalArtMap, ShapeIsSixTonesTimesEightLevels) {
  const TonalArtMap& m = Default();
  EXPECT_EQ(m.tones, 6);
  EXPECT_EQ(m.levels, 8);  // 128 .. 1
  for (int t = 0; t < m.tones; ++t)
    for (int l = 0; l < m.levels; ++l) {
      EXPECT_EQ(m.At(t, l).width, 128 >> l);
      EXPECT_EQ(m.At(t, l).height, 128 >> l);
      for (float v : m.At(t, l).data) ASSERT_TRUE(v >= 0.0f && v <= 1.0f) << t << " " << l;
    }
}

// A stroke of a tone is in every darker tone: texel by texel, a darker tone's ink is never below
// a lighter one's (over-compositing only adds ink), at every level, the filtered ones included.
TEST(TonalArtMap, DarkerTonesHoldEveryStrokeOfTheLighterOnes) {
  const TonalArtMap& m = Default();
  for (int t = 0; t + 1 < m.tones; ++t)
    for (int l = 0; l < m.levels; ++l) {
      const Grid<float>& a = m.At(t, l);
      const Grid<float>& b = m.At(t + 1, l);
      for (size_t i = 0; i < a.data.size(); ++i)
        ASSERT_GE(b.data[i], a.data[i] - 1e-6f) << "tone " << t << " level " << l << " texel " << i;
      const std::vector<uint32_t>& sa = m.StrokesAt(t, l);
      const std::vector<uint32_t>& sb = m.StrokesAt(t + 1, l);
      EXPECT_TRUE(std::includes(sb.begin(), sb.end(), sa.begin(), sa.end()));
      if (l <= 3) {
        EXPECT_GT(sb.size(), sa.size()) << "tone " << t + 1 << " adds strokes";
      }
    }
}

// A stroke of a level is in every finer level of its tone: by id, and texel by texel -- where a
// coarse texel is inked (>= 0.9: the stroke's centre line within ~0.4 coarse texels of its
// centre) the same stroke, as wide in texels at the finer level, crosses the 2 x 2 texels under it
// or their ring (within ~1.3 fine texels of the centre line: coverage >= 0.1 at width 1.6).
TEST(TonalArtMap, FinerLevelsHoldEveryStrokeOfTheCoarserOnes) {
  const TonalArtMap& m = Default();
  for (int t = 0; t < m.tones; ++t)
    for (int l = 1; l <= 3; ++l) {  // 64 .. 16 against the next finer
      const std::vector<uint32_t>& coarse_ids = m.StrokesAt(t, l);
      const std::vector<uint32_t>& fine_ids = m.StrokesAt(t, l - 1);
      EXPECT_TRUE(
          std::includes(fine_ids.begin(), fine_ids.end(), coarse_ids.begin(), coarse_ids.end()))
          << "tone " << t << " level " << l;
      const Grid<float>& coarse = m.At(t, l);
      const Grid<float>& fine = m.At(t, l - 1);
      const int n = fine.width;
      for (int y = 0; y < coarse.height; ++y)
        for (int x = 0; x < coarse.width; ++x) {
          if (coarse(x, y) < 0.9f) continue;
          float most = 0;
          for (int dy = -1; dy <= 2; ++dy)
            for (int dx = -1; dx <= 2; ++dx)
              most = std::max(most, fine((2 * x + dx + n) % n, (2 * y + dy + n) % n));
          ASSERT_GE(most, 0.1f) << "tone " << t << " level " << l << " texel (" << x << ", " << y
                                << ")";
        }
    }
}

// Every level of a tone has the tone's mean ink: the stroked levels to within what the last
// stroke adds (measured below; asserted <= 0.01, 1 % ink, an eighth of the step between two
// tones), the filtered ones exactly the mean of the 16 x 16 level.
TEST(TonalArtMap, EveryLevelOfAToneHasItsMeanInk) {
  const TonalArtMap& m = Default();
  double worst = 0;
  for (int t = 0; t < m.tones; ++t) {
    for (int l = 0; l <= 3; ++l) {
      const double mean = TonalArtMap::Mean(m.At(t, l));
      worst = std::max(worst, std::abs(mean - m.target[t]));
      EXPECT_NEAR(mean, m.target[t], 0.01) << "tone " << t << " level " << l;
    }
    const double at16 = TonalArtMap::Mean(m.At(t, 3));
    for (int l = 4; l < m.levels; ++l)
      EXPECT_NEAR(TonalArtMap::Mean(m.At(t, l)), at16, 1e-5) << "tone " << t << " level " << l;
  }
  std::printf("largest |mean - target| over the stroked levels: %.4f\n", worst);
}

TEST(TonalArtMap, IsDeterministicAndSeedsDiffer) {
  TonalArtMapOptions o;
  o.size = 32;
  const TonalArtMap a = BuildTonalArtMap(o), b = BuildTonalArtMap(o);
  for (size_t i = 0; i < a.ink.size(); ++i) EXPECT_EQ(a.ink[i].data, b.ink[i].data);
  o.seed = 2;
  const TonalArtMap c = BuildTonalArtMap(o);
  EXPECT_NE(a.ink[0].data, c.ink[0].data);
}

// Strokes wrap around, so the texture tiles: the ink along the left edge continues from the
// right one (no stroke is cut at the border). Measured as the mean absolute difference between
// the two edge columns, against that between two columns a texture apart in the middle.
TEST(TonalArtMap, TilesWithoutASeam) {
  const Grid<float>& g = Default().At(3, 0);
  const int n = g.width;
  const auto column_gap = [&](int a, int b) {
    double d = 0;
    for (int y = 0; y < n; ++y) d += std::abs(g(a, y) - g(b, y));
    return d / n;
  };
  EXPECT_LT(column_gap(n - 1, 0), 1.5 * column_gap(n / 2 - 1, n / 2) + 0.02);
}

TEST(TonalArtMap, BadOptionsAreNamed) {
  TonalArtMapOptions o;
  o.size = 100;
  EXPECT_NE(o.Validate().message().find("power of two"), std::string::npos);
  o = {};
  o.tone_ink = {0.3, 0.2};
  EXPECT_NE(o.Validate().message().find("tone 1"), std::string::npos);
  o = {};
  o.max_length = 0.1;
  EXPECT_FALSE(o.Validate().ok());
  EXPECT_THROW(BuildTonalArtMap(o), InvariantError);
}

// Contact sheet: each texture magnified to 128 x 128 (nearest), white paper, black ink.
TEST(TonalArtMap, ContactSheetIsWritten) {
  const TonalArtMap& m = Default();
  const int cell = 128, gap = 4;
  Grid<uint8_t> sheet(m.tones * (cell + gap), m.levels * (cell + gap), 200);
  for (int t = 0; t < m.tones; ++t)
    for (int l = 0; l < m.levels; ++l) {
      const Grid<float>& g = m.At(t, l);
      for (int y = 0; y < cell; ++y)
        for (int x = 0; x < cell; ++x)
          sheet(t * (cell + gap) + x, l * (cell + gap) + y) = static_cast<uint8_t>(
              std::lround(255.0 * (1.0 - g(x * g.width / cell, y * g.height / cell))));
    }
  // One file, replaced by every run (named per process, one was left behind per run).
  const auto path = std::filesystem::temp_directory_path() / "digitize_tonal_art_map_sheet.png";
  ASSERT_TRUE(WritePng8(path, sheet).ok());
  std::printf("contact sheet: %s\n", path.c_str());
}

}  // namespace
}  // namespace digitize::viewer
