#include "diffdyn/solvers/hjb.h"

#include <cmath>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {

TaskHjb::TaskHjb(const ControlTask& task, double rho)
    : task_(task),
      model_(task.plant.Model()),
      params_(ParseParams(*model_, task.plant.params)),
      damping_(TaskDamping(task)),
      actuated_(TaskActuatedJoints(task)) {
  set_rho(rho);
  DIFFDYN_CHECK(task.action_size() <= kDiagJetSize, "TaskHjb: at most ", kDiagJetSize, " actions, got ",
                task.action_size());
}

void TaskHjb::set_rho(double rho) {
  DIFFDYN_CHECK(rho > 0 && std::isfinite(rho), "hjb: the discount rho must be positive, got ", rho);
  rho_ = rho;
}

void TaskHjb::Affine(const Eigen::VectorXd& x, Eigen::VectorXd* a, Eigen::MatrixXd* b) const {
  // One pass at u = 0 with the m actions seeded: values a(x), derivatives B(x) (exact: f is affine in u).
  const int n = task_.state_size(), m = task_.action_size();
  VectorX<DiagJet> uj = VectorX<DiagJet>::Zero(m);
  for (int j = 0; j < m; ++j) uj[j].v[j] = 1.0;
  const VectorX<DiagJet> dxdt = model_->Dynamics(params_, actuated_, damping_, x.cast<DiagJet>(), uj);
  a->resize(n);
  b->resize(n, m);
  for (int i = 0; i < n; ++i) {
    (*a)[i] = dxdt[i].a;
    for (int j = 0; j < m; ++j) (*b)(i, j) = dxdt[i].v[j];
  }
}

Eigen::VectorXd TaskHjb::Policy(const Eigen::VectorXd& x, const Eigen::VectorXd& p) const {
  Eigen::VectorXd a;
  Eigen::MatrixXd b;
  Affine(x, &a, &b);
  return task_.action_cost.ConjugateGradient(-b.transpose() * p);
}

void TaskHjb::Evaluate(const Eigen::MatrixXd& x, const Eigen::VectorXd& v, const Eigen::MatrixXd& p,
                       Eigen::VectorXd* f, Eigen::VectorXd* f_v, Eigen::MatrixXd* f_p) const {
  const Eigen::Index batch = x.cols();
  f->resize(batch);
  f_p->resize(x.rows(), batch);
  *f_v = Eigen::VectorXd::Constant(batch, rho_);
  Eigen::VectorXd a;
  Eigen::MatrixXd b;
  for (Eigen::Index i = 0; i < batch; ++i) {
    Affine(x.col(i), &a, &b);
    const Eigen::VectorXd w = -b.transpose() * p.col(i);
    const Eigen::VectorXd u = task_.action_cost.ConjugateGradient(w);
    (*f)[i] = rho_ * v[i] - task_.StateCost(x.col(i)) - p.col(i).dot(a) + task_.action_cost.Conjugate(w);
    f_p->col(i) = -(a + b * u);
  }
}

}  // namespace diffdyn
