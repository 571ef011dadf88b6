// Forward sensitivities of an ODE solution with Jets.
//
// For controlled, parametrized dynamics
//
//   dx/dt = f(x, u, theta, t),   x(t0) = x0,   u held constant over [t0, t1],
//
// the sensitivities S_x0 = dx(t)/dx0 (n x n), S_u = dx(t)/du (n x m) and
// S_theta = dx(t)/dtheta (n x p) obey the variational equations
//
//   dS/dt = (df/dx) S + df/d(x0, u, theta),   S(t0) = [I, 0, 0].
//
// Integrating the state on Jet<double, K> with K = n + m + p, seeded as
//
//   x0_i + eps_i,   u_j + eps_{n+j},   theta_k + eps_{n+m+k},
//
// carries exactly these derivatives through every stage of the solver: one Jet
// integration gives x(t) and all three blocks of [S_x0, S_u, S_theta] (the derivative
// of the discrete solver map; with an adaptive method the accepted step sizes are held
// fixed, and they converge to the derivative of the exact flow as the tolerance
// tightens).
//
// Dynamics are scalar-generic:
//
//   struct Pendulum {
//     template <typename T>
//     void operator()(const diffdyn::VectorX<T>& x, const diffdyn::VectorX<T>& u,
//                     const diffdyn::VectorX<T>& theta, double t, diffdyn::VectorX<T>& dxdt) const;
//   };
//
// Simulate<T>() runs the same integration on any scalar, so a Ceres cost functor whose
// parameters are Jets fits theta through the integrator:
//
//   template <typename T> bool operator()(const T* theta, T* residual) const {
//     auto xs = diffdyn::Simulate<T>(Pendulum{}, x0.cast<T>(), u.cast<T>(),
//                                    Eigen::Map<const diffdyn::VectorX<T>>(theta, 2), times, opts);
//     ...
//   }
#pragma once

#include <vector>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/autodiff_ode/integrate.h"
#include "diffdyn/autodiff_ode/jacobian.h"

namespace diffdyn {

/// An odeint system dx/dt = f(x, u, theta, t) with u (m) and theta (p) bound; holds
/// references, so u and theta must outlive it.
template <typename Dynamics, typename T>
class BoundDynamics {
 public:
  /// Binds f to inputs u (m, may be empty) and parameters theta (p, may be empty).
  BoundDynamics(const Dynamics& f, const VectorX<T>& u, const VectorX<T>& theta)
      : f_(f), u_(u), theta_(theta) {}
  /// odeint's System concept: dxdt = f(x, u, theta, t) (n).
  void operator()(const VectorX<T>& x, VectorX<T>& dxdt, double t) const {
    f_(x, u_, theta_, t, dxdt);
  }

 private:
  const Dynamics& f_;
  const VectorX<T>& u_;
  const VectorX<T>& theta_;
};

/// x(times[i]) (n each) of dx/dt = f(x, u, theta, t), x(times[0]) = x0, on any scalar T
/// (double or Jet, e.g. inside a Ceres AutoDiffCostFunction). u (m) and theta (p) may be
/// empty. Errors as IntegrateTimes.
template <typename T, typename Dynamics>
std::vector<VectorX<T>> Simulate(const Dynamics& f, const VectorX<T>& x0, const VectorX<T>& u,
                                 const VectorX<T>& theta, const std::vector<double>& times,
                                 const OdeOptions& options) {
  const BoundDynamics<Dynamics, T> system(f, u, theta);
  std::vector<VectorX<T>> out;
  out.reserve(times.size());
  VectorX<T> x = x0;
  IntegrateTimes(system, x, times, options,
                 [&](int, double, const VectorX<T>& xi) { out.push_back(xi); });
  return out;
}

/// x(t) and its sensitivities at one time.
struct Sensitivities {
  /// x(t), n.
  Eigen::VectorXd x;
  /// dx(t)/dx0, n x n.
  Eigen::MatrixXd dx_dx0;
  /// dx(t)/du, n x m (u held constant from t0).
  Eigen::MatrixXd dx_du;
  /// dx(t)/dtheta, n x p.
  Eigen::MatrixXd dx_dtheta;
};

/// Sensitivities at every times[i] (times[0] = t0 included: [I, 0, 0]) from one
/// integration on Jet<double, K>. K must equal n + m + p (x0.size() + u.size() +
/// theta.size()); otherwise diffdyn::Error names the three sizes.
template <int K, typename Dynamics>
std::vector<Sensitivities> ForwardSensitivitiesAt(const Dynamics& f, const Eigen::VectorXd& x0,
                                                  const Eigen::VectorXd& u,
                                                  const Eigen::VectorXd& theta,
                                                  const std::vector<double>& times,
                                                  const OdeOptions& options) {
  const int n = static_cast<int>(x0.size());
  const int m = static_cast<int>(u.size());
  const int p = static_cast<int>(theta.size());
  DIFFDYN_CHECK(n + m + p == K, "ForwardSensitivities<", K, ">: x0 (", n, ") + u (", m,
                ") + theta (", p, ") must have ", K, " entries in all");
  DIFFDYN_CHECK(n > 0, "ForwardSensitivities: empty state");
  // Seed derivative directions: x0 -> [0, n), u -> [n, n + m), theta -> [n + m, K).
  VectorX<JetK<K>> xj, uj, thetaj;
  SeedJets<K>(x0, 0, &xj);
  SeedJets<K>(u, -n, &uj);
  SeedJets<K>(theta, -(n + m), &thetaj);
  std::vector<Sensitivities> out;
  out.reserve(times.size());
  const BoundDynamics<Dynamics, JetK<K>> system(f, uj, thetaj);
  IntegrateTimes(system, xj, times, options, [&](int, double, const VectorX<JetK<K>>& xi) {
    Sensitivities s;
    s.x.resize(n);
    Eigen::MatrixXd all(n, K);
    for (int i = 0; i < n; ++i) {
      s.x[i] = xi[i].a;
      all.row(i) = xi[i].v.transpose();
    }
    s.dx_dx0 = all.leftCols(n);
    s.dx_du = all.middleCols(n, m);
    s.dx_dtheta = all.rightCols(p);
    out.push_back(std::move(s));
  });
  return out;
}

/// x(t1) and dx(t1)/dx0, dx(t1)/du, dx(t1)/dtheta from one Jet integration on [t0, t1];
/// see ForwardSensitivitiesAt.
template <int K, typename Dynamics>
Sensitivities ForwardSensitivities(const Dynamics& f, const Eigen::VectorXd& x0,
                                   const Eigen::VectorXd& u, const Eigen::VectorXd& theta,
                                   double t0, double t1, const OdeOptions& options) {
  return ForwardSensitivitiesAt<K>(f, x0, u, theta, {t0, t1}, options).back();
}

}  // namespace diffdyn
