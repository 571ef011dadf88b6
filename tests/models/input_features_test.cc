// InputFeatures: the (sin, cos) map of periodic inputs and its derivatives, against Jets.
#include "diffdyn/models/input_features.h"

#include <ceres/jet.h>
#include <gtest/gtest.h>

namespace diffdyn {
namespace {

TEST(InputFeatures, ChainJacobianIsTheJetDerivativeOfTheEncoding) {
  constexpr int kN = 3;
  using Jet = ceres::Jet<double, kN>;
  const InputFeatures f{{0, 2}};
  Eigen::VectorXd x(kN);
  x << 0.4, -2.0, 7.5;
  Eigen::Matrix<Jet, Eigen::Dynamic, 1> xj(kN);
  for (int i = 0; i < kN; ++i) xj[i] = Jet(x[i], i);
  const Eigen::Matrix<Jet, Eigen::Dynamic, 1> zj = f.EncodeOne<Jet>(xj);
  ASSERT_EQ(zj.size(), f.size(kN));
  // dy/dz = I: ChainJacobian then gives D = dz/dx itself.
  const Eigen::MatrixXd eye = Eigen::MatrixXd::Identity(f.size(kN), f.size(kN));
  Eigen::MatrixXd d(f.size(kN), kN);
  f.ChainJacobian<double>(x, eye, &d);
  for (int r = 0; r < f.size(kN); ++r)
    for (int i = 0; i < kN; ++i) EXPECT_NEAR(d(r, i), zj[r].v[i], 1e-15) << r << "," << i;
  // The batch encoding is the single-sample one.
  const Eigen::MatrixXd z = f.Encode(Eigen::MatrixXd(x));
  for (int r = 0; r < f.size(kN); ++r) EXPECT_EQ(z(r, 0), zj[r].a);
}

TEST(InputFeatures, TransposesAgree) {
  const InputFeatures f{{1}};
  Eigen::VectorXd x(2);
  x << 1.3, -0.7;
  Eigen::MatrixXd a(4, 3), g(4, 2), jx(4, 2), gz(4, 3);
  a << 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12;
  g << 0.5, -1, 2, 0.25, -3, 1, 0.1, 0.2;
  f.ChainJacobian<double>(x, a, &jx);          // (a D)
  f.ChainJacobianTranspose(x, g, &gz);         // (g D^T)
  // <a D, g> = <a, g D^T>.
  EXPECT_NEAR((jx.array() * g.array()).sum(), (a.array() * gz.array()).sum(), 1e-12);
  // PushForward is the transpose of PullBack.
  const Eigen::MatrixXd p = Eigen::MatrixXd::Random(2, 1), v = Eigen::MatrixXd::Random(3, 1);
  EXPECT_NEAR(f.PullBack(Eigen::MatrixXd(x), v).col(0).dot(p.col(0)),
              v.col(0).dot(f.PushForward(Eigen::MatrixXd(x), p).col(0)), 1e-12);
}

TEST(InputFeatures, RefusesBadLists) {
  EXPECT_THROW(InputFeatures({{2}}).Validate(2), Error);
  EXPECT_THROW(InputFeatures({{1, 0}}).Validate(2), Error);
  EXPECT_THROW(InputFeatures({{-1}}).Validate(2), Error);
  EXPECT_NO_THROW(InputFeatures({{0, 1}}).Validate(2));
}

}  // namespace
}  // namespace diffdyn
