// DeLaN: structure (H, c, g from one network), the head's VJP against Jets, the
// training gradient against finite differences, thread invariance.
#include "diffdyn/models/delan.h"

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "diffdyn/autodiff_ode/random.h"

namespace diffdyn {
namespace {

DelanOptions SmallOptions(int dof) {
  return {.dof = dof, .hidden = 12, .depth = 2, .activation = Activation::Softplus()};
}

Eigen::MatrixXd RandomMatrix(int rows, int cols, Rng& rng, double scale = 1.0) {
  Eigen::MatrixXd m(rows, cols);
  for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = scale * (2.0 * UniformUnit(rng) - 1.0);
  return m;
}

// A DeLaN whose output layer is not near zero (the default init makes the heads small).
Delan RandomDelan(int dof, std::uint64_t seed) {
  Delan model = Delan::Initialized(SmallOptions(dof), seed);
  Rng rng(seed + 100);
  model.mutable_parameters() = RandomMatrix(static_cast<int>(model.num_parameters()), 1, rng, 0.5);
  return model;
}

TEST(Delan, MassMatrixIsSymmetricPositiveDefinite) {
  const Delan model = RandomDelan(3, 1);
  Rng rng(2);
  for (int t = 0; t < 10; ++t) {
    const Eigen::VectorXd q = RandomMatrix(3, 1, rng, 2.0);
    const Eigen::MatrixXd h = model.Head<double>(q, q, q).MassMatrix();
    EXPECT_LT((h - h.transpose()).norm(), 1e-14);
    const double min_eig = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(h).eigenvalues()[0];
    EXPECT_GE(min_eig, model.options().epsilon * (1.0 - 1e-12));
  }
}

// c and g from the closed-form Jacobian equal the Euler-Lagrange terms built from
// Jet derivatives of H(q) and V(q): c_k = sum_j (dH/dq)_kj qd - 1/2 qd^T dH/dq_k qd.
TEST(Delan, CoriolisAndGravityMatchJetDerivativesOfMassMatrixAndPotential) {
  constexpr int kN = 3;
  using Jet = ceres::Jet<double, kN>;
  const Delan model = RandomDelan(kN, 3);
  Rng rng(4);
  for (int t = 0; t < 5; ++t) {
    const Eigen::VectorXd q = RandomMatrix(kN, 1, rng, 1.5), qd = RandomMatrix(kN, 1, rng, 2.0);
    Eigen::Matrix<Jet, Eigen::Dynamic, 1> qj(kN), zero(kN);
    for (int i = 0; i < kN; ++i) qj[i] = Jet(q[i], i), zero[i] = Jet(0.0);
    const DelanHead<Jet> hj = model.Head<Jet>(qj, zero, zero);
    const Eigen::Matrix<Jet, Eigen::Dynamic, Eigen::Dynamic> hjm = hj.MassMatrix();
    Eigen::MatrixXd hdot = Eigen::MatrixXd::Zero(kN, kN);
    Eigen::VectorXd half(kN);
    for (int k = 0; k < kN; ++k) {
      Eigen::MatrixXd dh(kN, kN);
      for (int i = 0; i < kN; ++i)
        for (int j = 0; j < kN; ++j) dh(i, j) = hjm(i, j).v[k];
      hdot += qd[k] * dh;
      half[k] = 0.5 * qd.dot(dh * qd);
    }
    const DelanHead<double> h = model.Head<double>(q, qd, Eigen::VectorXd::Zero(kN).eval());
    const Eigen::VectorXd c_ref = hdot * qd - half;
    EXPECT_LT((h.coriolis() - c_ref).norm(), 1e-12 * (1.0 + c_ref.norm()));
    for (int k = 0; k < kN; ++k) EXPECT_NEAR(h.gravity()[k], hj.potential().v[k], 1e-12);
  }
}

// tau(q, 0, 0) = g, tau(q, qd, 0) - g = c, tau(q, 0, qdd) - g = H qdd; forward
// dynamics inverts inverse dynamics; and, with no friction, qd^T tau = dE/dt.
TEST(Delan, DecompositionForwardDynamicsAndPowerAreConsistent) {
  const Delan model = RandomDelan(2, 5);
  Rng rng(6);
  for (int t = 0; t < 10; ++t) {
    const Eigen::VectorXd q = RandomMatrix(2, 1, rng, 2), qd = RandomMatrix(2, 1, rng, 2),
                          qdd = RandomMatrix(2, 1, rng, 3), z = Eigen::VectorXd::Zero(2);
    const Eigen::VectorXd tau = model.InverseDynamics(q, qd, qdd);
    const DelanHead<double> h = model.Head<double>(q, qd, qdd);
    const Eigen::VectorXd g = model.InverseDynamics(q, z, z);
    EXPECT_LT((g - h.gravity()).norm(), 1e-13);
    EXPECT_LT((model.InverseDynamics(q, qd, z) - g - h.coriolis()).norm(), 1e-12);
    EXPECT_LT((model.InverseDynamics(q, z, qdd) - g - h.MassMatrix() * qdd).norm(), 1e-12);
    EXPECT_LT((model.ForwardDynamics(q, qd, tau) - qdd).norm(), 1e-10 * (1 + qdd.norm()));
    EXPECT_NEAR(qd.dot(tau), h.power(), 1e-12 * (1 + std::abs(h.power())));
    EXPECT_NEAR(h.kinetic(), 0.5 * qd.dot(h.MassMatrix() * qd), 1e-12);
  }
}

// The head's VJP (dL/dy, dL/dJ from dL/dtau) against forward-mode Jets seeded on y and J.
TEST(Delan, HeadBackwardMatchesJets) {
  constexpr int kN = 3, kM = 1 + kN * (kN + 1) / 2, kIn = kM * (kN + 1);
  using Jet = ceres::Jet<double, kIn>;
  const DelanOptions options = SmallOptions(kN);
  Rng rng(7);
  const Eigen::VectorXd y = RandomMatrix(kM, 1, rng), qd = RandomMatrix(kN, 1, rng, 2),
                        qdd = RandomMatrix(kN, 1, rng, 2), tbar = RandomMatrix(kN, 1, rng);
  const Eigen::MatrixXd jac = RandomMatrix(kM, kN, rng);
  DelanHead<double> head(options);
  head.Forward(y, jac, qd, qdd);
  Eigen::VectorXd ybar(kM);
  Eigen::MatrixXd jbar(kM, kN);
  head.Backward(tbar, y, jac, ybar, jbar);

  Eigen::Matrix<Jet, Eigen::Dynamic, 1> yj(kM);
  Eigen::Matrix<Jet, Eigen::Dynamic, Eigen::Dynamic> jj(kM, kN);
  for (int i = 0; i < kM; ++i) yj[i] = Jet(y[i], i);
  for (int k = 0; k < kN; ++k)
    for (int i = 0; i < kM; ++i) jj(i, k) = Jet(jac(i, k), kM + k * kM + i);
  DelanHead<Jet> hj(options);
  hj.Forward(yj, jj, qd, qdd);
  Eigen::Matrix<Jet, Eigen::Dynamic, 1> tau(kN);
  hj.Torque(tau);
  Jet loss(0.0);
  for (int k = 0; k < kN; ++k) loss += tbar[k] * tau[k];
  for (int i = 0; i < kM; ++i) EXPECT_NEAR(ybar[i], loss.v[i], 1e-12) << "y " << i;
  for (int k = 0; k < kN; ++k)
    for (int i = 0; i < kM; ++i) EXPECT_NEAR(jbar(i, k), loss.v[kM + k * kM + i], 1e-12) << i << "," << k;
}

struct Batch {
  Eigen::MatrixXd q, qd, qdd, tau;
};

Batch RandomBatch(int n, int b, std::uint64_t seed) {
  Rng rng(seed);
  return {RandomMatrix(n, b, rng, 1.5), RandomMatrix(n, b, rng, 2), RandomMatrix(n, b, rng, 3),
          RandomMatrix(n, b, rng, 2)};
}

// dL/dtheta by batched reverse mode (head VJP + Mlp::Backward through g'') against
// central differences.
TEST(Delan, TorqueLossGradientMatchesFiniteDifferences) {
  Delan model = RandomDelan(2, 8);
  const Batch d = RandomBatch(2, 37, 9);
  DelanWorkspace ws;
  Eigen::VectorXd grad;
  const double loss = model.TorqueLoss(d.q, d.qd, d.qdd, d.tau, &grad, &ws, 1);
  EXPECT_TRUE(std::isfinite(loss));
  ASSERT_EQ(grad.size(), model.num_parameters());
  const double h = 1e-6;
  double max_err = 0.0;
  for (Eigen::Index p = 0; p < model.num_parameters(); p += 7) {
    const double keep = model.parameters()[p];
    model.mutable_parameters()[p] = keep + h;
    const double up = model.TorqueLoss(d.q, d.qd, d.qdd, d.tau, nullptr, &ws, 1);
    model.mutable_parameters()[p] = keep - h;
    const double down = model.TorqueLoss(d.q, d.qd, d.qdd, d.tau, nullptr, &ws, 1);
    model.mutable_parameters()[p] = keep;
    max_err = std::max(max_err, std::abs((up - down) / (2 * h) - grad[p]) / (1.0 + std::abs(grad[p])));
  }
  EXPECT_LT(max_err, 1e-6);
}

TEST(Delan, LossIsTheSameAtAnyThreadCount) {
  const Delan model = RandomDelan(2, 10);
  const Batch d = RandomBatch(2, 300, 11);
  DelanWorkspace one, two;
  one.mlp = MlpWorkspace(model.network().architecture(), 300, 64, true);
  two.mlp = MlpWorkspace(model.network().architecture(), 300, 64, true);
  Eigen::VectorXd g1, g2;
  const double l1 = model.TorqueLoss(d.q, d.qd, d.qdd, d.tau, &g1, &one, 1);
  const double l2 = model.TorqueLoss(d.q, d.qd, d.qdd, d.tau, &g2, &two, 2);
  EXPECT_EQ(l1, l2);
  EXPECT_TRUE(g1 == g2);
}

TEST(Delan, RefusesBadSizes) {
  const Delan model = RandomDelan(2, 12);
  DelanWorkspace ws;
  const Eigen::MatrixXd q(3, 4), t(2, 4);
  EXPECT_THROW(model.TorqueLoss(q, q, q, t, nullptr, &ws), Error);
  EXPECT_THROW(Delan::Initialized({.dof = 0}, 1), Error);
  EXPECT_THROW(Delan::Initialized({.dof = 2, .epsilon = 0.0}, 1), Error);
}

}  // namespace
}  // namespace diffdyn
