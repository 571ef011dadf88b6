// diffdyn eval: the paper's Fig. 5 metrics of a pushing model file on a pushing CSV:
// the single-step SE(2) loss over every transition and the average 4-step loss
// (sum of the four undiscounted rollout losses / 4) over every 4-step window.
// --solver / --steps re-integrate a NeuralODE with another solver or grid than it was
// trained with (same weights), to see how much of its loss the integration carries.
#include <memory>
#include <string>

#include <fmt/core.h>

#include "command.h"
#include "diffdyn/models/learned_model.h"
#include "diffdyn/physics/pushing_csv.h"
#include "diffdyn/solvers/pushing_training.h"

namespace diffdyn::cli {
namespace {

struct EvalCommandOptions {
  CommonOptions common;
  std::string model;
  std::string data;
  std::string solver;
  int steps = 0;
  bool solver_given = false;  // else the model's own solver
  bool steps_given = false;   // else the model's own grid
  int threads = 0;
};

// The model file's network with the solver and grid of the options where given.
LearnedModel LoadWithSolver(const EvalCommandOptions& o) {
  const LearnedModel model = LoadLearnedModel(o.model);
  if (!o.solver_given && !o.steps_given) return model;
  DIFFDYN_CHECK(IsNeuralOde(model.config().type), o.solver_given ? "--solver" : "--steps",
                ": applies to NeuralODE models only; the model in ", o.model, " is ", model.kind());
  LearnedModelConfig config = model.config();
  if (o.solver_given) config.method = ParseMethod(o.solver);
  if (o.steps_given) config.steps = o.steps;
  return LearnedModel(config, model.net());
}

void RunEval(const EvalCommandOptions& o) {
  const LearnedModel model = LoadWithSolver(o);
  const auto trajectories = ReadPushingData(o.data);
  const PushingEvaluation e = EvaluatePushingModel(model, trajectories, o.threads);
  const bool ode = IsNeuralOde(model.config().type);
  if (o.common.json) {
    nlohmann::json summary = {{"n_samples", e.n_samples},
                              {"single_step_loss", e.single_step_loss},
                              {"avg_multi_step_loss", e.avg_multi_step_loss},
                              {"n_windows", e.n_windows},
                              {"model", model.kind()}};
    if (ode) {
      summary["solver"] = MethodName(model.config().method);
      summary["steps"] = model.config().steps;
    }
    PrintJson(summary);
  } else {
    const std::string integration =
        ode ? fmt::format(" ({}, {} points)", MethodName(model.config().method), model.config().steps)
            : "";
    fmt::print("{}{} on {}: {} transitions, {} 4-step windows\n", model.kind(), integration, o.data,
               e.n_samples, e.n_windows);
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
  const CLI::Option* solver = command->add_option("--solver", o->solver,
                      "NeuralODE only: integrate with this solver instead of the model's (rk4, "
                      "rk4-classic, euler, midpoint, dopri5)");
  const CLI::Option* steps = command->add_option("--steps", o->steps,
                      "NeuralODE only: grid points on [0, 1] instead of the model's (>= 2)")
                          ->default_str("");
  command->add_option("--threads", o->threads, "Threads (0: all cores)");
  command->callback([o, solver, steps] {
    o->solver_given = solver->count() > 0;
    o->steps_given = steps->count() > 0;
    RunEval(*o);
  });
}

}  // namespace diffdyn::cli
