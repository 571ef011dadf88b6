// Analytic models and named effects: ID/FD consistency, Jet derivatives
// against finite differences, power balance, Panda reference numbers.
#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>

#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>

#include "diffdyn/models/random.h"
#include "diffdyn/physics/effects.h"
#include "diffdyn/physics/model_registry.h"
#include "diffdyn/physics/panda_dynamics.h"

namespace diffdyn {
namespace {

Eigen::VectorXd RandomVector(int n, double scale, Rng& rng) {
  Eigen::VectorXd v(n);
  for (int i = 0; i < n; ++i) v[i] = Uniform(rng, -scale, scale);
  return v;
}

// The Panda's ready posture as a dynamic vector (element copies avoid a g++ 12
// array-bounds false positive on fixed-size 7-vectors under AVX-512).
Eigen::VectorXd ReadyQ() {
  const Panda::Vector7<double> ready = Panda::Ready();
  Eigen::VectorXd q(7);
  for (int i = 0; i < 7; ++i) q[i] = ready[i];
  return q;
}

VectorX<DiagJet> Constant(const Eigen::VectorXd& v) {
  VectorX<DiagJet> out(v.size());
  for (int i = 0; i < v.size(); ++i) out[i] = DiagJet(v[i]);
  return out;
}

class AllModels : public ::testing::TestWithParam<std::string> {};

TEST_P(AllModels, ForwardDynamicsInvertsInverseDynamics) {
  const auto model = MakeAnalyticModel(GetParam());
  const Eigen::VectorXd p = model->DefaultParams();
  Rng rng(1);
  for (int trial = 0; trial < 5; ++trial) {
    const int n = model->dof();
    Eigen::VectorXd q = RandomVector(n, 1.0, rng);
    if (model->name() == "panda") q += ReadyQ();
    const Eigen::VectorXd qd = RandomVector(n, 1.0, rng), qdd = RandomVector(n, 2.0, rng);
    const Eigen::VectorXd tau = model->InverseDynamics(q, qd, qdd, p);
    const Eigen::VectorXd back = model->ForwardDynamics(q, qd, tau, p);
    EXPECT_LT((back - qdd).norm(), 1e-9 * (1 + qdd.norm())) << GetParam();
    const Eigen::MatrixXd m = model->MassMatrix(q, p);
    EXPECT_GT(Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(m).eigenvalues().minCoeff(), 0.0);
  }
}

// d tau / dq from Jets against central finite differences.
TEST_P(AllModels, JetDerivativeMatchesFiniteDifference) {
  const auto model = MakeAnalyticModel(GetParam());
  const Eigen::VectorXd p = model->DefaultParams();
  const int n = model->dof();
  Rng rng(2);
  Eigen::VectorXd q = RandomVector(n, 1.0, rng);
  const Eigen::VectorXd qd = RandomVector(n, 1.0, rng), qdd = RandomVector(n, 2.0, rng);
  for (int j = 0; j < n; ++j) {
    VectorX<DiagJet> qj = Constant(q);
    qj[j].v[0] = 1.0;
    const VectorX<DiagJet> tau = model->InverseDynamics(qj, Constant(qd), Constant(qdd), Constant(p));
    const double h = 1e-6;
    Eigen::VectorXd qp = q, qm = q;
    qp[j] += h;
    qm[j] -= h;
    const Eigen::VectorXd fd =
        (model->InverseDynamics(qp, qd, qdd, p) - model->InverseDynamics(qm, qd, qdd, p)) / (2 * h);
    for (int i = 0; i < n; ++i) {
      EXPECT_NEAR(tau[i].v[0], fd[i], 1e-6 * (1 + std::abs(fd[i]))) << GetParam() << " " << i;
      EXPECT_NEAR(tau[i].a, model->InverseDynamics(q, qd, qdd, p)[i], 1e-12);
    }
  }
}

// Power balance: d/dt (T + V) = qd . tau, where T = qd' M qd / 2 and V is the
// work against gravity; checked along a rollout by integrating qd . tau.
TEST_P(AllModels, PowerBalanceAlongMotion) {
  const auto model = MakeAnalyticModel(GetParam());
  if (model->name() == "arm2") GTEST_SKIP() << "arm2 base parameters carry no potential";
  const Eigen::VectorXd p = model->DefaultParams();
  const int n = model->dof();
  Rng rng(3);
  Eigen::VectorXd q = RandomVector(n, 0.5, rng);
  if (model->name() == "panda") q += ReadyQ();
  Eigen::VectorXd qd = RandomVector(n, 0.5, rng);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  auto kinetic = [&](const Eigen::VectorXd& qq, const Eigen::VectorXd& vv) {
    return 0.5 * vv.dot(model->MassMatrix(qq, p) * vv);
  };
  // Free motion (tau = 0) conserves T + V; V from the line integral of g(q).
  const double dt = 1e-3;
  double potential = 0.0;
  const double e0 = kinetic(q, qd);
  for (int k = 0; k < 200; ++k) {
    // RK4 on (q, qd) with tau = 0, accumulating dV = g(q) . dq.
    auto f = [&](const Eigen::VectorXd& qq, const Eigen::VectorXd& vv) {
      return model->ForwardDynamics(qq, vv, zero, p);
    };
    const Eigen::VectorXd a1 = f(q, qd);
    const Eigen::VectorXd a2 = f(q + 0.5 * dt * qd, qd + 0.5 * dt * a1);
    const Eigen::VectorXd a3 = f(q + 0.5 * dt * (qd + 0.5 * dt * a1), qd + 0.5 * dt * a2);
    const Eigen::VectorXd a4 = f(q + dt * (qd + 0.5 * dt * a2), qd + dt * a3);
    const Eigen::VectorXd dq = dt * (qd + dt / 6.0 * (a1 + a2 + a3));
    const Eigen::VectorXd mid = q + 0.5 * dq;
    potential += model->InverseDynamics(mid, zero, zero, p).dot(dq);
    q += dq;
    qd += dt / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4);
  }
  EXPECT_NEAR(kinetic(q, qd) + potential, e0, 1e-5 * (1 + e0)) << GetParam();
}

INSTANTIATE_TEST_SUITE_P(Models, AllModels,
                         ::testing::Values("pendulum", "cartpole", "double-pendulum", "arm2",
                                           "panda"),
                         [](const auto& info) {
                           std::string s = info.param;
                           for (char& c : s) c = c == '-' ? '_' : c;
                           return s;
                         });

TEST(Panda, GravityMatchesReferenceNumbers) {
  const auto model = MakeAnalyticModel("panda");
  const Eigen::VectorXd p = model->DefaultParams();
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(7);
  Eigen::VectorXd q_test(7);
  q_test << 0, 0, 0, -std::numbers::pi / 2, 0, std::numbers::pi / 2, std::numbers::pi / 4;
  Eigen::VectorXd g_test(7), g_zero(7), g_ready(7);
  g_test << 0, -25.256618, 0, 18.567248, 0.633630, 1.693106, 0;
  g_zero << 0, -3.433259, 0, -3.256112, 0, 1.693638, 0;
  g_ready << 0, -1.770771, -0.643780, 18.567248, 0.633630, 1.693106, 0;
  EXPECT_LT((model->InverseDynamics(q_test, zero, zero, p) - g_test).cwiseAbs().maxCoeff(), 2e-6);
  EXPECT_LT((model->InverseDynamics(zero, zero, zero, p) - g_zero).cwiseAbs().maxCoeff(), 2e-6);
  const Eigen::VectorXd ready = ReadyQ();
  EXPECT_LT((model->InverseDynamics(ready, zero, zero, p) - g_ready).cwiseAbs().maxCoeff(), 2e-6);
}

TEST(Panda, MassMatrixAndFullInverseDynamicsMatchReference) {
  const auto model = MakeAnalyticModel("panda");
  const Eigen::VectorXd p = model->DefaultParams();
  Eigen::VectorXd q(7), qd(7), qdd(7), tau(7);
  q << 0, 0, 0, -std::numbers::pi / 2, 0, std::numbers::pi / 2, std::numbers::pi / 4;
  qd << 0.5, -0.4, 0.3, -0.2, 0.6, -0.5, 0.7;
  qdd << 1, -1, 0.5, -0.5, 1, -1, 0.5;
  tau << 1.495331, -27.698952, 1.457273, 19.193155, 0.708798, 1.653629, -0.007766;
  EXPECT_LT((model->InverseDynamics(q, qd, qdd, p) - tau).cwiseAbs().maxCoeff(), 2e-6);
  const double upper[7][7] = {
      {1.178108, -0.036057, 1.140771, 0.001574, 0.036181, 0.001664, -0.009169},
      {0, 2.412404, -0.035288, -1.082680, -0.028798, -0.085668, 0.000272},
      {0, 0, 1.140771, 0.001574, 0.036181, 0.001664, -0.009169},
      {0, 0, 0, 0.788736, 0.023467, 0.093175, -0.001302},
      {0, 0, 0, 0, 0.027855, 0.000820, -0.000795},
      {0, 0, 0, 0, 0, 0.032557, -0.001570},
      {0, 0, 0, 0, 0, 0, 0.004910}};
  const Eigen::MatrixXd m = model->MassMatrix(q, p);
  for (int r = 0; r < 7; ++r) {
    for (int c = r; c < 7; ++c) EXPECT_NEAR(m(r, c), upper[r][c], 2e-6) << r << "," << c;
  }
  Eigen::VectorXd friction(7);
  friction << 0.213076, -0.458654, 0.348417, -0.338506, 0.369304, -0.124441, 0.276868;
  EXPECT_LT((PandaSigmoidFriction(qd) - friction).cwiseAbs().maxCoeff(), 2e-6);
}

// The payload tip load at rest equals J_v^T (0, 0, g) from the kinematic Jacobian.
TEST(Panda, TipLoadMatchesJacobianTranspose) {
  const auto model = MakeAnalyticModel("panda");
  const Eigen::VectorXd p = model->DefaultParams();
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(7);
  const Eigen::VectorXd qv = ReadyQ();
  Panda::Vector7<double> q;
  for (int i = 0; i < 7; ++i) q[i] = qv[i];
  const Eigen::Matrix<double, 3, 7> jac = Panda::PositionJacobian(q, 0.0);
  Eigen::VectorXd expected(7);
  for (int i = 0; i < 7; ++i) expected[i] = jac(2, i) * Panda::kGravity;
  EXPECT_LT((model->TipLoad(qv, zero, zero, p) - expected).cwiseAbs().maxCoeff(), 1e-10);
}

// Arm2 defaults reproduce the DeLaN character torques.
TEST(Arm2, ReproducesDelanCharacterTorques) {
  std::ifstream in(std::string(DIFFDYN_SHARED_DATA_DIR) + "/delan_characters/character_data.csv");
  ASSERT_TRUE(in.good());
  std::string line;
  std::getline(in, line);
  const auto model = MakeAnalyticModel("arm2");
  const Eigen::VectorXd p = model->DefaultParams();
  double worst = 0;
  for (int row = 0; row < 200 && std::getline(in, line); ++row) {
    std::stringstream ss(line);
    std::string cell;
    std::vector<double> v;
    std::getline(ss, cell, ',');  // character label
    while (std::getline(ss, cell, ',')) v.push_back(std::stod(cell));
    // t_index, q1, q2, qd1, qd2, qdd1, qdd2, tau1, tau2, ...
    const Eigen::Vector2d q(v[1], v[2]), qd(v[3], v[4]), qdd(v[5], v[6]), tau(v[7], v[8]);
    worst = std::max(worst, (model->InverseDynamics(q, qd, qdd, p) - tau).cwiseAbs().maxCoeff());
  }
  EXPECT_LT(worst, 1e-8);
}

TEST(Params, ParseOverridesAndNamesTheOption) {
  const auto model = MakeAnalyticModel("cartpole");
  const Eigen::VectorXd p = ParseParams(*model, {"m_pole=0.2", "l=0.3"});
  EXPECT_DOUBLE_EQ(p[1], 0.2);
  EXPECT_DOUBLE_EQ(p[2], 0.3);
  EXPECT_DOUBLE_EQ(p[0], 0.57);
  try {
    ParseParams(*model, {"mass=3"});
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("--param mass=3"), std::string::npos);
  }
  EXPECT_THROW(ParseParams(*model, {"l=abc"}), Error);
  EXPECT_THROW(ParseParams(*model, {"l"}), Error);
  const auto panda = MakeAnalyticModel("panda");
  const Eigen::VectorXd pp = ParseParams(*panda, {"tool_com=0.01,0.02,0.1"});
  EXPECT_DOUBLE_EQ(pp[panda->ParamIndex("tool_com_z")], 0.1);
  EXPECT_THROW(MakeAnalyticModel("robot"), Error);
}

