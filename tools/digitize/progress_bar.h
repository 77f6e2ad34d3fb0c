// A progress bar on stderr for the command line: redrawn in place on a terminal, one line per
// step otherwise (logs, CI).
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
  std::chrono::steady_clock::time_point start_;
};

}  // namespace digitize::cli
