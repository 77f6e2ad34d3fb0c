// Mask operations shared by the canvas stages (private to the library: OpenCV types).
#pragma once

#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

namespace digitize {

// Adds to `mask` (CV_8U, 0/255) the pixels not reachable from the image border through non-mask
// pixels (the holes and islands it encloses), in place: one mask-sized buffer beside it, not
// three (a byte per scan sample each on the preprocess's largest masks).
void FillEnclosedIslands(cv::Mat& mask);

// A mask of one bit per pixel (an eighth of a byte mask), for the preprocess's masks of the scan's
// size. Each row starts on a 64-bit word, so rows, or blocks of 64 columns, can be written in
// parallel.
struct BitMask {
  int width = 0, height = 0;
  size_t words_per_row = 0;
  std::vector<uint64_t> words;

  BitMask(int w, int h)
      : width(w),
        height(h),
        words_per_row((static_cast<size_t>(w) + 63) / 64),
        words(words_per_row * static_cast<size_t>(h), 0) {}
  bool Get(int x, int y) const { return (Word(x, y) >> (x & 63)) & 1u; }
  void Set(int x, int y) { Word(x, y) |= uint64_t{1} << (x & 63); }

 private:
  const uint64_t& Word(int x, int y) const {
    return words[static_cast<size_t>(y) * words_per_row + static_cast<size_t>(x >> 6)];
  }
  uint64_t& Word(int x, int y) {
    return words[static_cast<size_t>(y) * words_per_row + static_cast<size_t>(x >> 6)];
  }
};

// The pixels within `radius` (Chebyshev distance) of `mask` (CV_8U, nonzero = in): `mask` dilated
// by a square of side 2 radius + 1, as bits, a strip of rows at a time (a byte mask of the scan's
// size never exists).
BitMask DilatedBits(const cv::Mat& mask, int radius);

}  // namespace digitize
