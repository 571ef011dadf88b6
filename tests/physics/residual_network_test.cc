// The learned residual torque: what its ridge fit recovers, that a constant input
// drops out, its Jet derivatives against central differences, and an extended
// model with a residual saved and loaded as the same model.
#include "diffdyn/physics/residual_network.h"

#include <cmath>
#include <filesystem>

#include <gtest/gtest.h>

#include "diffdyn/physics/effects.h"
#include "diffdyn/physics/model_registry.h"
#include "diffdyn/solvers/extended_model_file.h"

namespace diffdyn {
namespace {

// Samples of a 2-joint system: (q; qd; qdd = 0) and a smooth torque of (q, qd).
struct Samples {
  Eigen::MatrixXd inputs, targets;
};

Samples SmoothTorque(int count, std::uint64_t seed) {
  Rng rng(seed);
  Samples s{Eigen::MatrixXd::Zero(6, count), Eigen::MatrixXd(2, count)};
  for (int k = 0; k < count; ++k) {
    for (int i = 0; i < 4; ++i) s.inputs(i, k) = Uniform(rng, -1.5, 1.5);
    s.targets(0, k) = 0.3 * std::sin(s.inputs(0, k)) + 0.2 * std::tanh(2.0 * s.inputs(2, k));
    s.targets(1, k) = -0.1 * s.inputs(1, k) * s.inputs(3, k);
  }
  return s;
}

TEST(ResidualNetwork, FitRecoversASmoothTorqueOnNewSamples) {
  const Samples train = SmoothTorque(2000, 1), test = SmoothTorque(500, 2);
  Rng rng(3);
  const ResidualNetwork net = ResidualNetwork::Fit(train.inputs, train.targets, 128, 1e-6, rng);
  ASSERT_EQ(net.dof(), 2);
  EXPECT_EQ(net.hidden(), 128);
  double error = 0, energy = 0;
  for (int k = 0; k < test.inputs.cols(); ++k) {
    const Eigen::VectorXd x = test.inputs.col(k);
    const Eigen::VectorXd r = net(Eigen::VectorXd(x.head(2)), Eigen::VectorXd(x.segment(2, 2)),
                                  Eigen::VectorXd(x.tail(2)));
    error += (r - test.targets.col(k)).squaredNorm();
    energy += test.targets.col(k).squaredNorm();
  }
  EXPECT_LT(error / energy, 0.01) << "held-out relative squared error";
}

TEST(ResidualNetwork, ConstantInputDropsOut) {
  const Samples train = SmoothTorque(300, 4);  // qdd = 0 throughout
  Rng rng(5);
  const ResidualNetwork net = ResidualNetwork::Fit(train.inputs, train.targets, 32, 1e-3, rng);
  const Eigen::VectorXd q = Eigen::Vector2d(0.3, -0.2), qd = Eigen::Vector2d(0.5, 1.0);
  const Eigen::VectorXd a = net(q, qd, Eigen::VectorXd(Eigen::Vector2d::Zero()));
  const Eigen::VectorXd b = net(q, qd, Eigen::VectorXd(Eigen::Vector2d(5.0, -7.0)));
  EXPECT_EQ((a - b).cwiseAbs().maxCoeff(), 0.0);
}

TEST(ResidualNetwork, JetDerivativesMatchCentralDifferences) {
  const Samples train = SmoothTorque(400, 6);
  Rng rng(7);
  const ResidualNetwork net = ResidualNetwork::Fit(train.inputs, train.targets, 24, 1e-4, rng);
  using J = ceres::Jet<double, 2>;
  const Eigen::Vector2d q0(0.4, -0.3), qd0(0.2, 0.7);
  VectorX<J> q(2), qd(2), qdd(2);
  for (int j = 0; j < 2; ++j) {
    q[j] = J(q0[j], j);  // derivatives with respect to q1, q2
    qd[j] = J(qd0[j]);
    qdd[j] = J(0.0);
  }
  const VectorX<J> r = net(q, qd, qdd);
  const double h = 1e-6;
  for (int j = 0; j < 2; ++j) {
    Eigen::VectorXd plus = q0, minus = q0;
    plus[j] += h;
    minus[j] -= h;
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(2), v = qd0;
    const Eigen::VectorXd fd = (net(plus, v, zero) - net(minus, v, zero)) / (2 * h);
    for (int i = 0; i < 2; ++i) EXPECT_NEAR(r[i].v[j], fd[i], 1e-7) << "dr" << i << "/dq" << j;
  }
}

TEST(ResidualNetwork, ExtendedModelWithResidualRoundTripsThroughItsFile) {
  const auto arm = MakeAnalyticModel("arm2");
  const Samples train = SmoothTorque(300, 8);
  Rng rng(9);
  auto net = std::make_shared<const ResidualNetwork>(ResidualNetwork::Fit(train.inputs, train.targets, 16, 1e-4, rng));
  const ExtendedModel model(arm, arm->DefaultParams(), {Effect{EffectKind::kViscous, 1, {0.3}, {}}}, net);
  const auto path = std::filesystem::temp_directory_path() / "residual_network_round_trip.json";
  SaveExtendedModel(path, model, {}, {});
  const ExtendedModel loaded = LoadExtendedModel(path);
  ASSERT_NE(loaded.residual(), nullptr);
  EXPECT_EQ(loaded.residual()->net.parameters(), net->net.parameters());
  const Eigen::VectorXd q = Eigen::Vector2d(0.1, 0.9), qd = Eigen::Vector2d(-0.4, 0.3),
                        tau = Eigen::Vector2d(1.0, -0.5);
  EXPECT_EQ(loaded.ForwardDynamics(q, qd, tau), model.ForwardDynamics(q, qd, tau));
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace diffdyn
