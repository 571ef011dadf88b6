// Diagnosis stage: the candidate effects, their regressors, and what the data can identify.
//
// Linearised around "absent", every effect of effects.h adds columns X_c (each
// n x R) to a model of the nominal residual, r = sum_c X_c beta_c + noise. The
// per-joint columns are the effects' own torques at unit parameters,
//
//   X = JointEffectTorque(kind, e_i, q_j, qd_j, qdd_j) on row j (e_i: unit vector i),
//
// friction kinds as kernel averages of the raw velocity (smoothed like the
// torque), stribeck once per v_s of kStribeckGrid; the system-wide columns are
//
//   payload  TipLoad(q, qd, qdd)      beta = m_p
//   gain     ID(q, qd, qdd)           beta = 1/k - 1
//   delay    d tau / dt (smoothed)    beta = d
//
// so beta maps back to the effect's parameters by EffectFromCoefficients. An
// effect the model under test already holds (a fed-back extended model) is not
// a candidate again.
//
// Identifiability. Before any selection the library is checked against the data:
// a joint whose smoothed speed (95th percentile of |qd| on the train rows) stays
// below max(3 sigma_qd, 1e-3) does not move, so its velocity- and
// acceleration-dependent effects (viscous, coulomb, stribeck, armature) are
// dropped; with every joint still (static holds) the delay goes too and the
// data is flagged static. Two candidates whose columns are nearly parallel
// (|cos| > kCollinearCosine over the train rows) cannot be told apart: both stay
// (either may be named) and the pair is reported.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/physics/effects.h"
#include "diffdyn/solvers/diagnosis/prepare.h"

namespace diffdyn {

/// Stribeck velocities v_s tried by the linear stage (rad/s or m/s); the refit frees v_s.
inline constexpr double kStribeckGrid[] = {0.015, 0.03, 0.06, 0.12, 0.25, 0.5};
/// Columns more parallel than this cannot be separated by the data.
inline constexpr double kCollinearCosine = 0.995;

/// True for the friction laws whose torque is a smoothed function of the raw
/// velocity (coulomb, stribeck): they are compared with the data as kernel averages.
inline bool IsFrictionKind(EffectKind kind) {
  return kind == EffectKind::kCoulomb || kind == EffectKind::kStribeck;
}

/// One candidate effect with its regressor columns.
struct Candidate {
  EffectKind kind = EffectKind::kViscous;
  int joint = 0;                         ///< 1-based; 0 = the whole system
  double v_s = 0;                        ///< stribeck grid value
  std::vector<Eigen::MatrixXd> columns;  ///< each n x R
  std::string label;                     ///< "coulomb j2"; grid points share it
  int num_params() const { return static_cast<int>(Info(kind).params.size()); }
};

/// An effect the data cannot identify, and why (named in the report and JSON).
struct NotIdentifiable {
  EffectKind kind = EffectKind::kViscous;
  int joint = 0;
  std::string reason;
};

/// The candidate library after the identifiability checks.
struct CandidateLibrary {
  std::vector<Candidate> candidates;
  int distinct = 0;  ///< distinct effects tested (a stribeck grid counts once)
  std::vector<NotIdentifiable> not_identifiable;
  bool static_data = false;  ///< no joint moves
};

/// Builds the candidates of `kinds` (empty = every named kind) on `prep`, gain
/// and delay only when the data has torque, and runs the identifiability checks.
CandidateLibrary BuildCandidates(const PreparedData& prep, const std::vector<EffectKind>& kinds,
                                 bool has_tau);

/// The effect of candidate `c` from its coefficients `beta` (one per column) and
/// their covariance `cov`: parameters and standard errors (header mapping).
Effect EffectFromCoefficients(const Candidate& c, const Eigen::VectorXd& beta,
                              const Eigen::MatrixXd& cov);

/// The short name of an effect for reports: "coulomb j2", "gain".
std::string EffectLabel(const Effect& effect);

}  // namespace diffdyn
