// Diagnosis candidates: regressors from the effects, and what the data can identify.
#include "diffdyn/solvers/diagnosis/candidates.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "diffdyn/physics/model_registry.h"
#include "diffdyn/solvers/dataset_io.h"

namespace diffdyn {
namespace {

// A pendulum record at `rate` Hz: holds at fixed angles (static) or a swing.
Dataset Pendulum(bool static_holds, double rate, std::uint64_t seed) {
  const auto model = MakeAnalyticModel("pendulum");
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  const int count = static_cast<int>(40.0 * rate);
  struct {
    Eigen::VectorXd t;
    Eigen::MatrixXd q, qd, tau;
  } d;
  d.t.resize(count);
  d.q.resize(1, count);
  d.qd.resize(1, count);
  d.tau.resize(1, count);
  for (int k = 0; k < count; ++k) {
    const double t = k / rate;
    double q = 0.8 * std::sin(1.3 * t), qd = 0.8 * 1.3 * std::cos(1.3 * t), qdd = -1.69 * q;
    if (static_holds) q = 0.3 * std::floor(t / 4.0) - 1.0, qd = 0, qdd = 0;
    const Eigen::VectorXd tau = model->InverseDynamics(Eigen::VectorXd::Constant(1, q), Eigen::VectorXd::Constant(1, qd),
                                                       Eigen::VectorXd::Constant(1, qdd), model->DefaultParams());
    d.t[k] = t;
    d.q(0, k) = q + 1e-5 * normal(rng);
    d.qd(0, k) = qd + 1e-3 * normal(rng);
    d.tau(0, k) = tau[0] + 0.01 * normal(rng);
  }
  return JointSpaceDataset("pendulum.csv", d.t, d.q, d.qd, d.tau);
}

bool Has(const CandidateLibrary& lib, EffectKind kind) {
  for (const Candidate& c : lib.candidates) {
    if (c.kind == kind) return true;
  }
  return false;
}

bool Reported(const CandidateLibrary& lib, EffectKind kind) {
  for (const NotIdentifiable& u : lib.not_identifiable) {
    if (u.kind == kind) return true;
  }
  return false;
}

TEST(BuildCandidates, StaticHoldsCannotIdentifyVelocityEffects) {
  const auto model = MakeAnalyticModel("pendulum");
  const PreparedData prep = PrepareData(ExtendedModel(model, model->DefaultParams(), {}), Pendulum(true, 20.0, 1), PrepareOptions{});
  const CandidateLibrary lib = BuildCandidates(prep, {}, true);
  EXPECT_TRUE(lib.static_data);
  for (EffectKind kind : {EffectKind::kViscous, EffectKind::kCoulomb, EffectKind::kStribeck, EffectKind::kArmature,
                          EffectKind::kDelay}) {
    EXPECT_FALSE(Has(lib, kind)) << Info(kind).name;
    EXPECT_TRUE(Reported(lib, kind)) << Info(kind).name;
  }
  EXPECT_TRUE(Has(lib, EffectKind::kPayload));
  EXPECT_TRUE(Has(lib, EffectKind::kOffset));
}

TEST(BuildCandidates, ColumnsAreTheEffectsTorquesAndInseparablePairsAreReported) {
  const auto model = MakeAnalyticModel("pendulum");
  const PreparedData prep = PrepareData(ExtendedModel(model, model->DefaultParams(), {}), Pendulum(false, 500.0, 2), PrepareOptions{});
  const CandidateLibrary lib = BuildCandidates(prep, {}, true);
  EXPECT_FALSE(lib.static_data);
  for (const Candidate& c : lib.candidates) {
    if (c.kind == EffectKind::kViscous) {
      for (int r = 0; r < prep.rows; r += 97) EXPECT_DOUBLE_EQ(c.columns[0](0, r), prep.sd.qd(0, prep.Sample(r)));
    }
    if (c.kind == EffectKind::kArmature) {
      for (int r = 0; r < prep.rows; r += 97) EXPECT_DOUBLE_EQ(c.columns[0](0, r), prep.sd.qdd(0, prep.Sample(r)));
    }
  }
  // On a single pendulum a payload's torque is proportional to ID itself (the gain's column).
  EXPECT_TRUE(Reported(lib, EffectKind::kGain));
  // Distinct effects: 6 per-joint kinds on one joint + payload, gain, delay.
  EXPECT_EQ(lib.distinct, 9);
}

TEST(EffectFromCoefficients, MapsCoefficientsToParameters) {
  Candidate gain{EffectKind::kGain, 0, 0.0, {Eigen::MatrixXd()}, "gain"};
  const Effect g = EffectFromCoefficients(gain, Eigen::VectorXd::Constant(1, -0.2), Eigen::MatrixXd::Constant(1, 1, 1e-4));
  EXPECT_DOUBLE_EQ(g.params[0], 1.25);  // beta = 1/k - 1
  EXPECT_NEAR(g.stderrs[0], 0.01 / 0.64, 1e-12);
  Candidate stribeck{EffectKind::kStribeck, 2, 0.06, {Eigen::MatrixXd(), Eigen::MatrixXd()}, "stribeck j2"};
  Eigen::VectorXd beta(2);
  beta << 0.3, 0.5;
  const Effect s = EffectFromCoefficients(stribeck, beta, Eigen::MatrixXd::Identity(2, 2) * 4e-4);
  EXPECT_EQ(s.params, (std::vector<double>{0.3, 0.5, 0.06}));
  EXPECT_DOUBLE_EQ(s.stderrs[1], 0.02);
  EXPECT_EQ(EffectLabel(s), "stribeck j2");
}

}  // namespace
}  // namespace diffdyn
