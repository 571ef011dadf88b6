// The machine's two-thread matrix-product peak in double or float, for benchmarks that
// report a fraction of it: C = A B at 2048^3, timed two ways, the best of which is the
// peak: Eigen with the columns of C split over two threads, and OpenBLAS's cblas_dgemm
// (cblas_sgemm for float) on two threads (loaded with dlopen; the benchmark is skipped
// when it is absent). The OpenBLAS rows are labelled with the kernel set OpenBLAS chose
// for this CPU (`openblas_get_corename`, e.g. "Haswell" for AVX2 kernels, "SkylakeX"
// for AVX-512 ones; OPENBLAS_CORETYPE overrides its choice).
//
//   void BM_PeakDgemm2Threads(benchmark::State& s) { diffdyn::bench::PeakGemm2Threads<double>(s); }
//   void BM_PeakSgemmOpenBlas2Threads(benchmark::State& s) {
//     diffdyn::bench::PeakGemmOpenBlas2Threads<float>(s);
//   }
#pragma once

#include <benchmark/benchmark.h>
#include <dlfcn.h>

#include <string>
#include <type_traits>

#include <Eigen/Core>

#include "diffdyn/models/parallel.h"

namespace diffdyn::bench {

/// Sets the counter "GFLOP/s" of a C = A B benchmark (2 n^3 flops per iteration).
inline void SetGemmRate(benchmark::State& state, int n) {
  const double flops = 2.0 * n * n * double(n);
  state.counters["GFLOP/s"] =
      benchmark::Counter(flops * 1e-9, benchmark::Counter::kIsIterationInvariantRate);
}

/// Times C = A B (n x n of S, Eigen) with the columns of C split over two threads.
template <typename S>
void PeakGemm2Threads(benchmark::State& state, int n = 2048) {
  using Matrix = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;
  const Matrix a = Matrix::Constant(n, n, S(0.5));
  const Matrix b = Matrix::Constant(n, n, S(0.25));
  Matrix c(n, n);
  for (auto _ : state) {
    ParallelForChunks(n, n / 2, 2, [&](int, int begin, int end) {
      c.middleCols(begin, end - begin).noalias() = a * b.middleCols(begin, end - begin);
    });
    benchmark::DoNotOptimize(c.data());
  }
  SetGemmRate(state, n);
}

/// Times C = A B (n x n of S) with OpenBLAS's cblas_dgemm or cblas_sgemm on two
/// threads; skipped (with an error message) when libopenblas.so.0 cannot be loaded.
/// The row's label names OpenBLAS's kernel set ("OpenBLAS core Haswell").
template <typename S>
void PeakGemmOpenBlas2Threads(benchmark::State& state, int n = 2048) {
  using Gemm = void (*)(int, int, int, int, int, int, S, const S*, int, const S*, int, S, S*, int);
  using SetThreads = void (*)(int);
  using Matrix = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;
  const char* symbol = std::is_same_v<S, double> ? "cblas_dgemm" : "cblas_sgemm";
  void* lib = dlopen("libopenblas.so.0", RTLD_NOW | RTLD_LOCAL);
  Gemm gemm = lib ? reinterpret_cast<Gemm>(dlsym(lib, symbol)) : nullptr;
  SetThreads set_threads =
      lib ? reinterpret_cast<SetThreads>(dlsym(lib, "openblas_set_num_threads")) : nullptr;
  if (!gemm || !set_threads) {
    state.SkipWithError("libopenblas.so.0 not found");
    for (auto _ : state) {
    }
    return;
  }
  set_threads(2);
  using CoreName = const char* (*)();
  if (auto core_name = reinterpret_cast<CoreName>(dlsym(lib, "openblas_get_corename"))) {
    state.SetLabel(std::string("OpenBLAS core ") + core_name());
  }
  const Matrix a = Matrix::Constant(n, n, S(0.5));
  const Matrix b = Matrix::Constant(n, n, S(0.25));
  Matrix c(n, n);
  constexpr int kColMajor = 102, kNoTrans = 111;
  for (auto _ : state) {
    gemm(kColMajor, kNoTrans, kNoTrans, n, n, n, S(1), a.data(), n, b.data(), n, S(0), c.data(), n);
    benchmark::DoNotOptimize(c.data());
  }
  SetGemmRate(state, n);
}

}  // namespace diffdyn::bench
