// Diagnosis stage: what the extended model gains, on rows it was not fitted on.
//
//   heldout_sse_removed = 1 - sum_j SSE_j(extended) / sum_j SSE_j(nominal)
//
// on held-out rows (model_conventions.md), beside a purely learned residual
// network r(q, qd) fitted on the same train rows (ridge chosen on the last 20 %
// of them). Rollouts: from the measured state at the start of short held-out
// windows, the model under test and the extended model are integrated (rk4-classic) under the
// measured torque, and their state errors at the window's end compared.
// Energy balance: RMS over windows of int qd . (tau - tau_hat) dt (J).
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/physics/effects.h"
#include "diffdyn/solvers/diagnosis/prepare.h"

namespace diffdyn {

/// A train/held-out split and its scores.
struct SplitScore {
  std::string name;                 ///< "last 30% in time", "phase window ..."
  int heldout_rows = 0;
  Eigen::VectorXd sse_nominal;      ///< n
  Eigen::VectorXd sse_extended;     ///< n
  double sse_removed = 0;           ///< 1 - sum ext / sum nominal
  double sse_removed_learned = 0;   ///< purely learned residual on the nominal
  double sse_removed_baseline = std::numeric_limits<double>::quiet_NaN();  ///< a given baseline
};

/// Fits a residual network r(q, qd) (n outputs, `hidden` features) to the
/// columns `rows` of `target` (n x R); the ridge is chosen on the last 20 % of
/// `rows`, whose weighted SSE drop is returned in `validation_gain` (may be null).
std::shared_ptr<const ResidualNetwork> FitResidualNetwork(const PreparedData& prep,
                                                          const Eigen::MatrixXd& target,
                                                          const std::vector<int>& rows, int hidden,
                                                          std::uint64_t seed, double* validation_gain);

/// The network's output (n x R) at every row.
Eigen::MatrixXd PredictResidual(const PreparedData& prep, const ResidualNetwork& net);

/// Scores on the rows `held`: nominal, extended, learned-only and (when not
/// empty) a baseline prediction, each n x R.
SplitScore ScoreSplit(const PreparedData& prep, const std::string& name, const std::vector<int>& held,
                      const Eigen::MatrixXd& extended, const Eigen::MatrixXd& learned,
                      const Eigen::MatrixXd& baseline);

/// RMS state errors (n each) at the end of held-out rollout windows.
struct RolloutErrors {
  Eigen::VectorXd q_nominal, q_extended, qd_nominal, qd_extended;
  int windows = 0;
  int failed = 0;  ///< rollouts stopped by an indefinite mass matrix (their error is NaN)
};

/// Rollouts of `horizon` seconds from the held-out rows (header).
RolloutErrors ScoreRollouts(const PreparedData& prep, const ExtendedModel& extended, double horizon);

/// RMS over `window`-second windows of the held-out rows of int qd . (tau - prediction) dt (J).
double EnergyBalanceError(const PreparedData& prep, const Eigen::MatrixXd& prediction, double window);

}  // namespace diffdyn
