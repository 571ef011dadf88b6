// Reading and writing datasets: the pushing CSV, the joint-space CSV and the real
// datasets of shared/data/, all into the one Dataset type (models/trajectory.h).
//
//   file or folder                    system                       trajectories
//   pushing CSV (header               pushing (physics/pushing/    one per trajectory
//     trajectory,step,x,y,theta,...)    system.h)                    number, t_k = k
//   joint-space CSV (t, q, qd, tau,   joint space: x = (q, qd),    one per `trajectory`
//     ...; below)                       u = the actuated tau         value (or t restart)
//   panda_gaz2019_traj1/, DeLaN       joint space                  its segments
//     characters, IBM double pendulum
//
// The joint-space CSV (shared/DESIGN.md) has a header naming its columns t,
// q1..qn, qd1..qn, tau1..taun and optional qdd1..qddn, in any order; n is found
// from the q columns. Optional: a `trajectory` column (a number or label; a new
// value starts a new trajectory, t may restart there; without it, t restarting at
// its first value starts one) and ground-truth columns m1..mn (H qdd), c1..cn
// (Coriolis and centrifugal), g1..gn (gravity), f1..fn (friction), kinetic,
// potential. Without qd columns, qd is the central difference of q ("qd1".. are
// then listed in Dataset::unmeasured). The real datasets, detected from the path:
//
//   panda_gaz2019_traj1/   exciting_traj_{time,positions,velocity,torques}.txt
//                          (7 lines per sample), tau = link-side sensor torque;
//   ibm_double_pendulum/   headerless runs of pixel markers (pivot, bob 1,
//                          bob 2); angles q1 = atan2(dy1, dx1) from hanging
//                          down (gravity points along image +x: the camera is
//                          turned), q2 relative, unwrapped; 400 Hz, free motion
//                          (tau = 0, unmeasured), qd estimated; properties
//                          "link1_px", "link2_px"; a folder reads run 0.csv, a
//                          file reads that run;
//   delan_characters/      character_data.csv: one trajectory per character.
//
// A joint-space description names the state q1..qn, qd1..qdn and the action
// tau_j of each actuated joint (by default the joints whose torque is not zero
// throughout the data: the cart-pole task pushes the cart only); every q_j is an
// angle (wrapped in the loss, seen as sin/cos by learned models) unless the
// layout lists joint j as prismatic. The measured torque of every joint stays in
// the channel "tau", and qdd and the ground-truth components (m, c, g, f,
// kinetic, potential) in their channels. Every trajectory has at least 3 samples
// and increasing times. Errors name the file and line (diffdyn::Error).
//
//   Dataset data = ReadDataset("cartpole.csv", {.actuated = {1}, .prismatic = {1}});
//   WriteDataset("copy.csv", data);   // the schema it was read with
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/models/trajectory.h"

namespace diffdyn {

/// How a joint-space dataset's system description is built.
struct JointLayout {
  /// 1-based joints whose torque is part of the action; empty = the joints whose
  /// torque is not zero throughout the data (every joint if all are zero).
  std::vector<int> actuated{};
  /// Every joint's torque is part of the action (overrides `actuated`).
  bool all_actuated = false;
  /// 1-based joints that are prismatic (not angles); empty = every joint revolute.
  std::vector<int> prismatic{};
  /// How learned models see the angles.
  AngleFeatures angle_features = AngleFeatures::kSinCos;
  /// The description's label.
  std::string name = "joint-space";
};

/// The joint-space description of an n-joint robot under `layout` (an empty
/// `actuated` means every joint here); throws diffdyn::Error for a joint index outside 1..n.
SystemDescription JointSpaceSystem(int n, const JointLayout& layout = {});

/// One run of joint-space measurements at times `t` (N, increasing) as a dataset
/// of one trajectory: states [q; qd] (q, qd: n x N), actions the actuated joints'
/// torques (tau: n x N, every joint; the last sample's torque is in the channel
/// "tau" only), format "joint-csv". Throws diffdyn::Error naming `path` on sizes,
/// times or non-finite numbers.
Dataset JointSpaceDataset(const std::string& path, const Eigen::VectorXd& t, const Eigen::MatrixXd& q,
                          const Eigen::MatrixXd& qd, const Eigen::MatrixXd& tau, const JointLayout& layout = {});

/// The matrices of(t) of every trajectory t side by side, trajectory after
/// trajectory: rows x data.samples(), where of(t) is rows x (T + 1) (a block of
/// t.states, a channel, t.t.transpose(), ...). Throws diffdyn::Error naming
/// data.path when the row counts differ.
template <typename Of>
Eigen::MatrixXd StackTrajectories(const Dataset& data, Of&& of) {
  Eigen::MatrixXd out;
  Eigen::Index column = 0;
  for (const Trajectory& t : data.trajectories) {
    const auto& block = of(t);
    if (column == 0) out.resize(block.rows(), data.samples());
    DIFFDYN_CHECK(block.rows() == out.rows() && block.cols() == t.states.cols(), data.path, ": trajectory ",
                  t.label, " gives ", block.rows(), "x", block.cols(), " where ", out.rows(), "x",
                  t.states.cols(), " is needed");
    out.middleCols(column, block.cols()) = block;
    column += block.cols();
  }
  return out;
}

/// The channel `name` of every trajectory side by side (StackTrajectories); throws
/// diffdyn::Error when a trajectory lacks it.
inline Eigen::MatrixXd StackChannel(const Dataset& data, const std::string& name) {
  return StackTrajectories(data, [&](const Trajectory& t) -> const Eigen::MatrixXd& {
    const auto it = t.channels.find(name);
    DIFFDYN_CHECK(it != t.channels.end(), data.path, ": trajectory ", t.label, " has no channel '", name, "'");
    return it->second;
  });
}

/// n of a joint-space dataset (states [q; qd] with the channel "tau" of n rows in
/// every trajectory); throws diffdyn::Error naming `data.path` otherwise.
int JointCount(const Dataset& data);

/// Reads a pushing CSV, a joint-space CSV or a real-data folder (file comment);
/// `layout` applies to joint-space data. Throws diffdyn::Error naming the file.
Dataset ReadDataset(const std::string& path, const JointLayout& layout = {});

/// `data` as the model of description `model` sees it. With the same state names,
/// the model's description is taken (angles, bounds; the metric stays the data's:
/// loss weights and wrapping) and its actions are formed by
/// name: from the data's actions, or, for tauJ, from the channel "tau" (a model of
/// the actuated joints on data of every joint). Otherwise the data's description
/// stays and only the sizes must agree. Throws diffdyn::Error naming `what`.
Dataset DatasetForModel(const Dataset& data, const SystemDescription& model, const std::string& what);

/// Writes `data` atomically in the schema of its format: the pushing CSV for
/// "pushing-csv", else the joint-space CSV (states must then be [q; qd] with the
/// torque of every joint in the channel "tau" or as the action).
void WriteDataset(const std::string& path, const Dataset& data);

}  // namespace diffdyn
