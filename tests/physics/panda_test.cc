// The Panda description against the reference numbers of panda_parameters.md:
// forward kinematics, frames at q = 0, gravity torques and the mass matrix (which
// check the masses, COMs and inertias), and Jet Jacobians against finite differences.
#include "diffdyn/physics/panda.h"

#include <numbers>

#include <Eigen/LU>
#include <gtest/gtest.h>

namespace diffdyn {
namespace {

using Vec7 = Panda::Vector7<double>;
constexpr double kPi = std::numbers::pi;

Vec7 QTest() {
  Vec7 q;
  q << 0, 0, 0, -kPi / 2, 0, kPi / 2, kPi / 4;
  return q;
}

// A fixed, non-special configuration inside the limits.
Vec7 QGeneric() {
  Vec7 q;
  q << 0.3, -0.5, 0.4, -2.0, -0.6, 1.7, 0.2;
  return q;
}

// Gravity torques g(q) = sum_i m_i g0 d z_ci / dq from Jets of the COM positions.
Vec7 GravityTorques(const Vec7& q) {
  const auto coms = Panda::ComPositions<Panda::Jet7>(Panda::SeedJets(q));
  Vec7 g = Vec7::Zero();
  for (int i = 0; i < 7; ++i) g += Panda::kMass[i] * Panda::kGravity * coms(2, i).v;
  return g;
}

// M(q) = sum_i m_i Jv_i^T Jv_i + Jw_i^T R_i I_i R_i^T Jw_i, Jacobians from Jets.
Eigen::Matrix<double, 7, 7> MassMatrix(const Vec7& q) {
  const auto qj = Panda::SeedJets(q);
  const auto frames = Panda::Frames<Panda::Jet7>(qj);
  const auto coms = Panda::ComPositions<Panda::Jet7>(qj);
  Eigen::Matrix<double, 7, 7> m = Eigen::Matrix<double, 7, 7>::Zero();
  for (int i = 0; i < 7; ++i) {
    Eigen::Matrix<double, 3, 7> jv, jw;
    Eigen::Matrix3d rot;
    for (int r = 0; r < 3; ++r) {
      jv.row(r) = coms(r, i).v.transpose();
      for (int c = 0; c < 3; ++c) rot(r, c) = frames[i].R(r, c).a;
    }
    for (int j = 0; j < 7; ++j) {
      Eigen::Matrix3d d_rot;
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) d_rot(r, c) = frames[i].R(r, c).v[j];
      }
      const Eigen::Matrix3d skew = d_rot * rot.transpose();
      jw.col(j) << skew(2, 1), skew(0, 2), skew(1, 0);
    }
    const Eigen::Matrix3d inertia = rot * Panda::InertiaMatrix(i) * rot.transpose();
    m += Panda::kMass[i] * jv.transpose() * jv + jw.transpose() * inertia * jw;
  }
  return m;
}

TEST(Panda, FlangeMatchesReferenceAtZero) {
  const auto f = Panda::Flange<double>(Vec7::Zero());
  EXPECT_NEAR(f.p.x(), 0.088, 1e-12);
  EXPECT_NEAR(f.p.y(), 0.0, 1e-12);
  EXPECT_NEAR(f.p.z(), 0.926, 1e-12);
  EXPECT_TRUE(f.R.isApprox(Eigen::Vector3d(1, -1, -1).asDiagonal().toDenseMatrix(), 1e-12));
}

TEST(Panda, FlangeMatchesReferenceAtReadyAndTest) {
  Eigen::Matrix3d r_ref;
  r_ref << 0.70710678, -0.70710678, 0, -0.70710678, -0.70710678, 0, 0, 0, -1;
  const auto ready = Panda::Flange<double>(Panda::Ready());
  EXPECT_NEAR((ready.p - Eigen::Vector3d(0.3069, 0, 0.5903)).norm(), 0.0, 1e-4);
  EXPECT_NEAR((ready.R - r_ref).cwiseAbs().maxCoeff(), 0.0, 1e-6);
  const auto test = Panda::Flange<double>(QTest());
  EXPECT_NEAR((test.p - Eigen::Vector3d(0.5545, 0, 0.6245)).norm(), 0.0, 1e-4);
  EXPECT_NEAR((test.R - r_ref).cwiseAbs().maxCoeff(), 0.0, 1e-6);
}

TEST(Panda, FramesAndComsAtZeroMatchReferenceTable) {
  const auto frames = Panda::Frames<double>(Vec7::Zero());
  const double origins[7][3] = {{0, 0, 0.333},      {0, 0, 0.333},     {0, 0, 0.649},
                                {0.0825, 0, 0.649}, {0, 0, 1.033},     {0, 0, 1.033},
                                {0.088, 0, 1.033}};
  // Joint axes z_i at q = 0: +z, +y, +z, -y, +z, -y, -z.
  const double axes[7][3] = {{0, 0, 1}, {0, 1, 0},  {0, 0, 1}, {0, -1, 0},
                             {0, 0, 1}, {0, -1, 0}, {0, 0, -1}};
  const double coms[7][3] = {{0.0039, 0.0021, 0.333},   {-0.0031, 0.0035, 0.3617},
                             {0.0275, 0.0393, 0.5825},  {0.0293, -0.0274, 0.7534},
                             {-0.0120, 0.0411, 0.9946}, {0.0602, 0.0105, 1.0189},
                             {0.0985, 0.0043, 0.9714}};
  const auto com_pos = Panda::ComPositions<double>(Vec7::Zero());
  for (int i = 0; i < 7; ++i) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(frames[i].p[k], origins[i][k], 1e-12) << "frame " << i + 1;
      EXPECT_NEAR(frames[i].R(k, 2), axes[i][k], 1e-12) << "axis " << i + 1;
      EXPECT_NEAR(com_pos(k, i), coms[i][k], 1e-4) << "com " << i + 1;
    }
  }
}

