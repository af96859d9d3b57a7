#include "client/progress_bar.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <string>

namespace drillbif::client {

bool IsTerminal(std::FILE* stream) { return isatty(fileno(stream)) == 1; }

ProgressBar::ProgressBar(std::FILE* out, bool enabled, double delay_seconds)
    : out_(out),
      enabled_(enabled),
      show_after_(std::chrono::steady_clock::now() +
                  std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                      std::chrono::duration<double>(delay_seconds))) {}

ProgressBar::~ProgressBar() { Finish(); }

void ProgressBar::Update(double fraction) {
  if (!enabled_ || std::chrono::steady_clock::now() < show_after_) return;
  fraction = std::isfinite(fraction) ? std::clamp(fraction, 0.0, 1.0) : 0.0;
  const int percent = static_cast<int>(std::floor(fraction * 100.0));
  if (percent == last_percent_) return;
  last_percent_ = percent;
  const int filled = static_cast<int>(std::floor(fraction * kWidth));
  std::string line = "\r[";
  line.append(filled, '#').append(kWidth - filled, '.');
  line.append("] ").append(std::to_string(percent)).append("%");
  std::fputs(line.c_str(), out_);
  std::fflush(out_);
  drawn_ = true;
}

void ProgressBar::Finish() {
  if (!drawn_) return;
  // Overwrite the bar with spaces: "\r[" + kWidth + "] 100%".
  std::string blank = "\r";
  blank.append(kWidth + 7, ' ').append("\r");
  std::fputs(blank.c_str(), out_);
  std::fflush(out_);
  drawn_ = false;
  last_percent_ = -1;
}

}  // namespace drillbif::client
