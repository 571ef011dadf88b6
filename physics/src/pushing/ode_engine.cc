#include "diffdyn/physics/pushing/ode_engine.h"

#include <ode/ode.h>

#include <cstdlib>
#include <mutex>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {

void OdeEngine::Acquire() {
  static std::once_flag once;
  std::call_once(once, [] {
    if (dInitODE2(0) == 0) throw NumericalError("the Open Dynamics Engine failed to initialise");
    dAllocateODEDataForThread(dAllocateMaskAll);
    std::atexit([] { dCloseODE(); });
  });
}

std::string OdeEngine::Configuration() {
  Acquire();
  return dGetConfiguration();
}

bool OdeEngine::IsDoublePrecision() { return dCheckConfiguration("ODE_double_precision") != 0; }

}  // namespace diffdyn
