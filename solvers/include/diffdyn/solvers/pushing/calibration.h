// Calibrating the ODE-engine pusher against measured block poses: what
// `diffdyn diagnose --model pushing` computes.
//
// Every measured transition (x_i, u_i) -> x_{i+1} is replayed in the pushing world
// (env.h) from rest at x_i. The one-step error
//
//   e_i(p) = W (F(x_i, u_i; p) - x_{i+1}),   W = diag(1, 1, sqrt(rg)),  rg = 0.0408 m,
//
// is the seed's pose loss per transition (loss = mean |e_i|^2 / 3 x 3 channels as
// in models/losses.h: MSE(x) + MSE(y) + rg MSE(theta)). The physical parameters p
// (PusherParameterNames: frictions, block mass and inertia, tip geometry, push
// speed) are fitted by Ceres' Levenberg-Marquardt with bounds, its Jacobian by
// forward differences over the engine (which is not differentiable):
//
//   min_p  sum_i |e_i(p)|^2   over a seeded subsample of the training trajectories,
//
// started from the best point of a coarse search (each parameter in turn over a
// geometric grid of its plausible range, the others at the best so far, on a
// smaller subsample), with standard errors from the Gauss-Newton covariance s^2 (J^T J)^-1, s^2 =
// SSE / (3n - P). Held-out trajectories (a seeded split by trajectory) score the
// nominal and the calibrated world: the one-step error per channel and the
// open-loop rollout of each whole trajectory from its first pose. Each fitted
// parameter is also scored alone (the nominal world with only that parameter
// calibrated), which says which parameters carry the gain. Replays run in
// parallel (one world per thread); the numbers do not depend on the thread count.
//
//   PushingConfig nominal;
//   nominal.obstacle = false;                       // the seed's data has none
//   PusherCalibration fit = CalibratePusher(ReadPushingCsv(path), nominal, {});
//   fit.calibrated;                                 // a PushingConfig for collect and push
//   fit.heldout_loss_calibrated / fit.heldout_loss_nominal;
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/models/trajectory.h"
#include "diffdyn/physics/pushing/env.h"

