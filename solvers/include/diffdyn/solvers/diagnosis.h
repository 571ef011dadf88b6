// Diagnosis: what does the simulation get wrong, why, and how much is gained.
//
// Given a nominal model tau = ID(q, qd, qdd; p) and measured data, Diagnose runs
// the stages of solvers/diagnosis/, each a function with its own header:
//
//   prepare      (prepare.h) torque and velocity noise from the raw samples,
//                zero-phase smoothing at f_c = min(10 Hz, f_s / 4, max(f_s / 12, 2 f_99)), the nominal
//                residual r = tau - ID on decimated rows, a train / held-out split
//                (the last 30 % in time);
//   candidates   (candidates.h) each effect of effects.h linearised into regressor
//                columns; effects the data cannot identify (joints that do not
//                move, static holds, inseparable pairs) are dropped or reported;
//   selection    (selection.h) one forward stepwise selection: the BIC-best
//                candidate is named only if its likelihood-ratio test passes Holm's
//                family-wise threshold alpha / (P - |S|), its cross-validated error
//                falls, every value stays in its admissible range and its torque is
//                at least min_effect_to_noise times the joint's sensor noise
//                (a system-wide effect: RMS over the joints of RMS_j / sigma_j);
//   refit        (refit.h) the named effects' parameters refitted jointly through
//                the extended model (Ceres, bounded to the admissible ranges); an
//                effect the joint refit puts within 3 standard errors of absent
//                is dropped, and so, one at a time, is any added effect whose
//                likelihood-ratio test against the refit without it fails at alpha;
//   dissipation  (dissipation.h) free motion without a torque sensor: viscous
//                friction from the energy balance, by the same selection;
//   gain         (gain.h) held-out SSE removed, beside a purely learned residual;
//                a learned residual is added (and named "residual") only when it
//                lowers a validation error by more than residual_min_gain and its
//                torque is at least residual_min_to_noise (3) times the sensor
//                noise, the size model_conventions.md calls detectable;
//                rollouts and the energy balance on held-out windows.
//
// With nothing named the result says no_significant_discrepancy = true.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/physics/effects.h"
#include "diffdyn/solvers/diagnosis/candidates.h"
#include "diffdyn/solvers/diagnosis/gain.h"
#include "diffdyn/solvers/diagnosis/prepare.h"
#include "diffdyn/solvers/diagnosis/selection.h"
#include "diffdyn/models/trajectory.h"

namespace diffdyn {

/// Settings of Diagnose; defaults are what `diffdyn diagnose` uses.
struct DiagnosisOptions {
  double cutoff_hz = 0.0;            ///< smoothing cutoff f_c (Hz, <= 10); 0 = the rule of prepare.h
  double holdout_fraction = 0.3;     ///< last fraction of the rows held out
  int folds = 5;                     ///< blocked cross-validation folds
  double min_effect_to_noise = 1.0;  ///< an effect's torque RMS_j / noise sigma_j to count (system-wide: RMS over j)
  double alpha = 0.01;               ///< family-wise error of the selection (selection.h)
  int max_effects = 8;               ///< at most this many named effects
  double residual_min_gain = 0.2;    ///< validation SSE drop needed to name "residual"
  double residual_min_to_noise = 3.0;  ///< and its torque RMS / sensor-noise sigma (the detectable size)
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

/// Everything Diagnose finds; plot arrays are n x R over all rows.
struct DiagnosisResult {
  std::string model_name;
  double cutoff_hz = 0;                 ///< smoothing cutoff used (Hz)
  Eigen::VectorXd nominal_params;       ///< after calibration
  std::vector<std::string> notes;       ///< what was done (calibration, data)
  int n_samples = 0, train_rows = 0, heldout_rows = 0;
  double n_eff_train = 0;
  Eigen::VectorXd noise_std;            ///< n, torque-sensor noise sigma (prepare.h)
  Eigen::VectorXd qd_noise_std;         ///< n, velocity noise sigma
  std::vector<NotIdentifiable> not_identifiable;
  bool static_data = false;             ///< no joint moves
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

/// Runs the pipeline of the header comment on the joint-space dataset `data`
/// (dataset_io.h) and the model under test `nominal`: an
/// analytic model (no effects) or an extended model fed back, whose effects stay
/// and are not named again; named_effects lists only what is added. Throws
/// diffdyn::Error on a size mismatch naming --model and --measured,
/// NumericalError on non-finite residuals.
DiagnosisResult Diagnose(const ExtendedModel& nominal, const Dataset& data, const DiagnosisOptions& options);

/// Diagnose of the analytic `model` with nominal parameters `params` (its size).
DiagnosisResult Diagnose(std::shared_ptr<const AnalyticModel> model, const Eigen::VectorXd& params,
                         const Dataset& data, const DiagnosisOptions& options);

/// The unit of an effect's first parameter on `model` (prismatic joints use N, m).
std::string EffectUnit(const AnalyticModel& model, const Effect& effect, int param = 0);

}  // namespace diffdyn
