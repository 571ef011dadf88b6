// Pushing trials: MPPI over a transition model, executed in the ODE-engine world.
//
// The pushing task is a Task (physics/task.h) like the swing-up tasks, so the one
// evaluator (EvaluateController, solvers/control.h) runs it: PushingTask is the
// plant, starts and success test below, PushingMppiController the planner, and
// RunPushTrials the series `diffdyn push` reports. A trial puts the block at the task's start pose plus a seeded perturbation
// (uniform in a disc of radius start_xy_jitter and in +-start_theta_jitter),
// then repeats: MPPI (solvers/mppi.h) plans with `model` from the block's true
// pose, the first action is executed by PushingEnv (the ODE world), and the
// trial ends at the first of
//
//   success           |p_xy - g_xy| < goal_tolerance after a push
//   obstacle_contact  the block touched the obstacle in the ODE world (any contact fails)
//   off_table         the block left the table
//   unreachable       the arm could not execute the action
//   max_steps         max_steps pushes without any of the above
//
// Tasks (the NeuralODE-Panda seed's):
//   obstacle  start (0.4, 0, -0.2 pi), goal (0.8, -0.1, 0), cost with 100 x in_collision
//             (solvers/pushing/cost.h; collision_margin and collision_substeps add the
//             margin and the swept test, both 0 = the seed's cost; clearance adds an
//             optional smooth term, off by default)
//   free      start (0.4, 0, 0.2 pi),  goal (0.8, 0, 0),    no collision cost
// Both tasks can make MPPI aware of the arm's reach (PushingEnv::Reach, the annulus
// where the IK reaches the tool path): reach_limited rolls out ReachLimitedModel
// (physics/pushing/reach_limited_model.h: a push the arm cannot reach leaves the block in
// place, so no plan counts on one), and reach_weight charges the cost for the first
// reach_steps planned pushes that leave the annulus (1: the push executed now).
// MPPI: Sigma = 0.5 I, lambda = 0.01, u in [-1, 1] x [-pi/2, pi/2] x [0, 1].
//
// Each trial also records the model's prediction of every executed push
// (PushTrial::predicted): next to the executed pose it separates model error from
// controller error. The learned models meant for this task are trained on data
// collected WITHOUT the obstacle (`diffdyn collect --starts task --obstacle off`):
// a model trained with the obstacle in the world learns that the block stops at it,
// so it never predicts an overlap and the collision cost cannot see a push into it.
//
// Trial i draws its perturbation and its MPPI seed from TrajectoryRng(seed, i)
// (models/random.h), so any subset of trials and any thread count give the
// same poses and actions; only the timings vary. Each step's cost is the seed's
// cost of the executed push (PushingCost without margin, substeps or extra terms).
//
//   diffdyn::PushTaskOptions options;          // obstacle task, K = 1000, T = 20
//   auto summary = diffdyn::RunPushTrials(model, /*trials=*/20, options, /*seed=*/1);
//   summary.success_rate;                      // with summary.ci95_low / ci95_high
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/models/transition_model.h"
#include "diffdyn/physics/pushing/env.h"
#include "diffdyn/physics/pushing/reach_limited_model.h"
#include "diffdyn/physics/task.h"
#include "diffdyn/solvers/control.h"
#include "diffdyn/solvers/mppi.h"
#include "diffdyn/solvers/pushing/cost.h"

