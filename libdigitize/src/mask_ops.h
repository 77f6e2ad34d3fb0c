// Mask operations shared by the canvas stages (private to the library: OpenCV types).
#pragma once

#include <opencv2/core.hpp>

namespace digitize {

// Pixels of `mask` (CV_8U, 0/255) not reachable from the image border through non-mask pixels
// (the holes and islands it encloses) -> 255; everything else 0.
cv::Mat EnclosedIslands(const cv::Mat& mask);

}  // namespace digitize
