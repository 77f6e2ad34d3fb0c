#include "mask_ops.h"

#include <opencv2/imgproc.hpp>

namespace digitize {

cv::Mat EnclosedIslands(const cv::Mat& mask) {
  cv::Mat islands = cv::Mat::zeros(mask.size(), CV_8U);
  // Islands lie inside the mask's bounding rectangle: flood only that part.
  const cv::Rect box = cv::boundingRect(mask);
  if (box.empty()) return islands;
  cv::Mat inverse, padded;
  cv::bitwise_not(mask(box), inverse);
  cv::copyMakeBorder(inverse, padded, 1, 1, 1, 1, cv::BORDER_CONSTANT, cv::Scalar(255));
  cv::floodFill(padded, cv::Point(0, 0), cv::Scalar(0), nullptr, cv::Scalar(0), cv::Scalar(0), 8);
  padded(cv::Rect(1, 1, box.width, box.height)).copyTo(islands(box));
  return islands;
}

}  // namespace digitize
