#include "diffdyn/solvers/smoothing.h"

#include <cmath>
#include <numbers>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/solvers/dataset_io.h"

namespace diffdyn {

double SmoothedData::IndependentRate() const {
  return 1.0 / (2.0 * std::sqrt(std::numbers::pi) * sigma_t);
}

SmoothedData SmoothJointSpace(const Dataset& data, double cutoff_hz) {
  DIFFDYN_CHECK(cutoff_hz > 0 && std::isfinite(cutoff_hz), "--cutoff-hz ", cutoff_hz,
                ": must be a positive frequency");
  const int n = JointCount(data), count = data.samples();
  SmoothedData out;
  out.cutoff_hz = cutoff_hz;
  out.sigma_t = std::sqrt(std::log(2.0)) / (2.0 * std::numbers::pi * cutoff_hz);
  // The trajectories side by side: raw signals and segment bounds.
  bool has_qdd = true;
  for (const Trajectory& t : data.trajectories) has_qdd = has_qdd && t.channels.count("qdd");
  out.t = StackTrajectories(data, [](const Trajectory& t) { return t.t.transpose(); }).transpose();
  out.q_raw = StackTrajectories(data, [n](const Trajectory& t) { return t.states.topRows(n); });
  out.qd_raw = StackTrajectories(data, [n](const Trajectory& t) { return t.states.bottomRows(n); });
  out.tau_raw = StackChannel(data, "tau");
  const Eigen::MatrixXd qdd_raw = has_qdd ? StackChannel(data, "qdd") : Eigen::MatrixXd();
  out.segment_bounds = {0};
  for (const Trajectory& t : data.trajectories) {
    out.segment_bounds.push_back(out.segment_bounds.back() + static_cast<int>(t.states.cols()));
  }
  out.q.resize(n, count);
  out.qd.resize(n, count);
  out.qdd.resize(n, count);
  out.tau.resize(n, count);
  out.dtau.resize(n, count);
  out.segment_of.assign(count, 0);
  const double s = out.sigma_t, reach = 4.0 * s;

  for (std::size_t seg = 0; seg + 1 < out.segment_bounds.size(); ++seg) {
    const int begin = out.segment_bounds[seg], end = out.segment_bounds[seg + 1];
    double last_row_time = -1e300;
    int lo = begin, hi = begin;
    for (int k = begin; k < end; ++k) {
      out.segment_of[k] = static_cast<int>(seg);
      const double t0 = out.t[k];
      while (out.t[lo] < t0 - reach) ++lo;
      while (hi < end && out.t[hi] <= t0 + reach) ++hi;
      // Local-linear Gaussian weights alpha (value) and beta (slope).
      const int m = hi - lo;
      Eigen::VectorXd w(m), u(m);
      double s0 = 0, s1 = 0, s2 = 0;
      for (int i = 0; i < m; ++i) {
        u[i] = out.t[lo + i] - t0;
        w[i] = std::exp(-0.5 * u[i] * u[i] / (s * s));
        s0 += w[i];
        s1 += w[i] * u[i];
        s2 += w[i] * u[i] * u[i];
      }
      const double det = s0 * s2 - s1 * s1;
      DIFFDYN_CHECK(det > 0, data.path, ": fewer than 2 samples within ", reach,
                    " s of t = ", t0, "; raise --cutoff-hz or check the time column");
      const Eigen::VectorXd alpha = (w.array() * (s2 - u.array() * s1) / det).matrix();
      const Eigen::VectorXd beta = (w.array() * (u.array() * s0 - s1) / det).matrix();
      out.q.col(k) = out.q_raw.middleCols(lo, m) * alpha;
      out.qd.col(k) = out.qd_raw.middleCols(lo, m) * alpha;
      out.qdd.col(k) = has_qdd ? Eigen::VectorXd(qdd_raw.middleCols(lo, m) * alpha)
                               : Eigen::VectorXd(out.qd_raw.middleCols(lo, m) * beta);
      out.tau.col(k) = out.tau_raw.middleCols(lo, m) * alpha;
      out.dtau.col(k) = out.tau_raw.middleCols(lo, m) * beta;
      // Interior samples, decimated: the fitting rows.
      const bool interior = t0 - out.t[begin] >= 3 * s && out.t[end - 1] - t0 >= 3 * s;
      if (interior) {
        if (t0 >= last_row_time + 0.75 * s) {
          last_row_time = t0;
          out.rows.push_back(k);
          out.kernel_begin.push_back(lo);
          out.kernel_alpha.push_back(alpha);
        }
      }
    }
  }
  DIFFDYN_CHECK(out.rows.size() >= 10, data.path, ": only ", out.rows.size(),
                " usable samples after smoothing at --cutoff-hz ", cutoff_hz,
                " (the record is too short for this cutoff)");
  return out;
}

}  // namespace diffdyn
