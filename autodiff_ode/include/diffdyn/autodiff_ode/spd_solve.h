// Solving H x = b for a symmetric positive definite H, on double or on Jets.
//
// Eigen's triangular solvers skip a right-hand-side entry that compares equal to
// zero. A ceres::Jet compares by its value alone, so an entry with value 0 and
// non-zero derivatives is skipped and its derivatives are lost: the Jacobian of
// forward dynamics at rest, where the force is exactly zero, came out without the
// mass matrix. SpdSolve uses Eigen's LLT on double and a plain Cholesky
// factorisation with explicit loops (no such test) on any other scalar:
//
//   H = L L^T,   L y = b (forward),   L^T x = y (backward).
//
//   VectorX<Jet> qdd = SpdSolve(mass, force);   // n x n, n
#pragma once

#include <type_traits>

#include <Eigen/Cholesky>
#include <Eigen/Core>

namespace diffdyn {

/// x = H^-1 b for symmetric positive definite H (n x n) and b (n), any scalar; fixed
/// sizes stay fixed (no heap allocation).
template <typename DerivedH, typename DerivedB>
typename DerivedB::PlainObject SpdSolve(const Eigen::MatrixBase<DerivedH>& h, const Eigen::MatrixBase<DerivedB>& b) {
  using T = typename DerivedB::Scalar;
  static_assert(std::is_same_v<T, typename DerivedH::Scalar>, "SpdSolve: H and b need the same scalar");
  if constexpr (std::is_same_v<T, double>) {
    return h.llt().solve(b);
  } else {
    using std::sqrt;
    const Eigen::Index n = h.rows();
    typename DerivedH::PlainObject l = h;  // overwritten by the factor, lower triangle
    for (Eigen::Index j = 0; j < n; ++j) {
      T d = h(j, j);
      for (Eigen::Index k = 0; k < j; ++k) d -= l(j, k) * l(j, k);
      l(j, j) = sqrt(d);
      for (Eigen::Index i = j + 1; i < n; ++i) {
        T s = h(i, j);
        for (Eigen::Index k = 0; k < j; ++k) s -= l(i, k) * l(j, k);
        l(i, j) = s / l(j, j);
      }
    }
    typename DerivedB::PlainObject x = b;
    for (Eigen::Index i = 0; i < n; ++i) {
      for (Eigen::Index k = 0; k < i; ++k) x[i] -= l(i, k) * x[k];
      x[i] /= l(i, i);
    }
    for (Eigen::Index i = n - 1; i >= 0; --i) {
      for (Eigen::Index k = i + 1; k < n; ++k) x[i] -= l(k, i) * x[k];
      x[i] /= l(i, i);
    }
    return x;
  }
}

}  // namespace diffdyn