// A params file takes every parameter, a vector one as [x, y, z] or by components.
TEST(Params, FileTakesVectorParametersAsArrays) {
  const auto panda = MakeAnalyticModel("panda");
  const std::string path = ::testing::TempDir() + "/panda_params.json";
  {
    std::ofstream out(path);
    out << R"({"tool_mass": 0.5, "tool_com": [0.01, 0.02, 0.1]})";
  }
  const Eigen::VectorXd p = ReadParamsFile(*panda, path);
  EXPECT_DOUBLE_EQ(p[panda->ParamIndex("tool_mass")], 0.5);
  EXPECT_DOUBLE_EQ(p[panda->ParamIndex("tool_com_y")], 0.02);
  {
    std::ofstream out(path);
    out << R"({"tool_com": [0.01, 0.02]})";
  }
  EXPECT_THROW(ReadParamsFile(*panda, path), Error);
}

TEST(Effects, EveryParameterHasAnAdmissibleRange) {
  for (const EffectKindInfo& info : AllEffectKinds()) {
    ASSERT_EQ(info.lower.size(), info.params.size()) << info.name;
    ASSERT_EQ(info.upper.size(), info.params.size()) << info.name;
    for (std::size_t i = 0; i < info.params.size(); ++i) {
      EXPECT_LT(info.lower[i], info.upper[i]) << info.name;
      EXPECT_GE(info.neutral[i], info.lower[i]) << info.name;
      EXPECT_LE(info.neutral[i], info.upper[i]) << info.name;
    }
  }
}

