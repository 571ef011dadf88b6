#include "diffdyn/solvers/diagnosis/gain.h"

#include <algorithm>
#include <cmath>
#include <tuple>

#include "diffdyn/models/random.h"
#include "diffdyn/solvers/diagnosis/refit.h"

namespace diffdyn {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Network inputs (q, qd, 0) at the rows: qdd is left out, so the extended mass
// matrix stays the physical one and forward dynamics stays well posed.
Eigen::MatrixXd Inputs(const PreparedData& prep, const std::vector<int>& rows) {
  const int n = prep.n;
  Eigen::MatrixXd x(3 * n, rows.size());
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const int k = prep.Sample(rows[i]);
    x.col(static_cast<int>(i)) << prep.sd.q.col(k), prep.sd.qd.col(k), Eigen::VectorXd::Zero(n);
  }
  return x;
}

Eigen::MatrixXd Columns(const Eigen::MatrixXd& m, const std::vector<int>& rows) {
  Eigen::MatrixXd out(m.rows(), rows.size());
  for (std::size_t i = 0; i < rows.size(); ++i) out.col(static_cast<int>(i)) = m.col(rows[i]);
  return out;
}

// The measured torque at time `time` of segment `seg` (linear interpolation, clamped).
Eigen::VectorXd TorqueAt(const SmoothedData& sd, int seg, double time) {
  const int begin = sd.segment_bounds[seg], end = sd.segment_bounds[seg + 1];
  const double tt = std::clamp(time, sd.t[begin], sd.t[end - 1]);
  int lo = static_cast<int>(std::upper_bound(sd.t.data() + begin, sd.t.data() + end, tt) - sd.t.data()) - 1;
  lo = std::min(std::max(begin, lo), end - 2);
  const double w = (tt - sd.t[lo]) / (sd.t[lo + 1] - sd.t[lo]);
  return sd.tau.col(lo) + w * (sd.tau.col(lo + 1) - sd.tau.col(lo));
}

}  // namespace

std::shared_ptr<const ResidualNetwork> FitResidualNetwork(const PreparedData& prep,
                                                          const Eigen::MatrixXd& target,
                                                          const std::vector<int>& rows, int hidden,
                                                          std::uint64_t seed, double* validation_gain) {
  const int n = prep.n;
  const int cut = static_cast<int>(0.8 * rows.size());
  const std::vector<int> inner(rows.begin(), rows.begin() + cut), valid(rows.begin() + cut, rows.end());
  const Eigen::MatrixXd yv = Columns(target, valid), xv = Inputs(prep, valid);
  const Eigen::VectorXd wv =
      (1.0 / (Columns(target, rows).rowwise().squaredNorm().array() / rows.size() + 1e-300)).matrix();
  double best_lambda = 1e-3, best_sse = std::numeric_limits<double>::infinity();
  for (double lambda : {1e-5, 1e-4, 1e-3, 1e-2, 1e-1}) {
    Rng rng(seed);
    const ResidualNetwork net =
        ResidualNetwork::Fit(Inputs(prep, inner), Columns(target, inner), hidden, lambda, rng);
    double sse = 0;
    for (int i = 0; i < xv.cols(); ++i) {
      const Eigen::VectorXd x = xv.col(i);
      const Eigen::VectorXd pred =
          net(Eigen::VectorXd(x.head(n)), Eigen::VectorXd(x.segment(n, n)), Eigen::VectorXd(x.tail(n)));
      sse += (wv.array() * (yv.col(i) - pred).array().square()).sum();
    }
    if (sse < best_sse) {
      best_sse = sse;
      best_lambda = lambda;
    }
  }
  const double base = (wv.asDiagonal() * yv.array().square().matrix()).sum();
  if (validation_gain) *validation_gain = base > 0 ? 1.0 - best_sse / base : 0.0;
  Rng rng(seed);
  return std::make_shared<const ResidualNetwork>(
      ResidualNetwork::Fit(Inputs(prep, rows), Columns(target, rows), hidden, best_lambda, rng));
}

Eigen::MatrixXd PredictResidual(const PreparedData& prep, const ResidualNetwork& net) {
  Eigen::MatrixXd out(prep.n, prep.rows);
  for (int r = 0; r < prep.rows; ++r) {
    const int k = prep.Sample(r);
    out.col(r) = net(Eigen::VectorXd(prep.sd.q.col(k)), Eigen::VectorXd(prep.sd.qd.col(k)),
                     Eigen::VectorXd(prep.sd.qdd.col(k)));
  }
  return out;
}

