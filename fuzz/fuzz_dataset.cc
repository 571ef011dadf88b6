// Fuzz target: the dataset reader (pushing CSV and joint-space CSV, told apart by
// the header), then what every command does next with a dataset: sample
// intervals and 4-step training windows.
#include <cstddef>
#include <cstdint>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/training.h"
#include "fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = diffdyn::fuzz::WriteBytes(diffdyn::fuzz::ScratchFolder() / "data.csv", data, size);
  try {
    const diffdyn::Dataset dataset = diffdyn::ReadDataset(path);
    (void)dataset.Intervals();
    (void)diffdyn::MakeWindows(dataset, 4);
  } catch (const diffdyn::Error&) {
  }
  return 0;
}
