// Fuzz target: the --params JSON file of diagnose (names and limits checked
// against the Panda model, the one with the most parameters).
#include <cstddef>
#include <cstdint>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/physics/model_registry.h"
#include "fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const auto model = diffdyn::MakeAnalyticModel("panda");
  const std::string path = diffdyn::fuzz::WriteBytes(diffdyn::fuzz::ScratchFolder() / "params.json", data, size);
  try {
    (void)diffdyn::ReadParamsFile(*model, path);
  } catch (const diffdyn::Error&) {
  }
  return 0;
}
