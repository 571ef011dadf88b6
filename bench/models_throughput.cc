// Forward + backward of a batch of 500 through a 6-100-100-6 network, in double
// and in float, with softplus (the DDN's activation; argument relu:0) and with ReLU
// (the NeuralODE-Panda models' activation; relu:1), as achieved GFLOP/s against the
// peak of the same precision measured in the same run: the best two-thread matrix
// product at 2048^3 (Eigen split over two threads, and OpenBLAS's cblas_dgemm or
// cblas_sgemm on two threads when libopenblas is present, loaded at run time).
// bench/models_throughput_torch.py times the same work in PyTorch. BM_ApplyActivation
// times the activations alone (g and g' per value).
//
//   build/bench/bench_models_throughput      (prints "fraction of peak" at the end)
//
// FLOPs counted: GEMM multiply-adds only, 2 m n B per product; forward
// (W h), backward dW = abar h^T and the cotangents W^T abar down to the inputs:
// 3 * sum_l 2 n_{l+1} n_l B = 33.6 MFLOP per iteration.

#include <algorithm>
#include <array>
#include <cstdio>
#include <map>
#include <string>

#include <benchmark/benchmark.h>

#include "diffdyn/models/init.h"
#include "diffdyn/models/mlp.h"
#include "peak_dgemm.h"

