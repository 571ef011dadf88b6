// Fuzz target: the sweep spec reader (`diffdyn sweep --spec`) and the grid
// expansion of every spec it accepts.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/solvers/sweep.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const diffdyn::SweepSpec spec = diffdyn::ParseSweepSpec(text, "spec.json");
    if (spec.TaskCount() <= 1000) (void)diffdyn::ExpandSweep(spec, "out", "model.json");
  } catch (const diffdyn::Error&) {
  }
  return 0;
}
