// Sweeps: a grid of diffdyn runs as independent child processes, one gathered CSV.
//
// A sweep spec (DESIGN.md, "Sweep spec") names one command, fixed options and a
// grid of option values:
//
//   {"command": "train",
//    "options": {"--data": "d.csv", "--epochs": 20, "--threads": 1},
//    "grid":    {"--seed": [0, 1, 2], "--model": ["abs-nn", "abs-node"]}}
//
// Each combination of grid values is one task, run as `diffdyn COMMAND ... --json`.
// Tasks are numbered in grid order: the grid's keys in the order the spec writes
// them, the last key varying fastest (above: seed 0 with abs-nn, seed 0 with
// abs-node, seed 1 with abs-nn, ...). JSON `true` passes the bare flag, `false`
// omits it, numbers and strings are passed as written.
//
// A sweep's folder OUT holds, per task, OUT/tasks/<index>/ with the task's
// stdout.txt, stderr.txt and result.json (its arguments, exit code and the
// parsed --json summary, written atomically when the task ends), and at the end
// OUT/results.csv: one row per task in grid order with the grid values, the
// tasks' summary keys and `exit_code`. A task whose result.json records the same
// arguments is finished and is not run again: an interrupted sweep restarted
// with the same spec runs only what is missing.
//
//   diffdyn::SweepSpec spec = diffdyn::ReadSweepSpec("spec.json");
//   std::vector<diffdyn::SweepTask> tasks = diffdyn::ExpandSweep(spec, "out", "model.json");
//   diffdyn::SweepQueue queue(tasks, diffdyn::SweepFolder("out"));
//   diffdyn::RunSweepLocal("/usr/bin/diffdyn", queue, /*workers=*/2);
//   diffdyn::WriteSweepResults(spec, tasks, queue.Results(), "out/results.csv");
//
// The scheduler over Open MPI ranks is in sweep_mpi.h; both share SweepQueue.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

namespace diffdyn {

/// Most tasks one sweep may have (a larger grid is refused as bad input).
inline constexpr std::size_t kMaxSweepTasks = 100000;

/// Grid axes, in the spec's order: flag ("--name") and its non-empty list of
/// values (JSON scalars: strings, numbers or booleans).
using SweepGrid = std::vector<std::pair<std::string, std::vector<nlohmann::json>>>;

/// A parsed sweep spec.
struct SweepSpec {
  std::string command;
  /// Fixed options, in the spec's order: flag ("--name") and value.
  std::vector<std::pair<std::string, nlohmann::json>> options;
  SweepGrid grid;
  /// Number of tasks: the product of the grid's list lengths (1 without a grid).
  std::size_t TaskCount() const;
};

/// Parses a grid object {"--flag": [values], ...} (named `name` in errors).
/// Throws diffdyn::Error "<name>: ..." for a flag that does not start with "--",
/// `--json`, an empty list, a value that is not a scalar, or more than
/// kMaxSweepTasks combinations.
SweepGrid ParseSweepGrid(const nlohmann::ordered_json& grid, const std::string& name);

/// One combination of a grid's values.
struct SweepPoint {
  /// One value per axis, as SweepValueText.
  std::vector<std::string> values;
  /// The command-line arguments the values add ("--flag value", a bare flag for true).
  std::vector<std::string> args;
};

/// The combinations of `grid` in grid order: the axes in their order, the last
/// varying fastest; one empty point for an empty grid.
std::vector<SweepPoint> ExpandSweepGrid(const SweepGrid& grid);

/// Parses a spec from `text` (named `name` in errors). Throws diffdyn::Error
/// "<name>: ..." for invalid JSON, a missing or non-string `command`, a flag that
/// does not start with "--" or is given twice, `--json` (the sweep adds it), a
/// value that is not a scalar, an empty grid list, or more than kMaxSweepTasks tasks.
SweepSpec ParseSweepSpec(std::string_view text, const std::string& name);

/// ParseSweepSpec on the regular file `path`.
SweepSpec ReadSweepSpec(const std::filesystem::path& path);

/// The command-line text of a scalar JSON value: strings as they are, numbers
/// as JSON writes them, booleans as "true"/"false".
std::string SweepValueText(const nlohmann::json& value);

/// One task of a sweep.
struct SweepTask {
  int index = 0;
  /// The task's grid values (one per grid axis, as SweepValueText).
  std::vector<std::string> grid_values;
  /// The arguments after the executable: command, options, grid options, "--json".
  std::vector<std::string> args;
  /// The executable this task runs; empty: the scheduler's (the diffdyn binary).
  std::filesystem::path program;
};

/// The tasks of `spec` in grid order. If `out_name` is not empty and the spec
/// sets no `--out`, task i gets `--out <out_dir>/tasks/<i>/<out_name>`.
std::vector<SweepTask> ExpandSweep(const SweepSpec& spec, const std::filesystem::path& out_dir,
                                   const std::string& out_name);

/// How one task ended.
struct SweepResult {
  /// The child's exit code; 128 + N if signal N ended it; -1 if it never started.
  int exit_code = -1;
  /// The JSON object of the task's last stdout line (null if there is none).
  nlohmann::json summary;
  /// Wall time of the task (not part of results.csv).
  double seconds = 0;
};

/// The files of a sweep under its folder (see the file comment).
class SweepFolder {
 public:
  explicit SweepFolder(std::filesystem::path root) : root_(std::move(root)) {}

