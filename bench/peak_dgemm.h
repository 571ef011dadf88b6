// The machine's two-thread double-precision matrix-product peak, for benchmarks that
// report a fraction of it: C = A B at 2048^3, timed two ways, the best of which is the
// peak: Eigen with the columns of C split over two threads, and OpenBLAS's cblas_dgemm
// on two threads (loaded with dlopen; the benchmark is skipped when it is absent).
//
//   void BM_PeakDgemm2Threads(benchmark::State& s) { diffdyn::bench::PeakDgemm2Threads(s); }
//   void BM_PeakDgemmOpenBlas2Threads(benchmark::State& s) {
//     diffdyn::bench::PeakDgemmOpenBlas2Threads(s);
//   }
#pragma once

#include <benchmark/benchmark.h>
#include <dlfcn.h>

#include <Eigen/Core>

#include "diffdyn/models/parallel.h"

namespace diffdyn::bench {

/// Sets the counter "GFLOP/s" of a C = A B benchmark (2 n^3 flops per iteration).
inline void SetDgemmRate(benchmark::State& state, int n) {
  const double flops = 2.0 * n * n * double(n);
  state.counters["GFLOP/s"] =
      benchmark::Counter(flops * 1e-9, benchmark::Counter::kIsIterationInvariantRate);
}

/// Times C = A B (n x n, Eigen) with the columns of C split over two threads.
inline void PeakDgemm2Threads(benchmark::State& state, int n = 2048) {
  const Eigen::MatrixXd a = Eigen::MatrixXd::Constant(n, n, 0.5);
  const Eigen::MatrixXd b = Eigen::MatrixXd::Constant(n, n, 0.25);
  Eigen::MatrixXd c(n, n);
  for (auto _ : state) {
    ParallelForChunks(n, n / 2, 2, [&](int, int begin, int end) {
      c.middleCols(begin, end - begin).noalias() = a * b.middleCols(begin, end - begin);
    });
    benchmark::DoNotOptimize(c.data());
  }
  SetDgemmRate(state, n);
}

/// Times C = A B (n x n) with OpenBLAS's cblas_dgemm on two threads; skipped (with an
/// error message) when libopenblas.so.0 cannot be loaded.
inline void PeakDgemmOpenBlas2Threads(benchmark::State& state, int n = 2048) {
  using Dgemm = void (*)(int, int, int, int, int, int, double, const double*, int, const double*,
                         int, double, double*, int);
  using SetThreads = void (*)(int);
  void* lib = dlopen("libopenblas.so.0", RTLD_NOW | RTLD_LOCAL);
  Dgemm dgemm = lib ? reinterpret_cast<Dgemm>(dlsym(lib, "cblas_dgemm")) : nullptr;
  SetThreads set_threads =
      lib ? reinterpret_cast<SetThreads>(dlsym(lib, "openblas_set_num_threads")) : nullptr;
  if (!dgemm || !set_threads) {
    state.SkipWithError("libopenblas.so.0 not found");
    for (auto _ : state) {
    }
    return;
  }
  set_threads(2);
  const Eigen::MatrixXd a = Eigen::MatrixXd::Constant(n, n, 0.5);
  const Eigen::MatrixXd b = Eigen::MatrixXd::Constant(n, n, 0.25);
  Eigen::MatrixXd c(n, n);
  constexpr int kColMajor = 102, kNoTrans = 111;
  for (auto _ : state) {
    dgemm(kColMajor, kNoTrans, kNoTrans, n, n, n, 1.0, a.data(), n, b.data(), n, 0.0, c.data(), n);
    benchmark::DoNotOptimize(c.data());
  }
  SetDgemmRate(state, n);
}

}  // namespace diffdyn::bench
