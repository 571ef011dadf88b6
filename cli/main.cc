// diffdyn: the command-line tool. Parsing and error mapping; the commands are in
// their own files (see command.h).
#include <cstdio>
#include <exception>
#include <iostream>
#include <string>

#include <glog/logging.h>

#include "command.h"
#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/solvers/version.h"

namespace diffdyn::cli {
namespace {

// Exit codes of the command line.
constexpr int kExitRuntimeFailure = 1;
constexpr int kExitBadInput = 2;

// Prints one line "error: <message>" with newlines folded into spaces.
void PrintError(std::string message) {
  for (char& c : message) {
    if (c == '\n' || c == '\r') c = ' ';
  }
  while (!message.empty() && message.back() == ' ') message.pop_back();
  std::fprintf(stderr, "error: %s\n", message.c_str());
}

}  // namespace

void AddCommonOptions(CLI::App* command, CommonOptions& options) {
  command->add_option("--seed", options.seed, "Seed of every random thing");
  command->add_flag("--json", options.json, "Print a one-line JSON summary on stdout");
  command->add_flag("--quiet", options.quiet, "No progress bar");
}

void PrintJson(const nlohmann::json& summary) {
  std::cout << summary.dump() << std::endl;
}

int Run(int argc, char** argv) {
  CLI::App app{"diffdyn: learn, check and use robot dynamics with differential equations as the "
               "model prior.",
               "diffdyn"};
  app.set_version_flag("--version", "diffdyn " + Version());
  app.option_defaults()->always_capture_default();
  app.require_subcommand(1);
  app.fallthrough(false);
  RegisterCommands(app);

  // A first word that is no command is named before CLI11 complains about it.
  if (argc > 1 && argv[1][0] != '-') {
    try {
      app.get_subcommand(argv[1]);
    } catch (const CLI::OptionNotFound&) {
      PrintError(std::string("unknown command '") + argv[1] + "' (diffdyn --help lists them)");
      return kExitBadInput;
    }
  }
  try {
    app.parse(argc, argv);
    return 0;
  } catch (const CLI::Success& e) {  // --help, --version
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    PrintError(e.what());
    return kExitBadInput;
  } catch (const Error& e) {
    PrintError(e.what());
    return kExitBadInput;
  } catch (const std::exception& e) {
    PrintError(e.what());
    return kExitRuntimeFailure;
  }
}

}  // namespace diffdyn::cli

int main(int argc, char** argv) {
  // Ceres logs through glog; diffdyn reports failures itself, as one line.
  FLAGS_minloglevel = google::GLOG_FATAL;
  FLAGS_logtostderr = true;
  google::InitGoogleLogging(argv[0]);
  return diffdyn::cli::Run(argc, argv);
}