// Every per-joint effect's torque matches its table entry and the extended
// forward dynamics inverts the extended joint torque.
TEST(Effects, ExtendedModelForwardInvertsJointTorque) {
  const auto model = MakeAnalyticModel("double-pendulum");
  std::vector<Effect> effects = {{EffectKind::kViscous, 1, {0.3}, {}},
                                 {EffectKind::kStribeck, 2, {0.2, 0.5, 0.1}, {}},
                                 {EffectKind::kArmature, 2, {0.05}, {}},
                                 {EffectKind::kSpring, 1, {1.5}, {}},
                                 {EffectKind::kOffset, 2, {0.1}, {}},
                                 {EffectKind::kGain, 0, {0.9}, {}},
                                 {EffectKind::kPayload, 0, {0.4}, {}}};
  const ExtendedModel ext(model, model->DefaultParams(), effects);
  const Eigen::Vector2d q(0.3, -0.4), qd(0.7, -0.05), qdd(1.0, 2.0);
  const Eigen::VectorXd tau = ext.JointTorque(q, qd, qdd);
  const Eigen::VectorXd p = model->DefaultParams();
  Eigen::VectorXd expected = model->InverseDynamics(q, qd, qdd, p) +
                             0.4 * model->TipLoad(q, qd, qdd, p);
  expected[0] += 0.3 * qd[0] + 1.5 * q[0];
  expected[1] += (0.2 + 0.3 * std::exp(-std::pow(qd[1] / 0.1, 2))) * std::tanh(qd[1] / 0.01) +
                 0.05 * qdd[1] - 0.1;
  EXPECT_LT((tau - expected).norm(), 1e-12);
  const Eigen::VectorXd back = ext.ForwardDynamics(q, qd, tau / 0.9);
  EXPECT_LT((back - qdd).norm(), 1e-10);
  // Payload on the pendulum equals the mass parameter increase.
  const auto pend = MakeAnalyticModel("pendulum");
  const Eigen::VectorXd pq = Eigen::VectorXd::Constant(1, 0.4), pv = Eigen::VectorXd::Constant(1, 0.1),
                        pa = Eigen::VectorXd::Constant(1, -0.5);
  Eigen::VectorXd heavier = pend->DefaultParams();
  heavier[0] += 0.25;
  const ExtendedModel loaded(pend, pend->DefaultParams(), {{EffectKind::kPayload, 0, {0.25}, {}}});
  EXPECT_NEAR(loaded.JointTorque(pq, pv, pa)[0], pend->InverseDynamics(pq, pv, pa, heavier)[0],
              1e-12);
  EXPECT_THROW(ExtendedModel(model, p, {{EffectKind::kViscous, 3, {0.1}, {}}}), Error);
  EXPECT_THROW(ParseEffectKind("magic"), Error);
}

