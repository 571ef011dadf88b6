#include "diffdyn/solvers/model_training.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "diffdyn/autodiff_ode/butcher.h"
#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/delan.h"
#include "diffdyn/models/learned_model.h"
#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/delan_training.h"
#include "diffdyn/solvers/training.h"

namespace diffdyn {
namespace {

// The ranges the command line's validators enforce, for callers without them.
void CheckRequest(const TrainRequest& r) {
  std::error_code ec;
  DIFFDYN_CHECK(std::filesystem::exists(r.data, ec), "--data ", r.data, ": no such file or directory");
  DIFFDYN_CHECK(!std::filesystem::equivalent(r.data, r.out, ec) || ec, "--out ", r.out,
                " is also an input; refusing to overwrite it");
  DIFFDYN_CHECK(!r.epochs || *r.epochs >= 1, "--epochs must be >= 1, got ", *r.epochs);
  DIFFDYN_CHECK(!r.batch || *r.batch >= 1, "--batch must be >= 1, got ", *r.batch);
  DIFFDYN_CHECK(!r.hidden || *r.hidden >= 1, "--hidden must be >= 1, got ", *r.hidden);
  DIFFDYN_CHECK(!r.lr || (*r.lr > 0 && std::isfinite(*r.lr)), "--lr must be positive, got ", *r.lr);
  DIFFDYN_CHECK(r.val_fraction > 0 && r.val_fraction <= 0.9, "--val-fraction must be in (0, 0.9], got ",
                r.val_fraction);
  DIFFDYN_CHECK(r.gamma >= 0 && r.gamma <= 1, "--gamma must be in [0, 1], got ", r.gamma);
  DIFFDYN_CHECK(r.threads >= 0 && r.patience >= 0, "--threads and --patience must be >= 0");
  DIFFDYN_CHECK(r.normalize == "auto" || r.normalize == "on" || r.normalize == "off", "--normalize: unknown '",
                r.normalize, "' (expected auto, on or off)");
  DIFFDYN_CHECK(r.loss == "single" || r.loss == "multi", "--loss: unknown loss '", r.loss,
                "' (expected single or multi)");
  ParsePrecision(r.precision);
}

// The losses and timing a model file records of its training.
nlohmann::json TrainMetrics(const TrainResult& r) {
  return {{"final_train_loss", r.final_train_loss},
          {"final_val_loss", r.final_val_loss},
          {"seconds_per_epoch", r.seconds_per_epoch}};
}

// The summary keys of every run; callers add their model's own.
nlohmann::json TrainSummary(const TrainRequest& request, const TrainResult& r, const std::string& system,
                            Eigen::Index parameters) {
  nlohmann::json j = TrainMetrics(r);
  j.update({{"model_path", request.out},
            {"n_train", r.n_train},
            {"n_val", r.n_val},
            {"epochs", static_cast<int>(r.epochs.size())},
            {"stopped_early", r.stopped_early},
            {"system", system},
            {"model", request.model},
            {"parameters", parameters},
            {"precision", request.precision},
            {"solver_steps", r.solver_steps},
            {"rejected_steps", r.rejected_steps}});
  return j;
}

// The joints (0-based) a DeLaN's trunk sees as (sin q, cos q): none unless the
// angle features were asked for, then every joint not prismatic.
std::vector<int> DelanPeriodicJoints(const TrainRequest& r, int dof) {
  if (!r.angle_features_given || r.layout.angle_features != AngleFeatures::kSinCos) return {};
  for (int j : r.layout.prismatic) {
    DIFFDYN_CHECK(j >= 1 && j <= dof, "--prismatic: joint ", j, " is not one of the ", dof, " joints of --data");
  }
  std::vector<int> periodic;
  for (int j = 1; j <= dof; ++j) {
    if (std::find(r.layout.prismatic.begin(), r.layout.prismatic.end(), j) == r.layout.prismatic.end()) {
      periodic.push_back(j - 1);
    }
  }
  return periodic;
}

void CheckTrained(const TrainResult& result, const Eigen::VectorXd& parameters, const char* hint) {
  if (!std::isfinite(result.final_train_loss) || !parameters.allFinite()) {
    throw NumericalError(StrCat("training diverged: the train loss is ", result.final_train_loss, " (try ",
                                hint, "); nothing written"));
  }
}

nlohmann::json TrainDelanFiles(const TrainRequest& r) {
  const Dataset data = ReadDataset(r.data);
  const TrainOptions defaults = DelanTrainDefaults();
  TrainOptions options = defaults;
  options.epochs = r.epochs.value_or(defaults.epochs);
  options.learning_rate = r.lr.value_or(defaults.learning_rate);
  options.batch_size = r.batch.value_or(defaults.batch_size);
  options.val_fraction = r.val_fraction;
  options.seed = r.seed;
  options.threads = r.threads;
  options.patience = r.patience;
  options.progress = r.progress;
  const DelanSplit split = SplitForDelan(data, r.val_fraction, r.seed);
  DelanOptions arch;
  arch.dof = split.train.dof();
  arch.hidden = r.hidden.value_or(arch.hidden);
  arch.friction = r.model == "delan-friction";
  arch.epsilon = r.mass_epsilon;
  arch.diagonal_floor = r.diagonal_floor;
  arch.periodic = DelanPeriodicJoints(r, arch.dof);
  Delan model = Delan::Initialized(arch, r.seed);
  model.SetPrecision(ParsePrecision(r.precision));
  // normalize on: every joint's torque weighs the same; auto and off: the authors' plain MSE.
  const Eigen::VectorXd weights = r.normalize == "on" ? BalancedJointWeights(split.train) : Eigen::VectorXd();
  const TrainResult result = TrainDelan(&model, split.train, split.test, options, {}, weights);
  CheckTrained(result, model.parameters(), "a smaller --lr");
  const nlohmann::json provenance = {
      {"command", "diffdyn train"}, {"data", r.data},        {"seed", r.seed},
      {"epochs", options.epochs},   {"lr", options.learning_rate}, {"batch", options.batch_size},
      {"weight_decay", options.weight_decay}, {"amsgrad", options.amsgrad}, {"split", split.how},
      {"n_train", result.n_train},  {"n_val", result.n_val}, {"epochs_run", result.epochs.size()},
      {"joint_weights", std::vector<double>(weights.data(), weights.data() + weights.size())}};
  SaveDelan(r.out, model, provenance, TrainMetrics(result));
  nlohmann::json summary = TrainSummary(r, result, data.system.name, model.num_parameters());
  summary["loss"] = weights.size() > 0 ? "torque (joints weighted by 1 / variance)" : "torque";
  summary["split"] = split.how;
  summary["dof"] = model.dof();
  return summary;
}

}  // namespace

FittedModel FitLearnedModel(const Dataset& data, LearnedModelConfig config, const TrainOptions& options,
                            int horizon, bool normalize) {
  config.system = data.system;
  config.Validate();
  const Windows windows = MakeWindows(data, horizon);
  if (normalize) {
    std::vector<int> train_index, val_index;
    SplitWindows(windows.size(), options.val_fraction, options.seed, &train_index, &val_index);
    DIFFDYN_CHECK(!train_index.empty(), "the split of ", windows.size(), " windows at validation fraction ",
                  options.val_fraction, " leaves none for training");
    const Windows train = SelectWindows(windows, train_index);
    config.scaling = FitScaling(config, train.start, train.actions[0], train.targets[0]);
  }
  FittedModel fit{LearnedModel::Initialized(config, options.seed), {}};
  fit.model.set_time_step(data.Intervals().median);
  Trainer trainer(&fit.model, options);
  fit.result = trainer.Train(windows);
  return fit;
}

nlohmann::json TrainFiles(const TrainRequest& r) {
  CheckRequest(r);
  if (IsDelanKind(r.model)) return TrainDelanFiles(r);
  LearnedModelConfig config;
  config.type = ParseLearnedKind(r.model);
  JointLayout layout = r.layout;
  if (!r.angle_features_given) layout.angle_features = DefaultAngleFeatures(config.type);
  const Dataset dataset = ReadDataset(r.data, layout);
  const SampleIntervals dt = dataset.Intervals();
  config.system = dataset.system;
  config.method = ParseMethod(r.solver);
  config.steps = r.steps;
  config.hidden = r.hidden.value_or(100);
  config.precision = ParsePrecision(r.precision);
  config.Validate();
  const int horizon = r.loss == "multi" ? 4 : 1;
  std::vector<int> train_index, val_index;
  SplitWindows(MakeWindows(dataset, horizon).size(), r.val_fraction, r.seed, &train_index, &val_index);
  DIFFDYN_CHECK(!train_index.empty() && !val_index.empty(), "--val-fraction ", r.val_fraction, " of the ",
                train_index.size() + val_index.size(), " samples of ", r.data, " leaves ", train_index.size(),
                " for training and ", val_index.size(), " for validation (both need at least one)");
  // Unit-scale network inputs and outputs unless the data are the paper's pushing CSVs.
  const bool normalize = r.normalize == "on" || (r.normalize == "auto" && dataset.format != "pushing-csv");
  TrainOptions options;
  options.epochs = r.epochs.value_or(100);
  options.learning_rate = r.lr.value_or(1e-3);
  options.batch_size = r.batch.value_or(500);
  options.val_fraction = r.val_fraction;
  options.gamma = r.gamma;
  options.seed = r.seed;
  options.threads = r.threads;
  options.patience = r.patience;
  options.progress = r.progress;
  const FittedModel fit = FitLearnedModel(dataset, config, options, horizon, normalize);
  const LearnedModel& model = fit.model;
  const TrainResult& result = fit.result;
  CheckTrained(result, model.parameters(), "a smaller --lr or --normalize on");

  const nlohmann::json provenance = {
      {"command", "diffdyn train"}, {"data", r.data},          {"seed", r.seed},
      {"loss", r.loss},             {"gamma", r.gamma},         {"epochs", options.epochs},
      {"lr", options.learning_rate}, {"batch", options.batch_size}, {"val_fraction", r.val_fraction},
      {"n_train", result.n_train},  {"n_val", result.n_val},     {"dt", dt.median},
      {"dt_min", dt.min},           {"dt_max", dt.max},         {"epochs_run", result.epochs.size()},
      {"normalized", normalize}};
  SaveLearnedModel(r.out, model, provenance, TrainMetrics(result));
  nlohmann::json summary = TrainSummary(r, result, dataset.system.name, model.num_parameters());
  summary.update({{"dt", dt.median},
                  {"dt_jitter", dt.jitter()},
                  {"dt_min", dt.min},
                  {"dt_max", dt.max},
                  {"normalized", normalize},
                  {"loss", r.loss},
                  {"horizon", horizon},
                  {"state_size", model.state_size()},
                  {"action_size", model.action_size()}});
  return summary;
}

}  // namespace diffdyn
