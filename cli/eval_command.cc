// diffdyn eval: how well a dynamics model predicts a dataset.
//
//   diffdyn eval --model M --data D [--json]
//
// M is anything LoadTransitionModel opens (a learned or extended-physics model
// file, an analytic model name, `oracle`); D any dataset (pushing CSV, joint-space
// CSV, real-data folder). Reported, by the data's state metric (state_loss.h): the
// single-step loss over every transition, the average 4-step loss (sum of the four
// undiscounted rollout losses / 4) over every 4-step window, and the single-step
// loss of the baseline "the state stays". Physics models integrate each transition
// over its own interval (irregular logs); learned models predict their fixed one.
// --solver / --steps re-integrate a NeuralODE with another solver or grid than it
// was trained with (same weights); for continuous-time physics models --solver and
// --substeps set the integration.
//
// A DeLaN model file (kind "delan") is scored as inverse dynamics instead: on the
// DeLaN characters the test characters e, q, v, on other joint-space data every
// sample; the torque, force-component, energy and power errors of DESIGN.md
// (`torque_mse`, `inertial_mse`, ..., `*_nmse`) and `min_mass_eigenvalue`; and,
// rolled out as a dynamics model (forward dynamics, --solver and --substeps), the
// `single_step_loss`, `avg_multi_step_loss` (4 steps), `avg_10_step_loss` and the
// `baseline_single_step_loss` of "the state stays".
#include <cmath>
#include <filesystem>
#include <memory>
#include <string>

#include <fmt/core.h>

#include "command.h"
#include "diffdyn/models/delan.h"
#include "diffdyn/models/json_io.h"
#include "diffdyn/models/learned_model.h"
#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/delan_training.h"
#include "diffdyn/solvers/load_model.h"
#include "diffdyn/solvers/training.h"

namespace diffdyn::cli {
namespace {

struct EvalCommandOptions {
  CommonOptions common;
  std::string model;
  std::string data;
  std::string solver;
  int steps = 0;
  int substeps = 4;
  bool solver_given = false;  // else the model's own solver
  bool steps_given = false;   // else the model's own grid
  int threads = 0;
};

// The model file's network with the solver and grid of the options.
std::unique_ptr<TransitionModel> LoadNeuralOdeWithSolver(const EvalCommandOptions& o) {
  const LearnedModel model = LoadLearnedModel(o.model);
  DIFFDYN_CHECK(IsNeuralOde(model.config().type), o.steps_given ? "--steps" : "--solver",
                ": applies to NeuralODE and physics models; the model in ", o.model, " is ", model.kind());
  LearnedModelConfig config = model.config();
  if (o.solver_given) config.method = ParseMethod(o.solver);
  if (o.steps_given) config.steps = o.steps;
  config.Validate();
  return std::make_unique<LearnedModel>(config, model.net());
}

// The model of --model, integrated as the options say.
std::unique_ptr<TransitionModel> LoadModel(const EvalCommandOptions& o, double dt) {
  LoadModelOptions load;
  load.dt = dt;
  load.substeps = o.substeps;
  if (o.solver_given) load.method = ParseMethod(o.solver);
  std::unique_ptr<TransitionModel> model = LoadTransitionModel(o.model, load);
  const bool learned = dynamic_cast<const LearnedModel*>(model.get()) != nullptr;
  if (learned && (o.solver_given || o.steps_given)) return LoadNeuralOdeWithSolver(o);
  DIFFDYN_CHECK(!o.steps_given || learned, "--steps: applies to NeuralODE models only; ", o.model,
                " is ", model->kind(), " (use --substeps)");
  return model;
}

// Whether --model names a model file of kind "delan" or "delan-friction".
bool IsDelanFile(const std::string& spec) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(spec, ec)) return false;
  const nlohmann::json j = ReadJsonFile(spec);
  return j.is_object() && j.contains("kind") && j["kind"].is_string() && IsDelanKind(j["kind"].get<std::string>());
}

// The DeLaN as a dynamics model (forward dynamics through the continuous-time
// adapter, each transition over its own interval): the single-step, average 4-step
// and average 10-step losses of the state metric on the same samples as the scores.
void AddDelanRollouts(const EvalCommandOptions& o, bool test_characters_only,
                      std::map<std::string, double>* scores) {
  Dataset data = ReadDataset(o.data, JointLayout{.all_actuated = true});
  if (test_characters_only) {
    std::erase_if(data.trajectories, [](const Trajectory& t) {
      return t.label != "e" && t.label != "q" && t.label != "v";
    });
  }
  LoadModelOptions load;
  load.dt = data.Intervals().median;
  load.substeps = o.substeps;
  if (o.solver_given) load.method = ParseMethod(o.solver);
  const std::unique_ptr<TransitionModel> model = LoadTransitionModel(o.model, load);
  const Dataset fitted = DatasetForModel(data, model->description(), "--model " + o.model);
  const Windows single = MakeWindows(fitted, 1);
  (*scores)["single_step_loss"] = RolloutLoss(*model, single, 1.0, o.threads);
  (*scores)["baseline_single_step_loss"] = BaselineLoss(single);
  for (const int horizon : {4, 10}) {
    const double sum = RolloutLoss(*model, MakeWindows(fitted, horizon), 1.0, o.threads);
    (*scores)[horizon == 4 ? "avg_multi_step_loss" : "avg_10_step_loss"] = sum / horizon;
  }
}

