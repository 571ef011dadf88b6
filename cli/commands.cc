// The one place that lists the subcommands. A command is registered when it works.
#include "command.h"

namespace diffdyn::cli {

void RegisterCommands(CLI::App& app) {
  RegisterCollectCommand(app);
  RegisterControlCommand(app);
  RegisterDemoCommand(app);
  RegisterDiagnoseCommand(app);
  RegisterEvalCommand(app);
  RegisterFiguresCommand(app);
  RegisterHjbCommand(app);
  RegisterInfoCommand(app);
  RegisterPushCommand(app);
  RegisterSweepCommand(app);
  RegisterTrainCommand(app);
}

}  // namespace diffdyn::cli
