// The diffdyn command line: shared conventions of every subcommand.
//
// Each subcommand lives in its own file and exposes one function
//
//   void RegisterDemoCommand(CLI::App& app);
//
// called from RegisterCommands (commands.cc), the one place that lists them.
// Conventions every command follows:
//   --seed S     seeds every random thing (std::mt19937_64)
//   --json       one JSON object on one line on stdout (keys fixed in DESIGN.md)
//   --quiet      no progress bar (it is also off when stderr is not a terminal)
// Errors: diffdyn::Error (bad input) -> "error: ..." and exit 2;
// NumericalError or any other failure -> "error: ..." and exit 1.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "diffdyn/models/precision.h"

namespace diffdyn {
class SweepQueue;  // solvers/sweep.h
}  // namespace diffdyn

namespace diffdyn::cli {

/// Options shared by every command.
struct CommonOptions {
  std::uint64_t seed = 0;
  bool json = false;
  bool quiet = false;
};

/// Validator of a numeric option: a finite number in [lo, hi] (checked on the text
/// before conversion, so integers never wrap and NaN is refused).
CLI::Validator Bounded(double lo, double hi);

/// Validator of an input path: an existing regular file (FIFOs, devices and
/// sockets are refused), or with `allow_folder` also a folder.
CLI::Validator InputPath(bool allow_folder = false);

/// Validator of an output path: one that does not exist yet, or an existing
/// regular file (or, with `folder`, an existing folder); never a device or FIFO.
CLI::Validator OutputPath(bool folder = false);

/// Throws diffdyn::Error if `output` (the value of option `output_option`) names
/// the same file as `input`: no command overwrites its own input.
void CheckDistinct(const std::string& input, const std::string& output_option, const std::string& output);

/// Adds --precision (f32 or f64; empty: the model file's own) to `command`, bound to
/// `value`.
void AddPrecisionOption(CLI::App* command, std::string& value);

/// The precision a --precision value names; nullopt when it is empty. Throws
/// diffdyn::Error naming --precision for another value.
std::optional<Precision> PrecisionOption(const std::string& value);

/// Adds --seed, --json and --quiet to `command`, bound to `options`.
void AddCommonOptions(CLI::App* command, CommonOptions& options);

/// Prints `summary` as one line of JSON on stdout. A non-finite number anywhere
/// in it is a runtime failure (NumericalError naming the key), never printed.
void PrintJson(const nlohmann::json& summary);

/// Where the tasks of a sweep ran (RunSweepTasks).
struct SweepPlacement {
  /// False on the ranks other than 0 under mpirun: rank 0 holds the results and reports.
  bool coordinator = true;
  int ranks = 1;
  int workers = 1;
};

/// Runs the pending tasks of `queue` on the ranks of mpirun when this process was
/// started by it (solvers/sweep_mpi.h), else on `workers` local child processes at
/// once (0: the number of cores; solvers/sweep.h). `executable` runs tasks that name
/// no program of their own. Throws std::runtime_error under mpirun without MPI.
SweepPlacement RunSweepTasks(const std::filesystem::path& executable, SweepQueue& queue, int workers);

/// This process's rank under mpirun (OMPI_COMM_WORLD_RANK or PMIX_RANK), else 0.
int MpiRankFromEnvironment();

/// Registers every subcommand on `app` (commands.cc).
void RegisterCommands(CLI::App& app);

/// The whole command line on `app`: name, --version and every subcommand with
/// its options, validators and callback (run.cc).
void BuildApp(CLI::App& app);

/// Runs the command line; returns the process exit code (main.cc).
int Run(int argc, char** argv);

// One registration function per command file.
void RegisterInfoCommand(CLI::App& app);
void RegisterDiagnoseCommand(CLI::App& app);
void RegisterDemoCommand(CLI::App& app);
void RegisterCollectCommand(CLI::App& app);
void RegisterTrainCommand(CLI::App& app);
void RegisterEvalCommand(CLI::App& app);
void RegisterPushCommand(CLI::App& app);
void RegisterControlCommand(CLI::App& app);
void RegisterHjbCommand(CLI::App& app);
void RegisterSweepCommand(CLI::App& app);
void RegisterFiguresCommand(CLI::App& app);

}  // namespace diffdyn::cli