SplitScore ScoreSplit(const PreparedData& prep, const std::string& name, const std::vector<int>& held,
                      const Eigen::MatrixXd& extended, const Eigen::MatrixXd& learned,
                      const Eigen::MatrixXd& baseline) {
  SplitScore s;
  s.name = name;
  s.heldout_rows = static_cast<int>(held.size());
  s.sse_nominal = RowSse(prep, prep.id_nominal, held);
  s.sse_extended = RowSse(prep, extended, held);
  const double base = s.sse_nominal.sum();
  auto removed = [&](const Eigen::MatrixXd& p) { return base > 0 ? 1.0 - RowSse(prep, p, held).sum() / base : 0.0; };
  s.sse_removed = base > 0 ? 1.0 - s.sse_extended.sum() / base : 0.0;
  s.sse_removed_learned = removed(learned);
  if (baseline.size() > 0) s.sse_removed_baseline = removed(baseline);
  return s;
}

RolloutErrors ScoreRollouts(const PreparedData& prep, const ExtendedModel& extended, double horizon) {
  const SmoothedData& sd = prep.sd;
  const int n = prep.n;
  const ExtendedModel& nominal = *prep.nominal;
  const double delay = extended.Delay<double>(extended.EffectParams());
  RolloutErrors out;
  Eigen::VectorXd sq[4];
  for (auto& v : sq) v = Eigen::VectorXd::Zero(n);
  double next_start = -1e300;
  for (int r : prep.heldout) {
    const int k0 = prep.Sample(r), seg = sd.segment_of[k0];
    const double t0 = sd.t[k0];
    if (t0 < next_start) continue;
    if (t0 + horizon > sd.t[sd.segment_bounds[seg + 1] - 1] - 3 * sd.sigma_t) continue;
    next_start = t0 + horizon;
    const double dt = sd.t[std::min(static_cast<int>(sd.t.size()) - 1, k0 + 1)] - sd.t[k0];
    const int steps = std::max(10, static_cast<int>(std::ceil(horizon / std::max(1e-3, dt))));
    // An extended mass matrix that is not positive definite makes a rollout
    // meaningless: it is counted and its error is NaN.
    auto roll = [&](const ExtendedModel& m, double d) {
      Eigen::VectorXd q = sd.q.col(k0), v = sd.qd.col(k0);
      try {
        IntegrateJointMotion(m, [&](double time) { return TorqueAt(sd, seg, time - d); }, t0, t0 + horizon,
                             steps, q, v);
      } catch (const NumericalError&) {
        ++out.failed;
        q = v = Eigen::VectorXd::Constant(n, kNaN);
      }
      return std::make_pair(q, v);
    };
    Eigen::VectorXd q_end, v_end, unused;
    sd.StateAt<double>(t0 + horizon, seg, q_end, v_end, unused);
    const auto [qn, vn] = roll(nominal, nominal.Delay<double>(nominal.EffectParams()));
    const auto [qe, ve] = roll(extended, delay);
    sq[0] += (qn - q_end).array().square().matrix();
    sq[1] += (qe - q_end).array().square().matrix();
    sq[2] += (vn - v_end).array().square().matrix();
    sq[3] += (ve - v_end).array().square().matrix();
    ++out.windows;
  }
  const double w = std::max(1, out.windows);
  out.q_nominal = (sq[0] / w).cwiseSqrt();
  out.q_extended = (sq[1] / w).cwiseSqrt();
  out.qd_nominal = (sq[2] / w).cwiseSqrt();
  out.qd_extended = (sq[3] / w).cwiseSqrt();
  return out;
}

double EnergyBalanceError(const PreparedData& prep, const Eigen::MatrixXd& prediction, double window) {
  const SmoothedData& sd = prep.sd;
  double sum_sq = 0, acc = 0, start = sd.t[prep.Sample(prep.heldout.front())];
  int windows = 0;
  for (std::size_t i = 1; i < prep.heldout.size(); ++i) {
    const int ra = prep.heldout[i - 1], rb = prep.heldout[i];
    const int ka = prep.Sample(ra), kb = prep.Sample(rb);
    if (sd.segment_of[ka] != sd.segment_of[kb]) {
      acc = 0;
      start = sd.t[kb];
      continue;
    }
    const double pa = sd.qd.col(ka).dot(prep.tau.col(ra) - prediction.col(ra));
    const double pb = sd.qd.col(kb).dot(prep.tau.col(rb) - prediction.col(rb));
    acc += 0.5 * (pa + pb) * (sd.t[kb] - sd.t[ka]);
    if (sd.t[kb] - start >= window) {
      sum_sq += acc * acc;
      ++windows;
      acc = 0;
      start = sd.t[kb];
    }
  }
  return windows > 0 ? std::sqrt(sum_sq / windows) : 0.0;
}

}  // namespace diffdyn
