// A progress bar on stderr for long work.
//
//   diffdyn::ProgressBar bar("train", epochs, /*enabled=*/!quiet);
//   for (int e = 0; e < epochs; ++e) {
//     ...
//     bar.Update(e + 1, "train 1.2e-4 val 1.5e-4");
//   }
//   bar.Finish();
//
// The bar draws only when stderr is a terminal (and `enabled` is true), at most
// ten times a second, so piping output or running under CI prints nothing.
#pragma once

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>

namespace diffdyn {

class ProgressBar {
 public:
  /// `total` units of work labelled `label`; draws only if `enabled` and stderr is a tty.
  ProgressBar(std::string label, long total, bool enabled = true)
      : label_(std::move(label)),
        total_(total),
        enabled_(enabled && isatty(fileno(stderr))),
        start_(std::chrono::steady_clock::now()) {}
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;
  ~ProgressBar() { Finish(); }

  /// Reports that `done` of `total` units are finished, with an optional status text.
  void Update(long done, const std::string& status = "") {
    if (!enabled_ || finished_) return;
    const auto now = std::chrono::steady_clock::now();
    if (done < total_ && now - last_draw_ < std::chrono::milliseconds(100)) return;
    last_draw_ = now;
    const double elapsed = std::chrono::duration<double>(now - start_).count();
    const double frac = total_ > 0 ? std::clamp(static_cast<double>(done) / total_, 0.0, 1.0) : 1.0;
    constexpr int kWidth = 30;
    const int filled = static_cast<int>(frac * kWidth);
    const double eta = frac > 0 ? elapsed * (1.0 - frac) / frac : 0.0;
    const std::string bar = std::string(filled, '#') + std::string(kWidth - filled, ' ');
    std::fprintf(stderr, "\r%s [%s] %ld/%ld %.0fs eta %.0fs %s\x1b[K", label_.c_str(),
                 bar.c_str(), done, total_, elapsed, eta, status.c_str());
    std::fflush(stderr);
  }

  /// Ends the bar's line (called by the destructor too).
  void Finish() {
    if (enabled_ && !finished_) std::fputc('\n', stderr);
    finished_ = true;
  }

 private:
  std::string label_;
  long total_;
  bool enabled_;
  bool finished_ = false;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_draw_{};
};

}  // namespace diffdyn
