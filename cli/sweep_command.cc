// diffdyn sweep: a grid of diffdyn runs as child processes, on local workers or
// Open MPI ranks, gathered into one CSV (solvers/sweep.h, solvers/sweep_mpi.h).
//
//   diffdyn sweep --spec spec.json --out runs [--workers 2] [--json]
//   mpirun -np 4 diffdyn sweep --spec spec.json --out runs
//
// The spec's command and option names are checked against the command line
// before anything runs. Tasks whose result is recorded in --out with the same
// arguments are not run again. A failed task is recorded with its exit code and
// the sweep goes on; the sweep itself exits 0 once every task has a result.
#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <stdexcept>
#include <string>
#include <thread>

#include <fmt/core.h>

#include "command.h"
#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/io.h"
#include "diffdyn/solvers/sweep.h"
#ifdef DIFFDYN_HAVE_MPI
#include "diffdyn/solvers/sweep_mpi.h"
#endif

namespace diffdyn::cli {
namespace {
namespace fs = std::filesystem;

struct SweepCommandOptions {
  std::string spec;
  std::string out;
  int workers = 0;
  bool json = false;
  bool quiet = false;
};

// The file name a task's --out gets, by what the command writes there.
std::string OutName(const std::string& command) {
  static const std::map<std::string, std::string> kFiles = {
      {"collect", "data.csv"}, {"train", "model.json"}, {"hjb", "value.json"}};
  const auto it = kFiles.find(command);
  return it != kFiles.end() ? it->second : "out";
}

// Throws diffdyn::Error unless the spec's command and every option exist.
// Returns the name a task's --out gets ("" if the command has no --out).
std::string CheckAgainstCommandLine(const SweepSpec& spec, const std::string& spec_path, const CLI::App& root) {
  const CLI::App* command = nullptr;
  for (const CLI::App* sub : root.get_subcommands({})) {
    if (sub->get_name() == spec.command) command = sub;
  }
  DIFFDYN_CHECK(command != nullptr, spec_path, ": unknown command '", spec.command.substr(0, 60),
                "' (diffdyn --help lists them)");
  const auto check = [&](const std::string& flag) {
    DIFFDYN_CHECK(command->get_option_no_throw(flag) != nullptr, spec_path, ": 'diffdyn ", spec.command,
                  "' has no option '", flag, "'");
  };
  for (const auto& [flag, value] : spec.options) check(flag);
  for (const auto& [flag, values] : spec.grid) check(flag);
  return command->get_option_no_throw("--out") != nullptr ? OutName(spec.command) : "";
}

// One progress line per task that ran here.
SweepQueue::Progress ProgressPrinter(const SweepSpec& spec, std::size_t total, bool quiet) {
  if (quiet) return {};
  return [&spec, total](const SweepTask& task, const SweepResult& r, std::size_t finished) {
    std::string values;
    for (std::size_t a = 0; a < task.grid_values.size(); ++a) {
      values += fmt::format("{}{}={}", a ? " " : "", spec.grid[a].first.substr(2), task.grid_values[a]);
    }
    fmt::print(stderr, "sweep: [{}/{}] task {}{}{}: exit {}, {:.1f} s\n", finished, total, task.index,
               values.empty() ? "" : " ", values, r.exit_code, r.seconds);
  };
}

void RunSweep(const SweepCommandOptions& o, const CLI::App& root) {
  const auto start = std::chrono::steady_clock::now();
  const SweepSpec spec = ReadSweepSpec(o.spec);
  const std::string out_name = CheckAgainstCommandLine(spec, o.spec, root);
  const fs::path out(o.out);
  const fs::path results_path = out / "results.csv";
  CheckOutputPath(results_path);
  const std::vector<SweepTask> tasks = ExpandSweep(spec, out, out_name);
  std::error_code ec;
  fs::create_directories(out / "tasks", ec);
  if (ec) throw std::runtime_error(StrCat(o.out, ": cannot create the sweep folder: ", ec.message()));
  const fs::path executable = fs::read_symlink("/proc/self/exe");

  SweepQueue queue(tasks, SweepFolder(out), ProgressPrinter(spec, tasks.size(), o.quiet));
  if (!o.quiet && queue.RecordedCount() > 0) {
    fmt::print(stderr, "sweep: {} of {} tasks already recorded in {}, not run again\n", queue.RecordedCount(),
               tasks.size(), o.out);
  }
  const SweepPlacement placement = RunSweepTasks(executable, queue, o.workers);
  if (!placement.coordinator) return;  // rank 0 reports
  const int ranks = placement.ranks, workers = placement.workers;
  WriteSweepResults(spec, tasks, queue.Results(), results_path);

  std::size_t done = 0;
  for (const SweepResult& r : queue.Results()) done += r.exit_code == 0;
  const std::size_t failed = tasks.size() - done;
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (o.json) {
    PrintJson({{"tasks", tasks.size()}, {"done", done}, {"failed", failed}, {"ranks", ranks},
               {"workers", workers}, {"recorded", queue.RecordedCount()}, {"seconds", seconds},
               {"results_path", results_path.string()}});
  } else {
    fmt::print("{} tasks: {} done, {} failed ({} already recorded); {:.1f} s on {} {}\nresults in {}\n",
               tasks.size(), done, failed, queue.RecordedCount(), seconds, ranks > 1 ? ranks : workers,
               ranks > 1 ? "ranks" : "workers", results_path.string());
  }
}

}  // namespace

SweepPlacement RunSweepTasks(const fs::path& executable, SweepQueue& queue, int workers) {
  SweepPlacement placement;
  if (LaunchedByMpirun()) {
#ifdef DIFFDYN_HAVE_MPI
    const MpiSweepOutcome outcome = RunSweepMpi(executable, queue);
    placement.coordinator = outcome.coordinator;
    placement.ranks = outcome.ranks;
    return placement;
#else
    throw std::runtime_error("started by mpirun, but this diffdyn was built without MPI "
                             "(install libopenmpi-dev and rebuild)");
#endif
  }
  placement.workers = workers > 0 ? workers : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  RunSweepLocal(executable, queue, placement.workers);
  return placement;
}

int MpiRankFromEnvironment() {
  for (const char* name : {"OMPI_COMM_WORLD_RANK", "PMIX_RANK"}) {
    if (const char* value = std::getenv(name)) return std::atoi(value);
  }
  return 0;
}

void RegisterSweepCommand(CLI::App& app) {
  auto* command = app.add_subcommand(
      "sweep", "Run a grid of diffdyn commands as parallel tasks (local workers or mpirun ranks)");
  auto o = std::make_shared<SweepCommandOptions>();
  command->add_option("--spec", o->spec, "Sweep spec: {\"command\", \"options\", \"grid\"} (DESIGN.md)")
      ->required()
      ->check(InputPath());
  command->add_option("--out", o->out, "Sweep folder: tasks/<index>/ and results.csv (created)")
      ->required()
      ->check(OutputPath(/*folder=*/true));
  command->add_option("--workers", o->workers, "Tasks at once without mpirun (0 = the number of cores)")
      ->check(Bounded(0, 256));
  command->add_flag("--json", o->json, "Print a one-line JSON summary on stdout");
  command->add_flag("--quiet", o->quiet, "No line per finished task");
  command->callback([o, &app] { RunSweep(*o, app); });
}

}  // namespace diffdyn::cli
