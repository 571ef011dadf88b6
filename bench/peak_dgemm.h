// The machine's two-thread double-precision matrix-product peak, for benchmarks that
// report a fraction of it: C = A B at 2048^3 (Eigen), the columns of C split over two
// threads.
//
//   void BM_PeakDgemm2Threads(benchmark::State& s) { diffdyn::bench::PeakDgemm2Threads(s); }
#pragma once

#include <benchmark/benchmark.h>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/parallel.h"

namespace diffdyn::bench {

/// Times C = A B (n x n, n = 2048) on two threads; sets the counter "GFLOP/s" (2 n^3 flops).
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
  const double flops = 2.0 * n * n * double(n);
  state.counters["GFLOP/s"] =
      benchmark::Counter(flops * 1e-9, benchmark::Counter::kIsIterationInvariantRate);
}

}  // namespace diffdyn::bench
