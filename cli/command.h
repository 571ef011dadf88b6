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
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

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

/// Adds --seed, --json and --quiet to `command`, bound to `options`.
void AddCommonOptions(CLI::App* command, CommonOptions& options);

/// Prints `summary` as one line of JSON on stdout. A non-finite number anywhere
/// in it is a runtime failure (NumericalError naming the key), never printed.
void PrintJson(const nlohmann::json& summary);

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
