#include "diffdyn/solvers/lqr.h"

#include <cmath>
#include <numbers>

#include <Eigen/Dense>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/physics/analytic_model.h"

namespace diffdyn {
namespace {

// The relative Riccati residual of the header comment.
double RiccatiResidual(const Eigen::MatrixXd& A, const Eigen::MatrixXd& S, const Eigen::MatrixXd& Q,
                       const Eigen::MatrixXd& P) {
  const Eigen::MatrixXd atp = A.transpose() * P, psp = P * S * P;
  const double scale = 2.0 * atp.norm() + psp.norm() + Q.norm();
  return (atp + atp.transpose() - psp + Q).norm() / (scale > 0 ? scale : 1.0);
}

// X with F^T X + X F + C = 0 (Kronecker form; n is small).
Eigen::MatrixXd SolveLyapunov(const Eigen::MatrixXd& F, const Eigen::MatrixXd& C) {
  const Eigen::Index n = F.rows();
  const Eigen::MatrixXd I = Eigen::MatrixXd::Identity(n, n);
  Eigen::MatrixXd kron(n * n, n * n);
  // vec(F^T X + X F) = (I kron F^T + F^T kron I) vec(X), column-major vec.
  for (Eigen::Index i = 0; i < n; ++i)
    for (Eigen::Index j = 0; j < n; ++j)
      kron.block(i * n, j * n, n, n) = I(i, j) * F.transpose() + F(j, i) * I;
  const Eigen::VectorXd c = Eigen::Map<const Eigen::VectorXd>(C.data(), n * n);
  const Eigen::VectorXd x = kron.fullPivLu().solve(-c);
  const Eigen::MatrixXd X = Eigen::Map<const Eigen::MatrixXd>(x.data(), n, n);
  return 0.5 * (X + X.transpose());
}

}  // namespace

LqrSolution SolveLqr(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B, const Eigen::MatrixXd& Q,
                     const Eigen::MatrixXd& R) {
  const Eigen::Index n = A.rows(), m = B.cols();
  DIFFDYN_CHECK(A.cols() == n && B.rows() == n && Q.rows() == n && Q.cols() == n && R.rows() == m &&
                    R.cols() == m && n >= 1 && m >= 1,
                "SolveLqr: A must be n x n, B n x m, Q n x n and R m x m");
  Eigen::LLT<Eigen::MatrixXd> r_llt(R);
  DIFFDYN_CHECK(r_llt.info() == Eigen::Success, "SolveLqr: R is not positive definite");
  const Eigen::MatrixXd S = B * r_llt.solve(B.transpose());  // B R^-1 B^T
  // Stable invariant subspace of the Hamiltonian.
  Eigen::MatrixXd H(2 * n, 2 * n);
  H << A, -S, -Q, -A.transpose();
  const Eigen::EigenSolver<Eigen::MatrixXd> eig(H);
  DIFFDYN_CHECK(eig.info() == Eigen::Success, "SolveLqr: the Hamiltonian's eigenvalues did not converge");
  Eigen::MatrixXcd U(2 * n, n);
  Eigen::Index found = 0;
  for (Eigen::Index k = 0; k < 2 * n; ++k) {
    const double re = eig.eigenvalues()[k].real();
    if (!(std::abs(re) > 1e-12 * (1.0 + std::abs(eig.eigenvalues()[k])))) {
      throw NumericalError("SolveLqr: the Hamiltonian has an eigenvalue on the imaginary axis "
                           "(no stabilising solution: (A, B) not stabilisable or (A, Q) not detectable)");
    }
    if (re < 0 && found < n) U.col(found++) = eig.eigenvectors().col(k);
  }
  DIFFDYN_CHECK(found == n, "SolveLqr: ", found, " stable eigenvalues of the Hamiltonian, expected ", n);
  const Eigen::MatrixXcd Pc = U.bottomRows(n) * U.topRows(n).inverse();
  LqrSolution s{A, B, Q, R, 0.5 * (Pc.real() + Pc.real().transpose()), {}, 0.0};
  // Newton-Kleinman refinement while the residual decreases.
  s.riccati_residual = RiccatiResidual(A, S, Q, s.P);
  for (int it = 0; it < 20 && s.riccati_residual > 0; ++it) {
    const Eigen::MatrixXd K = r_llt.solve(B.transpose() * s.P);
    const Eigen::MatrixXd F = A - B * K;
    const Eigen::MatrixXd next = SolveLyapunov(F, Q + K.transpose() * R * K);
    const double residual = RiccatiResidual(A, S, Q, next);
    if (!(residual < s.riccati_residual)) break;
    s.P = next;
    s.riccati_residual = residual;
  }
  s.K = r_llt.solve(B.transpose() * s.P);
  if (!s.P.allFinite() || !s.K.allFinite()) throw NumericalError("SolveLqr: non-finite Riccati solution");
  return s;
}

LqrSolution TaskLqr(const ControlTask& task) {
  const auto model = task.plant.Model();
  const int n = model->dof(), m = task.action_size();
  Eigen::MatrixXd A, B;
  model->Linearize(ParseParams(*model, task.plant.params), TaskActuatedJoints(task), TaskDamping(task), task.goal,
                   Eigen::VectorXd::Zero(m), &A, &B);
  // Second-order expansion of the running cost at the goal.
  Eigen::MatrixXd Q = Eigen::MatrixXd::Zero(2 * n, 2 * n);
  for (int i = 0; i < 2 * n; ++i) {
    const double s = task.periodic[static_cast<std::size_t>(i)] ? std::numbers::pi * std::numbers::pi / 4.0 : 1.0;
    Q(i, i) = task.weights[i] * s;
  }
  Eigen::MatrixXd R = Eigen::MatrixXd::Zero(m, m);
  const ActionCost& g = task.action_cost;
  if (g.kind == ActionCost::Kind::kQuadratic) {
    R.diagonal() = g.r;
  } else {
    R(0, 0) = g.beta * std::numbers::pi / (4.0 * g.u_max);
  }
  return SolveLqr(A, B, Q, R);
}

Eigen::VectorXd LqrController::Command(const Eigen::VectorXd& x) {
  Eigen::VectorXd e(x.size());
  for (Eigen::Index i = 0; i < x.size(); ++i) e[i] = task_.Deviation(static_cast<int>(i), x[i]);
  return -lqr_.K * e;
}

}  // namespace diffdyn
