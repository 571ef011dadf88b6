// Diagnosis stage: one forward stepwise selection with family-wise error control.
//
// A SelectionProblem is a library of candidates and three scores of any subset S:
// a deviance D(S) (-2 log-likelihood up to a constant), a blocked cross-validated
// error, and a veto (an inadmissible value, too small an effect). ForwardSelect
// grows S one candidate at a time:
//
//   1. among candidates not in S (conflicting members replaced, see Conflicts), pick
//      the one minimising D(S + c) + p(S + c) log n_eff  (BIC);
//   2. test it: the likelihood-ratio statistic D(S) - D(S + c) is chi^2 with the
//      added parameter count under "c is absent"; it must have p < alpha / (P - |S|)
//      (Holm's step-down over the P effects of the family, so the chance of naming
//      any absent effect stays below alpha), and the cross-validated error must fall;
//      a candidate with a simpler nested alternative (stribeck over coulomb) must
//      also beat that alternative by the same test and differ from it by more
//      than the problem's Distinguishable says, or the alternative is taken;
//   3. a vetoed candidate is dropped (with every grid point of the same label) and
//      the search goes on; a failed test stops it.
//
// The same selection names effects from torque regressors (LinearSelection
// below) and dissipation from an energy balance (dissipation.h).
#pragma once

#include <limits>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/physics/effects.h"
#include "diffdyn/solvers/diagnosis/candidates.h"
#include "diffdyn/solvers/diagnosis/prepare.h"

namespace diffdyn {

/// P(X > x) for X ~ chi^2 with k >= 1 degrees of freedom (x >= 0).
double ChiSquareSurvival(double x, int k);

/// One step of a selection, for the report.
struct SelectionStep {
  std::string candidate;            ///< e.g. "coulomb j2"
  double deviance_before = 0, deviance_after = 0;
  double p_value = 1, threshold = 0;
  double cv_before = 0, cv_after = 0;
  double effect_to_noise = std::numeric_limits<double>::quiet_NaN();  ///< torque RMS_j / sigma_j (system-wide: RMS over j)
  bool accepted = false;
  std::string reason;
};

/// A library of candidates scored on subsets (header).
class SelectionProblem {
 public:
  virtual ~SelectionProblem() = default;
  virtual int NumCandidates() const = 0;
  /// Candidates with the same label are one effect (grid points of it).
  virtual std::string Label(int c) const = 0;
  virtual int NumParams(int c) const = 0;
  /// The simpler candidate nested in c (a special case of it), or -1.
  virtual int Simpler(int /*c*/) const { return -1; }
  /// Whether the fits of `complex_set` and `simple_set` differ by enough to name
  /// the more complex one (e.g. by more than the noise).
  virtual bool Distinguishable(const std::vector<int>& /*complex_set*/,
                               const std::vector<int>& /*simple_set*/) const {
    return true;
  }
  /// True when b replaces a in a set (e.g. two friction laws on one joint).
  virtual bool Conflicts(int /*a*/, int /*b*/) const { return false; }
  /// -2 log-likelihood of the set, up to a constant.
  virtual double Deviance(const std::vector<int>& set) const = 0;
  /// log of the sample count n_eff, the BIC's price per parameter.
  virtual double LogSamples() const = 0;
  /// Blocked cross-validated error of the set.
  virtual double CrossValidationError(const std::vector<int>& set) const = 0;
  /// Why candidate c in `set` may not be named ("" when it may).
  virtual std::string Veto(const std::vector<int>& set, int c) const = 0;
  /// The size of c's contribution relative to the noise (NaN when not defined).
  virtual double EffectToNoise(const std::vector<int>& /*set*/, int /*c*/) const {
    return std::numeric_limits<double>::quiet_NaN();
  }
};

/// Settings of ForwardSelect.
struct SelectionOptions {
  double alpha = 0.01;     ///< family-wise error: chance of naming any absent effect
  int family = 1;          ///< P, the distinct effects tested
  int max_selected = 8;
};

/// The selected candidates (in order of acceptance); every step is appended to `log`.
std::vector<int> ForwardSelect(const SelectionProblem& problem, const SelectionOptions& options,
                               std::vector<SelectionStep>* log);

/// The torque-regressor selection: weighted least squares of the nominal residual
/// on the candidates' columns over the train rows, per-joint noise variances
/// re-estimated from each set's own residual (two passes), D(S) = n_eff sum_j
/// log(SSE_j(S) / rows). Vetoes: any member's value outside its admissible range
/// (a delay also beyond 10 samples, or not beyond 1.1 T/2 + 2 stderr, T/2 the
/// half-sample lag a zero-order hold of the torque alone produces), or c's torque RMS below min_effect_to_noise
/// times the joint's raw noise sigma_j (a system-wide effect: the root mean square over
/// the joints of RMS_j / sigma_j).
class LinearSelection : public SelectionProblem {
 public:
  /// `lib` must outlive the selection.
  LinearSelection(const PreparedData& prep, const CandidateLibrary& lib, int folds,
                  double min_effect_to_noise);

  int NumCandidates() const override { return static_cast<int>(lib_.candidates.size()); }
  std::string Label(int c) const override { return lib_.candidates[c].label; }
  int NumParams(int c) const override { return lib_.candidates[c].num_params(); }
  bool Conflicts(int a, int b) const override;
  int Simpler(int c) const override;
  /// The fits' torques differ somewhere by an RMS of min_effect_to_noise sigma_j.
  bool Distinguishable(const std::vector<int>& complex_set, const std::vector<int>& simple_set) const override;
  double Deviance(const std::vector<int>& set) const override;
  double LogSamples() const override;
  double CrossValidationError(const std::vector<int>& set) const override;
  std::string Veto(const std::vector<int>& set, int c) const override;
  double EffectToNoise(const std::vector<int>& set, int c) const override;

  /// The effects of `set` with their least-squares values and standard errors
  /// (covariance inflated by rows / n_eff).
  std::vector<Effect> Effects(const std::vector<int>& set) const;
  /// Per-joint residual variance of `set` on the train rows (n).
  Eigen::VectorXd Variance(const std::vector<int>& set) const;

 private:
  struct Fit {
    Eigen::VectorXd beta, sse;  // coefficients of Columns(set); per-joint SSE
    Eigen::MatrixXd gram;       // weighted normal matrix
  };
  std::vector<int> Columns(const std::vector<int>& set) const;
  Fit Solve(const std::vector<int>& cols, const std::vector<bool>& use, const Eigen::VectorXd& w) const;
  Fit FeasibleGls(const std::vector<int>& set) const;
  double FoldSse(const std::vector<int>& cols, const Eigen::VectorXd& beta, int f, int j) const;
  Eigen::VectorXd Weights(const Eigen::VectorXd& sse) const;

  const PreparedData& prep_;
  const CandidateLibrary& lib_;
  int folds_;
  double min_effect_to_noise_;
  int train_count_ = 0;
  double sse_floor_ = 0;
  std::vector<std::vector<int>> candidate_columns_;   // global column ids per candidate
  std::vector<const Eigen::MatrixXd*> columns_;       // all columns
  std::vector<std::vector<Eigen::MatrixXd>> gram_;    // [fold][joint] cols x cols
  std::vector<std::vector<Eigen::VectorXd>> cross_;   // [fold][joint]
  std::vector<std::vector<double>> energy_;           // [fold][joint]
  Eigen::VectorXd nominal_weights_;
};

}  // namespace diffdyn
