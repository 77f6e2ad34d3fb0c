// A progress bar on stderr for the command line: redrawn in place on a terminal; otherwise (logs,
// CI) one line per step and then every 10 % or 5 s of it, whichever comes first.
#pragma once

#include <chrono>
#include <string>
#include <string_view>

#include "digitize/core.h"

namespace digitize::cli {

class ProgressBar {
 public:
  explicit ProgressBar(std::string title);
  ~ProgressBar();
  // Overall fraction in [0, 1]; `step` names what runs now.
  void Update(std::string_view step, double fraction);
  void Finish();
  ProgressCallback Callback();

 private:
  std::string title_;
  std::string last_step_;
  bool tty_ = false;
  bool finished_ = false;
  int last_percent_ = -1;
  static constexpr int kLogPercent = 10;
  static constexpr double kLogSeconds = 5.0;
  int logged_percent_ = -1;  // the last line written to a log, and when
  double logged_seconds_ = 0;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace digitize::cli
