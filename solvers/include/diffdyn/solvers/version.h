// The library's version.
//
//   std::cout << diffdyn::Version();  // "0.1.0"
#pragma once

#include <string>

namespace diffdyn {

/// The diffdyn version, "MAJOR.MINOR.PATCH", as configured by CMake.
std::string Version();

}  // namespace diffdyn
