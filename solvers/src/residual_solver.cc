#include "diffdyn/solvers/residual_solver.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <Eigen/Cholesky>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/solvers/lqr.h"

namespace diffdyn {

LinearQuadraticHjb::LinearQuadraticHjb(Eigen::MatrixXd a, const Eigen::MatrixXd& b, Eigen::MatrixXd q,
                                       const Eigen::MatrixXd& r, double rho)
    : a_(std::move(a)), b_(b), q_(std::move(q)), r_(r), rho_(rho) {
  const Eigen::Index n = a_.rows();
  DIFFDYN_CHECK(a_.cols() == n && b_.rows() == n && q_.rows() == n && q_.cols() == n && r_.rows() == b_.cols() &&
                    r_.cols() == b_.cols(),
                "LinearQuadraticHjb: A must be n x n, B n x m, Q n x n and R m x m");
  DIFFDYN_CHECK(rho > 0 && std::isfinite(rho), "LinearQuadraticHjb: rho must be positive, got ", rho);
  const Eigen::LLT<Eigen::MatrixXd> llt(r_);
  DIFFDYN_CHECK(llt.info() == Eigen::Success, "LinearQuadraticHjb: R must be positive definite");
  s_ = b_ * llt.solve(b_.transpose());
}

void LinearQuadraticHjb::Evaluate(const Eigen::MatrixXd& x, const Eigen::VectorXd& v, const Eigen::MatrixXd& p,
                                  Eigen::VectorXd* f, Eigen::VectorXd* f_v, Eigen::MatrixXd* f_p) const {
  // F = rho V - x^T Q x - p^T A x + p^T S p / 4;  F_V = rho;  F_p = -A x + S p / 2.
  const Eigen::MatrixXd ax = a_ * x, sp = s_ * p;
  *f = rho_ * v - (x.cwiseProduct(q_ * x)).colwise().sum().transpose() -
       (p.cwiseProduct(ax)).colwise().sum().transpose() + 0.25 * (p.cwiseProduct(sp)).colwise().sum().transpose();
  *f_v = Eigen::VectorXd::Constant(x.cols(), rho_);
  *f_p = -ax + 0.5 * sp;
}

Eigen::MatrixXd LinearQuadraticHjb::SolutionMatrix() const {
  // rho P = Q + A^T P + P A - P S P: the Riccati equation of A - rho/2 I.
  const Eigen::Index n = a_.rows();
  return SolveLqr(a_ - 0.5 * rho_ * Eigen::MatrixXd::Identity(n, n), b_, q_, r_).P;
}

Eigen::MatrixXd ValueFeatures::Encode(const Eigen::MatrixXd& x) const {
  Eigen::MatrixXd z(size(static_cast<int>(x.rows())), x.cols());
  Eigen::Index row = 0;
  std::size_t next = 0;
  for (Eigen::Index i = 0; i < x.rows(); ++i) {
    if (next < periodic.size() && periodic[next] == i) {
      z.row(row++) = x.row(i).array().sin().matrix();
      z.row(row++) = x.row(i).array().cos().matrix();
      ++next;
    } else {
      z.row(row++) = x.row(i);
    }
  }
  return z;
}

Eigen::MatrixXd ValueFeatures::PullBack(const Eigen::MatrixXd& x, const Eigen::MatrixXd& dvdz) const {
  Eigen::MatrixXd p(x.rows(), x.cols());
  Eigen::Index row = 0;
  std::size_t next = 0;
  for (Eigen::Index i = 0; i < x.rows(); ++i) {
    if (next < periodic.size() && periodic[next] == i) {
      // d sin / dx = cos, d cos / dx = -sin.
      p.row(i) = dvdz.row(row).cwiseProduct(x.row(i).array().cos().matrix()) -
                 dvdz.row(row + 1).cwiseProduct(x.row(i).array().sin().matrix());
      row += 2;
      ++next;
    } else {
      p.row(i) = dvdz.row(row++);
    }
  }
  return p;
}

Eigen::MatrixXd ValueFeatures::PushForward(const Eigen::MatrixXd& x, const Eigen::MatrixXd& dldp) const {
  Eigen::MatrixXd g(size(static_cast<int>(x.rows())), x.cols());
  Eigen::Index row = 0;
  std::size_t next = 0;
  for (Eigen::Index i = 0; i < x.rows(); ++i) {
    if (next < periodic.size() && periodic[next] == i) {
      g.row(row++) = dldp.row(i).cwiseProduct(x.row(i).array().cos().matrix());
      g.row(row++) = -dldp.row(i).cwiseProduct(x.row(i).array().sin().matrix());
      ++next;
    } else {
      g.row(row++) = dldp.row(i);
    }
  }
  return g;
}

namespace {

// dV/dz (n_z x B) from Forward's stacked 1 x n_z B Jacobian.
Eigen::MatrixXd Unstack(const Eigen::MatrixXd& jac, Eigen::Index nz, Eigen::Index batch) {
  return Eigen::Map<const Eigen::MatrixXd>(jac.data(), nz, batch);
}

void CheckNetwork(const Mlp<double>& net, int n, const ValueFeatures& features, const char* what) {
  DIFFDYN_CHECK(net.num_inputs() == features.size(n) && net.num_outputs() == 1, what, ": the network must map ",
                features.size(n), " features to 1 output, it maps ", net.num_inputs(), " to ", net.num_outputs());
  for (std::size_t k = 0; k < features.periodic.size(); ++k) {
    DIFFDYN_CHECK(features.periodic[k] >= 0 && features.periodic[k] < n &&
                      (k == 0 || features.periodic[k] > features.periodic[k - 1]),
                  what, ": periodic components must be increasing state indices below ", n);
  }
}

}  // namespace

void ValueAndGradient(const Mlp<double>& net, const Eigen::MatrixXd& x, Eigen::VectorXd* v, Eigen::MatrixXd* p,
                      const ValueFeatures& features, int threads) {
  CheckNetwork(net, static_cast<int>(x.rows()), features, "ValueAndGradient");
  MlpWorkspace ws(net.architecture(), static_cast<int>(x.cols()));
  Eigen::MatrixXd y, jac;
  net.Forward(features.Encode(x), &y, &jac, &ws, threads);
  *v = y.row(0).transpose();
  *p = features.PullBack(x, Unstack(jac, net.num_inputs(), x.cols()));
}

double ResidualLoss(const FirstOrderEquation& equation, const Mlp<double>& net, const Eigen::MatrixXd& x,
                    Eigen::VectorXd* grad, MlpWorkspace* ws, const ValueFeatures& features, int threads) {
  const Eigen::Index b = x.cols(), nz = net.num_inputs();
  Eigen::MatrixXd y, jac, f_p;
  Eigen::VectorXd f, f_v;
  net.Forward(features.Encode(x), &y, &jac, ws, threads);
  equation.Evaluate(x, y.row(0).transpose(), features.PullBack(x, Unstack(jac, nz, b)), &f, &f_v, &f_p);
  if (grad) {
    // dL/dV_i = 2 F_i F_V,i / B and dL/dp_i = 2 F_i F_p,i / B, then through the features
    // to dL/dz_i, stacked as in jac.
    const Eigen::VectorXd scale = (2.0 / static_cast<double>(b)) * f;
    const Eigen::MatrixXd gy = scale.cwiseProduct(f_v).transpose();
    const Eigen::MatrixXd gz = features.PushForward(x, f_p * scale.asDiagonal());
    const Eigen::MatrixXd gjac = Eigen::Map<const Eigen::MatrixXd>(gz.data(), 1, nz * b);
    net.Backward(gy, gjac, grad, nullptr, ws, threads);
  }
  return f.squaredNorm() / static_cast<double>(b);
}

TrainResult SolveResidual(const FirstOrderEquation& equation, const Eigen::MatrixXd& states,
                          const TrainOptions& options, Mlp<double>* net, const ValueFeatures& features,
                          const std::function<void(const EpochReport&)>& on_epoch) {
  const int n = equation.state_size();
  CheckNetwork(*net, n, features, "SolveResidual");
  DIFFDYN_CHECK(states.rows() == n && states.cols() >= 2 && states.allFinite(), "SolveResidual: states must be ", n,
                " x N with N >= 2, finite");
  std::vector<int> train, val;
  SplitWindows(static_cast<int>(states.cols()), options.val_fraction, options.seed, &train, &val);
  const int batch = std::min<int>(options.batch_size, static_cast<int>(train.size()));
  MlpWorkspace ws(net->architecture(), batch, options.chunk_size, true);
  MlpWorkspace val_ws(net->architecture(), std::max<int>(1, static_cast<int>(val.size())), options.chunk_size, true);
  const Eigen::MatrixXd val_states = states(Eigen::all, val);
  Eigen::MatrixXd x;
  MinibatchProblem problem;
  problem.n_train = static_cast<int>(train.size());
  problem.n_val = static_cast<int>(val.size());
  problem.batch_loss = [&](std::span<const int> positions, Eigen::VectorXd* grad) {
    x.resize(n, static_cast<Eigen::Index>(positions.size()));  // no-op unless the batch size changes
    for (std::size_t i = 0; i < positions.size(); ++i) {
      x.col(static_cast<Eigen::Index>(i)) = states.col(train[static_cast<std::size_t>(positions[i])]);
    }
    return ResidualLoss(equation, *net, x, grad, &ws, features, options.threads);
  };
  problem.validation_loss = [&] {
    return ResidualLoss(equation, *net, val_states, nullptr, &val_ws, features, options.threads);
  };
  return FitMinibatches(problem, options, &net->mutable_parameters(), on_epoch);
}

}  // namespace diffdyn
