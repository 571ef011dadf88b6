// Forward sensitivities through rk4 and dopri5 against central differences and the
// variational equations integrated on doubles.
#include "diffdyn/autodiff_ode/sensitivity.h"

#include <cmath>
#include <initializer_list>
#include <vector>

#include <gtest/gtest.h>

namespace diffdyn {
namespace {

// Damped, driven pendulum: q'' = -g sin q - c q' + u; theta = (g, c).
struct Pendulum {
  template <typename T>
  void operator()(const VectorX<T>& x, const VectorX<T>& u, const VectorX<T>& theta, double,
                  VectorX<T>& dxdt) const {
    using std::sin;
    dxdt[0] = x[1];
    dxdt[1] = -theta[0] * sin(x[0]) - theta[1] * x[1] + u[0];
  }
};

// State and the 2 x 5 sensitivity matrix S integrated together on doubles with the
// closed-form partials: S' = (df/dx) S + [0, df/du, df/dtheta] (the second mode).
struct PendulumVariational {
  double u, g, c;
  void operator()(const Eigen::VectorXd& z, Eigen::VectorXd& dz, double) const {
    const double q = z[0], qd = z[1];
    dz.resize(12);
    dz[0] = qd;
    dz[1] = -g * std::sin(q) - c * qd + u;
    Eigen::Map<const Eigen::Matrix<double, 2, 5>> s(z.data() + 2);
    Eigen::Map<Eigen::Matrix<double, 2, 5>> ds(dz.data() + 2);
    Eigen::Matrix2d dfdx;
    dfdx << 0, 1, -g * std::cos(q), -c;
    ds = dfdx * s;
    ds(1, 2) += 1.0;            // df/du
    ds(1, 3) += -std::sin(q);   // df/dg
    ds(1, 4) += -qd;            // df/dc
  }
};

// Dynamic vectors: g++ 12 reports false array-bounds errors on fixed-size globals
// copied into dynamic ones with AVX-512.
Eigen::VectorXd Vec(std::initializer_list<double> values) {
  Eigen::VectorXd v(values.size());
  int i = 0;
  for (double x : values) v[i++] = x;
  return v;
}
const Eigen::VectorXd kX0 = Vec({1.1, -0.4});
const Eigen::VectorXd kU = Vec({0.3});
const Eigen::VectorXd kTheta = Vec({9.81, 0.25});

Eigen::MatrixXd Stack(const Sensitivities& s) {
  Eigen::MatrixXd all(2, 5);
  all << s.dx_dx0, s.dx_du, s.dx_dtheta;
  return all;
}

// Central differences of x(t1) over the 5 inputs (x0, u, theta), step h relative.
Eigen::MatrixXd FiniteDifferenceSensitivity(const OdeOptions& options, double t1, double h) {
  Eigen::VectorXd all(5);
  all << kX0, kU, kTheta;
  auto flow = [&](const Eigen::VectorXd& v) {
    const Eigen::VectorXd x0 = v.head(2), u = v.segment(2, 1), theta = v.tail(2);
    return Simulate<double>(Pendulum{}, x0, u, theta, {0.0, t1}, options).back();
  };
  return JacobianCentralDifference(flow, all, h);
}

double MaxRelative(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return ((a - b).array().abs() / (1e-3 + b.array().abs())).maxCoeff();
}

TEST(Sensitivity, Rk4MatchesFiniteDifferencesAndVariational) {
  OdeOptions options;
  options.method = Method::kRk4;
  options.dt = 1e-3;
  const double t1 = 2.0;
  const Sensitivities s = ForwardSensitivities<5>(Pendulum{}, kX0, kU, kTheta, 0.0, t1, options);
  const Eigen::MatrixXd fd = FiniteDifferenceSensitivity(options, t1, 1e-5);
  EXPECT_LT(MaxRelative(Stack(s), fd), 1e-6) << Stack(s) << "\n" << fd;
  // Second mode: variational equations, same solver.
  Eigen::VectorXd z = Eigen::VectorXd::Zero(12);
  z.head(2) = kX0;
  z[2] = z[5] = 1.0;  // S(0) = [I, 0, 0] in column-major 2 x 5
  Integrate(PendulumVariational{kU[0], kTheta[0], kTheta[1]}, z, 0.0, t1, options);
  const Eigen::MatrixXd var = Eigen::Map<const Eigen::Matrix<double, 2, 5>>(z.data() + 2);
  EXPECT_LT(MaxRelative(Stack(s), var), 1e-10);
  EXPECT_LT((s.x - z.head(2)).norm(), 1e-13);
}

TEST(Sensitivity, Dopri5MatchesFiniteDifferencesAndVariational) {
  OdeOptions options;
  options.method = Method::kDopri5;
  options.abs_tol = options.rel_tol = 1e-10;
  const double t1 = 2.0;
  const Sensitivities s = ForwardSensitivities<5>(Pendulum{}, kX0, kU, kTheta, 0.0, t1, options);
  const Eigen::MatrixXd fd = FiniteDifferenceSensitivity(options, t1, 1e-4);
  EXPECT_LT(MaxRelative(Stack(s), fd), 1e-6) << Stack(s) << "\n" << fd;
  Eigen::VectorXd z = Eigen::VectorXd::Zero(12);
  z.head(2) = kX0;
  z[2] = z[5] = 1.0;
  OdeOptions tight = options;
  tight.abs_tol = tight.rel_tol = 1e-12;
  Integrate(PendulumVariational{kU[0], kTheta[0], kTheta[1]}, z, 0.0, t1, tight);
  const Eigen::MatrixXd var = Eigen::Map<const Eigen::Matrix<double, 2, 5>>(z.data() + 2);
  EXPECT_LT(MaxRelative(Stack(s), var), 1e-7);
}

TEST(Sensitivity, AtEveryTimePoint) {
  OdeOptions options;
  options.abs_tol = options.rel_tol = 1e-10;
  const std::vector<double> times{0.0, 0.5, 1.0, 1.5};
  const auto all = ForwardSensitivitiesAt<5>(Pendulum{}, kX0, kU, kTheta, times, options);
  ASSERT_EQ(all.size(), times.size());
  EXPECT_TRUE(all[0].dx_dx0.isIdentity(0.0));
  EXPECT_TRUE(all[0].dx_dtheta.isZero(0.0));
  for (size_t i = 1; i < times.size(); ++i) {
    const Sensitivities one = ForwardSensitivities<5>(Pendulum{}, kX0, kU, kTheta, 0.0,
                                                      times[i], options);
    EXPECT_LT(MaxRelative(Stack(all[i]), Stack(one)), 1e-7) << "t = " << times[i];
  }
}

TEST(Sensitivity, WrongSizesNameSizes) {
  OdeOptions options;
  try {
    ForwardSensitivities<4>(Pendulum{}, kX0, kU, kTheta, 0.0, 1.0, options);
    FAIL() << "expected diffdyn::Error";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("x0 (2) + u (1) + theta (2) must have 4"), std::string::npos) << msg;
  }
}

}  // namespace
}  // namespace diffdyn