TEST(Panda, GravityTorquesMatchReference) {
  const Vec7 ref_test = (Vec7() << 0, -25.256618, 0, 18.567248, 0.633630, 1.693106, 0).finished();
  const Vec7 ref_zero = (Vec7() << 0, -3.433259, 0, -3.256112, 0, 1.693638, 0).finished();
  const Vec7 ref_ready =
      (Vec7() << 0, -1.770771, -0.643780, 18.567248, 0.633630, 1.693106, 0).finished();
  EXPECT_LT((GravityTorques(QTest()) - ref_test).cwiseAbs().maxCoeff(), 1e-5);
  EXPECT_LT((GravityTorques(Vec7::Zero()) - ref_zero).cwiseAbs().maxCoeff(), 1e-5);
  EXPECT_LT((GravityTorques(Panda::Ready()) - ref_ready).cwiseAbs().maxCoeff(), 1e-5);
}

TEST(Panda, MassMatrixMatchesReferenceAtQTest) {
  const auto m = MassMatrix(QTest());
  const double upper[7][7] = {
      {1.178108, -0.036057, 1.140771, 0.001574, 0.036181, 0.001664, -0.009169},
      {0, 2.412404, -0.035288, -1.082680, -0.028798, -0.085668, 0.000272},
      {0, 0, 1.140771, 0.001574, 0.036181, 0.001664, -0.009169},
      {0, 0, 0, 0.788736, 0.023467, 0.093175, -0.001302},
      {0, 0, 0, 0, 0.027855, 0.000820, -0.000795},
      {0, 0, 0, 0, 0, 0.032557, -0.001570},
      {0, 0, 0, 0, 0, 0, 0.004910}};
  for (int r = 0; r < 7; ++r) {
    for (int c = r; c < 7; ++c) {
      EXPECT_NEAR(m(r, c), upper[r][c], 2e-6) << r << "," << c;
      EXPECT_NEAR(m(c, r), m(r, c), 1e-12);
    }
  }
}

TEST(Panda, JacobiansMatchCentralDifferences) {
  constexpr double kTool = 0.1034;
  const Vec7 q = QGeneric();
  const auto jac = Panda::GeometricJacobian(q, kTool);
  const auto jp = Panda::PositionJacobian(q, kTool);
  EXPECT_LT((jac.topRows<3>() - jp).cwiseAbs().maxCoeff(), 1e-15);
  const auto r0 = Panda::Tool<double>(q, kTool).R;
  constexpr double kH = 1e-6;
  for (int j = 0; j < 7; ++j) {
    Vec7 qp = q, qm = q;
    qp[j] += kH;
    qm[j] -= kH;
    const auto tp = Panda::Tool<double>(qp, kTool), tm = Panda::Tool<double>(qm, kTool);
    const Eigen::Vector3d dp = (tp.p - tm.p) / (2 * kH);
    const Eigen::Matrix3d skew = (tp.R - tm.R) / (2 * kH) * r0.transpose();
    const Eigen::Vector3d w(skew(2, 1), skew(0, 2), skew(1, 0));
    EXPECT_LT((jac.col(j).head<3>() - dp).cwiseAbs().maxCoeff(), 1e-8) << "joint " << j;
    EXPECT_LT((jac.col(j).tail<3>() - w).cwiseAbs().maxCoeff(), 1e-8) << "joint " << j;
  }
  // The angular part of a revolute chain: column j is the axis z_j in the base frame.
  const auto frames = Panda::Frames<double>(q);
  for (int j = 0; j < 7; ++j) {
    EXPECT_LT((jac.col(j).tail<3>() - frames[j].R.col(2)).norm(), 1e-12) << "joint " << j;
  }
}

TEST(Panda, FramesStayOrthonormalOnJets) {
  const auto frames = Panda::Frames<Panda::Jet7>(Panda::SeedJets(QGeneric()));
  for (const auto& f : frames) {
    Eigen::Matrix3d r;
    for (int a = 0; a < 3; ++a) {
      for (int b = 0; b < 3; ++b) r(a, b) = f.R(a, b).a;
    }
    EXPECT_LT((r * r.transpose() - Eigen::Matrix3d::Identity()).norm(), 1e-12);
    EXPECT_NEAR(r.determinant(), 1.0, 1e-12);
  }
}

TEST(Panda, LimitsAreConsistent) {
  for (int i = 0; i < 7; ++i) EXPECT_LT(Panda::kQMin[i], Panda::kQMax[i]);
  EXPECT_TRUE(Panda::WithinLimits(Panda::Ready()));
  EXPECT_FALSE(Panda::WithinLimits(Vec7::Zero()));  // q4 = 0 is above q4_max = -0.0698
  double total = 0;
  for (double m : Panda::kMass) total += m;
  EXPECT_NEAR(total, 16.062, 1e-3);
}

}  // namespace
}  // namespace diffdyn
