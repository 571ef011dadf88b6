#include "diffdyn/solvers/diagnosis/selection.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <Eigen/Cholesky>
#include <Eigen/QR>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {
namespace {

int ParamsOf(const SelectionProblem& problem, const std::vector<int>& set) {
  int k = 0;
  for (int c : set) k += problem.NumParams(c);
  return k;
}

// current + c, members that c conflicts with removed.
std::vector<int> With(const SelectionProblem& problem, const std::vector<int>& current, int c) {
  std::vector<int> set;
  for (int s : current) {
    if (!problem.Conflicts(s, c)) set.push_back(s);
  }
  set.push_back(c);
  return set;
}

}  // namespace

double ChiSquareSurvival(double x, int k) {
  DIFFDYN_CHECK(k >= 1, "ChiSquareSurvival: k = ", k);
  if (!(x > 0)) return 1.0;
  // Q(k/2, x/2) by the half-integer recurrences of the incomplete gamma function.
  const double h = 0.5 * x;
  double sum, term;
  int i;
  if (k % 2 == 0) {
    sum = term = 1.0;
    for (i = 1; i < k / 2; ++i) sum += (term *= h / i);
    return std::exp(-h) * sum;
  }
  double q = std::erfc(std::sqrt(h));
  term = std::sqrt(h) / std::sqrt(std::numbers::pi) * 2.0;  // h^{1/2} / Gamma(3/2)
  for (i = 1; i <= (k - 1) / 2; ++i) {
    q += std::exp(-h) * term;
    term *= h / (i + 0.5);
  }
  return std::min(1.0, q);
}

std::vector<int> ForwardSelect(const SelectionProblem& problem, const SelectionOptions& options,
                               std::vector<SelectionStep>* log) {
  std::vector<int> current;
  std::vector<std::string> dropped;
  double deviance = problem.Deviance(current);
  while (static_cast<int>(current.size()) < options.max_selected) {
    // 1. The BIC-best addition.
    int best = -1;
    double best_bic = 0, best_deviance = 0;
    std::vector<int> best_set;
    for (int c = 0; c < problem.NumCandidates(); ++c) {
      if (std::find(current.begin(), current.end(), c) != current.end()) continue;
      if (std::find(dropped.begin(), dropped.end(), problem.Label(c)) != dropped.end()) continue;
      std::vector<int> set = With(problem, current, c);
      const double d = problem.Deviance(set);
      const double bic = d + ParamsOf(problem, set) * problem.LogSamples();
      if (best < 0 || bic < best_bic) {
        best = c;
        best_bic = bic;
        best_deviance = d;
        best_set = std::move(set);
      }
    }
    if (best < 0) break;
    // 2. Its likelihood-ratio test (Holm) and cross-validation; a nested simpler
    // alternative replaces it unless it is beaten by the same test.
    SelectionStep step;
    const double threshold = options.alpha / std::max(1, options.family - static_cast<int>(current.size()));
    const int simpler = problem.Simpler(best);
    if (simpler >= 0 && std::find(dropped.begin(), dropped.end(), problem.Label(simpler)) == dropped.end()) {
      std::vector<int> set = With(problem, current, simpler);
      const double d = problem.Deviance(set);
      const double p = ChiSquareSurvival(d - best_deviance, std::max(1, problem.NumParams(best) - problem.NumParams(simpler)));
      if (!(p < threshold) || !problem.Distinguishable(best_set, set)) {
        step.reason = StrCat(problem.Label(simpler), " instead of ", problem.Label(best), " (p = ", p,
                             p < threshold ? ", within the noise" : "", "); ");
        best = simpler;
        best_deviance = d;
        best_set = std::move(set);
      }
    }
    step.candidate = problem.Label(best);
    step.deviance_before = deviance;
    step.deviance_after = best_deviance;
    const int added = std::max(1, ParamsOf(problem, best_set) - ParamsOf(problem, current));
    step.p_value = ChiSquareSurvival(deviance - best_deviance, added);
    step.threshold = threshold;
    step.cv_before = problem.CrossValidationError(current);
    step.cv_after = problem.CrossValidationError(best_set);
    step.effect_to_noise = problem.EffectToNoise(best_set, best);
    if (!(step.p_value < step.threshold)) {
      step.reason += StrCat("not significant (p = ", step.p_value, ", needs < ", step.threshold, ")");
      log->push_back(step);
      break;
    }
    if (!(step.cv_after < step.cv_before)) {
      step.reason += "held-out (cross-validated) error does not fall";
      log->push_back(step);
      break;
    }
    // 3. Vetoes drop the effect and go on.
    const std::string veto = problem.Veto(best_set, best);
    if (!veto.empty()) {
      step.reason += veto;
      dropped.push_back(problem.Label(best));
      log->push_back(step);
      continue;
    }
    step.accepted = true;
    step.reason += "accepted";
    log->push_back(step);
    current = std::move(best_set);
    deviance = best_deviance;
  }
  return current;
}

