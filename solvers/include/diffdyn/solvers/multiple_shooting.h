// Trajectory optimisation of a control task by multiple shooting, with Ceres.
//
// The task's optimal-control problem from x0 on its control grid (K = duration / period
// piecewise-constant actions u_k, m each, within the task's bounds):
//
//   min_u  sum_{k < K} period * c(x_k, u_k),   x_{k+1} = Phi(x_k, u_k),
//
// Phi the plant over one control period (rk4-classic, 4 substeps: the evaluator's plant
// of control.h) and c the task's running cost. Each term is a square: the state cost
// sum_i w_i e_i(x)^2 and the action cost g(u) = rho(u)^2 (quadratic: rho_j = sqrt(r_j) u_j;
// log-cosine: rho = sign(u) sqrt(g(u)), smooth through 0), so Ceres' Levenberg-Marquardt
// minimises it as a least-squares problem. The optimiser adds a terminal cost, the
// infinite-horizon LQR cost-to-go e(x_K)^T P e(x_K) at the goal (lqr.h; e_i = 2 sin(d_i / 2)
// for a periodic component), so that the finite-horizon optimum does not trade balancing
// at the end for action cost; the reported cost is the evaluator's, without it.
//
// Multiple shooting: the states x_1..x_K are parameters too (n each, x_0 held; bounded
// by the task's finite state limits, as the cart-pole's track), with
// the continuity defects as weighted residuals s (x_{k+1} - Phi(x_k, u_k)); Phi and its
// Jacobians come from the plant (TaskModel's rk4-classic, TransitionModel::Jacobian). The weight s
// rises tenfold per stage up to `final_weight`, each stage started from the last. A
// warm start sets the states on a straight line from x0 to a copy of the goal over a
// fraction of the run (then at the goal), with zero actions: for each periodic
// component the copy reached by increasing it, or the one reached by decreasing it
// (the two swing directions). A small first weight lets the states leave the line
// freely (swings found late), a large one keeps the dynamics from the start; the
// portfolio of warm starts, each in both directions, is solved and the smallest final
// objective (cost plus weighted defects) kept.
//
// Single-shooting polish: the states are then dropped and the actions alone optimised
// with the rollout x_{k+1} = Phi(x_k, u_k) from x0 (dense Jacobian from the chained step
// Jacobians), so the result is continuous by construction. When the stages stalled with a
// defect above `defect_tolerance` (a swing the penalty could not add), single shooting
// first makes the trajectory continuous and the stages from weight 1e3 refine it from
// its rollout. The returned states are the rollout on the evaluator's plant; `defect`
// compares each of its steps with the Jet integrator.
//
//   ControlTask task = ControlTaskByName("pendulum");
//   MultipleShootingSolution s = SolveMultipleShooting(task, x0, MultipleShootingOptions{});
//   // s.actions: m x K; s.states: n x (K + 1); s.cost: the evaluator's cost
//   MultipleShootingController controller(task, MultipleShootingOptions{});  // replays open loop
//   auto runs = EvaluateController(task, controller, {.starts = 300, .seed = 1, .threads = 2});
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/physics/analytic_model.h"
#include "diffdyn/physics/control_task.h"
#include "diffdyn/solvers/control.h"

namespace diffdyn {

/// The task's plant over one control period, x_{k+1} = Phi(x, u) (n): the evaluator's
/// plant (TaskModel, rk4-classic with 4 substeps) with its Jacobians fx = dPhi/dx
/// (n x n) and fu = dPhi/du (n x m) (TransitionModel::Jacobian). Not thread-safe.
class TaskStep {
 public:
  explicit TaskStep(const ControlTask& task);
  ~TaskStep();
  /// Phi(x, u) on double.
  Eigen::VectorXd Value(const Eigen::VectorXd& x, const Eigen::VectorXd& u) const;
  /// Phi(x, u) on Jets, with fx and fu.
  Eigen::VectorXd Jacobians(const Eigen::VectorXd& x, const Eigen::VectorXd& u, Eigen::MatrixXd* fx,
                            Eigen::MatrixXd* fu) const;

