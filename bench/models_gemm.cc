// The products of a training epoch through diffdyn::Gemm against the same
// product as one direct BLAS call (sgemm_ / dgemm_), one thread, in float and
// double. Shapes of a 6-100-100-6 network on a chunk of 250 samples:
//
//   0 out_fwd    C 6 x 250    = W 6 x 100   h 100 x 250      (forward of the output layer)
//   1 out_grad   C 6 x 100   += abar 6 x 250 h^T 250 x 100   (its weight gradient)
//   2 in_cot     C 100 x 250  = W^T 100 x 6 abar 6 x 250     (beta = 0: a cotangent)
//   3 mid_fwd    C 100 x 250 += W 100 x 100 h 100 x 250      (the middle layer's forward)
//   4 mid_grad   C 100 x 100 += abar 100 x 250 h^T 250 x 100 (its weight gradient)
//
// Gemm runs the first two on its thin kernel (internal::ThinGemm), the others on
// its panel kernel on AVX-512 (internal::PanelGemm) and elsewhere on BLAS after a
// fill of its own for beta = 0 (gemm.h); the direct call is the BLAS path alone.
// Without a BLAS only the Gemm rows are built.
//
//   OPENBLAS_NUM_THREADS=1 build/bench/bench_models_gemm --benchmark_repetitions=5
#include <benchmark/benchmark.h>

#include <Eigen/Core>
#include <type_traits>

#include "diffdyn/models/gemm.h"

namespace diffdyn {
namespace {

struct Shape {
  int m, n, k;
  bool transpose_b;
  float beta;
};

// The shape of each row, by its first argument.
Shape ShapeOf(int which) {
  switch (which) {
    case 0:
      return {6, 250, 100, false, 1.0f};  // out_fwd
    case 1:
      return {6, 100, 250, true, 1.0f};  // out_grad
    case 2:
      return {100, 250, 6, false, 0.0f};  // in_cot
    case 3:
      return {100, 250, 100, false, 1.0f};  // mid_fwd
    default:
      return {100, 100, 250, true, 1.0f};  // mid_grad
  }
}

template <typename S>
struct Operands {
  using Matrix = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;
  explicit Operands(const Shape& s)
      : a(Matrix::Random(s.m, s.k)),
        b(s.transpose_b ? Matrix::Random(s.n, s.k) : Matrix::Random(s.k, s.n)),
        c(Matrix::Random(s.m, s.n)) {}
  Matrix a, b, c;
};

template <typename S>
void BM_Gemm(benchmark::State& state) {
  const Shape s = ShapeOf(static_cast<int>(state.range(0)));
  Operands<S> x(s);
  for (auto _ : state) {
    Gemm(S(1), x.a, false, x.b, s.transpose_b, S(s.beta), x.c);
    benchmark::DoNotOptimize(x.c.data());
  }
  state.counters["GFLOP/s"] = benchmark::Counter(2.0 * s.m * s.n * s.k * 1e-9,
                                                 benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_Gemm<float>)->DenseRange(0, 4)->ArgName("shape");
BENCHMARK(BM_Gemm<double>)->DenseRange(0, 4)->ArgName("shape");

#if defined(DIFFDYN_HAVE_BLAS)
template <typename S>
void BM_Blas(benchmark::State& state) {
  const Shape s = ShapeOf(static_cast<int>(state.range(0)));
  Operands<S> x(s);
  internal::UseOneBlasThread();
  const char ta = 'N', tb = s.transpose_b ? 'T' : 'N';
  const S alpha = 1, beta = s.beta;
  const int lda = s.m, ldb = s.transpose_b ? s.n : s.k;
  for (auto _ : state) {
    if constexpr (std::is_same_v<S, float>) {
      sgemm_(&ta, &tb, &s.m, &s.n, &s.k, &alpha, x.a.data(), &lda, x.b.data(), &ldb, &beta,
             x.c.data(), &s.m);
    } else {
      dgemm_(&ta, &tb, &s.m, &s.n, &s.k, &alpha, x.a.data(), &lda, x.b.data(), &ldb, &beta,
             x.c.data(), &s.m);
    }
    benchmark::DoNotOptimize(x.c.data());
  }
  state.counters["GFLOP/s"] = benchmark::Counter(2.0 * s.m * s.n * s.k * 1e-9,
                                                 benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_Blas<float>)->DenseRange(0, 4)->ArgName("shape");
BENCHMARK(BM_Blas<double>)->DenseRange(0, 4)->ArgName("shape");
#endif

}  // namespace
}  // namespace diffdyn

BENCHMARK_MAIN();
