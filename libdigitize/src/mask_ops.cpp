#include "mask_ops.h"

#include <algorithm>
#include <opencv2/imgproc.hpp>

namespace digitize {

void FillEnclosedIslands(cv::Mat& mask) {
  // Islands lie inside the mask's bounding rectangle: flood only that part.
  const cv::Rect box = cv::boundingRect(mask);
  if (box.empty()) return;
  cv::Mat padded(box.height + 2, box.width + 2, CV_8U, cv::Scalar(255));
  cv::Mat inner = padded(cv::Rect(1, 1, box.width, box.height));
  cv::bitwise_not(mask(box), inner);
  cv::floodFill(padded, cv::Point(0, 0), cv::Scalar(0), nullptr, cv::Scalar(0), cv::Scalar(0), 8);
  cv::Mat target = mask(box);
  cv::bitwise_or(target, inner, target);
}

BitMask DilatedBits(const cv::Mat& mask, int radius) {
  const int w = mask.cols, h = mask.rows;
  BitMask out(w, h);
  if (w == 0 || h == 0) return out;
  const cv::Mat kernel = cv::Mat::ones(2 * radius + 1, 2 * radius + 1, CV_8U);
  constexpr int kStrip = 256;
  cv::Mat dilated;
  for (int y0 = 0; y0 < h; y0 += kStrip) {
    const int y1 = std::min(h, y0 + kStrip);
    // The strip and `radius` rows either side: its rows' dilation reads no further. Isolated,
    // so that the border rule of the whole image (nothing beyond it) holds at the strip's edges.
    const int ya = std::max(0, y0 - radius), yb = std::min(h, y1 + radius);
    cv::dilate(mask.rowRange(ya, yb), dilated, kernel, cv::Point(-1, -1), 1,
               cv::BORDER_CONSTANT | cv::BORDER_ISOLATED, cv::Scalar(0));
    for (int y = y0; y < y1; ++y) {
      const uint8_t* row = dilated.ptr<uint8_t>(y - ya);
      for (int x = 0; x < w; ++x)
        if (row[x]) out.Set(x, y);
    }
  }
  return out;
}

}  // namespace digitize
