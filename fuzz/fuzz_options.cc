// Fuzz target: the option parser of every command. Each line of the input is one
// argument. When a command's parsing completes it throws Parsed, so its own
// callback (which owns the option storage and would run the command) never runs:
// what runs is CLI11's parsing and diffdyn's validators (ranges, paths), which
// must answer every argument list with Parsed or a CLI::Error (exit 2).
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "command.h"

namespace {
struct Parsed {};
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::vector<std::string> args;
  std::string current;
  for (std::size_t i = 0; i < size; ++i) {
    if (data[i] == '\n') {
      args.push_back(current);
      current.clear();
    } else {
      current += static_cast<char>(data[i]);
    }
  }
  if (!current.empty()) args.push_back(current);
  CLI::App app;
  diffdyn::cli::BuildApp(app);
  for (CLI::App* command : app.get_subcommands([](CLI::App*) { return true; })) {
    command->parse_complete_callback([] { throw Parsed{}; });
  }
  // CLI11 takes the arguments last to first.
  std::vector<std::string> reversed(args.rbegin(), args.rend());
  try {
    app.parse(reversed);
  } catch (const CLI::Error&) {
  } catch (const Parsed&) {
  }
  return 0;
}
