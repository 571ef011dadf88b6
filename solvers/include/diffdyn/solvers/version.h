// The library's version, and where its installed plot scripts are.
//
//   std::cout << diffdyn::Version();          // "0.1.0"
//   std::filesystem::path dir = diffdyn::PlotScriptsDir();   // .../scripts/plots
#pragma once

#include <filesystem>
#include <string>

namespace diffdyn {

/// The diffdyn version, "MAJOR.MINOR.PATCH", as configured by CMake.
std::string Version();

/// The folder of the Python plot scripts (scripts/plots): $DIFFDYN_PLOTS_DIR when
/// set, else the source tree's when it is there, else the installed copy
/// (<prefix>/share/diffdyn/plots).
std::filesystem::path PlotScriptsDir();

}  // namespace diffdyn