// ---------------- LinearSelection ----------------

LinearSelection::LinearSelection(const PreparedData& prep, const CandidateLibrary& lib, int folds,
                                 double min_effect_to_noise)
    : prep_(prep), lib_(lib), folds_(folds), min_effect_to_noise_(min_effect_to_noise) {
  DIFFDYN_CHECK(folds >= 2, "diagnose: need at least 2 folds, got ", folds);
  const int n = prep.n;
  train_count_ = static_cast<int>(prep.train.size());
  sse_floor_ = 1e-24 * (1.0 + prep.tau.squaredNorm());
  for (const Candidate& c : lib.candidates) {
    candidate_columns_.emplace_back();
    for (const Eigen::MatrixXd& col : c.columns) {
      candidate_columns_.back().push_back(static_cast<int>(columns_.size()));
      columns_.push_back(&col);
    }
  }
  // Gram blocks per fold and joint over contiguous folds of the train rows.
  const int cols = static_cast<int>(columns_.size());
  gram_.assign(folds, std::vector<Eigen::MatrixXd>(n));
  cross_.assign(folds, std::vector<Eigen::VectorXd>(n));
  energy_.assign(folds, std::vector<double>(n, 0.0));
  for (int f = 0; f < folds; ++f) {
    const int a = f * train_count_ / folds, b = (f + 1) * train_count_ / folds;
    for (int j = 0; j < n; ++j) {
      Eigen::MatrixXd x(b - a, cols);
      for (int c = 0; c < cols; ++c) x.col(c) = columns_[c]->row(j).segment(a, b - a).transpose();
      const Eigen::VectorXd y = prep.residual.row(j).segment(a, b - a).transpose();
      gram_[f][j] = x.transpose() * x;
      cross_[f][j] = x.transpose() * y;
      energy_[f][j] = y.squaredNorm();
    }
  }
  Eigen::VectorXd sse = Eigen::VectorXd::Zero(n);
  for (int f = 0; f < folds; ++f) {
    for (int j = 0; j < n; ++j) sse[j] += energy_[f][j];
  }
  nominal_weights_ = Weights(sse);
}

bool LinearSelection::Conflicts(int a, int b) const {
  const Candidate& x = lib_.candidates[a];
  const Candidate& y = lib_.candidates[b];
  return x.joint == y.joint && x.joint > 0 && IsFrictionKind(x.kind) && IsFrictionKind(y.kind);
}

int LinearSelection::Simpler(int c) const {
  const Candidate& x = lib_.candidates[c];
  if (x.kind != EffectKind::kStribeck) return -1;
  for (int s = 0; s < NumCandidates(); ++s) {
    const Candidate& y = lib_.candidates[s];
    if (y.kind == EffectKind::kCoulomb && y.joint == x.joint) return s;
  }
  return -1;
}

bool LinearSelection::Distinguishable(const std::vector<int>& complex_set,
                                      const std::vector<int>& simple_set) const {
  // Fitted torques of both sets on the train rows, per joint.
  auto fitted = [&](const std::vector<int>& set) {
    const Fit fit = FeasibleGls(set);
    const std::vector<int> cols = Columns(set);
    Eigen::MatrixXd out = Eigen::MatrixXd::Zero(prep_.n, train_count_);
    for (std::size_t a = 0; a < cols.size(); ++a) out += fit.beta[a] * columns_[cols[a]]->leftCols(train_count_);
    return out;
  };
  const Eigen::MatrixXd diff = fitted(complex_set) - fitted(simple_set);
  for (int j = 0; j < prep_.n; ++j) {
    const double rms = std::sqrt(diff.row(j).squaredNorm() / train_count_);
    if (rms >= min_effect_to_noise_ * prep_.noise_std[j]) return true;
  }
  return false;
}

