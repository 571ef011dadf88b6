// How well a dynamics model predicts a dataset: the numbers `diffdyn eval` reports.
//
// EvaluateFiles opens a model (anything LoadTransitionModel opens: a learned or
// extended-physics model file, an analytic model name, `oracle`; or a DeLaN model
// file) and a dataset (pushing CSV, joint-space CSV, real-data folder) and returns
// the summary `eval --json` prints, so the command line and the Python module
// (`diffdyn.evaluate`) report the same numbers from one computation:
//
//   EvalRequest request{.model = "out/model.json", .data = "data.csv"};
//   nlohmann::json summary = EvaluateFiles(request);
//   double loss = summary["single_step_loss"];
//
// Dynamics models, by the data's state metric (state_loss.h): `single_step_loss`
// over every transition, `avg_multi_step_loss` (the sum of the four undiscounted
// rollout losses / 4) over every 4-step window, `baseline_single_step_loss` of "the
// state stays"; `n_samples`, `n_windows`, `model` (its kind), `system`, `dt` (the
// median sample interval), `dt_jitter`, `dt_min`, `dt_max`, and for NeuralODEs
// `solver` and `steps`. Physics models integrate each transition over its own
// interval; learned models predict their fixed one. `solver` / `steps` re-integrate
// a NeuralODE with another solver or grid than it was trained with (same weights);
// for continuous-time physics models `solver` and `substeps` set the integration.
//
// A DeLaN model file is scored as inverse dynamics (on the DeLaN characters the
// test characters e, q, v, on other joint-space data every sample): the torque,
// force-component, energy and power errors of DESIGN.md (`torque_mse`, ...,
// `*_nmse`), `min_mass_eigenvalue`, the friction parameters of a delan-friction
// model, and rolled out as a dynamics model `single_step_loss`,
// `avg_multi_step_loss` (4 steps), `avg_10_step_loss` and
// `baseline_single_step_loss`; `test_characters_only` says which samples.
#pragma once

#include <string>

#include <nlohmann/json.hpp>

namespace diffdyn {

/// What EvaluateFiles evaluates, named as `diffdyn eval`'s options (errors name them).
struct EvalRequest {
  /// --model: a model file, an analytic model name or `oracle`.
  std::string model;
  /// --data: a dataset path.
  std::string data;
  /// --solver: empty for the model's own.
  std::string solver{};
  /// --steps: a NeuralODE's grid points on [0, 1]; 0 for the model's own.
  int steps = 0;
  /// --substeps: solver steps per transition of physics models (>= 1).
  int substeps = 4;
  /// --threads: 0 for all cores. The numbers do not depend on it.
  int threads = 0;
  /// --precision: f32 or f64; empty for the model file's own.
  std::string precision{};
};

/// The `eval --json` summary of `request` (file comment). Throws diffdyn::Error
/// (one line naming the option and the file) for bad input, diffdyn::NumericalError
/// when a loss is not finite.
nlohmann::json EvaluateFiles(const EvalRequest& request);

}  // namespace diffdyn
