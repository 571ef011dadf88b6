// Jacobians by Jets (fixed-size and chunked) against closed forms and central differences.
#include "diffdyn/autodiff_ode/jacobian.h"

#include <cmath>

#include <gtest/gtest.h>

namespace diffdyn {
namespace {

// f(x) = [x0 x1 + sin x2, exp(x0) x2^2, log(1 + x1^2) / (1 + x0^2)].
struct Analytic {
  template <typename T>
  Eigen::Matrix<T, 3, 1> operator()(const Eigen::Matrix<T, 3, 1>& x) const {
    using std::exp, std::log, std::sin;
    Eigen::Matrix<T, 3, 1> y;
    y[0] = x[0] * x[1] + sin(x[2]);
    y[1] = exp(x[0]) * x[2] * x[2];
    y[2] = log(1.0 + x[1] * x[1]) / (1.0 + x[0] * x[0]);
    return y;
  }
  template <typename T>
  VectorX<T> operator()(const VectorX<T>& x) const {
    return (*this)(Eigen::Matrix<T, 3, 1>(x));
  }
};

Eigen::Matrix3d AnalyticJacobian(const Eigen::Vector3d& x) {
  const double l = std::log(1.0 + x[1] * x[1]);
  const double d = 1.0 + x[0] * x[0];
  Eigen::Matrix3d j;
  j << x[1], x[0], std::cos(x[2]),                                      //
      std::exp(x[0]) * x[2] * x[2], 0.0, 2.0 * std::exp(x[0]) * x[2],  //
      -l * 2.0 * x[0] / (d * d), 2.0 * x[1] / ((1.0 + x[1] * x[1]) * d), 0.0;
  return j;
}

double MaxRelativeError(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return (a - b).cwiseAbs().maxCoeff() / std::max(1.0, b.cwiseAbs().maxCoeff());
}

const Eigen::Vector3d kPoint(0.3, -1.2, 0.7);

TEST(Jacobian, FixedSizeMatchesSymbolic) {
  Eigen::Vector3d value;
  const Eigen::Matrix3d jac = Jacobian<3>(Analytic{}, kPoint, &value);
  EXPECT_LT(MaxRelativeError(jac, AnalyticJacobian(kPoint)), 1e-12);
  EXPECT_LT((value - Analytic{}(kPoint)).norm(), 1e-15);
}

TEST(Jacobian, MatchesCentralDifferences) {
  const Eigen::Matrix3d jac = Jacobian<3>(Analytic{}, kPoint);
  const Eigen::MatrixXd fd = JacobianCentralDifference(
      [](const Eigen::VectorXd& x) { return Eigen::VectorXd(Analytic{}(Eigen::Vector3d(x))); },
      kPoint);
  EXPECT_LT(MaxRelativeError(fd, jac), 1e-6);
}

// The same Jacobian whatever the chunk size K (typed over Jet widths).
template <typename KType>
class JacobianChunks : public ::testing::Test {};
using ChunkSizes = ::testing::Types<std::integral_constant<int, 1>, std::integral_constant<int, 2>,
                                    std::integral_constant<int, 8>>;
TYPED_TEST_SUITE(JacobianChunks, ChunkSizes);

TYPED_TEST(JacobianChunks, DynamicMatchesSymbolic) {
  constexpr int kK = TypeParam::value;
  Eigen::VectorXd value;
  const Eigen::MatrixXd jac = JacobianDynamic<kK>(Analytic{}, Eigen::VectorXd(kPoint), &value);
  ASSERT_EQ(jac.rows(), 3);
  ASSERT_EQ(jac.cols(), 3);
  EXPECT_LT(MaxRelativeError(jac, AnalyticJacobian(kPoint)), 1e-12);
  EXPECT_LT((value - Analytic{}(kPoint)).norm(), 1e-15);
}

// y = A tanh(B x): J = A diag(1 - tanh^2(Bx)) B, n = 21 spans 3 chunks of 8 with a remainder.
TYPED_TEST(JacobianChunks, LargeInputInChunks) {
  constexpr int kK = TypeParam::value;
  const int n = 21, h = 7, m = 4;
  Eigen::MatrixXd a(m, h), b(h, n);
  for (int i = 0; i < a.size(); ++i) a.data()[i] = std::sin(1.3 * i + 0.2);
  for (int i = 0; i < b.size(); ++i) b.data()[i] = 0.3 * std::cos(0.7 * i);
  Eigen::VectorXd x(n);
  for (int i = 0; i < n; ++i) x[i] = 0.1 * i - 1.0;
  auto f = [&](const auto& v) {
    using T = typename std::decay_t<decltype(v)>::Scalar;
    const VectorX<T> z = b.cast<T>() * v;
    VectorX<T> s(h);
    for (int i = 0; i < h; ++i) s[i] = tanh(z[i]);
    return VectorX<T>(a.cast<T>() * s);
  };
  const Eigen::MatrixXd jac = JacobianDynamic<kK>(f, x);
  const Eigen::ArrayXd t = (b * x).array().tanh();
  const Eigen::MatrixXd expected = a * (1.0 - t.square()).matrix().asDiagonal() * b;
  EXPECT_LT(MaxRelativeError(jac, expected), 1e-12);
  const Eigen::MatrixXd fd =
      JacobianCentralDifference([&](const Eigen::VectorXd& v) { return f(v); }, x);
  EXPECT_LT(MaxRelativeError(fd, jac), 1e-6);
}

// Typed over the scalar: the value part of every Jet evaluation equals the double one.
template <typename T>
class JacobianScalars : public ::testing::Test {};
using JacobianScalarTypes = ::testing::Types<double, ceres::Jet<double, 1>, ceres::Jet<double, 3>>;
TYPED_TEST_SUITE(JacobianScalars, JacobianScalarTypes);

TYPED_TEST(JacobianScalars, ValuePartAndDirectionalDerivative) {
  using T = TypeParam;
  Eigen::Matrix<T, 3, 1> x;
  for (int i = 0; i < 3; ++i) x[i] = T(kPoint[i]);
  // Seed direction e_0 for Jets.
  if constexpr (IsJet<T>::value) x[0].v[0] = 1.0;
  const Eigen::Matrix<T, 3, 1> y = Analytic{}(x);
  const Eigen::Vector3d y_double = Analytic{}(kPoint);
  const Eigen::Matrix3d jac = AnalyticJacobian(kPoint);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(ValuePart(y[i]), y_double[i]);
    if constexpr (IsJet<T>::value) {
      EXPECT_NEAR(y[i].v[0], jac(i, 0), 1e-12 * std::max(1.0, std::abs(jac(i, 0))));
    }
  }
}

TEST(Jacobian, EmptyInputIsAnError) {
  EXPECT_THROW(JacobianDynamic<4>(Analytic{}, Eigen::VectorXd()), Error);
}

TEST(Jacobian, ChangingOutputSizeNamesSizes) {
  // Output size depends on the chunk: 2 outputs for the first chunk, 1 after.
  auto f = [](const VectorX<JetK<2>>& x) {
    return x[0].v[0] == 1.0 ? VectorX<JetK<2>>(x.head(2)) : VectorX<JetK<2>>(x.head(1));
  };
  try {
    JacobianDynamic<2>(f, Eigen::VectorXd::Ones(4));
    FAIL() << "expected diffdyn::Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("returned 1 outputs"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace diffdyn
