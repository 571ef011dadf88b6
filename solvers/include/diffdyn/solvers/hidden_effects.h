// Hidden-effect data: "measured" trajectories with one effect chosen by a seed.
//
// To test a diagnosis blind, a generator plays the real robot. From a seed it
// picks one named effect (kind, joint, magnitude), tracks a random smooth
// reference q_ref(t) = c + sum_l A_l sin(2 pi f_l t + phi_l) with
//
//   tau_meas = ID_nom(q_ref, qd_ref, qdd_ref) + M_nom(q_ref) (w^2 (q_ref - q) + 2 w (qd_ref - qd)),
//
// recomputed at 1 kHz and held in between, and integrates the TRUE (extended)
// forward dynamics qdd = FD_ext(q, qd, tau_meas(t - d)) with fine RK4 steps.
// The record is subsampled (200 Hz) and sensor noise is added to q, qd and
// tau (one sigma_tau for every joint, 0.5 % of the overall torque RMS). The
// effect's magnitude is chosen so that its torque contribution along the
// reference has an RMS of `ratio` times the torque noise, ratio drawn in
// [ratio_min, ratio_max] (model_conventions.md asks for at least 3). A control
// case hides nothing.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "diffdyn/physics/effects.h"
#include "diffdyn/solvers/dataset_io.h"

namespace diffdyn {

/// Settings of the generator.
struct HiddenEffectOptions {
  double duration = 20.0;     ///< s of data
  double sample_hz = 200.0;   ///< recorded rate
  double control_hz = 1000.0; ///< torque update rate
  int substeps = 4;           ///< RK4 steps per control period
  double ratio_min = 3.0;     ///< effect RMS / torque-noise RMS, lower end
  double ratio_max = 10.0;    ///< upper end
  double q_noise = 1e-4;      ///< position-sensor noise sigma (rad or m)
  double qd_noise = 2e-3;     ///< velocity-sensor noise sigma (rad/s or m/s)
  /// Torque-sensor noise: false, one sigma for every joint (0.5 % of the overall
  /// torque RMS); true, sigma_j = 1 % of joint j's own torque RMS, as sensors
  /// scaled to their joint's range give (a Panda's wrist far quieter than its shoulder).
  bool per_joint_noise = false;
  std::vector<EffectKind> kinds;  ///< kinds to draw from; empty = every named kind
};

/// One generated case: the truth and the data.
struct HiddenEffectCase {
  std::string model;
  bool control = false;       ///< true: no effect hidden
  Effect effect;              ///< the hidden effect (unset for a control)
  double ratio = 0.0;         ///< its torque RMS / noise RMS
  Eigen::VectorXd tau_noise;  ///< per-joint torque-noise sigma
  Dataset data;  ///< one joint-space trajectory (dataset_io.h)
};

/// Generates the case of `seed` for `model` (pendulum, cartpole,
/// double-pendulum, arm2, panda) with default nominal parameters.
HiddenEffectCase GenerateHiddenEffectCase(const std::string& model, std::uint64_t seed,
                                          bool control, const HiddenEffectOptions& options = {});

/// Whether `named` finds `truth`: same kind and joint (pendulum payload and
/// gain are equivalent) and the magnitude within `tolerance` (relative);
/// `magnitude_error` receives the relative error of the magnitude.
bool MatchesHiddenEffect(const std::string& model, const Effect& truth,
                         const std::vector<Effect>& named, double tolerance,
                         double* magnitude_error = nullptr);

}  // namespace diffdyn