std::vector<int> LinearSelection::Columns(const std::vector<int>& set) const {
  std::vector<int> cols;
  for (int c : set) cols.insert(cols.end(), candidate_columns_[c].begin(), candidate_columns_[c].end());
  return cols;
}

Eigen::VectorXd LinearSelection::Weights(const Eigen::VectorXd& sse) const {
  return (1.0 / (sse.array() / train_count_ + sse_floor_)).matrix();
}

LinearSelection::Fit LinearSelection::Solve(const std::vector<int>& cols, const std::vector<bool>& use,
                                            const Eigen::VectorXd& w) const {
  const int k = static_cast<int>(cols.size());
  Fit fit;
  fit.gram = Eigen::MatrixXd::Zero(k, k);
  Eigen::VectorXd h = Eigen::VectorXd::Zero(k);
  for (int f = 0; f < folds_; ++f) {
    if (!use[f]) continue;
    for (int j = 0; j < prep_.n; ++j) {
      for (int a = 0; a < k; ++a) {
        h[a] += w[j] * cross_[f][j][cols[a]];
        for (int b = 0; b < k; ++b) fit.gram(a, b) += w[j] * gram_[f][j](cols[a], cols[b]);
      }
    }
  }
  fit.beta = Eigen::VectorXd::Zero(k);
  if (k > 0) {
    // A tiny ridge keeps exactly collinear candidates (payload and gain on a
    // pendulum) solvable; the second then adds nothing and is not selected.
    Eigen::MatrixXd g = fit.gram;
    g.diagonal().array() += 1e-10 * (g.diagonal().maxCoeff() + 1e-300);
    fit.beta = g.ldlt().solve(h);
  }
  return fit;
}

double LinearSelection::FoldSse(const std::vector<int>& cols, const Eigen::VectorXd& beta, int f,
                                int j) const {
  double sse = energy_[f][j];
  for (std::size_t a = 0; a < cols.size(); ++a) {
    sse -= 2 * beta[a] * cross_[f][j][cols[a]];
    for (std::size_t b = 0; b < cols.size(); ++b) sse += beta[a] * beta[b] * gram_[f][j](cols[a], cols[b]);
  }
  return std::max(sse, 0.0);
}

LinearSelection::Fit LinearSelection::FeasibleGls(const std::vector<int>& set) const {
  const std::vector<int> cols = Columns(set);
  const std::vector<bool> all(folds_, true);
  Eigen::VectorXd w = nominal_weights_;
  Fit fit;
  for (int pass = 0; pass < 2; ++pass) {
    fit = Solve(cols, all, w);
    fit.sse = Eigen::VectorXd::Zero(prep_.n);
    for (int f = 0; f < folds_; ++f) {
      for (int j = 0; j < prep_.n; ++j) fit.sse[j] += FoldSse(cols, fit.beta, f, j);
    }
    w = Weights(fit.sse);
  }
  return fit;
}

double LinearSelection::Deviance(const std::vector<int>& set) const {
  const Fit fit = FeasibleGls(set);
  double d = 0;
  for (int j = 0; j < prep_.n; ++j) d += prep_.n_eff * std::log(fit.sse[j] / train_count_ + sse_floor_);
  return d;
}

double LinearSelection::LogSamples() const { return std::log(prep_.n_eff); }

double LinearSelection::CrossValidationError(const std::vector<int>& set) const {
  const std::vector<int> cols = Columns(set);
  double total = 0;
  for (int f = 0; f < folds_; ++f) {
    std::vector<bool> use(folds_, true);
    use[f] = false;
    const Fit fit = Solve(cols, use, nominal_weights_);
    for (int j = 0; j < prep_.n; ++j) total += nominal_weights_[j] * FoldSse(cols, fit.beta, f, j);
  }
  return total;
}

Eigen::VectorXd LinearSelection::Variance(const std::vector<int>& set) const {
  return FeasibleGls(set).sse / train_count_;
}

