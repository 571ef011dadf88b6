// The linear-quadratic regulator of a control task at its goal.
//
// Linearisation: A = df/dx, B = df/du of the task's plant dx/dt = f(x, u) at the goal
// with u = 0, by Jets (AnalyticModel::Linearize). Quadratic cost, the second-order
// expansion of the task's running cost at the goal:
//
//   Q = diag(w_i s_i),  s_i = pi^2 / 4 for a periodic component (pi^2 sin^2(d/2) ~ pi^2 d^2 / 4), else 1;
//   R = diag(r_j) (quadratic action cost), or beta pi / (4 u_max) (log-cosine:
//       -(2 beta u_max / pi) log cos(pi u / (2 u_max)) ~ beta pi u^2 / (4 u_max)).
//
// Riccati: the stabilising P of the continuous-time algebraic Riccati equation
//
//   A^T P + P A - P B R^-1 B^T P + Q = 0,
//
// from the stable invariant subspace of the Hamiltonian [[A, -B R^-1 B^T], [-Q, -A^T]]
// (eigenvectors), then Newton-Kleinman steps (each a Lyapunov equation solved by its
// Kronecker form) until the relative residual
//
//   |A^T P + P A - P B R^-1 B^T P + Q|_F / (2 |A^T P|_F + |P B R^-1 B^T P|_F + |Q|_F)
//
// stops decreasing; K = R^-1 B^T P. The controller commands u = -K e(x), e the
// deviation from the goal (periodic components wrapped), which the evaluator clips
// to the task's bounds.
//
//   const ControlTask task = ControlTaskByName("pendulum");
//   const LqrSolution lqr = TaskLqr(task);      // lqr.K: 1 x 2, lqr.riccati_residual ~ 1e-16
//   LqrController controller(task, lqr);
//   auto runs = EvaluateController(task, controller, {.starts = 300, .seed = 1});
#pragma once

#include <memory>

#include <Eigen/Core>

#include "diffdyn/physics/control_task.h"
#include "diffdyn/solvers/control.h"

namespace diffdyn {

/// A, B (the linearisation), Q, R (the cost), P (Riccati) and K = R^-1 B^T P.
struct LqrSolution {
  Eigen::MatrixXd A, B, Q, R, P, K;
  /// The relative residual of the header comment.
  double riccati_residual = 0.0;
};

/// The stabilising solution of the Riccati equation for (A, B, Q, R): A n x n, B n x m,
/// Q n x n symmetric positive semi-definite, R m x m symmetric positive definite.
/// Throws diffdyn::Error for bad sizes and diffdyn::NumericalError when (A, B) has no
/// stabilising solution (the Hamiltonian has eigenvalues on the imaginary axis).
LqrSolution SolveLqr(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B, const Eigen::MatrixXd& Q,
                     const Eigen::MatrixXd& R);

/// The LQR of `task` at its goal (header comment).
LqrSolution TaskLqr(const ControlTask& task);

/// u = -K e(x) (header comment).
class LqrController final : public Controller {
 public:
  /// Keeps a reference to the task.
  LqrController(const ControlTask& task, LqrSolution lqr) : task_(task), lqr_(std::move(lqr)) {}
  void Reset(const Eigen::VectorXd&, std::uint64_t) override {}
  Eigen::VectorXd Command(const Eigen::VectorXd& x) override;
  std::unique_ptr<Controller> Clone() const override { return std::make_unique<LqrController>(task_, lqr_); }
  const LqrSolution& solution() const { return lqr_; }

 private:
  const ControlTask& task_;
  LqrSolution lqr_;
};

}  // namespace diffdyn
