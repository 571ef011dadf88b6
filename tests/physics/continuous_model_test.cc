// Analytic models as transition models through the continuous-time adapter
// (models/continuous_model.h): batched = templated paths; the Jets' Jacobian of the
// discrete map = central differences = the forward sensitivities of sensitivity.h
// = I + dt A with the pendulum's closed-form A for one Euler step; errors.
#include "diffdyn/models/continuous_model.h"

#include <cmath>
#include <memory>

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "diffdyn/autodiff_ode/sensitivity.h"
#include "diffdyn/models/random.h"
#include "diffdyn/physics/analytic_model.h"
#include "diffdyn/physics/simple_models.h"

namespace diffdyn {
namespace {

template <typename Model>
ContinuousTransitionModel<AnalyticDynamics<Model>> Adapted(ContinuousOptions options) {
  const AnalyticModelAdapter<Model> runtime;
  return ContinuousTransitionModel<AnalyticDynamics<Model>>(
      AnalyticDynamics<Model>{}, AnalyticSystem(runtime), runtime.DefaultParams(), options, Model::kName);
}

// Jacobian [dF/dx, dF/du] (n x (n + m)) of one transition through the generic
// interface (TransitionModel::Jacobian, Jets), its value checked against PredictBatch.
Eigen::MatrixXd JetJacobian(const TransitionModel& model, const Eigen::VectorXd& x, const Eigen::VectorXd& u) {
  EXPECT_TRUE(model.differentiable());
  Eigen::MatrixXd jac, next(model.state_size(), 1);
  const Eigen::VectorXd value = model.Jacobian(x, u, &jac);
  auto ws = model.MakeWorkspace(1);
  model.PredictBatch(x, u, next, *ws);
  EXPECT_LT((value - next.col(0)).cwiseAbs().maxCoeff(), 1e-12);
  return jac;
}

TEST(ContinuousModel, BatchedAndTemplatedPathsAgreeForTheCartPole) {
  const auto model = Adapted<CartPoleModel>({.method = Method::kRk4, .dt = 0.02, .substeps = 3});
  EXPECT_EQ(model.state_size(), 4);
  EXPECT_EQ(model.action_size(), 2);
  EXPECT_EQ(model.system().angles, std::vector<int>{1});  // the cart is prismatic
  Rng rng(2);
  const int b = 6;
  Eigen::MatrixXd x(4, b), u(2, b), next(4, b);
  for (Eigen::Index i = 0; i < x.size(); ++i) x.data()[i] = StandardNormal(rng);
  for (Eigen::Index i = 0; i < u.size(); ++i) u.data()[i] = StandardNormal(rng);
  auto ws = model.MakeWorkspace(b);
  model.PredictBatch(x, u, next, *ws);
  for (int j = 0; j < b; ++j) {
    const Eigen::VectorXd one = model.Predict(x.col(j), u.col(j));
    EXPECT_LT((next.col(j) - one).cwiseAbs().maxCoeff(), 1e-12) << "sample " << j;
  }
  // The state moved, and by about dt * dx/dt.
  Eigen::VectorXd dxdt;
  AnalyticDynamics<CartPoleModel>{}(Eigen::VectorXd(x.col(0)), Eigen::VectorXd(u.col(0)),
                                    model.theta(), 0.0, dxdt);
  EXPECT_LT((next.col(0) - x.col(0) - 0.02 * dxdt).norm(), 0.02 * dxdt.norm());
}

TEST(ContinuousModel, JacobianMatchesDifferencesSensitivitiesAndTheClosedForm) {
  const auto model = Adapted<DoublePendulumModel>({.method = Method::kRk4Classic, .dt = 0.05, .substeps = 2});
  const Eigen::Vector4d x(0.4, -0.7, 1.1, 0.3);
  const Eigen::Vector2d u(0.5, -0.2);
  const Eigen::MatrixXd jac = JetJacobian(model, x, u);
  // Central differences of the batched double path.
  auto ws = model.MakeWorkspace(1);
  const double eps = 1e-6;
  for (int k = 0; k < 6; ++k) {
    Eigen::VectorXd xp = x, xm = x, up = u, um = u;
    (k < 4 ? xp[k] : up[k - 4]) += eps;
    (k < 4 ? xm[k] : um[k - 4]) -= eps;
    Eigen::MatrixXd fp(4, 1), fm(4, 1);
    model.PredictBatch(xp, up, fp, *ws);
    model.PredictBatch(xm, um, fm, *ws);
    const Eigen::VectorXd fd = (fp - fm) / (2 * eps);
    EXPECT_LT((jac.col(k) - fd).cwiseAbs().maxCoeff(), 1e-7) << "direction " << k;
  }
  // The forward sensitivities of the same discrete map (sensitivity.h).
  OdeOptions o;
  o.method = Method::kRk4Classic;
  o.dt = 0.025;
  const Sensitivities s = ForwardSensitivities<6 + 5>(AnalyticDynamics<DoublePendulumModel>{}, x, u,
                                                      model.theta(), 0.0, 0.05, o);
  EXPECT_LT((jac.leftCols(4) - s.dx_dx0).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((jac.rightCols(2) - s.dx_du).cwiseAbs().maxCoeff(), 1e-12);

  // One Euler step of the pendulum: F = x + dt f, so dF/dx = I + dt A with the
  // closed form A = [[0, 1], [-(g / l) cos q, 0]] and dF/du = dt [0, 1 / (m l^2)].
  const double dt = 0.01;
  const auto pendulum = Adapted<PendulumModel>({.method = Method::kEuler, .dt = dt, .substeps = 1});
  const double m = pendulum.theta()[0], l = pendulum.theta()[1], g = pendulum.theta()[2];
  const Eigen::Vector2d xp(0.9, -0.4);
  const Eigen::VectorXd up = Eigen::VectorXd::Constant(1, 0.3);
  const Eigen::MatrixXd jp = JetJacobian(pendulum, xp, up);
  Eigen::MatrixXd expected(2, 3);
  expected << 1.0, dt, 0.0, -dt * g / l * std::cos(xp[0]), 1.0, dt / (m * l * l);
  EXPECT_LT((jp - expected).cwiseAbs().maxCoeff(), 1e-13) << jp;
}

TEST(ContinuousModel, RefusesAdaptiveSolversBadStepsAndWrongSizes) {
  EXPECT_THROW(Adapted<PendulumModel>({.method = Method::kDopri5, .dt = 0.01}), Error);
  EXPECT_THROW(Adapted<PendulumModel>({.dt = 0.0}), Error);
  EXPECT_THROW(Adapted<PendulumModel>({.dt = 0.01, .substeps = 0}), Error);
  const auto model = Adapted<PendulumModel>({.dt = 0.01});
  auto ws = model.MakeWorkspace(2);
  Eigen::MatrixXd next(2, 2);
  EXPECT_THROW(model.PredictBatch(Eigen::MatrixXd::Zero(3, 2), Eigen::MatrixXd::Zero(1, 2), next, *ws),
               Error);
  EXPECT_THROW(model.Predict(Eigen::Vector3d::Zero(), Eigen::VectorXd::Zero(1)), Error);
}

}  // namespace
}  // namespace diffdyn