  const std::filesystem::path& Root() const { return root_; }
  /// OUT/tasks/<index>.
  std::filesystem::path TaskDir(int index) const;
  /// The recorded result of `task`, if its result.json exists, is readable and
  /// records the same arguments.
  std::optional<SweepResult> Recorded(const SweepTask& task) const;
  /// Writes `task`'s result.json atomically (creating the task's folder).
  void Record(const SweepTask& task, const SweepResult& result) const;

 private:
  std::filesystem::path root_;
};

/// A child process running one task.
struct RunningTask {
  int index = 0;
  pid_t pid = -1;
  std::chrono::steady_clock::time_point start;
};

/// Starts `task` as a child process of `task.program` (of `executable` when
/// that is empty) with stdin from /dev/null,
/// stdout and stderr to `task_dir`/stdout.txt and stderr.txt (the folder is
/// created), and the launcher's OMPI_* and PMIX_* variables removed from its
/// environment. The child is sent SIGTERM if this process dies. Throws
/// std::runtime_error if the process cannot be started.
RunningTask StartSweepTask(const std::filesystem::path& executable, const SweepTask& task,
                           const std::filesystem::path& task_dir);

/// The result of a finished child: `wait_status` as waitpid returned it; the
/// summary is read from `task_dir`/stdout.txt.
SweepResult FinishSweepTask(const RunningTask& running, int wait_status, const std::filesystem::path& task_dir);

/// The queue both schedulers share: which tasks remain, their results, progress.
/// Tasks already recorded in the folder count as finished from the start.
class SweepQueue {
 public:
  /// Called after each task that ran here finishes: task, result, finished so far.
  using Progress = std::function<void(const SweepTask&, const SweepResult&, std::size_t finished)>;

  SweepQueue(const std::vector<SweepTask>& tasks, SweepFolder folder, Progress progress = {});

  const std::vector<SweepTask>& Tasks() const { return tasks_; }
  const SweepFolder& Folder() const { return folder_; }
  /// The next task to run (its index), or nullopt when none is left to hand out.
  std::optional<int> Next();
  /// Records task `index`'s result (result.json, progress).
  void Finish(int index, SweepResult result);
  /// Tasks found recorded at construction (not run again).
  std::size_t RecordedCount() const { return recorded_; }
  /// Tasks finished (recorded or run).
  std::size_t FinishedCount() const { return finished_; }
  bool AllFinished() const { return finished_ == tasks_.size(); }
  /// Results in task order (exit_code -1 for tasks not finished).
  const std::vector<SweepResult>& Results() const { return results_; }

 private:
  std::vector<SweepTask> tasks_;
  SweepFolder folder_;
  Progress progress_;
  std::vector<int> pending_;  // task indices still to hand out, in reverse order
  std::vector<SweepResult> results_;
  std::size_t recorded_ = 0;
  std::size_t finished_ = 0;
};

/// Runs every pending task of `queue` on this machine, at most `workers` child
/// processes at once, waiting (blocked, not spinning) for each to end.
void RunSweepLocal(const std::filesystem::path& executable, SweepQueue& queue, int workers);

/// True when this process was started by an MPI launcher (Open MPI's
/// OMPI_COMM_WORLD_SIZE or PMIx's PMIX_RANK is set): then sweep_mpi.h schedules.
bool LaunchedByMpirun();

/// Writes `path` (atomically): the header is the grid's flags without "--", the
/// summary keys in order of first appearance over the tasks in grid order (keys
/// equal to a grid column or `exit_code` are left out), then `exit_code`; one row
/// per task, an empty cell where a task's summary lacks a key. Strings with a
/// comma, quote or newline are quoted; arrays and objects are written as JSON.
void WriteSweepResults(const SweepSpec& spec, const std::vector<SweepTask>& tasks,
                       const std::vector<SweepResult>& results, const std::filesystem::path& path);

}  // namespace diffdyn
