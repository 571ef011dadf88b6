// The machine's two-thread matrix-product peak in double or float, for benchmarks that
// report a fraction of it: C = A B at 2048^3, timed two ways, the best of which is the
// peak: Eigen with the columns of C split over two threads, and OpenBLAS's cblas_dgemm
// (cblas_sgemm for float) on two threads (loaded with dlopen; the benchmark is skipped
// when it is absent). The OpenBLAS rows are labelled with the kernel set OpenBLAS chose
// for this CPU (`openblas_get_corename`, e.g. "Haswell" for AVX2 kernels, "SkylakeX"
// for AVX-512 ones; OPENBLAS_CORETYPE overrides its choice). On a CPU with AVX-512 a
// third row times OpenBLAS's AVX-512 kernels whatever its own choice, from a private
// copy of the library (PeakGemmOpenBlasAvx512Kernels2Threads).
//
//   void BM_PeakDgemm2Threads(benchmark::State& s) { diffdyn::bench::PeakGemm2Threads<double>(s); }
//   void BM_PeakSgemmOpenBlas2Threads(benchmark::State& s) {
//     diffdyn::bench::PeakGemmOpenBlas2Threads<float>(s);
//   }
#pragma once

#include <benchmark/benchmark.h>
#include <dlfcn.h>

#include <cstdlib>
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

/// OpenBLAS's entry points the peak rows call, from libopenblas.so.0 as the process
/// loads it (the kernel set OpenBLAS picks for this CPU, or that of OPENBLAS_CORETYPE),
/// or with avx512_kernels from a private copy loaded into a link namespace of its own
/// (dlmopen) with OPENBLAS_CORETYPE=SkylakeX while it loads. Each is loaded once per
/// process; members are null when the library or a symbol is missing.
template <typename S>
struct OpenBlasGemm {
  using Gemm = void (*)(int, int, int, int, int, int, S, const S*, int, const S*, int, S, S*, int);
  Gemm gemm = nullptr;
  void (*set_threads)(int) = nullptr;
  const char* (*core_name)() = nullptr;

  static const OpenBlasGemm& Load(bool avx512_kernels) {
    if (!avx512_kernels) {
      static const OpenBlasGemm own = Open(nullptr);
      return own;
    }
    static const OpenBlasGemm avx512 = Open("SkylakeX");
    return avx512;
  }

 private:
  static OpenBlasGemm Open(const char* coretype) {
    void* lib = nullptr;
    if (coretype == nullptr) {
      lib = dlopen("libopenblas.so.0", RTLD_NOW | RTLD_LOCAL);
    } else {
      // OpenBLAS reads OPENBLAS_CORETYPE once, as it loads: set it for the copy only.
      const char* previous = std::getenv("OPENBLAS_CORETYPE");
      const std::string saved = previous ? previous : "";
      setenv("OPENBLAS_CORETYPE", coretype, 1);
      lib = dlmopen(LM_ID_NEWLM, "libopenblas.so.0", RTLD_NOW | RTLD_LOCAL);
      previous ? setenv("OPENBLAS_CORETYPE", saved.c_str(), 1) : unsetenv("OPENBLAS_CORETYPE");
    }
    OpenBlasGemm blas;
    if (lib == nullptr) return blas;
    blas.gemm = reinterpret_cast<Gemm>(
        dlsym(lib, std::is_same_v<S, double> ? "cblas_dgemm" : "cblas_sgemm"));
    blas.set_threads = reinterpret_cast<void (*)(int)>(dlsym(lib, "openblas_set_num_threads"));
    blas.core_name = reinterpret_cast<const char* (*)()>(dlsym(lib, "openblas_get_corename"));
    return blas;
  }
};

/// Times C = A B (n x n of S) with OpenBLAS's cblas_dgemm or cblas_sgemm on two
/// threads; skipped (with an error message) when libopenblas.so.0 cannot be loaded.
/// The row's label names OpenBLAS's kernel set ("OpenBLAS core Haswell").
/// avx512_kernels: a private copy with OpenBLAS's AVX-512 kernels (OpenBlasGemm).
template <typename S>
void PeakGemmOpenBlas2Threads(benchmark::State& state, int n = 2048,
                              bool avx512_kernels = false) {
  using Matrix = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;
  const OpenBlasGemm<S>& blas = OpenBlasGemm<S>::Load(avx512_kernels);
  if (!blas.gemm || !blas.set_threads) {
    state.SkipWithError("libopenblas.so.0 not found");
    for (auto _ : state) {
    }
    return;
  }
  blas.set_threads(2);
  if (blas.core_name) state.SetLabel(std::string("OpenBLAS core ") + blas.core_name());
  const Matrix a = Matrix::Constant(n, n, S(0.5));
  const Matrix b = Matrix::Constant(n, n, S(0.25));
  Matrix c(n, n);
  constexpr int kColMajor = 102, kNoTrans = 111;
  for (auto _ : state) {
    blas.gemm(kColMajor, kNoTrans, kNoTrans, n, n, n, S(1), a.data(), n, b.data(), n, S(0),
              c.data(), n);
    benchmark::DoNotOptimize(c.data());
  }
  SetGemmRate(state, n);
}

/// The same with OpenBLAS's AVX-512 kernels (its SkylakeX set) on a CPU that has
/// AVX-512 F, CD, BW, DQ and VL, whichever set OpenBLAS picks for it itself: Debian's
/// OpenBLAS 0.3.21 runs its AVX2 kernels on AVX-512 CPUs it does not know (AMD Zen 5),
/// where the peak of its own choice is not the machine's. Skipped on other CPUs.
template <typename S>
void PeakGemmOpenBlasAvx512Kernels2Threads(benchmark::State& state, int n = 2048) {
  const bool avx512 = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512cd") &&
                      __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512dq") &&
                      __builtin_cpu_supports("avx512vl");
  if (!avx512) {
    state.SkipWithError("this CPU has no AVX-512");
    for (auto _ : state) {
    }
    return;
  }
  PeakGemmOpenBlas2Threads<S>(state, n, /*avx512_kernels=*/true);
}

}  // namespace diffdyn::bench
