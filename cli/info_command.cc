// diffdyn info: the build's configuration (versions, ODE precision, threads).
#include <thread>

#include <Eigen/Core>
#include <ceres/version.h>
#include <fmt/core.h>

#include "command.h"
#include "diffdyn/physics/pushing/ode_engine.h"
#include "diffdyn/solvers/version.h"

namespace diffdyn::cli {

void RegisterInfoCommand(CLI::App& app) {
  auto* command = app.add_subcommand("info", "Print the build configuration");
  auto options = std::make_shared<CommonOptions>();
  AddCommonOptions(command, *options);
  command->callback([options] {
    const std::string eigen = fmt::format("{}.{}.{}", EIGEN_WORLD_VERSION, EIGEN_MAJOR_VERSION,
                                          EIGEN_MINOR_VERSION);
    const nlohmann::json summary = {
        {"version", Version()},
        {"eigen", eigen},
        {"eigen_simd", Eigen::SimdInstructionSetsInUse()},
        {"ceres", CERES_VERSION_STRING},
        {"ode", OdeEngine::Configuration()},
        {"ode_double_precision", OdeEngine::IsDoublePrecision()},
        {"hardware_threads", std::thread::hardware_concurrency()},
    };
    if (options->json) {
      PrintJson(summary);
      return;
    }
    for (const auto& [key, value] : summary.items()) {
      fmt::print("{:<22}{}\n", key, value.is_string() ? value.get<std::string>() : value.dump());
    }
  });
}

}  // namespace diffdyn::cli
