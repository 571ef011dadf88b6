// Diagnosis: what does the simulation get wrong, why, and how much is gained.
//
// Given a nominal model tau = ID(q, qd, qdd; p) and measured data, all signals
// are smoothed consistently (smoothing.h, one cutoff f_c <= 10 Hz) and the torque residual
//
//   r_k = tau_k - ID(q_k, qd_k, qdd_k)                (n per sample)
//
// is examined on decimated rows. The first 1 - h of the rows (in time) train,
// the last h (default 30 %) are held out.
//
// Naming the cause. Each effect of effects.h, linearised around "absent", adds
// regressor columns to the residual model r = X beta + noise:
//   viscous  qd_j        coulomb  S[tanh(qd_j/0.01)]    offset -1
//   spring   q_j         armature qdd_j                 payload TipLoad(q, qd, qdd)
//   stribeck S[tanh], S[exp(-(qd_j/v_s)^2) tanh] on a v_s grid
//   gain     ID (beta = 1/k - 1)    delay  d tau/dt (beta = d)
// where S[.] applies the smoothing weights to the raw signal so that
// nonlinear friction is smoothed exactly like the torque. Forward stepwise
// selection adds the candidate that most lowers an extended Bayesian
// information criterion with per-joint noise variances,
//
//   EBIC(S) = n_eff sum_j log(SSE_j(S) / R) + |theta_S| log n_eff + 2 log C(P, |S|),
//
// (n_eff: independent samples of the smoothed record, P: number of candidate
// effects; the binomial term corrects for testing many candidates) and keeps
// it only if the blocked K-fold cross-validated error also falls and its
// torque contribution is at least `min_effect_to_noise` times the sensor-noise
// RMS. Magnitudes come with standard errors from the weighted least-squares
// covariance, inflated by R / n_eff for the correlation of smoothed noise.
//
// Cutoff. qdd is the derivative of the smoothed qd, so velocity noise reaches
// the residual amplified by M(q) sum_k beta_k^2 ~ f_c^3: where inertia
// dominates the torque (a cart) it can swamp every effect at 10 Hz. With
// cutoff_hz = 0 the cutoff is chosen from kCutoffGrid: the selection below is
// run at each, scored by the blocked cross-validated fraction of the nominal
// residual SSE its effects remove on the training rows, and the highest
// cutoff scoring within kCutoffTolerance of the best is used (the held-out
// rows are never looked at). With calibrated nominal parameters (fit_params,
// scale_params) the nominal model itself would change with the cutoff, so
// 10 Hz is kept. The torque-noise estimate always comes from the 10 Hz smoothing.
//
// Refit. The selected effects' parameters are refitted jointly through the
// extended model (Ceres, Jets of JointTorque; delay through interpolation of
// the state at t + d), giving final values and standard errors.
//
// Gain. heldout_sse_removed = 1 - sum_j SSE_j(ext) / sum_j SSE_j(nominal) on
// the held-out rows (model_conventions.md), per joint and overall, beside a
// purely learned residual network trained on the same rows. A learned residual
// is added to the extended model (and named "residual") only when it lowers a
// validation error by more than 20 %. With nothing selected the result says
// no_significant_discrepancy = true and names nothing.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/physics/effects.h"
#include "diffdyn/solvers/joint_data.h"
#include "diffdyn/solvers/smoothing.h"

