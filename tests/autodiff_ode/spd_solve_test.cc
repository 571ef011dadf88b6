// SpdSolve: Eigen's LLT on double; on Jets, derivatives of right-hand-side entries
// whose value is zero survive (Eigen's triangular solvers skip such entries); fixed
// sizes give the dynamic-size result.
#include "diffdyn/autodiff_ode/spd_solve.h"

#include <Eigen/LU>
#include <ceres/jet.h>
#include <gtest/gtest.h>

namespace diffdyn {
namespace {

Eigen::MatrixXd Spd() {
  Eigen::MatrixXd h(3, 3);
  h << 4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0;
  return h;
}

TEST(SpdSolve, DoubleIsEigensLlt) {
  const Eigen::VectorXd b = Eigen::Vector3d(1.0, -2.0, 0.5);
  EXPECT_TRUE(SpdSolve(Spd(), b) == Spd().llt().solve(b));
}

TEST(SpdSolve, JetsKeepDerivativesOfZeroValuedEntries) {
  using Jet = ceres::Jet<double, 3>;
  const Eigen::MatrixXd h = Spd();
  Eigen::Matrix<Jet, Eigen::Dynamic, Eigen::Dynamic> hj = h.cast<Jet>();
  Eigen::Matrix<Jet, Eigen::Dynamic, 1> b(3);
  for (int i = 0; i < 3; ++i) b[i] = Jet(0.0, i);  // value 0, db/dz = I
  const Eigen::Matrix<Jet, Eigen::Dynamic, 1> x = SpdSolve(hj, b);
  const Eigen::MatrixXd inverse = h.inverse();
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(x[i].a, 0.0);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(x[i].v[k], inverse(i, k), 1e-14) << i << "," << k;
  }
  // Values as Eigen's on a non-zero right-hand side.
  const Eigen::VectorXd bd = Eigen::Vector3d(1.0, -2.0, 0.5);
  const Eigen::Matrix<Jet, Eigen::Dynamic, 1> xv = SpdSolve(hj, Eigen::Matrix<Jet, Eigen::Dynamic, 1>(bd.cast<Jet>()));
  const Eigen::VectorXd ref = h.llt().solve(bd);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(xv[i].a, ref[i], 1e-14);
}

TEST(SpdSolve, FixedSizesGiveTheDynamicResult) {
  using Jet = ceres::Jet<double, 3>;
  const Eigen::MatrixXd h = Spd();
  const Eigen::VectorXd b = Eigen::Vector3d(1.0, -2.0, 0.5);
  const Eigen::Matrix3d hf = h;
  const Eigen::Matrix<double, 3, 1> x = SpdSolve(hf, Eigen::Matrix<double, 3, 1>(b));
  EXPECT_LT((x - SpdSolve(h, b)).norm(), 1e-15);
  // Jets of fixed size: the plain Cholesky on a 3 x 3 stack matrix, db/dz = I again.
  Eigen::Matrix<Jet, 3, 1> bj;
  for (int i = 0; i < 3; ++i) bj[i] = Jet(b[i], i);
  const Eigen::Matrix<Jet, 3, 1> xj = SpdSolve(Eigen::Matrix<Jet, 3, 3>(hf.cast<Jet>()), bj);
  const Eigen::MatrixXd inverse = h.inverse();
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(xj[i].a, x[i], 1e-14);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(xj[i].v[k], inverse(i, k), 1e-14) << i << "," << k;
  }
}

}  // namespace
}  // namespace diffdyn
