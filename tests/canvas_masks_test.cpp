// The preprocess's scan-sized mask steps, written to hold less memory (a scan or bits instead of
// extra byte masks), against the OpenCV operations they replace: the same pixels, on random
// masks whose sizes are not multiples of a word or a strip.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "canvas_steps.h"
#include "mask_ops.h"

namespace digitize {
namespace {

// Blobs of 255 on 0: rectangles and discs of random size, with holes punched in some.
cv::Mat RandomMask(int w, int h, unsigned seed, int blobs) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> ux(0, w - 1), uy(0, h - 1), size(1, 40);
  cv::Mat m = cv::Mat::zeros(h, w, CV_8U);
  for (int i = 0; i < blobs; ++i) {
    const cv::Point c(ux(rng), uy(rng));
    if (i % 3 == 0)
      cv::circle(m, c, size(rng), cv::Scalar(i % 5 == 0 ? 0 : 255), cv::FILLED);
    else
      cv::rectangle(m, cv::Rect(c.x, c.y, size(rng), size(rng)), cv::Scalar(255), cv::FILLED);
  }
  return m;
}

// Scattered single pixels set to `value` with probability p (dropouts, specks).
void Sprinkle(cv::Mat& m, unsigned seed, double p, uint8_t value) {
  std::mt19937 rng(seed);
  std::bernoulli_distribution hit(p);
  for (int y = 0; y < m.rows; ++y)
    for (int x = 0; x < m.cols; ++x)
      if (hit(rng)) m.at<uint8_t>(y, x) = value;
}

size_t Differing(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat d;
  cv::compare(a, b, d, cv::CMP_NE);
  return static_cast<size_t>(cv::countNonZero(d));
}

// The enclosed pixels by flood-filling the inverse from outside (the former EnclosedIslands).
cv::Mat FilledReference(const cv::Mat& mask) {
  cv::Mat padded;
  cv::copyMakeBorder(~mask, padded, 1, 1, 1, 1, cv::BORDER_CONSTANT, cv::Scalar(255));
  cv::floodFill(padded, cv::Point(0, 0), cv::Scalar(0), nullptr, cv::Scalar(0), cv::Scalar(0), 8);
  cv::Mat out;
  cv::bitwise_or(mask, padded(cv::Rect(1, 1, mask.cols, mask.rows)), out);
  return out;
}

TEST(CanvasMasks, FillEnclosedIslandsAddsExactlyTheEnclosedPixels) {
  for (unsigned seed = 1; seed <= 6; ++seed) {
    const int w = 150 + 37 * static_cast<int>(seed), h = 120 + 23 * static_cast<int>(seed);
    cv::Mat mask = RandomMask(w, h, seed, 60);
    // A ring with a hole inside: at least one enclosed region, whatever the blobs do.
    cv::rectangle(mask, cv::Rect(10, 10, 40, 40), cv::Scalar(255), 3);
    Sprinkle(mask, seed + 100, 0.01, 0);
    const cv::Mat want = FilledReference(mask);
    ASSERT_GT(Differing(want, mask), 0u) << "seed " << seed << ": nothing enclosed to fill";
    cv::Mat got = mask.clone();
    FillEnclosedIslands(got);
    EXPECT_EQ(Differing(got, want), 0u) << "seed " << seed;
  }
  cv::Mat empty = cv::Mat::zeros(30, 40, CV_8U);
  FillEnclosedIslands(empty);
  EXPECT_EQ(cv::countNonZero(empty), 0);
}

TEST(CanvasMasks, DilatedBitsEqualOpenCvDilation) {
  // 700 rows: strips of 256 rows with a partial last one; 777 columns: not a multiple of 64.
  const cv::Mat mask = RandomMask(777, 700, 7, 80);
  const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3));
  for (int radius : {0, 1, 3, 11}) {
    cv::Mat want;
    cv::dilate(mask, want, kernel, cv::Point(-1, -1), radius);
    const BitMask got = DilatedBits(mask, radius);
    size_t differ = 0, set = 0;
    for (int y = 0; y < mask.rows; ++y)
      for (int x = 0; x < mask.cols; ++x) {
        differ += got.Get(x, y) != (want.at<uint8_t>(y, x) != 0);
        set += got.Get(x, y);
      }
    EXPECT_EQ(differ, 0u) << "radius " << radius;
    EXPECT_GT(set, static_cast<size_t>(cv::countNonZero(mask)) - 1) << "radius " << radius;
  }
}

// The former JoinMissingSamples: four dilations of the mask.
cv::Mat JoinReference(const cv::Mat& filled, const cv::Mat& valid, cv::Mat mask) {
  cv::Mat missing, add;
  cv::compare(valid, 0, missing, cv::CMP_EQ);
  cv::bitwise_and(filled, missing, add);
  mask.setTo(255, add);
  const int r = canvas_detail::kConvexReachPx;
  auto reach = [&](int kw, int kh, cv::Point anchor) {
    cv::Mat out;
    cv::dilate(mask, out, cv::Mat::ones(kh, kw, CV_8U), anchor, 1, cv::BORDER_CONSTANT,
               cv::Scalar(0));
    return out;
  };
  cv::Mat rows, columns;
  cv::bitwise_and(reach(r + 1, 1, cv::Point(r, 0)), reach(r + 1, 1, cv::Point(0, 0)), rows);
  cv::bitwise_and(reach(1, r + 1, cv::Point(0, r)), reach(1, r + 1, cv::Point(0, 0)), columns);
  cv::bitwise_or(rows, columns, add);
  cv::bitwise_and(add, missing, add);
  mask.setTo(255, add);
  return FilledReference(mask);
}

TEST(CanvasMasks, JoinMissingSamplesEqualsTheDilationsItReplaces) {
  for (unsigned seed = 1; seed <= 6; ++seed) {
    const int w = 300 + 61 * static_cast<int>(seed), h = 200 + 29 * static_cast<int>(seed);
    // valid: 0/1, most samples valid, dropouts scattered and in blobs; filled: 0/255 blobs;
    // the mask: blobs with dropouts of its own, near the filled region.
    cv::Mat valid(h, w, CV_8U, cv::Scalar(1));
    cv::Mat holes = RandomMask(w, h, seed + 10, 25);
    valid.setTo(0, holes);
    Sprinkle(valid, seed + 20, 0.05, 0);
    const cv::Mat filled = RandomMask(w, h, seed + 30, 70);
    cv::Mat mask = RandomMask(w, h, seed + 40, 90);
    Sprinkle(mask, seed + 50, 0.08, 0);
    const cv::Mat want = JoinReference(filled, valid, mask.clone());
    cv::Mat got = mask.clone();
    canvas_detail::JoinMissingSamples(filled, valid, got);
    EXPECT_GT(Differing(want, mask), 100u) << "seed " << seed << ": the case joins nothing";
    EXPECT_EQ(Differing(got, want), 0u) << "seed " << seed;
  }
}

}  // namespace
}  // namespace digitize
