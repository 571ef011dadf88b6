// Periodic inputs of a network: angles enter as (sin, cos).
//
// A network of an angle q (a pendulum's, a pole's) should be periodic in it, and
// data that spin the pole reach |q| of tens of radians. InputFeatures maps a
// vector x (n) to the network's inputs
//
//   z = phi(x):  x_i            for a component not listed in `periodic`,
//                (sin x_i, cos x_i)  for a listed one,                (size n + |periodic|)
//
// and moves derivatives between x and z: the Jacobian D = dz/dx (size(n) x n) has
// one 1 per plain component and (cos x_i, -sin x_i) in the two rows of a periodic
// one. A gradient p = dV/dx = D^T dV/dz (PullBack); its transpose takes dL/dp to
// dL/dz (PushForward); a network Jacobian dy/dx = (dy/dz) D (ChainJacobian).
//
//   InputFeatures f{{1}};                            // q2 periodic, q1 plain
//   Eigen::MatrixXd z = f.Encode(q);                 // 3 x B from 2 x B
//   Eigen::VectorXd z0 = f.EncodeOne<double>(q.col(0));
#pragma once

#include <cmath>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {

/// z = phi(x) of the file comment: each component listed in `periodic` (0-based,
/// increasing) enters as (sin x_i, cos x_i), the others as they are.
struct InputFeatures {
  std::vector<int> periodic;

  /// The number of features for n inputs: n + |periodic|.
  int size(int n) const { return n + static_cast<int>(periodic.size()); }

  /// Throws diffdyn::Error unless `periodic` is increasing and within [0, n).
  void Validate(int n) const {
    for (std::size_t k = 0; k < periodic.size(); ++k) {
      DIFFDYN_CHECK(periodic[k] >= 0 && periodic[k] < n, "periodic input ", periodic[k] + 1,
                    " is not one of the ", n, " inputs");
      DIFFDYN_CHECK(k == 0 || periodic[k] > periodic[k - 1], "periodic inputs must be increasing");
    }
  }

  /// Calls row(i, f, is_periodic) for each input i with its first feature row f.
  template <typename F>
  void ForEachInput(int n, F&& row) const {
    std::size_t next = 0;
    for (int i = 0, f = 0; i < n; ++i) {
      const bool p = next < periodic.size() && periodic[next] == i;
      row(i, f, p);
      f += p ? 2 : 1;
      if (p) ++next;
    }
  }

  /// z (size(n)) of one input x (n), on double or Jets.
  template <typename S>
  Eigen::Matrix<S, Eigen::Dynamic, 1> EncodeOne(const Eigen::Matrix<S, Eigen::Dynamic, 1>& x) const {
    using std::cos;
    using std::sin;
    const int n = static_cast<int>(x.size());
    Eigen::Matrix<S, Eigen::Dynamic, 1> z(size(n));
    ForEachInput(n, [&](int i, int f, bool p) {
      if (p) {
        z[f] = sin(x[i]);
        z[f + 1] = cos(x[i]);
      } else {
        z[f] = x[i];
      }
    });
    return z;
  }

  /// dy/dx (rows x n) = (dy/dz) D from dy/dz (rows x size(n)) at x (n), into *out.
  template <typename S, typename X, typename JZ, typename JX>
  void ChainJacobian(const X& x, const JZ& dydz, JX* out) const {
    using std::cos;
    using std::sin;
    const int n = static_cast<int>(x.size());
    ForEachInput(n, [&](int i, int f, bool p) {
      if (p) {
        out->col(i) = dydz.col(f) * S(cos(x[i])) - dydz.col(f + 1) * S(sin(x[i]));
      } else {
        out->col(i) = dydz.col(f);
      }
    });
  }

  /// dL/d(dy/dz) (rows x size(n)) = dL/d(dy/dx) D^T at x (n): the transpose of
  /// ChainJacobian, into *out.
  template <typename X, typename GX, typename GZ>
  void ChainJacobianTranspose(const X& x, const GX& gx, GZ* out) const {
    const int n = static_cast<int>(x.size());
    ForEachInput(n, [&](int i, int f, bool p) {
      if (p) {
        using S = typename GX::Scalar;
        out->col(f) = gx.col(i) * S(std::cos(x[i]));
        out->col(f + 1) = -gx.col(i) * S(std::sin(x[i]));
      } else {
        out->col(f) = gx.col(i);
      }
    });
  }

  /// z (size(n) x B; resized) of inputs x (n x B), float or double: computed in
  /// x's scalar, stored in z's.
  template <typename X, typename Z>
  void Encode(const X& x, Z* z) const {
    using S = typename Z::Scalar;
    const int n = static_cast<int>(x.rows());
    z->resize(size(n), x.cols());
    ForEachInput(n, [&](int i, int f, bool p) {
      if (p) {
        z->row(f) = x.row(i).array().sin().matrix().template cast<S>();
        z->row(f + 1) = x.row(i).array().cos().matrix().template cast<S>();
      } else {
        z->row(f) = x.row(i).template cast<S>();
      }
    });
  }
  Eigen::MatrixXd Encode(const Eigen::MatrixXd& x) const {
    Eigen::MatrixXd z;
    Encode(x, &z);
    return z;
  }

  /// p = D^T diag(s) g (n x B; resized) from g (size(n) x B) at inputs x (n x B),
  /// s = `row_scale` (size(n)) or ones when empty: a gradient dV/dz taken to dV/dx.
  /// x, g and p share one scalar, float or double.
  template <typename X, typename G, typename P>
  void PullBack(const X& x, const G& g, P* p, const Eigen::VectorXd& row_scale = {}) const {
    using S = typename P::Scalar;
    const int n = static_cast<int>(x.rows());
    const auto s = [&](int f) { return S(row_scale.size() > 0 ? row_scale[f] : 1.0); };
    p->resize(n, x.cols());
    ForEachInput(n, [&](int i, int f, bool per) {
      if (per) {
        p->row(i) = s(f) * g.row(f).cwiseProduct(x.row(i).array().cos().matrix()) -
                    s(f + 1) * g.row(f + 1).cwiseProduct(x.row(i).array().sin().matrix());
      } else {
        p->row(i) = s(f) * g.row(f);
      }
    });
  }
  Eigen::MatrixXd PullBack(const Eigen::MatrixXd& x, const Eigen::MatrixXd& dvdz) const {
    Eigen::MatrixXd p;
    PullBack(x, dvdz, &p);
    return p;
  }

  /// dL/dz = D dL/dp (size(n) x B; resized) from dL/dp (n x B) at inputs x: the
  /// transpose of PullBack.
  void PushForward(const Eigen::MatrixXd& x, const Eigen::MatrixXd& dldp, Eigen::MatrixXd* g) const {
    const int n = static_cast<int>(x.rows());
    g->resize(size(n), x.cols());
    ForEachInput(n, [&](int i, int f, bool per) {
      if (per) {
        g->row(f) = dldp.row(i).cwiseProduct(x.row(i).array().cos().matrix());
        g->row(f + 1) = -dldp.row(i).cwiseProduct(x.row(i).array().sin().matrix());
      } else {
        g->row(f) = dldp.row(i);
      }
    });
  }
  Eigen::MatrixXd PushForward(const Eigen::MatrixXd& x, const Eigen::MatrixXd& dldp) const {
    Eigen::MatrixXd g;
    PushForward(x, dldp, &g);
    return g;
  }
};

}  // namespace diffdyn
