// diffdyn collect: pushing data from the ODE-engine Panda world as a pushing CSV.
//
//   diffdyn collect --trajectories 400 --length 10 --seed 1 --threads 2
//                   --starts seed --out pushes.csv [--json]
//
// Trajectories run in parallel worlds (one ODE threading object each); the CSV
// is byte-identical for the same seed at any thread count.
#include <chrono>
#include <ctime>
#include <filesystem>
#include <map>
#include <string>

#include <fmt/core.h>

#include "command.h"
#include "diffdyn/autodiff_ode/progress.h"
#include "diffdyn/physics/pushing_collect.h"
#include "diffdyn/physics/pushing_csv.h"

namespace diffdyn::cli {
namespace {

struct CollectArgs {
  CommonOptions common;
  int trajectories = 100;
  int length = 10;
  int threads = 1;
  std::string starts = "seed";
  std::string obstacle = "auto";
  std::string out;
};

void RunCollect(const CollectArgs& args) {
  DIFFDYN_CHECK(args.trajectories >= 1, "--trajectories must be at least 1, got ",
                args.trajectories);
  DIFFDYN_CHECK(args.length >= 1, "--length must be at least 1, got ", args.length);
  DIFFDYN_CHECK(args.threads >= 1, "--threads must be at least 1, got ", args.threads);
  const std::filesystem::path out(args.out);
  const std::filesystem::path parent = out.has_parent_path() ? out.parent_path() : ".";
  DIFFDYN_CHECK(std::filesystem::is_directory(parent), "--out ", args.out, ": directory ",
                parent.string(), " does not exist");

  CollectOptions options;
  options.trajectories = args.trajectories;
  options.length = args.length;
  options.seed = args.common.seed;
  options.threads = args.threads;
  options.starts = args.starts == "task" ? StartDistribution::kTask : StartDistribution::kSeed;
  // The seed's data were collected without the obstacle; the task has it.
  options.world.obstacle = args.obstacle == "on" || (args.obstacle == "auto" && args.starts == "task");
  ProgressBar bar("collect", args.trajectories, !args.common.quiet);
  options.progress = [&bar](int done) { bar.Update(done); };

  const auto t0 = std::chrono::steady_clock::now();
  const std::clock_t cpu0 = std::clock();
  CollectStats stats;
  const auto data = CollectPushingData(options, &stats);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double cpu_seconds = static_cast<double>(std::clock() - cpu0) / CLOCKS_PER_SEC;
  bar.Finish();
  WritePushingCsvFile(out, data);

  const nlohmann::json summary = {
      {"path", out.string()},
      {"trajectories", static_cast<int>(data.size())},
      {"pushes", stats.pushes},
      {"seconds", seconds},
      {"pushes_per_second", stats.pushes / seconds},
      {"cpu_seconds", cpu_seconds},  // all threads; wall time suffers on a loaded machine
      {"threads", args.threads},
      {"starts", args.starts},
      {"obstacle", options.world.obstacle},
      {"off_table", stats.off_table},
      {"unreachable", stats.unreachable},
      {"max_tracking_error_mm", stats.max_tracking_error * 1e3},
  };
  if (args.common.json) {
    PrintJson(summary);
  } else {
    fmt::print("wrote {} trajectories ({} pushes) to {} in {:.2f} s ({:.1f} pushes/s, {:.1f} s CPU); "
               "off_table {}, unreachable {}, max tip tracking error {:.3f} mm\n",
               data.size(), stats.pushes, out.string(), seconds, stats.pushes / seconds,
               cpu_seconds, stats.off_table, stats.unreachable, stats.max_tracking_error * 1e3);
  }
}

}  // namespace

void RegisterCollectCommand(CLI::App& app) {
  auto* command = app.add_subcommand(
      "collect", "Collect block-pushing trajectories from the ODE-engine Panda world");
  auto args = std::make_shared<CollectArgs>();
  AddCommonOptions(command, args->common);
  command->add_option("--trajectories", args->trajectories, "Number of trajectories");
  command->add_option("--length", args->length, "Pushes per trajectory");
  command->add_option("--threads", args->threads, "Worker threads (output does not depend on it)");
  command->add_option("--starts", args->starts,
                      "Start poses: seed = the seed's (0.4, 0, 0.2 pi); task = spread over the "
                      "obstacle task's region")
      ->check(CLI::IsMember({"seed", "task"}));
  command->add_option("--obstacle", args->obstacle,
                      "Obstacle in the world: auto = only with --starts task")
      ->check(CLI::IsMember({"auto", "on", "off"}));
  command->add_option("--out", args->out, "Output pushing CSV")->required();
  command->callback([args] { RunCollect(*args); });
}

}  // namespace diffdyn::cli
