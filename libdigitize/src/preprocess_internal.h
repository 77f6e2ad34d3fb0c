// What preprocess.cpp and preprocess_tiled.cpp share: the step lines (printf-style text, wall
// time since a step began) and how the canvas folder's texel maps are written
// (docs/formats.md). Private to the preprocess layer.
#pragma once

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <string>

#include "digitize/height_field.h"
#include "digitize/image_io.h"

namespace digitize::preprocess_internal {

using Clock = std::chrono::steady_clock;

inline double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// One line of at most 511 characters (longer is cut).
template <class... Args>
std::string Format(const char* fmt, Args... args) {
  char buffer[512];
  std::snprintf(buffer, sizeof(buffer), fmt, args...);
  return buffer;
}

// mask.png's value of a texel state, spread over 0..255 so the PNG is readable by eye.
inline uint8_t MaskPngCode(TexelState state) {
  switch (state) {
    case TexelState::kMeasured:
      return 255;
    case TexelState::kFilled:
      return 170;
    case TexelState::kUnfilled:
      return 85;
    case TexelState::kOutside:
      break;
  }
  return 0;
}

// The header attributes of height.exr and normals.exr.
inline ImageMetadata HeightMapMetadata(double pitch_mm) {
  return {{"digitize:pitch_mm", Format("%.9g", pitch_mm)},
          {"digitize:frame", "canvas (docs/formats.md)"},
          {"digitize:version", DIGITIZE_VERSION},
          {"digitize:quantity", "height_mm"}};
}
inline ImageMetadata NormalMapMetadata(double pitch_mm) {
  ImageMetadata meta = HeightMapMetadata(pitch_mm);
  meta["digitize:quantity"] = "unit normal (nx, ny, nz) in R, G, B";
  return meta;
}

}  // namespace digitize::preprocess_internal
