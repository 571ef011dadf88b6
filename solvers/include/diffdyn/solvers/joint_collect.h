// Joint-space data from a simulated task: what `diffdyn collect --system NAME` writes.
//
// Each trajectory starts uniformly in the task's start domain and is driven, on
// each actuated joint j, by a sum of 5 seeded sinusoids
//
//   u_j(t) = sum_l a_l sin(2 pi f_l t + phi_l),   f_l ~ U(0.2, 3) Hz,  phi_l ~ U(0, 2 pi),
//   a_l >= 0 with sum_l a_l = 0.6 bound_j,
//
// plus the task's feedback (the cart-pole's centring loop), clipped to the bounds.
// The torque is sampled at t_k = k dt and held until t_{k+1}; the task's plant
// (model, parameters, effects) integrates (q, qd) with rk4-classic at dt / substeps.
// Every sample records the state, the full torque (0 on an unactuated joint), the
// true acceleration and the ground-truth components of the model's equation
//
//   m = H(q) qdd,  c = C(q, qd) qd,  g = g(q),  f = what the effects take away,
//   kinetic = 1/2 qd^T H(q) qd,  potential = V(q) - V(0) = int_0^1 g(s q)^T q ds
//
// (the potential by Gauss-Legendre quadrature along the straight path from q = 0).
// Trajectory i draws from its own generator (TrajectoryRng(seed, i)): the data are
// the same at any thread count.
//
//   Dataset data = CollectJointSpace(JointTaskByName("pendulum"), {.trajectories = 100, .seed = 1});
//   WriteDataset("pendulum.csv", data);
#pragma once

#include <cstdint>
#include <functional>

#include "diffdyn/models/trajectory.h"
#include "diffdyn/physics/joint_task.h"

namespace diffdyn {

/// Settings of CollectJointSpace (DESIGN.md's defaults).
struct JointCollectOptions {
  int trajectories = 100;
  /// Seconds per trajectory and the sample interval dt (s).
  double seconds = 5.0;
  double dt = 0.04;
  /// rk4-classic steps per sample interval.
  int substeps = 10;
  std::uint64_t seed = 0;
  int threads = 1;
  /// Called with the number of finished trajectories (from the calling thread).
  std::function<void(int)> progress{};
};

/// The dataset of `task` (file comment): states (q, qd), actions the actuated
/// torques, channels tau, qdd, m, c, g, f, kinetic, potential; format "joint-csv".
/// Throws diffdyn::Error for bad options and diffdyn::NumericalError when the
/// simulation diverges.
Dataset CollectJointSpace(const JointTask& task, const JointCollectOptions& options);

/// Adds the channels of the file comment (tau, qdd, m, c, g, f, kinetic, potential)
/// to a trajectory of `task`'s plant that has states (q, qd) (2n x K+1) and actions
/// (the actuated torques, m x K, each held from its sample; the last sample holds
/// the last action), e.g. a controller's run on the task (solvers/control.h).
/// Throws diffdyn::Error for sizes that do not fit the task (a task without delay).
void AddGroundTruth(const JointTask& task, Trajectory* trajectory);

}  // namespace diffdyn
