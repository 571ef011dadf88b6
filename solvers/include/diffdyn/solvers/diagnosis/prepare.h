// Diagnosis stage 1: data preparation — noise, smoothing, nominal residual, split.
//
// Every later stage works on the same prepared record:
//
//   noise     sigma_j, the torque-sensor noise of joint j, from the raw samples
//             alone: at each interior sample k of a segment the deviation from
//             the straight line through its two neighbours,
//               e_k = tau_k - (w0 tau_{k-1} + w2 tau_{k+1}),  w0 = (t_{k+1} - t_k) / (t_{k+1} - t_{k-1}),
//             has variance sigma^2 (1 + w0^2 + w2^2) for white noise and loses
//             every linear trend; sigma = 1.4826 median |e_k| / sqrt(1 + w0^2 + w2^2)
//             (robust to the jumps between held poses). It needs no smoothing,
//             so it holds at 20 Hz as at 1 kHz. The same estimate on qd gives
//             the velocity noise used by the excitation checks.
//   velocity  a qd column that is the backward difference of q (q_k - q_{k-1}) / dt
//             lags the motion by half a sample; it is detected (equal to within
//             0.3 % relative RMS, which time stamps rounded to 1 us pass) and re-centred by interpolating each value,
//             which belongs to the midpoint (t_{k-1} + t_k) / 2, back to t_k.
//   cutoff    the zero-phase smoothing cutoff, unless given,
//               f_c = min(10 Hz, f_s / 4, max(f_s / 12, 2 f_99)),
//             f_s the median sample rate, f_99 the frequency below which 99 % of
//             the measured torque's power lies (TorqueBandwidthHz). f_s / 12 makes
//             the Gaussian's s = sqrt(ln 2) / (2 pi f_c) at least 1.6 sample
//             periods, so velocities and accelerations average several samples
//             rather than differencing neighbours: at 50-100 Hz a torque held over
//             each sample period (zero-order hold) otherwise reads as extra inertia,
//             because the sampled motion averages the held steps while the torque
//             record does not. The floor 2 f_99 keeps the dynamics (amplitude
//             >= 0.92 up to f_99), f_s / 4 keeps two samples in the kernel's half
//             width; above 120 Hz the rule is 10 Hz. The nominal and every extended
//             model see the same smoothing.
//   nominal   r_k = tau_k - tau_hat_k on the decimated rows, tau_hat the model
//             under test: ID(q_k, qd_k, qdd_k; p) for an analytic model, or the
//             prediction of an extended model fed back (refit.h), after optional
//             calibration of named nominal parameters.
//   split     the first 1 - h of the rows (in time) train, the last h are held out;
//             n_eff = the independent samples of the smoothed train record.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/physics/analytic_model.h"
#include "diffdyn/physics/effects.h"
#include "diffdyn/models/trajectory.h"
#include "diffdyn/solvers/smoothing.h"

namespace diffdyn {

/// Highest smoothing cutoff (Hz) the diagnosis uses (model_conventions.md).
inline constexpr double kMaxCutoffHz = 10.0;
/// The default cutoff is at most this fraction of the sample rate unless the torque's
/// own bandwidth needs more (header).
inline constexpr double kMinKernelSpan = 1.0 / 12;

/// Robust white-noise standard deviation of each row of `signal` (n x N, samples at
/// times `t`, segments starting at `segment_starts`) from the deviation of each
/// sample from the line through its neighbours (header). Rows with fewer than
/// 3 samples per segment get 0.
Eigen::VectorXd EstimateWhiteNoise(const Eigen::VectorXd& t, const Eigen::MatrixXd& signal,
                                   const std::vector<int>& segment_starts);

/// True when the velocities qd of the joint-space dataset `data` are the backward
/// difference of its positions q in every trajectory (header).
bool IsBackwardDifference(const Dataset& data);

/// `data` with a backward-difference qd moved to the sample times (header).
Dataset RecentreVelocity(const Dataset& data);

/// The frequency (Hz) below which `fraction` of the measured torque's power lies:
/// per trajectory, the Hann-weighted DFT of each joint's torque (mean removed) on
/// the samples' own times, summed over the joints and accumulated bin by bin
/// against the total power (Parseval); searched up to `max_hz` (returned when not
/// reached); the median over the trajectories with torque (0 without any).
double TorqueBandwidthHz(const Dataset& data, double fraction, double max_hz);

/// The default cutoff of `data` (Hz, header): min(10, f_s / 4, max(f_s / 12, 2 f_99)).
double DefaultCutoffHz(const Dataset& data);

/// The prepared record every later stage reads.
struct PreparedData {
  std::shared_ptr<const AnalyticModel> model;
  Eigen::VectorXd params;          ///< nominal parameters after calibration
  std::shared_ptr<const ExtendedModel> nominal;  ///< the model under test (its effects, if fed back)
  SmoothedData sd;                 ///< smoothed signals at cutoff sd.cutoff_hz
  int n = 0;                       ///< joints
  int rows = 0;                    ///< R, decimated rows
  Eigen::MatrixXd tau;             ///< n x R smoothed measured torque
  Eigen::MatrixXd id_nominal;      ///< n x R the nominal model's predicted torque
  Eigen::MatrixXd tip;             ///< n x R TipLoad (a unit payload's torque)
  Eigen::MatrixXd residual;        ///< n x R, tau - id_nominal
  std::vector<int> train, heldout; ///< row indices, in time order
  double n_eff = 0;                ///< independent samples in the train rows
  Eigen::VectorXd noise_std;       ///< n, raw torque-noise sigma_j
  Eigen::VectorXd qd_noise_std;    ///< n, raw velocity-noise sigma
  double median_dt = 0;            ///< s, median sample spacing
  bool velocity_recentred = false; ///< qd was a backward difference of q (header)
  std::vector<std::string> notes;  ///< what was done (for the report)

  /// Index of row r's sample in sd.
  int Sample(int r) const { return sd.rows[r]; }
};

/// Options of PrepareData (a subset of DiagnosisOptions).
struct PrepareOptions {
  double cutoff_hz = 0.0;                  ///< 0 = DefaultCutoffHz(data)
  double holdout_fraction = 0.3;
  std::vector<std::string> fit_params;     ///< nominal parameters fitted first
  std::vector<std::string> scale_params;   ///< scaled by one common factor
  double calibration_fraction = 0.25;      ///< first rows used to fit them
};

/// Runs stage 1 (header) for the model under test `nominal` (an analytic model
/// with no effects, or an extended model fed back). Throws diffdyn::Error on
/// sizes, options or a record too short to split, naming --model, --measured or
/// the option; NumericalError on a non-finite residual.
PreparedData PrepareData(const ExtendedModel& nominal, const Dataset& data, const PrepareOptions& options);

}  // namespace diffdyn