std::vector<Effect> LinearSelection::Effects(const std::vector<int>& set) const {
  const Fit fit = FeasibleGls(set);
  const Eigen::VectorXd w = Weights(fit.sse);
  const Fit final_fit = Solve(Columns(set), std::vector<bool>(folds_, true), w);
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(final_fit.beta.size(), final_fit.beta.size());
  if (cov.size() > 0) {
    cov = final_fit.gram.completeOrthogonalDecomposition().pseudoInverse() * (train_count_ / prep_.n_eff);
  }
  std::vector<Effect> effects;
  int at = 0;
  for (int c : set) {
    const int k = static_cast<int>(candidate_columns_[c].size());
    effects.push_back(EffectFromCoefficients(lib_.candidates[c], final_fit.beta.segment(at, k),
                                             cov.block(at, at, k, k)));
    at += k;
  }
  return effects;
}

std::string LinearSelection::Veto(const std::vector<int>& set, int c) const {
  const std::vector<Effect> effects = Effects(set);
  for (const Effect& e : effects) {
    const EffectKindInfo& info = Info(e.kind);
    for (std::size_t i = 0; i < e.params.size(); ++i) {
      if (e.params[i] < info.lower[i] || e.params[i] > info.upper[i]) {
        return StrCat(EffectLabel(e), " would need ", info.params[i], " = ", e.params[i],
                      ", outside its admissible range [", info.lower[i], ", ", info.upper[i], "]");
      }
    }
    if (e.kind == EffectKind::kDelay && e.params[0] > 10 * prep_.median_dt) {
      return StrCat("delay would need d = ", e.params[0], " s, more than 10 samples");
    }
    const double hold_lag = 0.5 * prep_.median_dt;
    if (e.kind == EffectKind::kDelay && e.params[0] <= 1.1 * hold_lag + 2 * e.stderrs[0]) {
      return StrCat("delay d = ", e.params[0], " +- ", e.stderrs[0], " s is not beyond the half-sample lag a "
                    "zero-order hold of the torque alone produces (T/2 = ", hold_lag, " s)");
    }
  }
  const double size = EffectToNoise(set, c);
  if (size < min_effect_to_noise_) {
    return StrCat("torque contribution ", size, " x the sensor noise, below ", min_effect_to_noise_);
  }
  return "";
}

double LinearSelection::EffectToNoise(const std::vector<int>& set, int c) const {
  const Fit fit = FeasibleGls(set);
  const std::vector<int> cols = Columns(set);
  const Candidate& cand = lib_.candidates[c];
  Eigen::MatrixXd part = Eigen::MatrixXd::Zero(prep_.n, prep_.rows);
  for (std::size_t a = 0; a < cols.size(); ++a) {
    const auto& own = candidate_columns_[c];
    if (std::find(own.begin(), own.end(), cols[a]) != own.end()) part += fit.beta[a] * *columns_[cols[a]];
  }
  // Per joint RMS_j / sigma_j; a system-wide effect takes the root mean square of
  // these over the joints with a torque signal (sigma_j > 0: an unactuated joint's
  // zero torque has none), so a payload that stands out on the quiet wrist is not
  // drowned by the noisy shoulder's sigma (and then absorbed piecemeal by wrist
  // springs and offsets that pass their own joint's gate). The largest joint
  // instead of the mean named small gains (0.99) as extras on blind Panda cases.
  const auto rms = [&](int j) { return std::sqrt(part.row(j).head(train_count_).squaredNorm() / train_count_); };
  const auto ratio = [](double r, double noise) {
    return noise > 0 ? r / noise : (r > 0 ? std::numeric_limits<double>::infinity() : 0.0);
  };
  if (cand.joint > 0) return ratio(rms(cand.joint - 1), prep_.noise_std[cand.joint - 1]);
  double sum = 0, largest = 0;
  int sensed = 0;
  for (int j = 0; j < prep_.n; ++j) {
    const double r = rms(j);
    largest = std::max(largest, r);
    if (prep_.noise_std[j] <= 0) continue;
    sum += (r / prep_.noise_std[j]) * (r / prep_.noise_std[j]);
    ++sensed;
  }
  return sensed > 0 ? std::sqrt(sum / sensed) : ratio(largest, 0.0);
}

}  // namespace diffdyn
