// Training and scoring DeLaN (models/delan.h) on joint-space measurements.
//
// Data: any joint-space dataset (dataset_io.h) with measured torques, as samples
// (q, qd, qdd, tau) in no particular order (DelanSamples). Where qdd was not
// measured it is estimated as `diagnose` does (smoothing.h, 10 Hz cutoff: q, qd,
// tau smoothed alike, qdd the derivative of the smoothed qd).
//
// Split: on the DeLaN characters (format "delan-characters") the authors' split,
// the characters e, q and v held out for testing and the other 17 for training;
// on other data a seeded split of the samples (SplitWindows over samples,
// val_fraction of them held out).
//
// Training: FitMinibatches (training.h) on the torque loss
// (1/B) sum_b |tau^_b - tau_b|^2, validated on the held-out samples, with the
// DeLaN authors' defaults in DelanTrainDefaults (Adam with AMSGrad, lr 5e-4, L2
// weight decay 1e-5, batch 512).
//
// Scores (DESIGN.md, eval): *_mse = (1/N) sum_samples sum_joints (y^ - y)^2 for the
// torque and, where the data has ground-truth channels, H qdd ("m"), c, g, friction
// ("f"; zero for a DeLaN without friction head), the energies (potential
// offset-matched); power_mse of dE^/dt + qd^T f^ against qd^T tau; *_nmse the same
// divided by the total variance; the smallest eigenvalue of H over the samples.
//
//   Dataset data = ReadDataset("../shared/data/delan_characters");
//   DelanSplit split = SplitForDelan(data, 0.2, seed);
//   Delan model = Delan::Initialized({.dof = split.train.dof()}, seed);
//   TrainResult r = TrainDelan(&model, split.train, split.test, DelanTrainDefaults());
//   DelanScores s = ScoreDelan(model, split.test);
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "diffdyn/models/delan.h"
#include "diffdyn/models/trajectory.h"
#include "diffdyn/solvers/training.h"

namespace diffdyn {

/// Joint-space samples for DeLaN, one per column (n x N each), in no time order.
struct DelanSamples {
  std::string path;      ///< the dataset they come from (for errors)
  Eigen::MatrixXd q, qd, qdd, tau;
  /// Ground-truth channels of the dataset ("m", "c", "g", "f": n x N; "kinetic",
  /// "potential": 1 x N).
  std::map<std::string, Eigen::MatrixXd> channels;
  bool measured_torque = true;  ///< false: free motion, tau taken as zero

  /// n, the number of joints.
  int dof() const { return static_cast<int>(q.rows()); }
  /// N, the number of samples.
  int size() const { return static_cast<int>(q.cols()); }
};

/// Training and held-out samples, with how they were chosen.
struct DelanSplit {
  DelanSamples train, test;
  /// "characters e, q, v held out" or "seeded split of samples".
  std::string how;
};

/// Every sample of the joint-space dataset `data` in time order, trajectory after
/// trajectory, with qdd (estimated when a trajectory lacks the channel "qdd",
/// see the header comment).
DelanSamples SamplesOf(const Dataset& data);

/// The samples `index` of `samples` (q, qd, qdd, tau and the channels).
DelanSamples SelectSamples(const DelanSamples& samples, const std::vector<int>& index);

/// The split of the header comment; throws diffdyn::Error when a side would be empty.
DelanSplit SplitForDelan(const Dataset& data, double val_fraction, std::uint64_t seed);

/// The DeLaN authors' training settings: 10,000 epochs of batch 512, Adam with
/// AMSGrad, learning rate 5e-4, weight decay 1e-5.
TrainOptions DelanTrainDefaults();

/// Trains *model in place on `train`, validating on `val` (may be empty: no
/// validation), on the torque loss with `joint_weights` (Delan::TorqueLoss; empty:
/// the plain MSE of the DeLaN authors). Throws diffdyn::Error for data of another dof, without qdd, or
/// without measured torques (free motion).
TrainResult TrainDelan(Delan* model, const DelanSamples& train, const DelanSamples& val,
                       const TrainOptions& options,
                       const std::function<void(const EpochReport&)>& on_epoch = {},
                       const Eigen::VectorXd& joint_weights = {});

/// Joint weights that give every joint's torque the same say in the loss:
/// w_j = 1 / Var(tau_j) over `train`; a joint whose torque does not vary (an
/// unactuated one) gets the largest weight of the others. Throws diffdyn::Error
/// when no joint's torque varies.
Eigen::VectorXd BalancedJointWeights(const DelanSamples& train);

/// (1/N) sum |y^ - y|^2 over the total variance (1/N) sum |y - mean y|^2 of the
/// truth y (rows x N): DESIGN.md's *_nmse; NaN when the truth does not vary.
double NormalizedMse(const Eigen::MatrixXd& predicted, const Eigen::MatrixXd& truth);

/// The scores of the header comment, by key ("torque_mse", "inertial_mse", ...,
/// "torque_nmse", ..., "min_mass_eigenvalue"); keys for channels the data lacks are absent.
std::map<std::string, double> ScoreDelan(const Delan& model, const DelanSamples& data, int threads = 0);

}  // namespace diffdyn
