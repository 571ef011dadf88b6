// Diagnosis stage for free motion (no torque sensor): dissipation from the energy balance.
//
// Without input torque a conservative mismatch (inertia, lengths) dominates the
// torque residual but does no net work, while dissipation drains energy steadily.
// Over windows w of the train rows (each `window` seconds) the work the model
// leaves unexplained,
//
//   y_w = int_w qd . (tau - tau_hat) dt,   regressed on   x_wj = int_w qd_j^2 dt,
//
// is explained by viscous coefficients b_j; ForwardSelect (selection.h) picks the
// joints (deviance W log(SSE / W), blocked cross-validation over windows) and a
// b_j <= 0 (not dissipative) is vetoed.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "diffdyn/physics/effects.h"
#include "diffdyn/solvers/diagnosis/prepare.h"
#include "diffdyn/solvers/diagnosis/selection.h"

namespace diffdyn {

/// Viscous effects (joint, b, stderr) named by the energy balance of the train
/// rows, for joints in `candidates` (0-based); `prediction` is tau_hat (n x R).
/// Steps are appended to `log`. Empty when there are fewer than 2 folds of windows.
std::vector<Effect> SelectDissipation(const PreparedData& prep, const Eigen::MatrixXd& prediction,
                                      const std::vector<int>& candidates, double window, int folds,
                                      double alpha, std::vector<SelectionStep>* log);

}  // namespace diffdyn