namespace diffdyn {

/// Settings of a series of pushing trials (see the file comment).
struct PushTaskOptions {
  bool obstacle = true;              ///< obstacle task (true) or free task (false)
  int samples = 1000;                ///< MPPI K
  int horizon = 20;                  ///< MPPI T
  int max_steps = 20;                ///< pushes per trial (>= 1)
  double start_xy_jitter = 0.02;     ///< start perturbation: uniform in a disc of this radius (m)
  double start_theta_jitter = 0.1;   ///< start perturbation: uniform in +-this (rad)
  double goal_tolerance = 0.1;       ///< success: block centre within this of the goal (m)
  int threads = 0;                   ///< MPPI threads (<= 0: all cores); results do not depend on it
  PushingConfig world;               ///< the ODE world (its obstacle flag is set from `obstacle`)
  double lambda = 0.01;              ///< MPPI temperature
  double noise_variance = 0.5;       ///< MPPI Sigma = noise_variance I
  std::optional<Eigen::Vector3d> start;  ///< overrides the task's nominal start pose
  std::optional<Eigen::Vector3d> goal;   ///< overrides the task's goal pose
  /// PushingCost safety margin m per side (m); 0 with collision_substeps 0 is the
  /// seed's cost. 0.02 and 4 were picked on the obstacle task (paper_figures/mppi_obstacle).
  double collision_margin = 0.02;
  int collision_substeps = 4;        ///< PushingCost swept-test substeps S; 0: end pose only
  /// MppiOptions::fallback_margin (solvers/mppi.h, step 6): the averaged action
  /// sequence is replaced by the best sample's when the model predicts it to cost
  /// more than the best plus this; infinity: off (pytorch_mppi's algorithm).
  double fallback_margin = std::numeric_limits<double>::infinity();
  /// PushingCost clearance term (distance c in m, weight w_l); c = 0 or w_l = 0: off.
  double clearance = 0.0;
  double clearance_weight = 0.0;
  /// PushingCost reach term: weight w_r (0: off) over the first `reach_steps` planned
  /// pushes, annulus PushingEnv::Reach(world): MPPI pays w_r for each of those pushes
  /// that the arm cannot execute. With reach_limited, the defaults took the obstacle
  /// task from 140/150 to 148/150 on trial seeds 1-3 (paper_figures/mppi_obstacle).
  double reach_weight = 100.0;
  int reach_steps = 1;
  /// MPPI rolls out ReachLimitedModel(model, PushingEnv::Reach(world)): a planned push
  /// the arm cannot execute leaves the block where it is. false with reach_weight 0:
  /// the planner of the seed, blind to the arm.
  bool reach_limited = true;
};

/// One trial's record.
struct PushTrial {
  bool success = false;
  int pushes = 0;
  /// "success", "obstacle_contact", "off_table", "unreachable" or "max_steps".
  std::string outcome;
  Eigen::Vector3d start = Eigen::Vector3d::Zero();  ///< perturbed start pose
  Eigen::Vector3d goal = Eigen::Vector3d::Zero();
  std::vector<Eigen::Vector3d> poses;    ///< pushes + 1 block poses, poses[0] = start
  std::vector<Eigen::Vector3d> actions;  ///< pushes actions
  /// The model's prediction of each executed push, F(poses[k], actions[k]) (pushes of
  /// them); compared with poses[k + 1] it separates model error from controller error.
  std::vector<Eigen::Vector3d> predicted;
  std::vector<double> command_ms;        ///< wall time of each MPPI command (ms)
};

/// Totals of RunPushTrials.
struct PushTrialsSummary {
  int trials = 0, successes = 0;
  double success_rate = 0, ci95_low = 0, ci95_high = 0;  ///< Wilson score interval
  double mean_pushes = 0;            ///< over all trials
  double ms_per_command = 0;         ///< median over all commands
  int fallbacks = 0;                 ///< commands where MPPI kept its best sample (mppi.h, step 6)
  std::vector<PushTrial> runs;
};

/// The task's nominal start pose: obstacle (0.4, 0, -0.2 pi), free (0.4, 0, 0.2 pi).
Eigen::Vector3d PushTaskStart(bool obstacle);

/// The task's goal pose: obstacle (0.8, -0.1, 0), free (0.8, 0, 0).
Eigen::Vector3d PushTaskGoal(bool obstacle);

/// Throws diffdyn::Error naming the option when `options` is unusable.
void ValidatePushTaskOptions(const PushTaskOptions& options);

/// The pushing task of `options` as a Task: states and actions of size 3, one push
/// per step (step_period 1), at most max_steps pushes, actions clipped to
/// [-1, 1] x [-pi/2, pi/2] x [0, 1], the seeded starts and outcomes of the file comment.
class PushingTask final : public Task {
 public:
  /// Throws diffdyn::Error naming the option when `options` is unusable.
  explicit PushingTask(const PushTaskOptions& options);
  int state_size() const override { return 3; }
  int action_size() const override { return 3; }
  double step_period() const override { return 1.0; }
  int max_steps() const override { return options_.max_steps; }
  Eigen::VectorXd Clip(const Eigen::Ref<const Eigen::VectorXd>& u) const override;
  std::vector<TaskStart> Starts(int count, std::uint64_t seed) const override;
  std::unique_ptr<TaskRun> Begin() const override;

  const PushTaskOptions& options() const { return options_; }
  /// The ODE world of the task (obstacle and goal set).
  const PushingConfig& world() const { return world_; }
  const Eigen::Vector3d& goal() const { return world_.goal; }

 private:
  PushTaskOptions options_;
  PushingConfig world_;
};

/// MPPI over `model` with pushing's cost (file comment): the safety margin, swept
/// test, clearance and reach terms of the task's options; with reach_limited the
/// rollouts go through ReachLimitedModel. Keeps references to the task and the
/// model. Throws diffdyn::Error unless the model has 3 states and 3 actions.
class PushingMppiController final : public Controller {
 public:
  PushingMppiController(const PushingTask& task, const TransitionModel& model);
  void Reset(const Eigen::VectorXd& x0, std::uint64_t seed) override;
  Eigen::VectorXd Command(const Eigen::VectorXd& x) override;
  /// Commands so far, over every run, where MPPI kept its best sample (mppi.h, step 6).
  int fallbacks() const;

 private:
  const TransitionModel& model_;
  std::optional<ReachLimitedModel> limited_;
  PushingCost cost_;
  MppiOptions mppi_options_;
  std::unique_ptr<Mppi> mppi_;
  int past_fallbacks_ = 0;
};

/// Runs trial `index` of a series seeded by `seed` (see the file comment).
/// `model` must have state and action size 3.
PushTrial RunPushTrial(const TransitionModel& model, int index, const PushTaskOptions& options,
                       std::uint64_t seed);

/// Runs `trials` seeded trials of MPPI over `model` in the ODE world, one after
/// another, through EvaluateController; trial i uses seeds derived from (seed, i).
/// `progress` (may be empty) is called after each trial with the trials done and the
/// successes so far. Throws diffdyn::Error for bad options or a model of the wrong sizes.
PushTrialsSummary RunPushTrials(const TransitionModel& model, int trials,
                                const PushTaskOptions& options, std::uint64_t seed,
                                const std::function<void(int done, int successes)>& progress = {});

}  // namespace diffdyn
