// Fuzz target: the real-data readers. The first byte picks the layout the rest
// of the input is written into:
//   '0' a Panda Gaz 2019 folder (the input as positions, velocities and torques,
//       with one time per 7 lines),
//   '1' an IBM double-pendulum folder (0.csv),
//   '2' a DeLaN characters folder (character_data.csv),
//   '3' a single file, whose kind the reader detects.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/solvers/dataset_io.h"
#include "fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  namespace fs = std::filesystem;
  if (size == 0) return 0;
  const int layout = data[0] % 4;
  ++data;
  --size;
  const fs::path folder = diffdyn::fuzz::ScratchFolder() / "measured";
  fs::remove_all(folder);
  fs::create_directories(folder);
  std::string input = folder.string();
  switch (layout) {
    case 0:
      for (const char* name : {"exciting_traj_positions.txt", "exciting_traj_velocity.txt",
                               "exciting_traj_torques.txt"}) {
        diffdyn::fuzz::WriteBytes(folder / name, data, size);
      }
      {
        std::ofstream time(folder / "exciting_traj_time.txt");
        const auto lines = std::count(data, data + size, '\n');
        for (long k = 0; k < lines / 7; ++k) time << 0.001 * static_cast<double>(k) << '\n';
      }
      break;
    case 1:
      diffdyn::fuzz::WriteBytes(folder / "0.csv", data, size);
      break;
    case 2:
      diffdyn::fuzz::WriteBytes(folder / "character_data.csv", data, size);
      break;
    default:
      input = diffdyn::fuzz::WriteBytes(folder / "log.csv", data, size);
  }
  try {
    (void)diffdyn::ReadDataset(input);
  } catch (const diffdyn::Error&) {
  }
  return 0;
}
