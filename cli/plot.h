// Drawing figures: C++ writes CSV, Python (matplotlib, Agg) draws the PNG.
//
// Plot scripts live in scripts/plots/ of the source tree (installed to
// share/diffdyn/plots). A command calls
//
//   diffdyn::cli::RunPlotScript("demo_fit.py", {csv_path, png_path});
//
// which runs `<python> <plots>/demo_fit.py <args...>` with the Python CMake found
// (Debian's /usr/bin/python3, which has python3-matplotlib). The folder is
// PlotScriptsDir() (solvers/version.h): $DIFFDYN_PLOTS_DIR, else the source tree the
// binary was built from, else the install prefix. A failing script is reported on stderr as one warning line
// and returns false: the numbers (CSV, JSON) are written either way.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "diffdyn/solvers/version.h"

namespace diffdyn::cli {

/// Runs `<python> PlotScriptsDir()/script args...`; true on success, else warns and returns false.
bool RunPlotScript(const std::string& script, const std::vector<std::string>& args);

}  // namespace diffdyn::cli
