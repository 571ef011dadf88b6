#include "diffdyn/solvers/version.h"

namespace diffdyn {

std::string Version() { return DIFFDYN_VERSION; }

}  // namespace diffdyn