namespace diffdyn {
namespace {

constexpr int kBatch = 500;

template <typename S>
Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic> RandomMatrix(int rows, int cols,
                                                              std::uint64_t seed) {
  Rng rng(seed);
  Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic> m(rows, cols);
  for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = static_cast<S>(StandardNormal(rng));
  return m;
}

double ForwardBackwardFlops(const MlpArchitecture& arch, int batch) {
  double flops = 0.0;
  for (int l = 0; l < arch.num_layers(); ++l) flops += 2.0 * arch.sizes[l] * arch.sizes[l + 1] * batch;
  return 3.0 * flops;
}

// Arguments: threads, relu (0: softplus, 1: ReLU).
template <typename S>
void BM_ForwardBackward(benchmark::State& state) {
  using Matrix = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;
  const int threads = static_cast<int>(state.range(0));
  const Activation g = state.range(1) == 0 ? Activation::Softplus() : Activation::Relu();
  const MlpArchitecture arch{{6, 100, 100, 6}, {g, g}};
  const Mlp<S> net = MakeInitializedMlp(arch, InitOptions{}, 1).template cast<S>();
  const Matrix x = RandomMatrix<S>(6, kBatch, 2);
  const Matrix gy = RandomMatrix<S>(6, kBatch, 3);
  BasicMlpWorkspace<S> ws(arch, kBatch, (kBatch + threads - 1) / threads, false);
  Matrix y, gx;
  Eigen::Matrix<S, Eigen::Dynamic, 1> grad(net.num_parameters());
  for (auto _ : state) {
    net.Forward(x, &y, nullptr, &ws, threads);
    net.Backward(gy, Matrix(), &grad, &gx, &ws, threads);
    benchmark::DoNotOptimize(grad.data());
  }
  state.counters["GFLOP/s"] = benchmark::Counter(ForwardBackwardFlops(arch, kBatch) * 1e-9,
                                                 benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_ForwardBackward<double>)
    ->ArgsProduct({{1, 2}, {0, 1}})
    ->ArgNames({"threads", "relu"})
    ->UseRealTime()
    ->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_ForwardBackward<float>)
    ->ArgsProduct({{1, 2}, {0, 1}})
    ->ArgNames({"threads", "relu"})
    ->UseRealTime()
    ->Unit(benchmark::kMicrosecond);

// ApplyActivation alone: g and g' of 3200 pre-activations (a 32-sample block of two
// 100-unit layers), N(0, 3^2) values, one thread, as nanoseconds per value. Argument:
// 0 softplus, 1 sigmoid, 2 tanh (the counter s/value prints e.g. "3.5n": 3.5 ns).
template <typename S>
void BM_ApplyActivation(benchmark::State& state) {
  constexpr Eigen::Index kValues = 3200;
  const Activation act = std::array{Activation::Softplus(), Activation::Sigmoid(),
                                    Activation::Tanh()}[static_cast<std::size_t>(state.range(0))];
  const Eigen::Matrix<S, Eigen::Dynamic, 1> a = S(3) * RandomMatrix<S>(kValues, 1, 4);
  Eigen::Matrix<S, Eigen::Dynamic, 1> g(kValues), dg(kValues);
  for (auto _ : state) {
    ApplyActivation<S>(act, a.data(), kValues, g.data(), dg.data(), nullptr);
    benchmark::DoNotOptimize(g.data());
    benchmark::DoNotOptimize(dg.data());
  }
  state.counters["s/value"] = benchmark::Counter(
      double(kValues), benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.SetLabel(ActivationName(act.kind));
}
BENCHMARK(BM_ApplyActivation<double>)->DenseRange(0, 2)->ArgName("act")->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_ApplyActivation<float>)->DenseRange(0, 2)->ArgName("act")->Unit(benchmark::kMicrosecond);

// The peak candidates (peak_dgemm.h): Eigen, OpenBLAS with its own kernel set and
// (on AVX-512 CPUs) with its AVX-512 kernels, C = A B at 2048^3 on two threads, per
// precision.
template <typename S>
void BM_PeakGemmEigenTwoThreads(benchmark::State& state) {
  bench::PeakGemm2Threads<S>(state);
}
template <typename S>
void BM_PeakGemmOpenBlasTwoThreads(benchmark::State& state) {
  bench::PeakGemmOpenBlas2Threads<S>(state);
}
template <typename S>
void BM_PeakGemmOpenBlasAvx512KernelsTwoThreads(benchmark::State& state) {
  bench::PeakGemmOpenBlasAvx512Kernels2Threads<S>(state);
}
BENCHMARK(BM_PeakGemmEigenTwoThreads<double>)->UseRealTime()->Unit(benchmark::kMillisecond)->MinTime(1.0);
BENCHMARK(BM_PeakGemmOpenBlasTwoThreads<double>)->UseRealTime()->Unit(benchmark::kMillisecond)->MinTime(1.0);
BENCHMARK(BM_PeakGemmEigenTwoThreads<float>)->UseRealTime()->Unit(benchmark::kMillisecond)->MinTime(1.0);
BENCHMARK(BM_PeakGemmOpenBlasTwoThreads<float>)->UseRealTime()->Unit(benchmark::kMillisecond)->MinTime(1.0);
BENCHMARK(BM_PeakGemmOpenBlasAvx512KernelsTwoThreads<double>)->UseRealTime()->Unit(benchmark::kMillisecond)->MinTime(1.0);
BENCHMARK(BM_PeakGemmOpenBlasAvx512KernelsTwoThreads<float>)->UseRealTime()->Unit(benchmark::kMillisecond)->MinTime(1.0);

// Console output plus a record of every GFLOP/s counter.
class RecordingReporter : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& run : runs) {
      const auto it = run.counters.find("GFLOP/s");
      if (!run.error_occurred && it != run.counters.end()) gflops[run.benchmark_name()] = it->second.value;
    }
    ConsoleReporter::ReportRuns(runs);
  }
  std::map<std::string, double> gflops;
};

}  // namespace
}  // namespace diffdyn

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  diffdyn::RecordingReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  benchmark::Shutdown();
  // Per precision: the peak and each activation's best forward+backward.
  for (const std::string precision : {"double", "float"}) {
    const std::string tag = "<" + precision + ">";
    double peak = 0.0;
    std::string peak_name;
    std::map<std::string, std::pair<double, std::string>> best;  // per activation
    for (const auto& [name, value] : reporter.gflops) {
      if (name.find(tag) == std::string::npos) continue;
      if (name.find("PeakGemm") != std::string::npos && value > peak) peak = value, peak_name = name;
      if (name.find("ForwardBackward") != std::string::npos) {
        const std::string act = name.find("relu:1") != std::string::npos ? "relu" : "softplus";
        if (value > best[act].first) best[act] = {value, name};
      }
    }
    if (peak <= 0.0) continue;
    std::printf("%s peak (best two-thread gemm 2048^3): %.1f GFLOP/s (%s)\n", precision.c_str(),
                peak, peak_name.c_str());
    for (const auto& [act, run] : best) {
      std::printf("%s forward+backward best, %s: %.1f GFLOP/s (%s) = %.0f%% of peak\n",
                  precision.c_str(), act.c_str(), run.first, run.second.c_str(),
                  100.0 * run.first / peak);
    }
  }
  return 0;
}
