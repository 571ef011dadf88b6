// Shared by the paper_figures programs: drawing the figure's PNGs with its plot.py,
// and the command line's error convention (one line "error: ...", exit code 2 for a
// caller's mistake such as a bad option or file, 1 for a runtime failure).
//
//   try {
//     Run(options);
//     if (plot) diffdyn::figures::RunPlot(out);
//   } catch (const std::exception& e) {
//     return diffdyn::figures::ReportError(e);
//   }
#pragma once

#include <cstdio>
#include <cstdlib>
#include <exception>
#include <stdexcept>
#include <string>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn::figures {

/// Runs `DIFFDYN_PYTHON DIFFDYN_FIGURE_DIR/plot.py 'out'` (both set by the figure's
/// CMake target); throws std::runtime_error, naming the command, when it fails.
inline void RunPlot(const std::string& out) {
  const std::string cmd = DIFFDYN_PYTHON " " DIFFDYN_FIGURE_DIR "/plot.py '" + out + "'";
  if (std::system(cmd.c_str()) != 0) throw std::runtime_error("plot.py failed: " + cmd);
}

/// Prints "error: <what>" on one line; returns 2 for diffdyn::Error (the caller's
/// mistake) and 1 for any other exception (a runtime or numerical failure).
inline int ReportError(const std::exception& e) {
  std::fprintf(stderr, "error: %s\n", e.what());
  return dynamic_cast<const Error*>(&e) != nullptr ? 2 : 1;
}

}  // namespace diffdyn::figures