// d JointTorque / d theta from Jets against finite differences.
TEST(Effects, JetParameterDerivativeMatchesFiniteDifference) {
  const auto model = MakeAnalyticModel("cartpole");
  const ExtendedModel ext(model, model->DefaultParams(),
                          {{EffectKind::kStribeck, 1, {0.2, 0.5, 0.1}, {}},
                           {EffectKind::kPayload, 0, {0.1}, {}}});
  const Eigen::Vector2d q(0.1, 0.2), qd(0.05, -0.3), qdd(0.5, 1.0);
  const Eigen::VectorXd theta = ext.EffectParams();
  VectorX<DiagJet> tj(theta.size());
  for (int i = 0; i < theta.size(); ++i) tj[i] = DiagJet(theta[i], i);
  const VectorX<DiagJet> tau = ext.JointTorque<DiagJet>(Constant(q), Constant(qd), Constant(qdd), tj);
  for (int i = 0; i < theta.size(); ++i) {
    const double h = 1e-6;
    Eigen::VectorXd tp = theta, tm = theta;
    tp[i] += h;
    tm[i] -= h;
    const Eigen::VectorXd fd =
        (ext.JointTorque<double>(q, qd, qdd, tp) - ext.JointTorque<double>(q, qd, qdd, tm)) / (2 * h);
    for (int r = 0; r < 2; ++r) EXPECT_NEAR(tau[r].v[i], fd[r], 1e-6) << i << "," << r;
  }
}

}  // namespace
}  // namespace diffdyn
