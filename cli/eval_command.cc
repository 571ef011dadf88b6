// diffdyn eval: the paper's Fig. 5 metrics of a pushing model file on a pushing CSV:
// the single-step SE(2) loss over every transition and the average 4-step loss
// (sum of the four undiscounted rollout losses / 4) over every 4-step window.
#include <memory>
#include <string>

#include <fmt/core.h>

#include "command.h"
#include "diffdyn/models/pushing_models.h"
#include "diffdyn/physics/pushing_csv.h"
#include "diffdyn/solvers/pushing_training.h"

namespace diffdyn::cli {
namespace {

struct EvalCommandOptions {
  CommonOptions common;
  std::string model;
  std::string data;
  int threads = 0;
};

void RunEval(const EvalCommandOptions& o) {
  const PushingModel model = LoadPushingModel(o.model);
  const auto trajectories = ReadPushingData(o.data);
  const PushingEvaluation e = EvaluatePushingModel(model, trajectories, o.threads);
  if (o.common.json) {
    PrintJson({{"n_samples", e.n_samples},
               {"single_step_loss", e.single_step_loss},
               {"avg_multi_step_loss", e.avg_multi_step_loss},
               {"n_windows", e.n_windows},
               {"model", model.kind()}});
  } else {
    fmt::print("{} on {}: {} transitions, {} 4-step windows\n", model.kind(), o.data, e.n_samples,
               e.n_windows);
    fmt::print("single-step loss {:.4e}, average multi-step loss {:.4e}\n", e.single_step_loss,
               e.avg_multi_step_loss);
  }
}

}  // namespace

void RegisterEvalCommand(CLI::App& app) {
  auto* command = app.add_subcommand(
      "eval", "Single-step and average multi-step SE(2) loss of a pushing model on a CSV");
  auto o = std::make_shared<EvalCommandOptions>();
  AddCommonOptions(command, o->common);
  command->add_option("--model", o->model, "Model file (abs-nn, res-nn, abs-node, res-node)")
      ->required();
  command->add_option("--data", o->data, "Pushing CSV")->required();
  command->add_option("--threads", o->threads, "Threads (0: all cores)");
  command->callback([o] { RunEval(*o); });
}

}  // namespace diffdyn::cli
