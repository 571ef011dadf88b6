// Dense float and double matrix products for the batched network paths.
//
// The batched MLP passes are a handful of matrix products per layer (for a
// 6-100-100-6 network and a chunk of 256 samples, 100 x 100 times 100 x 256).
// On x86 CPUs with AVX-512 an optimised BLAS runs these shapes 20-50 % faster
// than Eigen's own product kernels, so when the build found a BLAS (CMake
// option DIFFDYN_USE_BLAS, on by default; OpenBLAS preferred) Gemm calls its
// dgemm (double operands) or sgemm (float operands); otherwise it falls back to
// Eigen. Either way:
//
//   auto c = workspace.topLeftCorner(m, n);             // any column-major block
//   diffdyn::Gemm(1.0, W, /*transpose_a=*/false, h, false, 0.0, c);   // c = W h
//
// Operands are column-major with unit inner stride, all of one scalar type
// (double or float): MatrixXd or MatrixXf, their blocks
// (leftCols, middleCols, topLeftCorner, ...) and Maps of them.
//
// Threads: diffdyn splits batches over its own threads in fixed chunks, so a
// threaded BLAS inside each chunk would only oversubscribe the cores. The
// first product therefore sets OpenBLAS (when it is the BLAS in use) to one
// thread for the process. Products of fixed chunks on one BLAS thread are
// deterministic, so results stay identical at any diffdyn thread count.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <type_traits>

#if defined(DIFFDYN_HAVE_BLAS)
extern "C" {
// Fortran BLAS (every BLAS provides it; character arguments of length one).
void dgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k,
            const double* alpha, const double* a, const int* lda, const double* b, const int* ldb,
            const double* beta, double* c, const int* ldc);
void sgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k,
            const float* alpha, const float* a, const int* lda, const float* b, const int* ldb,
            const float* beta, float* c, const int* ldc);
// OpenBLAS only; null when another BLAS is linked.
void openblas_set_num_threads(int num_threads) __attribute__((weak));
}
#endif

namespace diffdyn {

#if defined(DIFFDYN_HAVE_BLAS)
namespace internal {
// Sets OpenBLAS (if linked) to one thread, once per process, whatever the
// Gemm instantiation that asks first.
inline void UseOneBlasThread() {
  static const bool once = [] {
    if (openblas_set_num_threads != nullptr) openblas_set_num_threads(1);
    return true;
  }();
  (void)once;
}
}  // namespace internal
#endif

/// Whether Gemm calls an external BLAS (true) or Eigen's products (false).
constexpr bool GemmUsesBlas() {
#if defined(DIFFDYN_HAVE_BLAS)
  return true;
#else
  return false;
#endif
}

/// C = alpha op(A) op(B) + beta C, with op(X) = X^T if the flag is set, else X.
/// Sizes: op(A) is m x k, op(B) is k x n, C is m x n (checked in debug builds).
/// With beta = 0, C is overwritten (its old entries may be NaN). A, B and C are
/// column-major blocks of one scalar S (double or float) with unit inner stride;
/// C must not alias A or B. alpha and beta are given in S.
template <typename DA, typename DB, typename DC>
void Gemm(typename DC::Scalar alpha, const Eigen::MatrixBase<DA>& a, bool transpose_a,
          const Eigen::MatrixBase<DB>& b, bool transpose_b, typename DC::Scalar beta,
          const Eigen::MatrixBase<DC>& c_out) {
  using S = typename DC::Scalar;
  static_assert(std::is_same_v<S, double> || std::is_same_v<S, float>,
                "Gemm needs double or float operands");
  static_assert(std::is_same_v<typename DA::Scalar, S> && std::is_same_v<typename DB::Scalar, S>,
                "Gemm needs operands of one scalar type");
  static_assert(DA::InnerStrideAtCompileTime == 1 && DB::InnerStrideAtCompileTime == 1 &&
                    DC::InnerStrideAtCompileTime == 1,
                "Gemm needs operands with unit inner stride");
  static_assert(!DA::IsRowMajor && !DB::IsRowMajor && !DC::IsRowMajor,
                "Gemm needs column-major operands");
  Eigen::MatrixBase<DC>& c = const_cast<Eigen::MatrixBase<DC>&>(c_out);
  const Eigen::Index m = c.rows();
  const Eigen::Index n = c.cols();
  const Eigen::Index k = transpose_a ? a.rows() : a.cols();
  eigen_assert((transpose_a ? a.cols() : a.rows()) == m);
  eigen_assert((transpose_b ? b.rows() : b.cols()) == n);
  eigen_assert((transpose_b ? b.cols() : b.rows()) == k);
  if (m == 0 || n == 0) return;
  if (k == 0) {
    if (beta == S(0)) {
      c.setZero();
    } else {
      c *= beta;
    }
    return;
  }
#if defined(DIFFDYN_HAVE_BLAS)
  internal::UseOneBlasThread();
  const char ta = transpose_a ? 'T' : 'N';
  const char tb = transpose_b ? 'T' : 'N';
  const int mi = static_cast<int>(m), ni = static_cast<int>(n), ki = static_cast<int>(k);
  const int lda = static_cast<int>(std::max<Eigen::Index>(1, a.derived().outerStride()));
  const int ldb = static_cast<int>(std::max<Eigen::Index>(1, b.derived().outerStride()));
  const int ldc = static_cast<int>(std::max<Eigen::Index>(1, c.derived().outerStride()));
  if constexpr (std::is_same_v<S, double>) {
    dgemm_(&ta, &tb, &mi, &ni, &ki, &alpha, a.derived().data(), &lda, b.derived().data(), &ldb,
           &beta, c.derived().data(), &ldc);
  } else {
    sgemm_(&ta, &tb, &mi, &ni, &ki, &alpha, a.derived().data(), &lda, b.derived().data(), &ldb,
           &beta, c.derived().data(), &ldc);
  }
#else
  if (beta == S(0)) {
    c.setZero();
  } else if (beta != S(1)) {
    c *= beta;
  }
  if (transpose_a && transpose_b) {
    c.noalias() += alpha * a.transpose() * b.transpose();
  } else if (transpose_a) {
    c.noalias() += alpha * a.transpose() * b;
  } else if (transpose_b) {
    c.noalias() += alpha * a * b.transpose();
  } else {
    c.noalias() += alpha * a * b;
  }
#endif
}

}  // namespace diffdyn
