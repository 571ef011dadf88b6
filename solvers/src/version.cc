#include "diffdyn/solvers/version.h"

#include <cstdlib>

namespace diffdyn {

std::string Version() { return DIFFDYN_VERSION; }

std::filesystem::path PlotScriptsDir() {
  namespace fs = std::filesystem;
  if (const char* env = std::getenv("DIFFDYN_PLOTS_DIR"); env != nullptr && *env != '\0') return env;
  const fs::path source = fs::path(DIFFDYN_SOURCE_DIR) / "scripts" / "plots";
  if (fs::is_directory(source)) return source;
  return fs::path(DIFFDYN_INSTALL_DATADIR) / "plots";
}

}  // namespace diffdyn
