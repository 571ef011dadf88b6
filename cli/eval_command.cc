// diffdyn eval: how well a dynamics model predicts a dataset.
//
//   diffdyn eval --model M --data D [--solver S] [--steps K] [--substeps K] [--json]
//
// The numbers are EvaluateFiles' (solvers/model_evaluation.h, which says what each
// is): single-step, average 4-step and baseline losses of a dynamics model, or a
// DeLaN's inverse-dynamics scores. This file parses the options and prints.
#include <string>

#include <fmt/core.h>

#include "command.h"
#include "diffdyn/solvers/model_evaluation.h"

namespace diffdyn::cli {
namespace {

struct EvalCommandOptions {
  CommonOptions common;
  EvalRequest request;
};

// The summary as text: a dynamics model's three losses, or a DeLaN's scores.
void PrintSummary(const EvalRequest& r, const nlohmann::json& s) {
  if (s.contains("test_characters_only")) {
    fmt::print("{} on {} ({} samples{}):\n", s["model"].get<std::string>(), r.data, s["n_samples"].get<int>(),
               s["test_characters_only"].get<bool>() ? ", test characters e, q, v" : "");
    for (const auto& [key, value] : s.items()) {
      if (value.is_number_float()) fmt::print("  {:<20} {:.4e}\n", key, value.get<double>());
    }
    return;
  }
  const std::string integration =
      s.contains("solver")
          ? fmt::format(" ({}, {} points)", s["solver"].get<std::string>(), s["steps"].get<int>())
          : "";
  fmt::print("{}{} on {} ({}): {} transitions, {} 4-step windows\n", s["model"].get<std::string>(), integration,
             r.data, s["system"].get<std::string>(), s["n_samples"].get<int>(), s["n_windows"].get<int>());
  if (s["dt_jitter"].get<double>() > 1e-6) {
    fmt::print("irregular sampling: dt from {:.4g} to {:.4g} s (median {:.4g} s)\n", s["dt_min"].get<double>(),
               s["dt_max"].get<double>(), s["dt"].get<double>());
  }
  fmt::print("single-step loss {:.4e} (baseline 'state stays' {:.4e}), average multi-step loss {:.4e}\n",
             s["single_step_loss"].get<double>(), s["baseline_single_step_loss"].get<double>(),
             s["avg_multi_step_loss"].get<double>());
}

void RunEval(const EvalCommandOptions& o) {
  const nlohmann::json summary = EvaluateFiles(o.request);
  if (o.common.json) {
    PrintJson(summary);
  } else {
    PrintSummary(o.request, summary);
  }
}

}  // namespace

void RegisterEvalCommand(CLI::App& app) {
  auto* command = app.add_subcommand(
      "eval", "Single-step, average multi-step and baseline loss of any dynamics model on a dataset "
              "(a DeLaN: torque, force-component and energy errors)");
  auto o = std::make_shared<EvalCommandOptions>();
  AddCommonOptions(command, o->common);
  command->add_option("--model", o->request.model,
                      "Model file (learned, extended-physics or delan), an analytic model (pendulum, "
                      "cartpole, double-pendulum, arm2, panda) or oracle")
      ->required();
  command->add_option("--data", o->request.data,
                      "Dataset: a pushing CSV, a joint-space CSV or a real-data folder")
      ->check(InputPath(true))
      ->required();
  command->add_option("--solver", o->request.solver,
                      "Integrate a NeuralODE or physics model with this solver instead of its own "
                      "(rk4, rk4-classic, euler, midpoint; dopri5 for NeuralODEs)");
  command->add_option("--steps", o->request.steps,
                      "NeuralODE only: grid points on [0, 1] instead of the model's (>= 2)")
      ->check(Bounded(2, 10000))
      ->default_str("");
  command->add_option("--substeps", o->request.substeps, "Physics models: solver steps per transition")
      ->check(Bounded(1, 10000))
      ->capture_default_str();
  command->add_option("--threads", o->request.threads, "Threads (0: all cores)")
      ->check(Bounded(0, 256));
  AddPrecisionOption(command, o->request.precision);
  command->callback([o] { RunEval(*o); });
}

}  // namespace diffdyn::cli
