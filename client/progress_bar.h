// A one-line text progress bar, "[############............] 42%", redrawn in place with '\r'.
#ifndef DRILLBIF_CLIENT_PROGRESS_BAR_H_
#define DRILLBIF_CLIENT_PROGRESS_BAR_H_

#include <chrono>
#include <cstdio>

namespace drillbif::client {

// True when the stream is a terminal (isatty on its file descriptor).
bool IsTerminal(std::FILE* stream);

class ProgressBar {
 public:
  // Draws on `out` only when `enabled` (typically IsTerminal(stderr)) and only once
  // `delay_seconds` have passed since construction, so that quick runs print nothing.
  ProgressBar(std::FILE* out, bool enabled, double delay_seconds = 0.5);
  ~ProgressBar();
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;

  // Shows `fraction` (clamped to [0, 1]); redraws only when the text changes.
  void Update(double fraction);
  // Erases the bar, if it was drawn, leaving the cursor at the start of an empty line.
  void Finish();

 private:
  static constexpr int kWidth = 40;  // characters between the brackets

  std::FILE* out_;
  bool enabled_;
  std::chrono::steady_clock::time_point show_after_;
  int last_percent_ = -1;
  bool drawn_ = false;
};

}  // namespace drillbif::client

#endif  // DRILLBIF_CLIENT_PROGRESS_BAR_H_
