// Diagnosis stage: the extended model's predicted sensor torque, and the refit of
// its effect parameters through that model.
//
// At row r the extended model predicts the torque the sensor reads,
//
//   tau_hat_r = JointTorque(x(t_r + d); theta) / k,
//
// with the state interpolated at t_r + d for a delay d and gain k (effects.h),
// and each friction effect replaced by its smoothed value sum_i alpha_i f(qd_raw_i)
// (the same kernel weights as the data), so sharp friction is compared with
// smoothed torque like for like. The refit minimises
//
//   sum_{r in rows} sum_j ((tau_hat_rj(theta) - tau_rj) / sigma_j)^2
//
// over theta with Ceres (DiagJet derivatives), inside each parameter's admissible
// range (EffectKindInfo::lower, upper). Standard errors come from s^2 (J^T J)^+,
// inflated by `inflation` for the correlation of smoothed noise.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "diffdyn/physics/effects.h"
#include "diffdyn/solvers/diagnosis/prepare.h"

namespace diffdyn {

/// Predicted sensor torque (n x R) of `ext` at every row of `prep`, including a
/// learned residual when `ext` holds one.
Eigen::MatrixXd PredictAll(const PreparedData& prep, const ExtendedModel& ext);

/// Per-joint SSE (n) of prep.tau - prediction over the rows `rows`.
Eigen::VectorXd RowSse(const PreparedData& prep, const Eigen::MatrixXd& prediction,
                       const std::vector<int>& rows);

/// Refits every effect parameter of `ext` on `rows` with weights inv_sigma (n),
/// bounded by the admissible ranges; more than kDiagJetSize parameters are
/// fitted in blocks of whole effects (two sweeps). Returns the model with the
/// fitted values and standard errors. Throws NumericalError on a non-finite fit.
ExtendedModel RefitEffects(const PreparedData& prep, const ExtendedModel& ext,
                           const std::vector<int>& rows, const Eigen::VectorXd& inv_sigma,
                           double inflation);

}  // namespace diffdyn