namespace diffdyn {

/// A physical parameter of the pushing world the calibration can fit.
struct PusherParameterInfo {
  std::string name;                           ///< PushingConfig's field name
  std::string unit;                           ///< "1", "kg", "kg m^2", "m", "m/s"
  double lower = 0, upper = 0;                ///< bounds of the fit
  double search_lower = 0, search_upper = 0;  ///< range of the coarse search (geometric grid)
  std::string meaning;                        ///< one line for the report
};

/// The parameters CalibratePusher can fit, in a fixed order.
const std::vector<PusherParameterInfo>& PusherParameters();

/// The value of parameter `name` in `config` (block_inertia 0 reads as the solid
/// box's m (a^2 + a^2) / 12; tip_pad_x / tip_pad_y 0, the capsule tip, read as
/// tip_radius, the half width of the square around it). Throws diffdyn::Error
/// naming the parameter if it is not one of PusherParameters().
double PusherParameter(const PushingConfig& config, const std::string& name);

/// Sets parameter `name` of `config` to `value` (setting either pad half width
/// turns the tip into a pad; the other one keeps its PusherParameter value).
void SetPusherParameter(PushingConfig& config, const std::string& name, double value);

/// Settings of CalibratePusher.
struct PusherCalibrationOptions {
  /// The parameters to fit (names of PusherParameters()).
  std::vector<std::string> parameters = {"tip_pad_x", "tip_pad_y", "tip_block_friction",
                                         "block_table_friction", "block_inertia"};
  /// Fraction of the trajectories held out (seeded choice), in (0, 0.9].
  double holdout_fraction = 0.2;
  /// Training transitions the fit replays (a seeded subsample; 0 = all).
  int fit_transitions = 400;
  /// Levenberg-Marquardt iterations at most.
  int max_iterations = 12;
  /// Coarse search before the local fit: grid points per parameter, sweeps over
  /// the parameters (0 = none) and training transitions it replays.
  int coarse_points = 6, coarse_sweeps = 2, coarse_transitions = 150;
  /// Forward-difference step, relative to each parameter's value.
  double relative_step = 0.03;
  /// Worker threads (0 = all cores); the numbers do not depend on it.
  int threads = 0;
  std::uint64_t seed = 0;
  /// Called with one line per fit iteration and stage (may be empty).
  std::function<void(const std::string&)> progress{};
};

/// One fitted parameter.
struct PusherParameterFit {
  std::string name, unit;
  double nominal = 0;         ///< PusherParameter of the nominal world
  double value = 0;           ///< calibrated value
  double standard_error = 0;  ///< Gauss-Newton standard error (NaN when J^T J is singular)
  /// Held-out loss of the nominal world with only this parameter calibrated.
  double heldout_loss_alone = 0;
};

/// One held-out transition replayed: states 3 x 1 each (x, y, theta).
struct PusherReplay {
  int trajectory = 0, step = 0;
  Eigen::Vector3d state, action, measured, nominal, calibrated;
};

/// The result of CalibratePusher.
struct PusherCalibration {
  PushingConfig nominal, calibrated;
  std::vector<PusherParameterFit> parameters;
  /// Pose loss (file comment) of the fit subsample at the nominal world, at the
  /// coarse search's best point and after the fit.
  double fit_loss_nominal = 0, fit_loss_coarse = 0, fit_loss_calibrated = 0;
  /// Pose loss of the held-out transitions, nominal and calibrated.
  double heldout_loss_nominal = 0, heldout_loss_calibrated = 0;
  /// Pose loss of the identity prediction x_{i+1} = x_i on the held-out transitions.
  double heldout_loss_identity = 0;
  /// The held-out gain's t statistic: per held-out trajectory the sum over its
  /// transitions of |e_nominal|^2 - |e_calibrated|^2, their mean over its standard
  /// error (transitions of one trajectory are not independent; trajectories are).
  double heldout_gain_t = 0;
  /// Held-out RMSE per channel (x m, y m, theta rad).
  Eigen::Vector3d heldout_rmse_nominal = Eigen::Vector3d::Zero();
  Eigen::Vector3d heldout_rmse_calibrated = Eigen::Vector3d::Zero();
  /// Mean final-position error (m) of the open-loop rollouts of the held-out trajectories.
  double rollout_error_nominal = 0, rollout_error_calibrated = 0;
  std::vector<PusherReplay> heldout;
  /// Per held-out trajectory: the measured poses and the nominal and calibrated
  /// rollouts from its first pose (3 x (T + 1) each).
  std::vector<Eigen::Matrix3Xd> rollout_measured, rollout_nominal, rollout_calibrated;
  int train_trajectories = 0, heldout_trajectories = 0, fit_transitions = 0;
  int iterations = 0;  ///< Levenberg-Marquardt iterations taken
  int replays = 0;     ///< pushes simulated in all
};

/// Replays transitions: next(:, i) = the world `config` after actions(:, i) from
/// rest at states(:, i) (the state itself where the push is unreachable or the
/// pose cannot be held). Sizes 3 x n. Parallel over `threads` (0 = all cores).
Eigen::Matrix3Xd ReplayPushes(const PushingConfig& config, const Eigen::Matrix3Xd& states,
                              const Eigen::Matrix3Xd& actions, int threads);

/// The seed's pose loss of predictions against measurements (3 x n each).
double PusherPoseLoss(const Eigen::Matrix3Xd& predicted, const Eigen::Matrix3Xd& measured);

/// Fits `options.parameters` of `nominal` to `measured` pushing trajectories (file
/// comment). Throws diffdyn::Error for an unknown or repeated parameter, a pad
/// half width fitted without the other, too few trajectories to hold some out, or
/// trajectories that are not pushing ones (3 states, 3 actions).
PusherCalibration CalibratePusher(const std::vector<Trajectory>& measured,
                                  const PushingConfig& nominal,
                                  const PusherCalibrationOptions& options);

}  // namespace diffdyn
