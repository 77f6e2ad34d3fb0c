#include "progress_bar.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>

namespace digitize::cli {

ProgressBar::ProgressBar(std::string title)
    : title_(std::move(title)),
      tty_(::isatty(STDERR_FILENO) != 0),
      start_(std::chrono::steady_clock::now()) {}

ProgressBar::~ProgressBar() { Finish(); }

void ProgressBar::Update(std::string_view step, double fraction) {
  fraction = std::clamp(fraction, 0.0, 1.0);
  const int percent = static_cast<int>(fraction * 100.0);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  if (tty_) {
    if (percent == last_percent_ && step == last_step_) return;
    constexpr int kWidth = 30;
    const int filled = static_cast<int>(fraction * kWidth);
    std::fprintf(stderr, "\r%s [%.*s%*s] %3d%% %5.1fs  %-24.*s", title_.c_str(), filled,
                 "##############################", kWidth - filled, "", percent, seconds,
                 static_cast<int>(std::min<size_t>(step.size(), 24)), step.data());
    std::fflush(stderr);
  } else {
    // A log file: a line when the step changes, then every kLogPercent or kLogSeconds of
    // progress, whichever comes first (a bar redrawn in place would leave one line at 0 %).
    const bool due = step != last_step_ || percent >= logged_percent_ + kLogPercent ||
                     (percent > logged_percent_ && seconds >= logged_seconds_ + kLogSeconds);
    if (due) {
      std::fprintf(stderr, "%s: %3d%% %5.1fs %.*s\n", title_.c_str(), percent, seconds,
                   static_cast<int>(step.size()), step.data());
      logged_percent_ = percent;
      logged_seconds_ = seconds;
    }
  }
  last_percent_ = percent;
  last_step_ = std::string(step);
}

void ProgressBar::Finish() {
  if (finished_) return;
  finished_ = true;
  if (tty_ && last_percent_ >= 0) {
    Update("done", 1.0);
    std::fprintf(stderr, "\n");
  }
}

ProgressCallback ProgressBar::Callback() {
  return [this](std::string_view step, double fraction) { Update(step, fraction); };
}

}  // namespace digitize::cli
