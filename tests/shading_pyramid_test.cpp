// The prefiltered reflectance pyramid (shading_pyramid.h): GL-free, against values computed by
// hand from the synthetic painting's truth pack.
#include "digitize_viewer/shading_pyramid.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include "checker_pack.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/truth_pack.h"
#include "digitize_viewer/painting_setup.h"

namespace digitize::viewer {
namespace {

Pack SmallPainting(int resolution_px) {
  synth::PaintingOptions po;
  po.width_mm = 60;
  po.height_mm = 45;
  po.resolution_px = resolution_px;
  po.seed = 5;
  po.impasto_count = 3;
  return synth::MakeTruthPack(synth::MakePainting(po), {});
}

// The mean over texels [x0, x0 + n) x [y0, y0 + n) of level 0's channel c, component k.
double BlockMean(const ShadingLevel& l, int c, int k, int x0, int y0, int n) {
  double sum = 0;
  for (int y = y0; y < y0 + n; ++y)
    for (int x = x0; x < x0 + n; ++x) sum += l.rgba[c][4 * (size_t(y) * l.width + x) + k];
  return sum / (n * n);
}

// Sizes follow GL's mip chain down to 1 x  1; a texel of level l is the exact box mean of the
// 2^l x 2^l level-0 texels it covers (even sizes), every channel and component (float sums:
// 1e-5 relative); every value is finite; the weights are shares in [0, 1] and the models'
// shares add up to the shaded one.
TEST(ShadingPyramidTest, LevelsAreBoxMeansOfTheTexels) {
  const Pack pack = SmallPainting(128);
  const ShadingPyramid pyr = BuildShadingPyramid(pack, ShadingSource(pack));
  const int w = pack.width(), h = pack.height();
  ASSERT_GE(pyr.levels.size(), 5u);
  for (size_t l = 0; l < pyr.levels.size(); ++l) {
    EXPECT_EQ(pyr.levels[l].width, std::max(1, w >> l)) << l;
    EXPECT_EQ(pyr.levels[l].height, std::max(1, h >> l)) << l;
  }
  EXPECT_EQ(pyr.levels.back().width, 1);
  EXPECT_EQ(pyr.levels.back().height, 1);
  const ShadingLevel& base = pyr.levels[0];
  for (int l : {1, 2, 3}) {
    const ShadingLevel& lev = pyr.levels[l];
    const int n = 1 << l;
    for (int y = 0; y < lev.height; y += 3)
      for (int x = 0; x < lev.width; x += 5)
        for (int c = 0; c < kShadingChannels; ++c)
          for (int k = 0; k < 4; ++k) {
            const double want = BlockMean(base, c, k, x * n, y * n, n);
            const double got = lev.rgba[c][4 * (size_t(y) * lev.width + x) + k];
            ASSERT_NEAR(got, want, 1e-5 * std::max(1.0, std::abs(want)))
                << "level " << l << " texel " << x << "," << y << " channel " << c << "." << k;
          }
  }
  for (const ShadingLevel& lev : pyr.levels)
    for (size_t i = 0; i < size_t(lev.width) * lev.height; ++i) {
      for (int c = 0; c < kShadingChannels; ++c)
        for (int k = 0; k < 4; ++k) ASSERT_TRUE(std::isfinite(lev.rgba[c][4 * i + k]));
      const float ws = lev.rgba[kDiffuse][4 * i + 3];
      EXPECT_GE(ws, 0.0f);
      EXPECT_LE(ws, 1.0f + 1e-6f);
      EXPECT_NEAR(lev.rgba[kLafortune][4 * i + 3] + lev.rgba[kGgx][4 * i + 3], ws, 1e-5);
    }
}

// An odd size loses nothing: the 1 x 1 level's mean equals level 0's mean for 37 x 23 texels
// (each halving weighs the texels a child covers in part by their share).
TEST(ShadingPyramidTest, OddSizesKeepTheMean) {
  ShadingLevel l;
  l.width = 37;
  l.height = 23;
  double mean = 0;
  for (auto& c : l.rgba) c.assign(4 * 37 * 23, 0.0f);
  for (int i = 0; i < 37 * 23; ++i) {
    const float v = float((i * 7919) % 101) / 100.0f;
    l.rgba[kDiffuse][4 * i] = v;
    mean += v;
  }
  mean /= 37 * 23;
  while (l.width > 1 || l.height > 1) l = HalveShadingLevel(l);
  EXPECT_NEAR(l.rgba[kDiffuse][0], mean, 1e-5);
}

// The normals' spread is what the lobes widen by: on a flat region the mean normal stays unit,
// where the relief bends it the mean's length drops below 1 (Toksvig's |mean n| < 1).
TEST(ShadingPyramidTest, MeanNormalShortensWhereTheReliefBends) {
  const Pack pack = SmallPainting(128);
  const ShadingPyramid pyr = BuildShadingPyramid(pack, ShadingSource(pack));
  const ShadingLevel& lev = pyr.levels[3];
  double shortest = 1, longest = 0;
  for (size_t i = 0; i < size_t(lev.width) * lev.height; ++i) {
    const float* n = &lev.rgba[kNormal][4 * i];
    const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) /
                       std::max(lev.rgba[kDiffuse][4 * i + 3], 1e-6f);
    shortest = std::min(shortest, len);
    longest = std::max(longest, len);
  }
  EXPECT_LE(longest, 1.0 + 1e-5);
  EXPECT_GT(longest, 0.999);  // flat canvas somewhere
  EXPECT_LT(shortest, 0.99);  // impasto flanks somewhere
}

// Degenerate grids: the smallest pack the viewer takes (2 x 2 texels; and 3 x 2) goes down to
// 1 x 1 holding the mean (0.15); a grid none of whose texels is shaded gives all-zero levels
// (the shader then draws it black, as the point-sampled texels).
TEST(ShadingPyramidTest, SmallAndUnshadedGrids) {
  for (const auto& [w, h] : {std::pair{2, 2}, std::pair{3, 2}}) {
    const Pack small = FlatCheckerPack(w, h, 5.0, 0.2f, 0.1f);
    const ShadingPyramid pyr = BuildShadingPyramid(small, ShadingSource(small));
    ASSERT_EQ(pyr.levels.size(), 2u);
    EXPECT_EQ(pyr.levels[1].width, 1);
    EXPECT_EQ(pyr.levels[1].height, 1);
    EXPECT_NEAR(pyr.levels[1].rgba[kDiffuse][0], w == 2 ? 0.15 : (0.2 * 3 + 0.1 * 3) / 6, 1e-6);
    EXPECT_NEAR(pyr.levels[1].rgba[kDiffuse][3], 1.0, 1e-6);
  }
  const Pack pack = SmallPainting(64);
  const ShadingPyramid pyr = BuildShadingPyramid(pack, ShadingSource(pack));
  EXPECT_EQ(pyr.levels.back().width, 1);
  EXPECT_EQ(pyr.levels.back().height, 1);
  const std::vector<size_t> none(size_t(pack.width()) * pack.height(), SIZE_MAX);
  const ShadingPyramid dark = BuildShadingPyramid(pack, none);
  for (const ShadingLevel& lev : dark.levels)
    for (int c = 0; c < kShadingChannels; ++c)
      for (float v : lev.rgba[c]) ASSERT_EQ(v, 0.0f);
}

}  // namespace
}  // namespace digitize::viewer