void RunEvalDelan(const EvalCommandOptions& o) {
  const Delan model = LoadDelan(o.model);
  const JointData data = ReadMeasured(o.data);
  DIFFDYN_CHECK(data.dof() == model.dof(), "--data ", o.data, ": ", data.dof(), " joints, the DeLaN in ",
                o.model, " has ", model.dof());
  // The held-out characters on the DeLaN data; every sample elsewhere.
  const JointData test = data.format == "delan-characters" ? SplitForDelan(data, 0.2, 0).test
                                                          : WithAccelerations(data);
  std::map<std::string, double> scores = ScoreDelan(model, test, o.threads);
  if (model.options().friction) {
    for (int j = 0; j < model.dof(); ++j) {
      scores[StrCat("viscous_", j + 1)] = model.viscous()[j];
      scores[StrCat("coulomb_", j + 1)] = model.coulomb()[j];
    }
  }
  AddDelanRollouts(o, data.format == "delan-characters", &scores);
  for (const auto& [key, value] : scores) {
    if (!std::isfinite(value)) {
      throw NumericalError(StrCat("--model ", o.model, ": ", key, " on ", o.data, " is not finite"));
    }
  }
  if (o.common.json) {
    nlohmann::json summary = {{"model", model.options().kind()}};
    for (const auto& [key, value] : scores) summary[key] = value;
    summary["n_samples"] = test.size();
    PrintJson(summary);
    return;
  }
  fmt::print("{} on {} ({} samples{}):\n", model.options().kind(), o.data, test.size(),
             data.format == "delan-characters" ? ", test characters e, q, v" : "");
  for (const auto& [key, value] : scores) {
    if (key != "n_samples") fmt::print("  {:<20} {:.4e}\n", key, value);
  }
}

void RunEval(const EvalCommandOptions& o) {
  if (IsDelanFile(o.model)) return RunEvalDelan(o);
  DIFFDYN_CHECK(o.substeps >= 1, "--substeps must be >= 1, got ", o.substeps);
  const Dataset read = ReadDataset(o.data, JointLayout{.all_actuated = true});
  const SampleIntervals dt = read.Intervals();
  const std::unique_ptr<TransitionModel> model = LoadModel(o, dt.median);
  const Dataset data = DatasetForModel(read, model->description(), "--model " + o.model);
  const Evaluation e = EvaluateModel(*model, data, o.threads);
  DIFFDYN_CHECK(e.n_windows > 0, "--data ", o.data, ": no trajectory has the 5 samples of a 4-step window");
  // A model whose predictions overflow is a runtime failure, not a result.
  if (!std::isfinite(e.single_step_loss) || !std::isfinite(e.baseline_single_step_loss) ||
      !std::isfinite(e.avg_multi_step_loss)) {
    throw NumericalError(StrCat("--model ", o.model, ": the loss on ", o.data,
                                " is not finite (the model's predictions overflow on this data)"));
  }
  const auto* learned = dynamic_cast<const LearnedModel*>(model.get());
  const bool ode = learned && IsNeuralOde(learned->config().type);
  if (o.common.json) {
    nlohmann::json summary = {{"n_samples", e.n_samples},
                              {"single_step_loss", e.single_step_loss},
                              {"avg_multi_step_loss", e.avg_multi_step_loss},
                              {"baseline_single_step_loss", e.baseline_single_step_loss},
                              {"n_windows", e.n_windows},
                              {"model", model->kind()},
                              {"dt", dt.median},
                              {"dt_jitter", dt.jitter()}};
    if (ode) {
      summary["solver"] = MethodName(learned->config().method);
      summary["steps"] = learned->config().steps;
    }
    PrintJson(summary);
    return;
  }
  const std::string integration =
      ode ? fmt::format(" ({}, {} points)", MethodName(learned->config().method), learned->config().steps)
          : "";
  fmt::print("{}{} on {} ({}): {} transitions, {} 4-step windows\n", model->kind(), integration,
             o.data, data.system.name, e.n_samples, e.n_windows);
  if (dt.jitter() > 1e-6) {
    fmt::print("irregular sampling: dt from {:.4g} to {:.4g} s (median {:.4g} s)\n", dt.min, dt.max,
               dt.median);
  }
  fmt::print("single-step loss {:.4e} (baseline 'state stays' {:.4e}), average multi-step loss {:.4e}\n",
             e.single_step_loss, e.baseline_single_step_loss, e.avg_multi_step_loss);
}

}  // namespace

void RegisterEvalCommand(CLI::App& app) {
  auto* command = app.add_subcommand(
      "eval", "Single-step, average multi-step and baseline loss of any dynamics model on a dataset "
              "(a DeLaN: torque, force-component and energy errors)");
  auto o = std::make_shared<EvalCommandOptions>();
  AddCommonOptions(command, o->common);
  command->add_option("--model", o->model,
                      "Model file (learned, extended-physics or delan), an analytic model (pendulum, "
                      "cartpole, double-pendulum, arm2, panda) or oracle")
      ->required();
  command->add_option("--data", o->data,
                      "Dataset: a pushing CSV, a joint-space CSV or a real-data folder")
      ->check(InputPath(true))
      ->required();
  const CLI::Option* solver = command->add_option("--solver", o->solver,
                      "Integrate a NeuralODE or physics model with this solver instead of its own "
                      "(rk4, rk4-classic, euler, midpoint; dopri5 for NeuralODEs)");
  const CLI::Option* steps = command->add_option("--steps", o->steps,
                      "NeuralODE only: grid points on [0, 1] instead of the model's (>= 2)")
      ->check(Bounded(2, 10000))
                          ->default_str("");
  command->add_option("--substeps", o->substeps, "Physics models: solver steps per transition")
      ->check(Bounded(1, 10000))
      ->capture_default_str();
  command->add_option("--threads", o->threads, "Threads (0: all cores)")
      ->check(Bounded(0, 256));
  command->callback([o, solver, steps] {
    o->solver_given = solver->count() > 0;
    o->steps_given = steps->count() > 0;
    RunEval(*o);
  });
}

}  // namespace diffdyn::cli
