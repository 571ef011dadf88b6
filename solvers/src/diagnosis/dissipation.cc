#include "diffdyn/solvers/diagnosis/dissipation.h"

#include <cmath>
#include <string>

#include <Eigen/QR>

namespace diffdyn {
namespace {

// y_w and x_w (header) over windows of the train rows.
void EnergyWindows(const PreparedData& prep, const Eigen::MatrixXd& prediction, double window,
                   Eigen::VectorXd* y, Eigen::MatrixXd* x) {
  const SmoothedData& sd = prep.sd;
  std::vector<double> ys;
  std::vector<Eigen::VectorXd> xs;
  double acc = 0, start = sd.t[prep.Sample(prep.train.front())];
  Eigen::VectorXd acc_x = Eigen::VectorXd::Zero(prep.n);
  for (std::size_t i = 1; i < prep.train.size(); ++i) {
    const int ra = prep.train[i - 1], rb = prep.train[i];
    const int ka = prep.Sample(ra), kb = prep.Sample(rb);
    if (sd.segment_of[ka] != sd.segment_of[kb]) {
      acc = 0;
      acc_x.setZero();
      start = sd.t[kb];
      continue;
    }
    const double dt = sd.t[kb] - sd.t[ka];
    acc += 0.5 * dt * (sd.qd.col(ka).dot(prep.tau.col(ra) - prediction.col(ra)) +
                       sd.qd.col(kb).dot(prep.tau.col(rb) - prediction.col(rb)));
    acc_x += 0.5 * dt * (sd.qd.col(ka).array().square() + sd.qd.col(kb).array().square()).matrix();
    if (sd.t[kb] - start >= window) {
      ys.push_back(acc);
      xs.push_back(acc_x);
      acc = 0;
      acc_x.setZero();
      start = sd.t[kb];
    }
  }
  *y = Eigen::Map<const Eigen::VectorXd>(ys.data(), static_cast<int>(ys.size()));
  x->resize(static_cast<int>(xs.size()), prep.n);
  for (std::size_t w = 0; w < xs.size(); ++w) x->row(static_cast<int>(w)) = xs[w].transpose();
}

// Viscous joints explaining the window energies (SelectionProblem).
class EnergyBalance : public SelectionProblem {
 public:
  EnergyBalance(Eigen::VectorXd y, Eigen::MatrixXd x, std::vector<int> joints, int folds)
      : y_(std::move(y)), x_(std::move(x)), joints_(std::move(joints)), folds_(folds) {}

  int NumCandidates() const override { return static_cast<int>(joints_.size()); }
  std::string Label(int c) const override { return StrCat("viscous j", joints_[c] + 1, " (energy balance)"); }
  int NumParams(int) const override { return 1; }
  double Deviance(const std::vector<int>& set) const override {
    const double w = static_cast<double>(y_.size());
    return w * std::log(Sse(set, Beta(set, All()), All()) / w + 1e-300);
  }
  double LogSamples() const override { return std::log(static_cast<double>(y_.size())); }
  double CrossValidationError(const std::vector<int>& set) const override {
    const int windows = static_cast<int>(y_.size());
    double total = 0;
    for (int f = 0; f < folds_; ++f) {
      const int a = f * windows / folds_, b = (f + 1) * windows / folds_;
      std::vector<int> train, test;
      for (int w = 0; w < windows; ++w) (w >= a && w < b ? test : train).push_back(w);
      total += Sse(set, Beta(set, train), test);
    }
    return total;
  }
  std::string Veto(const std::vector<int>& set, int /*c*/) const override {
    const Eigen::VectorXd beta = Beta(set, All());
    return beta[static_cast<int>(set.size()) - 1] > 0 ? "" : "not dissipative (b <= 0)";
  }

  /// b and its standard error for each member of `set`.
  std::vector<Effect> Effects(const std::vector<int>& set) const {
    const Eigen::VectorXd beta = Beta(set, All());
    const Eigen::MatrixXd a = Design(set, All());
    const double s2 = Sse(set, beta, All()) / std::max(1, static_cast<int>(y_.size() - set.size()));
    const Eigen::MatrixXd cov = Eigen::MatrixXd(a.transpose() * a).inverse() * s2;
    std::vector<Effect> out;
    for (std::size_t i = 0; i < set.size(); ++i) {
      const int k = static_cast<int>(i);
      out.push_back({EffectKind::kViscous, joints_[set[i]] + 1, {beta[k]}, {std::sqrt(cov(k, k))}});
    }
    return out;
  }

 private:
  std::vector<int> All() const {
    std::vector<int> all(y_.size());
    for (std::size_t w = 0; w < all.size(); ++w) all[w] = static_cast<int>(w);
    return all;
  }
  Eigen::MatrixXd Design(const std::vector<int>& set, const std::vector<int>& windows) const {
    Eigen::MatrixXd a(windows.size(), set.size());
    for (std::size_t r = 0; r < windows.size(); ++r) {
      for (std::size_t c = 0; c < set.size(); ++c) a(r, c) = x_(windows[r], joints_[set[c]]);
    }
    return a;
  }
  Eigen::VectorXd Beta(const std::vector<int>& set, const std::vector<int>& windows) const {
    if (set.empty()) return Eigen::VectorXd();
    Eigen::VectorXd b(windows.size());
    for (std::size_t r = 0; r < windows.size(); ++r) b[r] = y_[windows[r]];
    return Design(set, windows).colPivHouseholderQr().solve(b);
  }
  double Sse(const std::vector<int>& set, const Eigen::VectorXd& beta, const std::vector<int>& windows) const {
    double sse = 0;
    for (int w : windows) {
      double p = 0;
      for (std::size_t c = 0; c < set.size(); ++c) p += beta[c] * x_(w, joints_[set[c]]);
      sse += (y_[w] - p) * (y_[w] - p);
    }
    return sse;
  }

  Eigen::VectorXd y_;
  Eigen::MatrixXd x_;
  std::vector<int> joints_;
  int folds_;
};

}  // namespace

std::vector<Effect> SelectDissipation(const PreparedData& prep, const Eigen::MatrixXd& prediction,
                                      const std::vector<int>& candidates, double window, int folds,
                                      double alpha, std::vector<SelectionStep>* log) {
  Eigen::VectorXd y;
  Eigen::MatrixXd x;
  EnergyWindows(prep, prediction, window, &y, &x);
  if (y.size() < 2 * folds || candidates.empty()) return {};
  const EnergyBalance problem(y, x, candidates, folds);
  SelectionOptions options;
  options.alpha = alpha;
  options.family = static_cast<int>(candidates.size());
  options.max_selected = static_cast<int>(candidates.size());
  return problem.Effects(ForwardSelect(problem, options, log));
}

}  // namespace diffdyn
