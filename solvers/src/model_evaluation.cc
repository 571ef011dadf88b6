#include "diffdyn/solvers/model_evaluation.h"

#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <string>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/delan.h"
#include "diffdyn/models/json_io.h"
#include "diffdyn/models/learned_model.h"
#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/delan_training.h"
#include "diffdyn/solvers/load_model.h"
#include "diffdyn/solvers/training.h"

namespace diffdyn {
namespace {

// The model file's network with the solver and grid of the request.
std::unique_ptr<TransitionModel> LoadNeuralOdeWithSolver(const EvalRequest& r) {
  const LearnedModel model = LoadLearnedModel(r.model);
  DIFFDYN_CHECK(IsNeuralOde(model.config().type), r.steps > 0 ? "--steps" : "--solver",
                ": applies to NeuralODE and physics models; the model in ", r.model, " is ", model.kind());
  LearnedModelConfig config = model.config();
  if (!r.solver.empty()) config.method = ParseMethod(r.solver);
  if (r.steps > 0) config.steps = r.steps;
  if (!r.precision.empty()) config.precision = ParsePrecision(r.precision);
  config.Validate();
  return std::make_unique<LearnedModel>(config, model.net());
}

// The model of --model, integrated as the request says.
std::unique_ptr<TransitionModel> LoadModel(const EvalRequest& r, double dt) {
  LoadModelOptions load;
  load.dt = dt;
  load.substeps = r.substeps;
  if (!r.solver.empty()) load.method = ParseMethod(r.solver);
  if (!r.precision.empty()) load.precision = ParsePrecision(r.precision);
  std::unique_ptr<TransitionModel> model = LoadTransitionModel(r.model, load);
  const bool learned = dynamic_cast<const LearnedModel*>(model.get()) != nullptr;
  if (learned && (!r.solver.empty() || r.steps > 0)) return LoadNeuralOdeWithSolver(r);
  DIFFDYN_CHECK(r.steps == 0 || learned, "--steps: applies to NeuralODE models only; ", r.model, " is ",
                model->kind(), " (use --substeps)");
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
void AddDelanRollouts(const EvalRequest& r, bool test_characters_only, std::map<std::string, double>* scores) {
  Dataset data = ReadDataset(r.data, JointLayout{.all_actuated = true});
  if (test_characters_only) {
    std::erase_if(data.trajectories, [](const Trajectory& t) {
      return t.label != "e" && t.label != "q" && t.label != "v";
    });
  }
  LoadModelOptions load;
  load.dt = data.Intervals().median;
  load.substeps = r.substeps;
  if (!r.solver.empty()) load.method = ParseMethod(r.solver);
  const std::unique_ptr<TransitionModel> model = LoadTransitionModel(r.model, load);
  const Dataset fitted = DatasetForModel(data, model->description(), "--model " + r.model);
  const Windows single = MakeWindows(fitted, 1);
  (*scores)["single_step_loss"] = RolloutLoss(*model, single, 1.0, r.threads);
  (*scores)["baseline_single_step_loss"] = BaselineLoss(single);
  for (const int horizon : {4, 10}) {
    const double sum = RolloutLoss(*model, MakeWindows(fitted, horizon), 1.0, r.threads);
    (*scores)[horizon == 4 ? "avg_multi_step_loss" : "avg_10_step_loss"] = sum / horizon;
  }
}

nlohmann::json EvaluateDelan(const EvalRequest& r) {
  Delan model = LoadDelan(r.model);
  if (!r.precision.empty()) model.SetPrecision(ParsePrecision(r.precision));
  const Dataset data = ReadDataset(r.data);
  const int dof = JointCount(data);
  DIFFDYN_CHECK(dof == model.dof(), "--data ", r.data, ": ", dof, " joints, the DeLaN in ", r.model, " has ",
                model.dof());
  // The held-out characters on the DeLaN data; every sample elsewhere.
  const bool characters = data.format == "delan-characters";
  const DelanSamples test = characters ? SplitForDelan(data, 0.2, 0).test : SamplesOf(data);
  std::map<std::string, double> scores = ScoreDelan(model, test, r.threads);
  if (model.options().friction) {
    for (int j = 0; j < model.dof(); ++j) {
      scores[StrCat("viscous_", j + 1)] = model.viscous()[j];
      scores[StrCat("coulomb_", j + 1)] = model.coulomb()[j];
    }
  }
  AddDelanRollouts(r, characters, &scores);
  for (const auto& [key, value] : scores) {
    if (!std::isfinite(value)) {
      throw NumericalError(StrCat("--model ", r.model, ": ", key, " on ", r.data, " is not finite"));
    }
  }
  nlohmann::json summary = {{"model", model.options().kind()}, {"precision", PrecisionName(model.precision())}};
  for (const auto& [key, value] : scores) summary[key] = value;
  summary["n_samples"] = test.size();
  summary["test_characters_only"] = characters;
  return summary;
}

}  // namespace

nlohmann::json EvaluateFiles(const EvalRequest& r) {
  DIFFDYN_CHECK(r.threads >= 0, "--threads must be >= 0, got ", r.threads);
  DIFFDYN_CHECK(r.steps == 0 || r.steps >= 2, "--steps must be >= 2, got ", r.steps);
  std::error_code ec;
  DIFFDYN_CHECK(std::filesystem::exists(r.data, ec), "--data ", r.data, ": no such file or directory");
  if (IsDelanFile(r.model)) return EvaluateDelan(r);
  DIFFDYN_CHECK(r.substeps >= 1, "--substeps must be >= 1, got ", r.substeps);
  const Dataset read = ReadDataset(r.data, JointLayout{.all_actuated = true});
  const SampleIntervals dt = read.Intervals();
  const std::unique_ptr<TransitionModel> model = LoadModel(r, dt.median);
  const Dataset data = DatasetForModel(read, model->description(), "--model " + r.model);
  const Evaluation e = EvaluateModel(*model, data, r.threads);
  DIFFDYN_CHECK(e.n_windows > 0, "--data ", r.data, ": no trajectory has the 5 samples of a 4-step window");
  // A model whose predictions overflow is a runtime failure, not a result.
  if (!std::isfinite(e.single_step_loss) || !std::isfinite(e.baseline_single_step_loss) ||
      !std::isfinite(e.avg_multi_step_loss)) {
    throw NumericalError(StrCat("--model ", r.model, ": the loss on ", r.data,
                                " is not finite (the model's predictions overflow on this data)"));
  }
  nlohmann::json summary = {{"n_samples", e.n_samples},
                            {"single_step_loss", e.single_step_loss},
                            {"avg_multi_step_loss", e.avg_multi_step_loss},
                            {"baseline_single_step_loss", e.baseline_single_step_loss},
                            {"n_windows", e.n_windows},
                            {"model", model->kind()},
                            {"system", data.system.name},
                            {"dt", dt.median},
                            {"dt_jitter", dt.jitter()},
                            {"dt_min", dt.min},
                            {"dt_max", dt.max}};
  const auto* learned = dynamic_cast<const LearnedModel*>(model.get());
  if (learned && IsNeuralOde(learned->config().type)) {
    summary["solver"] = MethodName(learned->config().method);
    summary["steps"] = learned->config().steps;
  }
  return summary;
}

}  // namespace diffdyn