namespace diffdyn {

/// Highest smoothing cutoff (Hz) the diagnosis uses (model_conventions.md).
inline constexpr double kMaxCutoffHz = 10.0;
/// Cutoffs (Hz) tried when DiagnosisOptions::cutoff_hz is 0, highest first.
inline constexpr double kCutoffGrid[] = {10.0, 7.0, 5.0, 3.5, 2.5};
/// A lower cutoff must raise the cross-validated SSE fraction removed by more than this.
inline constexpr double kCutoffTolerance = 0.02;

/// Settings of Diagnose; defaults are what `diffdyn diagnose` uses.
struct DiagnosisOptions {
  double cutoff_hz = 0.0;            ///< smoothing cutoff f_c (Hz, <= 10); 0 = chosen (header)
  double holdout_fraction = 0.3;     ///< last fraction of the rows held out
  int folds = 5;                     ///< blocked cross-validation folds
  double min_effect_to_noise = 1.0;  ///< an effect's torque RMS / sensor-noise RMS to count
  int max_effects = 8;               ///< at most this many named effects
  double residual_min_gain = 0.2;    ///< validation SSE drop needed to name "residual"
  int residual_hidden = 64;          ///< hidden features of the learned residual
  double rollout_horizon = 0.1;      ///< s, window length of rollout errors
  double energy_window = 1.0;        ///< s, window of the energy-balance error
  double phase_period = 0.0;         ///< > 0: also score a held-out phase window
  double phase_window_fraction = 0.3;  ///< its width as a fraction of the period
  std::vector<std::string> fit_params;    ///< nominal parameters fitted first
  std::vector<std::string> scale_params;  ///< parameters scaled by one common factor
  double calibration_fraction = 0.25;     ///< first fraction of rows used to fit them
  std::vector<EffectKind> kinds;          ///< candidate kinds; empty = all named kinds
  std::uint64_t seed = 0;            ///< seeds the learned residual's features
  bool refit = true;                 ///< refit through the model with Ceres
};

/// One step of the stepwise selection, for the report.
struct SelectionStep {
  std::string candidate;  ///< e.g. "coulomb j2"
  double ebic_before = 0, ebic_after = 0;
  double cv_before = 0, cv_after = 0;
  double contribution_to_noise = 0;
  bool accepted = false;
  std::string reason;
};

/// A train/held-out split and its scores.
struct SplitScore {
  std::string name;                 ///< "last 30% in time", "phase window ..."
  int heldout_rows = 0;
  Eigen::VectorXd sse_nominal;      ///< n
  Eigen::VectorXd sse_extended;     ///< n
  double sse_removed = 0;           ///< 1 - sum ext / sum nominal
  double sse_removed_learned = 0;   ///< purely learned residual on the nominal
  double sse_removed_baseline = std::numeric_limits<double>::quiet_NaN();  ///< published friction (Panda)
};

/// Everything Diagnose finds; plot arrays are n x R over all rows.
struct DiagnosisResult {
  std::string model_name;
  double cutoff_hz = 0;                 ///< smoothing cutoff used (Hz)
  Eigen::VectorXd nominal_params;       ///< after calibration
  std::vector<std::string> notes;       ///< what was done (calibration, data)
  int n_samples = 0, train_rows = 0, heldout_rows = 0;
  double n_eff_train = 0;
  Eigen::VectorXd tau_noise;            ///< n
  Eigen::VectorXd nominal_rmse, extended_rmse;  ///< n, held-out torque RMSE
  Eigen::VectorXd sse_removed_per_joint;        ///< n
  double heldout_sse_removed = 0;
  double heldout_sse_removed_learned = 0;
  bool no_significant_discrepancy = true;
  std::vector<Effect> named_effects;    ///< includes {residual, 0} when named
  std::optional<ExtendedModel> extended;
  std::vector<SplitScore> splits;       ///< [0] = the main split
  Eigen::VectorXd rollout_q_nominal, rollout_q_extended;    ///< n, RMS at the horizon
  Eigen::VectorXd rollout_qd_nominal, rollout_qd_extended;  ///< n
  double energy_error_nominal = 0, energy_error_extended = 0;  ///< RMS over windows (J)
  Eigen::MatrixXd residual_correlation;  ///< n x 4n: corr(r_j, [q, qd, qdd, tau])
  std::vector<SelectionStep> steps;
  Eigen::VectorXd row_t;                 ///< R
  std::vector<bool> row_heldout;         ///< R
  Eigen::MatrixXd row_q, row_qd;         ///< n x R
  Eigen::MatrixXd residual_nominal, residual_extended;  ///< n x R
  double seconds = 0;
};

/// Runs the pipeline of the header comment. `params`: nominal parameters (the
/// model's size). Throws diffdyn::Error on a size mismatch naming --model and
/// --measured, NumericalError on non-finite residuals.
DiagnosisResult Diagnose(std::shared_ptr<const AnalyticModel> model, const Eigen::VectorXd& params,
                         const JointData& data, const DiagnosisOptions& options);

/// The short name of an effect for reports: "coulomb j2", "gain".
std::string EffectLabel(const Effect& effect);

/// The unit of an effect's first parameter on `model` (prismatic joints use N, m).
std::string EffectUnit(const AnalyticModel& model, const Effect& effect, int param = 0);

}  // namespace diffdyn
