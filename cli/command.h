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

/// Adds --seed, --json and --quiet to `command`, bound to `options`.
void AddCommonOptions(CLI::App* command, CommonOptions& options);

/// Prints `summary` as one line of JSON on stdout.
void PrintJson(const nlohmann::json& summary);

/// Registers every subcommand on `app` (commands.cc).
void RegisterCommands(CLI::App& app);

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

}  // namespace diffdyn::cli
