// The Jacobian of a planar two-link arm's fingertip, three ways:
//
//   p(q) = [l1 cos q1 + l2 cos(q1 + q2), l1 sin q1 + l2 sin(q1 + q2)]
//
//   1. Jets: evaluate p on ceres::Jet<double, 2> seeded q_i + eps_i (exact, one call);
//   2. central differences (p(q + h e_i) - p(q - h e_i)) / 2h (error O(h^2) + O(eps/h));
//   3. the closed form J = [[-y, -l2 s12], [x, l2 c12]].
//
// Usage: example_jacobian_three_ways [--quick]   (exit 1 if the three disagree)
#include <chrono>
#include <cmath>
#include <cstring>

#include <fmt/core.h>

#include "diffdyn/autodiff_ode/jacobian.h"

namespace {

constexpr double kL1 = 0.6, kL2 = 0.4;

// Scalar-generic forward kinematics: works on double and on Jets.
struct Fingertip {
  template <typename T>
  Eigen::Matrix<T, 2, 1> operator()(const Eigen::Matrix<T, 2, 1>& q) const {
    using std::cos, std::sin;
    return {kL1 * cos(q[0]) + kL2 * cos(q[0] + q[1]), kL1 * sin(q[0]) + kL2 * sin(q[0] + q[1])};
  }
};

Eigen::Matrix2d ClosedForm(const Eigen::Vector2d& q) {
  const double s1 = std::sin(q[0]), c1 = std::cos(q[0]);
  const double s12 = std::sin(q[0] + q[1]), c12 = std::cos(q[0] + q[1]);
  Eigen::Matrix2d j;
  j << -kL1 * s1 - kL2 * s12, -kL2 * s12, kL1 * c1 + kL2 * c12, kL2 * c12;
  return j;
}

// Mean seconds per call of f over `reps` calls.
template <typename F>
double SecondsPerCall(int reps, F&& f) {
  const auto start = std::chrono::steady_clock::now();
  for (int i = 0; i < reps; ++i) f();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() / reps;
}

void Print(const char* name, const Eigen::Matrix2d& j, double error, double seconds) {
  fmt::print("{:<20} [{:+.12f} {:+.12f}; {:+.12f} {:+.12f}]  max diff {:.1e}  {:.0f} ns\n", name,
             j(0, 0), j(0, 1), j(1, 0), j(1, 1), error, seconds * 1e9);
}

}  // namespace

int main(int argc, char** argv) {
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  const int reps = quick ? 10'000 : 1'000'000;
  const Eigen::Vector2d q(0.7, -1.1);

  const Eigen::Matrix2d closed = ClosedForm(q);
  const Eigen::Matrix2d jets = diffdyn::Jacobian<2>(Fingertip{}, q);
  auto p = [](const Eigen::VectorXd& v) {
    return Eigen::VectorXd(Fingertip{}(Eigen::Vector2d(v)));
  };
  const Eigen::Matrix2d fd = diffdyn::JacobianCentralDifference(p, q, 1e-6);

  volatile double sink = 0;
  const double t_closed = SecondsPerCall(reps, [&] { sink = sink + ClosedForm(q)(0, 0); });
  const double t_jets =
      SecondsPerCall(reps, [&] { sink = sink + diffdyn::Jacobian<2>(Fingertip{}, q)(0, 0); });
  const double t_fd = SecondsPerCall(
      reps, [&] { sink = sink + diffdyn::JacobianCentralDifference(p, q, 1e-6)(0, 0); });

  const double err_jets = (jets - closed).cwiseAbs().maxCoeff();
  const double err_fd = (fd - closed).cwiseAbs().maxCoeff();
  fmt::print("fingertip Jacobian at q = ({}, {})\n", q[0], q[1]);
  Print("closed form", closed, 0.0, t_closed);
  Print("Jets", jets, err_jets, t_jets);
  Print("central differences", fd, err_fd, t_fd);

  // Jets are exact to rounding; differences carry truncation and cancellation error.
  const bool ok = err_jets < 1e-14 && err_fd < 1e-8;
  fmt::print("{}\n", ok ? "agree" : "DISAGREE");
  return ok ? 0 : 1;
}