 private:
  static constexpr int kSubsteps = 4;  // the evaluator's plant (control.h)
  std::unique_ptr<TransitionModel> plant_;
  std::unique_ptr<TransitionWorkspace> workspace_;
};

/// One warm start of SolveMultipleShooting: the first continuity weight and the fraction of
/// the run over which the warm-start states reach the goal (file comment).
struct ShootingWarmStart {
  double first_weight = 1.0;
  double reach_fraction = 0.5;
};

/// Settings of SolveMultipleShooting (file comment).
struct MultipleShootingOptions {
  /// Warm starts, each solved in both swing directions; the smallest final objective wins.
  std::vector<ShootingWarmStart> warm_starts{{1.0, 0.5}, {100.0, 1.0}};
  /// The continuity weight rises tenfold per stage from a warm start's first weight to this.
  double final_weight = 1e6;
  /// Relative cost change that ends an intermediate stage (the last stage: 1e-12) and
  /// a polish (a hundredth of it).
  double stage_tolerance = 1e-6;
  /// Levenberg-Marquardt iterations per stage and per polish.
  int max_iterations = 50;
  /// A multiple-shooting defect above this sends the solution through single shooting
  /// and a multiple-shooting refinement before the final polish.
  double defect_tolerance = 1e-8;
  /// Run the single-shooting polish.
  bool polish = true;
  /// Add the terminal cost e(x_K)^T P e(x_K), P the task's LQR cost-to-go (file comment).
  bool terminal_lqr = true;
};

/// The result of SolveMultipleShooting.
struct MultipleShootingSolution {
  /// Actions u_0..u_{K-1} (m x K) and their rollout x_0..x_K (n x (K + 1)).
  Eigen::MatrixXd actions, states;
  /// sum_k period * c(x_k, u_k) over the rollout.
  double cost = 0.0;
  /// Largest continuity defect |x_{k+1} - Phi(x_k, u_k)|_inf of the multiple-shooting
  /// solution before the polish.
  double shooting_defect = 0.0;
  /// Largest continuity defect of the returned rollout: its states come from the
  /// evaluator's plant, Phi from the Jet integrator the optimiser differentiates.
  double defect = 0.0;
  /// The warm start kept: +1 (periodic components increasing) or -1.
  int direction = 1;
  /// Levenberg-Marquardt iterations over all stages of both warm starts and the polish.
  int iterations = 0;
};

/// Solves the task's optimal-control problem from x0 (n) (file comment). Throws
/// diffdyn::Error for bad options or sizes, diffdyn::NumericalError when no warm
/// start gives a finite solution.
MultipleShootingSolution SolveMultipleShooting(const ControlTask& task, const Eigen::VectorXd& x0,
                                               const MultipleShootingOptions& options);

/// What the solves of a MultipleShootingController and its clones had in common: the largest
/// defects and the iterations, over every Reset so far.
struct ShootingTotals {
  int solves = 0;
  double largest_shooting_defect = 0.0, largest_defect = 0.0;
  long iterations = 0;
};

/// Solves from each start in Reset and replays the actions open loop in Command.
class MultipleShootingController final : public Controller {
 public:
  /// Keeps a reference to the task.
  MultipleShootingController(const ControlTask& task, MultipleShootingOptions options);
  void Reset(const Eigen::VectorXd& x0, std::uint64_t seed) override;
  Eigen::VectorXd Command(const Eigen::VectorXd& x) override;
  /// A controller with the same options that adds to the same totals.
  std::unique_ptr<Controller> Clone() const override;
  /// The solution of the last Reset.
  const MultipleShootingSolution& solution() const { return solution_; }
  /// Totals over this controller and its clones (thread-safe).
  ShootingTotals totals() const;

 private:
  struct Shared;
  MultipleShootingController(const ControlTask& task, MultipleShootingOptions options,
                             std::shared_ptr<Shared> shared);
  const ControlTask& task_;
  MultipleShootingOptions options_;
  std::shared_ptr<Shared> shared_;
  MultipleShootingSolution solution_;
  int next_ = 0;
};

}  // namespace diffdyn
