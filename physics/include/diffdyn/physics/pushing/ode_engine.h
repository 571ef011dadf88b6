// The Open Dynamics Engine, initialised once per process.
//
// Every ODE world in diffdyn (the pushing environment, the oracle model) calls
// OdeEngine::Acquire() first; the engine is initialised on first use, for all
// threads, and closed at process exit. ODE's own headers stay private to the
// compiled diffdyn::pusher library.
//
//   diffdyn::OdeEngine::Acquire();
//   std::cout << diffdyn::OdeEngine::Configuration();  // "ODE_double_precision ..."
#pragma once

#include <string>

namespace diffdyn {

class OdeEngine {
 public:
  /// Initialises ODE (dInitODE2 with all thread-local data) if not done yet.
  /// Thread-safe. Throws diffdyn::NumericalError if ODE cannot initialise.
  static void Acquire();

  /// ODE's build configuration string (dGetConfiguration), e.g. to check that
  /// the engine was built in double precision.
  static std::string Configuration();

  /// True when ODE was built with double-precision dReal.
  static bool IsDoublePrecision();
};

}  // namespace diffdyn
