// Zero-phase smoothing and differentiation of measured joint signals.
//
// Torque residuals need qdd, which sensors rarely give; differentiating noisy
// qd amplifies noise, so every signal is smoothed by the same zero-phase
// filter and qdd is the derivative of the smoothed qd. At each sample time t0
// a straight line is fitted by Gaussian-weighted least squares,
//
//   min_{a,b} sum_k w_k (y_k - a - b (t_k - t0))^2,  w_k = exp(-(t_k - t0)^2 / (2 s^2)),
//
// over |t_k - t0| <= 4 s inside the sample's segment. The value a is the
// smoothed signal and the slope b its derivative; both are linear in y,
//
//   a = sum_k alpha_k y_k,   b = sum_k beta_k y_k,
//
// so the filter is zero-phase (symmetric weights in the interior), works on
// irregular time stamps, stays unbiased for linear trends at the edges, and
// b is exactly d/dt of a Gaussian-smoothed signal in the interior. With
// s = sqrt(ln 2) / (2 pi f_c) the Gaussian's amplitude response falls to
// 1/sqrt(2) at f_c (default 10 Hz). tau, q, qd (and a measured qdd) are all
// smoothed with the same alpha, and qdd = sum_k beta_k qd_k, so the residual
// tau - ID(q, qd, qdd) compares like with like.
//
// Residual noise after smoothing is correlated over about 2 sqrt(pi) s, so a
// record of length T holds about T / (2 sqrt(pi) s) independent samples; the
// information criteria of the diagnosis use this count. Fitting uses a
// decimated subset of rows (spacing >= 0.75 s), away from segment edges (3 s).
#pragma once

#include <type_traits>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/models/trajectory.h"

namespace diffdyn {

/// Smoothed signals at full rate (n x N) and the decimated rows used for fits.
struct SmoothedData {
  double cutoff_hz = 10.0;  ///< f_c
  double sigma_t = 0.0;     ///< s = sqrt(ln 2) / (2 pi f_c), seconds
  Eigen::VectorXd t;        ///< N sample times
  Eigen::MatrixXd q, qd, qdd, tau;  ///< smoothed (alpha) and qdd = beta * qd
  Eigen::MatrixXd dtau;             ///< beta * tau, the smoothed torque rate
  Eigen::MatrixXd q_raw, qd_raw, tau_raw;  ///< the unsmoothed inputs
  std::vector<int> segment_of;      ///< N: segment index of each sample
  std::vector<int> rows;            ///< decimated interior sample indices
  std::vector<int> kernel_begin;    ///< per row: first sample of its window
  std::vector<Eigen::VectorXd> kernel_alpha;  ///< per row: the alpha weights

  int dof() const { return static_cast<int>(q.rows()); }
  /// Independent samples per second of smoothed noise, 1 / (2 sqrt(pi) s).
  double IndependentRate() const;
  /// Smoothed state (q, qd, qdd) at time `time` by linear interpolation between
  /// the samples of segment `segment` (clamped at its ends). Templated weight:
  /// `time` may carry a Jet derivative (delay fits).
  template <typename T>
  void StateAt(const T& time, int segment, Eigen::Matrix<T, Eigen::Dynamic, 1>& q_out,
               Eigen::Matrix<T, Eigen::Dynamic, 1>& qd_out,
               Eigen::Matrix<T, Eigen::Dynamic, 1>& qdd_out) const;
  /// The kernel average sum_i alpha_i f(qd_raw(joint, i)) over row `r`'s window
  /// (r indexes `rows`): a function of the raw velocity smoothed like the data.
  template <typename T, typename F>
  T KernelAverage(int r, int joint, F&& f) const {
    const Eigen::VectorXd& alpha = kernel_alpha[r];
    T acc = T(0.0);
    for (int i = 0; i < alpha.size(); ++i) acc += alpha[i] * f(qd_raw(joint, kernel_begin[r] + i));
    return acc;
  }
  /// First and one-past-last samples of each segment.
  std::vector<int> segment_bounds;  ///< size segments + 1
};

/// Smooths the joint-space dataset `data` (dataset_io.h: states [q; qd], channel
/// "tau", optional "qdd"; its trajectories side by side in the result) with
/// cutoff `cutoff_hz` (> 0); throws diffdyn::Error naming --cutoff-hz when the
/// cutoff leaves fewer than 10 usable rows.
SmoothedData SmoothJointSpace(const Dataset& data, double cutoff_hz);

// Template implementation.
template <typename T>
void SmoothedData::StateAt(const T& time, int segment, Eigen::Matrix<T, Eigen::Dynamic, 1>& q_out,
                           Eigen::Matrix<T, Eigen::Dynamic, 1>& qd_out,
                           Eigen::Matrix<T, Eigen::Dynamic, 1>& qdd_out) const {
  const int begin = segment_bounds[segment], end = segment_bounds[segment + 1];
  double tv;
  if constexpr (std::is_same_v<T, double>) {
    tv = time;
  } else {
    tv = time.a;
  }
  // Binary search for the interval [k, k + 1] holding tv.
  int lo = begin, hi = end - 1;
  if (tv <= t[lo]) {
    hi = lo + 1;
  } else if (tv >= t[hi]) {
    lo = hi - 1;
  } else {
    while (hi - lo > 1) {
      const int mid = (lo + hi) / 2;
      (t[mid] <= tv ? lo : hi) = mid;
    }
  }
  const T w = (time - t[lo]) / (t[hi] - t[lo]);
  const int n = dof();
  q_out.resize(n);
  qd_out.resize(n);
  qdd_out.resize(n);
  for (int j = 0; j < n; ++j) {
    q_out[j] = q(j, lo) + w * (q(j, hi) - q(j, lo));
    qd_out[j] = qd(j, lo) + w * (qd(j, hi) - qd(j, lo));
    qdd_out[j] = qdd(j, lo) + w * (qdd(j, hi) - qdd(j, lo));
  }
}

}  // namespace diffdyn
