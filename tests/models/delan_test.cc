// DeLaN: structure (H, c, g from one network), the head's VJP against Jets, the
// training gradient against finite differences, thread invariance; periodic joints
// and the friction head (kind delan-friction).
#include "diffdyn/models/delan.h"

#include <filesystem>
#include <limits>
#include <numbers>

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "diffdyn/models/random.h"

namespace diffdyn {
namespace {

DelanOptions SmallOptions(int dof, std::vector<int> periodic = {}, bool friction = false) {
  return {.dof = dof, .hidden = 12, .depth = 2, .activation = Activation::Softplus(), .periodic = periodic,
          .friction = friction};
}

Eigen::MatrixXd RandomMatrix(int rows, int cols, Rng& rng, double scale = 1.0) {
  Eigen::MatrixXd m(rows, cols);
  for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = scale * (2.0 * UniformUnit(rng) - 1.0);
  return m;
}

// A DeLaN whose output layer is not near zero (the default init makes the heads small).
Delan RandomDelan(const DelanOptions& options, std::uint64_t seed) {
  Delan model = Delan::Initialized(options, seed);
  Rng rng(seed + 100);
  model.SetParameters(RandomMatrix(static_cast<int>(model.num_parameters()), 1, rng, 0.5));
  return model;
}
Delan RandomDelan(int dof, std::uint64_t seed) { return RandomDelan(SmallOptions(dof), seed); }

// The variants every structural test runs on: plain; joint 2 periodic; joint 1
// periodic with the friction head.
std::vector<DelanOptions> Variants(int dof) {
  return {SmallOptions(dof), SmallOptions(dof, {1}), SmallOptions(dof, {0}, true)};
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
  for (const DelanOptions& options : Variants(kN)) {
  const Delan model = RandomDelan(options, 3);
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
}

// tau(q, 0, 0) = g, tau(q, qd, 0) - g = c, tau(q, 0, qdd) - g = H qdd; forward
// dynamics inverts inverse dynamics; and qd^T tau = dE/dt + qd^T f.
TEST(Delan, DecompositionForwardDynamicsAndPowerAreConsistent) {
  for (const DelanOptions& options : Variants(2)) {
  const Delan model = RandomDelan(options, 5);
  Rng rng(6);
  for (int t = 0; t < 10; ++t) {
    const Eigen::VectorXd q = RandomMatrix(2, 1, rng, 2), qd = RandomMatrix(2, 1, rng, 2),
                          qdd = RandomMatrix(2, 1, rng, 3), z = Eigen::VectorXd::Zero(2);
    const Eigen::VectorXd tau = model.InverseDynamics(q, qd, qdd);
    const DelanHead<double> h = model.Head<double>(q, qd, qdd);
    const Eigen::VectorXd g = model.InverseDynamics(q, z, z), f = model.Friction(qd);
    EXPECT_LT((g - h.gravity()).norm(), 1e-13);
    EXPECT_LT((model.InverseDynamics(q, qd, z) - g - h.coriolis() - f).norm(), 1e-12);
    EXPECT_LT((model.InverseDynamics(q, z, qdd) - g - h.MassMatrix() * qdd).norm(), 1e-12);
    EXPECT_LT((model.ForwardDynamics(q, qd, tau) - qdd).norm(), 1e-10 * (1 + qdd.norm()));
    EXPECT_NEAR(qd.dot(tau), h.power() + qd.dot(f), 1e-12 * (1 + std::abs(h.power())));
    EXPECT_NEAR(h.kinetic(), 0.5 * qd.dot(h.MassMatrix() * qd), 1e-12);
    // The batched decomposition agrees with the single-sample one.
    DelanWorkspace ws;
    const DelanParts p = model.Decompose(q, qd, qdd, &ws, 1);
    EXPECT_LT((p.torque.col(0) - tau).norm(), 1e-12 * (1 + tau.norm()));
    EXPECT_LT((p.friction.col(0) - f).norm(), 1e-15);
  }
  }
}

// f = viscous qd + coulomb tanh(qd / v_c) with coefficients softplus(w) >= 0; none without the head.
TEST(Delan, FrictionHeadIsNonNegativeViscousPlusCoulomb) {
  const Delan model = RandomDelan(SmallOptions(2, {}, true), 13);
  const Eigen::VectorXd v = model.viscous(), c = model.coulomb();
  EXPECT_TRUE((v.array() > 0).all() && (c.array() > 0).all());
  Eigen::VectorXd qd(2);
  qd << 0.7, -0.003;
  for (int j = 0; j < 2; ++j) {
    EXPECT_NEAR(model.Friction<double>(qd)[j], v[j] * qd[j] + c[j] * std::tanh(qd[j] / 0.01), 1e-15);
  }
  EXPECT_EQ(RandomDelan(2, 13).Friction<double>(qd).norm(), 0.0);
  EXPECT_EQ(RandomDelan(SmallOptions(2, {}, true), 13).num_parameters(), RandomDelan(2, 13).num_parameters() + 4);
}

// A periodic joint: tau and the energies repeat after 2 pi; a plain one does not.
TEST(Delan, PeriodicJointRepeatsAfterTwoPi) {
  const Delan model = RandomDelan(SmallOptions(2, {1}), 14);
  Rng rng(15);
  const Eigen::VectorXd q = RandomMatrix(2, 1, rng, 2), qd = RandomMatrix(2, 1, rng, 2),
                        qdd = RandomMatrix(2, 1, rng, 2);
  Eigen::VectorXd turn2(2), turn1(2);
  turn2 << 0.0, 2 * std::numbers::pi;
  turn1 << 2 * std::numbers::pi, 0.0;
  const Eigen::VectorXd tau = model.InverseDynamics(q, qd, qdd);
  EXPECT_LT((model.InverseDynamics<double>(q + turn2, qd, qdd) - tau).norm(), 1e-11 * (1 + tau.norm()));
  EXPECT_NEAR(model.Head<double>(q + turn2, qd, qdd).potential(), model.Head<double>(q, qd, qdd).potential(), 1e-12);
  EXPECT_GT((model.InverseDynamics<double>(q + turn1, qd, qdd) - tau).norm(), 1e-6);
}

// A delan-friction file with a periodic joint loads back to the same model; a file
// whose architecture lies about its input size is refused.
TEST(Delan, FrictionModelFileRoundTrips) {
  const Delan model = RandomDelan(SmallOptions(2, {1}, true), 16);
  const auto path = std::filesystem::temp_directory_path() / "diffdyn_delan_friction_test.json";
  SaveDelan(path, model);
  ModelFile file;
  const Delan back = LoadDelan(path, &file);
  EXPECT_EQ(file.kind, "delan-friction");
  EXPECT_TRUE(back.parameters() == model.parameters());
  EXPECT_EQ(back.options().periodic, std::vector<int>{1});
  Eigen::VectorXd q(2), qd(2);
  q << 0.3, -1.0;
  qd << -1.0, 2.0;
  EXPECT_TRUE(back.InverseDynamics(q, qd, qd) == model.InverseDynamics(q, qd, qd));
  EXPECT_EQ(back.precision(), Precision::kF64);
  Delan single = model;
  single.SetPrecision(Precision::kF32);
  SaveDelan(path, single);
  EXPECT_EQ(LoadDelan(path).precision(), Precision::kF32);
  nlohmann::json arch = DelanArchitectureToJson(model.options());
  arch["periodic"] = nlohmann::json::array();
  EXPECT_THROW(DelanArchitectureFromJson(arch, true), Error);  // mlp has 3 inputs, not 2
  arch["periodic"] = {5};
  EXPECT_THROW(DelanArchitectureFromJson(arch, true), Error);
  arch = DelanArchitectureToJson(model.options());
  arch.erase("coulomb_velocity");
  EXPECT_THROW(DelanArchitectureFromJson(arch, true), Error);
  std::filesystem::remove(path);
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
  for (const DelanOptions& options : Variants(2)) {
  Delan model = RandomDelan(options, 8);
  const Batch d = RandomBatch(2, 37, 9);
  DelanWorkspace ws;
  Eigen::VectorXd grad, w;  // the friction variant weighs the joints
  if (options.friction) {
    w.resize(2);
    w << 2.0, 0.5;
  }
  const double loss = model.TorqueLoss(d.q, d.qd, d.qdd, d.tau, &grad, &ws, 1, w);
  EXPECT_TRUE(std::isfinite(loss));
  ASSERT_EQ(grad.size(), model.num_parameters());
  const double h = 1e-6;
  double max_err = 0.0;
  const Eigen::VectorXd theta = model.parameters();
  std::vector<Eigen::Index> checked;
  for (Eigen::Index p = 0; p < model.num_parameters(); p += 7) checked.push_back(p);
  for (int k = 0; k < options.num_friction_parameters(); ++k) checked.push_back(model.num_parameters() - 1 - k);
  for (const Eigen::Index p : checked) {
    Eigen::VectorXd moved = theta;
    moved[p] = theta[p] + h;
    model.SetParameters(moved);
    const double up = model.TorqueLoss(d.q, d.qd, d.qdd, d.tau, nullptr, &ws, 1, w);
    moved[p] = theta[p] - h;
    model.SetParameters(moved);
    const double down = model.TorqueLoss(d.q, d.qd, d.qdd, d.tau, nullptr, &ws, 1, w);
    max_err = std::max(max_err, std::abs((up - down) / (2 * h) - grad[p]) / (1.0 + std::abs(grad[p])));
  }
  model.SetParameters(theta);
  if (w.size() > 0) {  // the weighted loss itself
    double manual = 0.0;
    for (int b = 0; b < 37; ++b) {
      const Eigen::VectorXd e = model.InverseDynamics<double>(d.q.col(b), d.qd.col(b), d.qdd.col(b)) - d.tau.col(b);
      manual += e.dot(w.cwiseProduct(e)) / 37.0;
    }
    EXPECT_NEAR(loss, manual, 1e-12 * manual);
  }
  EXPECT_LT(max_err, 1e-6) << "periodic " << options.periodic.size() << " friction " << options.friction;
  }
}

TEST(Delan, LossIsTheSameAtAnyThreadCountInEachPrecision) {
  Delan model = RandomDelan(SmallOptions(2, {1}, true), 10);
  const Batch d = RandomBatch(2, 300, 11);
  for (const Precision precision : {Precision::kF64, Precision::kF32}) {
    model.SetPrecision(precision);
    DelanWorkspace one(model.network().architecture(), 300, 64, precision);
    DelanWorkspace two(model.network().architecture(), 300, 64, precision);
    Eigen::VectorXd g1, g2;
    const double l1 = model.TorqueLoss(d.q, d.qd, d.qdd, d.tau, &g1, &one, 1);
    const double l2 = model.TorqueLoss(d.q, d.qd, d.qdd, d.tau, &g2, &two, 2);
    EXPECT_EQ(l1, l2) << PrecisionName(precision);
    EXPECT_TRUE(g1 == g2) << PrecisionName(precision);
    const DelanParts p1 = model.Decompose(d.q, d.qd, d.qdd, &one, 1);
    const DelanParts p2 = model.Decompose(d.q, d.qd, d.qdd, &two, 2);
    EXPECT_TRUE(p1.torque == p2.torque && p1.power == p2.power) << PrecisionName(precision);
  }
}

// The float32 batched paths follow float64 on the same parameters: loss,
// gradient and parts agree to a tolerance set by float's epsilon (not bits).
TEST(Delan, Float32FollowsFloat64) {
  for (const DelanOptions& options : Variants(2)) {
    Delan model = RandomDelan(options, 13);
    const Batch d = RandomBatch(2, 200, 14);
    DelanWorkspace ws;
    Eigen::VectorXd g64, g32;
    const double l64 = model.TorqueLoss(d.q, d.qd, d.qdd, d.tau, &g64, &ws, 2);
    const DelanParts p64 = model.Decompose(d.q, d.qd, d.qdd, &ws, 2);
    model.SetPrecision(Precision::kF32);
    EXPECT_EQ(model.precision(), Precision::kF32);
    const double l32 = model.TorqueLoss(d.q, d.qd, d.qdd, d.tau, &g32, &ws, 2);
    const DelanParts p32 = model.Decompose(d.q, d.qd, d.qdd, &ws, 2);
    const double eps = std::numeric_limits<float>::epsilon();
    EXPECT_NE(l32, l64);  // really computed in float
    EXPECT_NEAR(l32, l64, 200 * eps * l64);
    EXPECT_LT((g32 - g64).norm(), 500 * eps * g64.norm());
    EXPECT_LT((p32.torque - p64.torque).norm(), 200 * eps * p64.torque.norm());
    EXPECT_LT((p32.min_mass_eigenvalue - p64.min_mass_eigenvalue).norm(),
              200 * eps * p64.min_mass_eigenvalue.norm());
    // A parameter change reaches the float network.
    Eigen::VectorXd theta = model.parameters();
    theta *= 1.01;
    model.SetParameters(theta);
    const double moved = model.TorqueLoss(d.q, d.qd, d.qdd, d.tau, nullptr, &ws, 2);
    model.SetPrecision(Precision::kF64);
    EXPECT_NEAR(moved, model.TorqueLoss(d.q, d.qd, d.qdd, d.tau, nullptr, &ws, 2), 200 * eps * moved);
  }
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
