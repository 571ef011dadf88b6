// The Hamilton-Jacobi-Bellman equation of a control task, as a first-order equation for
// residual minimisation (residual_solver.h).
//
// A task's plant is control-affine, dx/dt = a(x) + B(x) u (the manipulator equation:
// a = (qd, M^-1 (-ID(q, qd, 0) - D qd)), B = (0; M^-1 S), S the actuated joints), and
// its running cost is q(x) + g(u) with g strictly convex (control_task.h). With discount
// rho the value function V solves
//
//   rho V = min_u [q + g(u) + p^T (a + B u)],   p = dV/dx,
//
// whose minimiser is closed form through the convex conjugate g~ (ActionCost::Conjugate):
//
//   u*(x, p) = grad g~(-B^T p),
//   F(x, V, p) = rho V - q(x) - p^T a(x) + g~(-B(x)^T p) = 0,
//   F_V = rho,   F_p = -(a(x) + B(x) u*).
//
// For the log-cosine cost u* = (2 u_max / pi) atan(-B^T p / beta) stays within the
// bounds by construction (lutter_facts.md (d)). a(x) and B(x) come from one Jet pass of
// AnalyticModel::Dynamics at u = 0 with the actions seeded.
//
//   const ControlTask task = ControlTaskByName("pendulum");
//   TaskHjb hjb(task, /*rho=*/1.0);
//   TrainResult r = SolveResidual(hjb, states, options, &net);     // residual_solver.h
//   Eigen::VectorXd u = hjb.Policy(x, p);                          // the feedback action
#pragma once

#include <memory>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/physics/analytic_model.h"
#include "diffdyn/physics/control_task.h"
#include "diffdyn/solvers/residual_solver.h"

namespace diffdyn {

/// The discounted HJB of a control task (file comment). Keeps a reference to the task.
class TaskHjb final : public FirstOrderEquation {
 public:
  /// Throws diffdyn::Error unless rho > 0 is finite, or when the task's plant has an
  /// effect other than viscous friction.
  TaskHjb(const ControlTask& task, double rho);
  int state_size() const override { return task_.state_size(); }
  void Evaluate(const Eigen::MatrixXd& x, const Eigen::VectorXd& v, const Eigen::MatrixXd& p, Eigen::VectorXd* f,
                Eigen::VectorXd* f_v, Eigen::MatrixXd* f_p) const override;

  /// The discount rho (1/s).
  double rho() const { return rho_; }
  /// Changes the discount (the homotopy's stages); throws diffdyn::Error unless rho > 0.
  void set_rho(double rho);
  /// a(x) (n) and B(x) (n x m) of the plant at one state x (n).
  void Affine(const Eigen::VectorXd& x, Eigen::VectorXd* a, Eigen::MatrixXd* b) const;
  /// u*(x, p) = grad g~(-B(x)^T p) (m) at one state x and value gradient p (n each).
  Eigen::VectorXd Policy(const Eigen::VectorXd& x, const Eigen::VectorXd& p) const;

 private:
  const ControlTask& task_;
  std::shared_ptr<const AnalyticModel> model_;
  Eigen::VectorXd params_, damping_;
  std::vector<int> actuated_;
  double rho_ = 1.0;
};

}  // namespace diffdyn
