// The command line's shared parts: option validators, the JSON summary, parsing
// and the mapping of failures to exit codes (command.h); the commands are in
// their own files.
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <functional>
#include <iostream>
#include <new>
#include <string>
#include <system_error>

#include <fmt/core.h>

#include "command.h"
#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/io.h"
#include "diffdyn/solvers/version.h"

namespace diffdyn::cli {
namespace {

// Exit codes of the command line.
constexpr int kExitRuntimeFailure = 1;
constexpr int kExitBadInput = 2;

// Longest error message printed (longer ones, which quote input, are cut).
constexpr std::size_t kMaxErrorLength = 300;

// Prints one line "error: <message>" with newlines folded into spaces and
// control characters shown as '?'.
void PrintError(std::string message) {
  for (char& c : message) {
    if (c == '\n' || c == '\r' || c == '\t') c = ' ';
    else if (static_cast<unsigned char>(c) < 0x20) c = '?';
  }
  while (!message.empty() && message.back() == ' ') message.pop_back();
  if (message.size() > kMaxErrorLength) message = message.substr(0, kMaxErrorLength - 3) + "...";
  std::fprintf(stderr, "error: %s\n", message.c_str());
}

// The first 60 characters of `text`, for quoting input in a message.
std::string Quote(const std::string& text) {
  return text.size() <= 60 ? text : text.substr(0, 57) + "...";
}

}  // namespace

void AddPrecisionOption(CLI::App* command, std::string& value) {
  command->add_option("--precision", value,
                      "Compute in f32 or f64 (learned models: abs-nn, res-nn, abs-node, res-node; "
                      "default: the model file's own)");
}

std::optional<Precision> PrecisionOption(const std::string& value) {
  if (value.empty()) return std::nullopt;
  return ParsePrecision(value, "--precision");
}

CLI::Validator Bounded(double lo, double hi) {
  const std::string range = fmt::format("[{:g}, {:g}]", lo, hi);
  return CLI::Validator(
      [lo, hi, range](std::string& text) -> std::string {
        double value = 0;
        std::size_t used = 0;
        try {
          value = std::stod(text, &used);
        } catch (const std::exception&) {
          used = 0;
        }
        if (used != text.size() || text.empty() || !std::isfinite(value)) {
          return "'" + Quote(text) + "' is not a finite number";
        }
        if (value < lo || value > hi) return Quote(text) + " is outside " + range;
        return {};
      },
      "in " + range);
}

namespace {

// A validator whose message is the diffdyn::Error `check(text)` throws.
CLI::Validator FromCheck(std::function<void(const std::string&)> check, std::string description) {
  return CLI::Validator(
      [check = std::move(check)](std::string& text) -> std::string {
        try {
          check(text);
        } catch (const Error& e) {
          return e.what();
        }
        return {};
      },
      std::move(description));
}

}  // namespace

CLI::Validator InputPath(bool allow_folder) {
  return FromCheck([allow_folder](const std::string& path) { CheckInputPath(path, allow_folder); },
                   allow_folder ? "FILE|FOLDER" : "FILE");
}

CLI::Validator OutputPath(bool folder) {
  return FromCheck(
      [folder](const std::string& path) {
        DIFFDYN_CHECK(!path.empty(), "empty path");
        CheckOutputPath(path, folder);
      },
      folder ? "FOLDER" : "FILE");
}

void CheckDistinct(const std::string& input, const std::string& output_option, const std::string& output) {
  std::error_code ec;
  DIFFDYN_CHECK(!std::filesystem::equivalent(input, output, ec) || ec, output_option, " ", Quote(output),
                " is also an input; refusing to overwrite it");
}

void AddCommonOptions(CLI::App* command, CommonOptions& options) {
  command->add_option("--seed", options.seed, "Seed of every random thing");
  command->add_flag("--json", options.json, "Print a one-line JSON summary on stdout");
  command->add_flag("--quiet", options.quiet, "No progress bar");
}

namespace {

// The key path of the first non-finite number in `j` ("" if there is none).
std::string NonFiniteKey(const nlohmann::json& j, const std::string& path) {
  if (j.is_number_float()) return std::isfinite(j.get<double>()) ? "" : (path.empty() ? "(value)" : path);
  if (j.is_object()) {
    for (const auto& [key, value] : j.items()) {
      std::string found = NonFiniteKey(value, path.empty() ? key : path + "." + key);
      if (!found.empty()) return found;
    }
  } else if (j.is_array()) {
    for (std::size_t i = 0; i < j.size(); ++i) {
      std::string found = NonFiniteKey(j[i], path + "[" + std::to_string(i) + "]");
      if (!found.empty()) return found;
    }
  }
  return "";
}

}  // namespace

void PrintJson(const nlohmann::json& summary) {
  const std::string key = NonFiniteKey(summary, "");
  if (!key.empty()) throw NumericalError("the result '" + key + "' is not finite");
  std::cout << summary.dump() << std::endl;
}

void BuildApp(CLI::App& app) {
  app.description("diffdyn: learn, check and use robot dynamics with differential equations as the model prior.");
  app.name("diffdyn");
  app.set_version_flag("--version", "diffdyn " + Version());
  // A flag takes no value other than "true": `--free=<number>` is a parse error (exit 2),
  // not CLI11's numeric conversion of the value.
  app.option_defaults()->always_capture_default()->disable_flag_override();
  app.require_subcommand(1);
  app.fallthrough(false);
  RegisterCommands(app);
}

int Run(int argc, char** argv) {
  CLI::App app;
  BuildApp(app);

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
  } catch (const std::bad_alloc&) {
    PrintError("out of memory (a count or size option is too large for this machine)");
    return kExitRuntimeFailure;
  } catch (const std::exception& e) {
    PrintError(e.what());
    return kExitRuntimeFailure;
  }
}

}  // namespace diffdyn::cli
