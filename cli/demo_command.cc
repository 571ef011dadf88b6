// diffdyn demo: the end-to-end pipeline that exists so far.
#include <fmt/core.h>

#include "command.h"

namespace diffdyn::cli {

void RegisterDemoCommand(CLI::App& app) {
  auto* command = app.add_subcommand("demo", "Run the end-to-end pipeline that exists so far");
  auto options = std::make_shared<CommonOptions>();
  AddCommonOptions(command, *options);
  command->callback([options] { fmt::print("diffdyn demo: no stages yet\n"); });
}

}  // namespace diffdyn::cli
