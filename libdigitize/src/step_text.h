// The preprocess's step lines (preprocess.cpp, preprocess_tiled.cpp): printf-style text and the
// wall time since a step began. Private to the preprocess layer.
#pragma once

#include <chrono>
#include <cstdio>
#include <string>

namespace digitize::step_text {

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

}  // namespace digitize::step_text
