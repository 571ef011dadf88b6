// What a simulation model gets wrong on measured data: `diffdyn diagnose` as one
// library call.
//
// DiagnoseFiles opens the model under test (an analytic model by name, or an
// extended-physics file: a diagnosis fed back, whose effects stay), sets its
// nominal parameters (the model's or the file's, then `params_file`, then
// `params`), reads the measured data (a joint-space CSV or a dataset folder of
// shared/data), runs Diagnose (diagnosis.h) and writes to `out`:
//
//   report.md            verdict, named effects with standard errors, errors per
//                        joint, selection log, what cannot be identified, gains
//   extended_model.json  the nominal model plus the named effects (kind extended-physics)
//   residuals.csv        t, heldout, q_j, qd_j, res_nominal_j, res_extended_j
//
// and returns the summary `diagnose --json` prints, so the command line and the
// Python module (`diffdyn.diagnose`) report the same numbers from one computation.
// The command line adds the plots drawn from residuals.csv.
//
//   DiagnoseRequest request{.model = "panda", .measured = "../shared/data/panda_gaz2019_traj1",
//                           .out = "diag"};
//   nlohmann::json summary = DiagnoseFiles(request);
//   for (const auto& effect : summary["named_effects"]) use(effect["kind"], effect["joint"]);
//
// Dataset conventions: the Panda trajectory (format panda-gaz2019) repeats every
// 2 / 0.15 s, which sets the held-out phase window unless `phase_period` is given;
// the IBM double pendulum is measured in pixels, so unless parameters to fit are
// named, its link lengths start at the pixel ratio and m2 and the common length
// scale are fitted.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "diffdyn/solvers/diagnosis.h"
#include "diffdyn/solvers/pushing/calibration.h"

namespace diffdyn {

/// What DiagnoseFiles diagnoses, named as `diffdyn diagnose`'s options (errors name them).
struct DiagnoseRequest {
  /// --model: an analytic model name or an extended-physics file.
  std::string model;
  /// --measured: a joint-space CSV or a dataset folder.
  std::string measured;
  /// --out: the output folder (created once every input has been checked).
  std::string out;
  /// --param: nominal parameter overrides "name=value".
  std::vector<std::string> params{};
  /// --params: a JSON file {name: value} of nominal parameters.
  std::string params_file{};
  /// --fit-param / --scale-param (DiagnosisOptions' fit_params and scale_params).
  std::vector<std::string> fit_params{}, scale_params{};
  /// The pipeline's settings (seed, cutoff, hold-out, alpha, ...).
  DiagnosisOptions pipeline{};
  /// --model pushing: the calibration's settings (its parameters come from
  /// fit_params when given; seed and hold-out fraction from `pipeline`).
  PusherCalibrationOptions pusher{};
};

/// Runs the diagnosis of `request` and writes its files (file comment); returns the
/// `diagnose --json` summary (keys model, n_samples, nominal_rmse, extended_rmse,
/// heldout_sse_removed, no_significant_discrepancy, named_effects, noise_std,
/// not_identifiable, static_data, cutoff_hz, heldout_sse_removed_per_joint,
/// heldout_sse_removed_learned, splits, energy_error_nominal, energy_error_extended,
/// rollout_q_nominal, rollout_q_extended, report, extended_model, seconds). Throws
/// diffdyn::Error (one line naming the option and the file) for bad input, before
/// anything is written.
nlohmann::json DiagnoseFiles(const DiagnoseRequest& request);

/// DiagnoseFiles for `--model pushing` (or a pusher world file, kind oracle) and
/// a pushing CSV: the ODE-engine pusher calibrated against the measured poses
/// (pushing/calibration.h). Writes report.md, calibrated_pusher.json (a pusher
/// world file), replays.csv (the held-out transitions: state, action, measured,
/// nominal and calibrated next pose) and rollouts.csv; returns the summary (keys
/// model, n_samples, nominal_rmse and extended_rmse per state x, y, theta,
/// heldout_sse_removed, no_significant_discrepancy, named_effects {kind = the
/// parameter, joint 0, value, unit, stderr}, parameters, nominal_loss,
/// calibrated_loss, identity_loss, rollout_error_nominal, rollout_error_calibrated,
/// fit_transitions, train_trajectories, heldout_trajectories, iterations, replays,
/// report, extended_model, seconds). DiagnoseFiles calls it for those models.
nlohmann::json DiagnosePusherFiles(const DiagnoseRequest& request);

/// True when `model` names the pusher: "pushing", or a model file of kind oracle.
bool IsPusherModel(const std::string& model);

}  // namespace diffdyn
