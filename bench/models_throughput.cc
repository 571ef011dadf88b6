// Forward + backward of a batch of 500 through a 6-100-100-6 network, double,
// with softplus (the DDN's activation; second argument 0) and with ReLU (the
// NeuralODE-Panda models' activation; 1), as achieved GFLOP/s against the peak measured in the same run: the
// best two-thread double-precision matrix product at 2048^3 (Eigen split over
// two threads, and OpenBLAS's cblas_dgemm on two threads when libopenblas is
// present, loaded at run time).
//
//   build/bench/bench_models_throughput      (prints "fraction of peak" at the end)
//
// FLOPs counted: GEMM multiply-adds only, 2 m n B per product; forward
// (W h), backward dW = abar h^T and the cotangents W^T abar down to the inputs:
// 3 * sum_l 2 n_{l+1} n_l B = 33.6 MFLOP per iteration.

#include <algorithm>
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

Eigen::MatrixXd RandomMatrix(int rows, int cols, std::uint64_t seed) {
  Rng rng(seed);
  Eigen::MatrixXd m(rows, cols);
  for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = StandardNormal(rng);
  return m;
}

double ForwardBackwardFlops(const MlpArchitecture& arch, int batch) {
  double flops = 0.0;
  for (int l = 0; l < arch.num_layers(); ++l) flops += 2.0 * arch.sizes[l] * arch.sizes[l + 1] * batch;
  return 3.0 * flops;
}

void BM_ForwardBackward(benchmark::State& state) {
  const int threads = static_cast<int>(state.range(0));
  const Activation g = state.range(1) == 0 ? Activation::Softplus() : Activation::Relu();
  const MlpArchitecture arch{{6, 100, 100, 6}, {g, g}};
  const Mlp<double> net = MakeInitializedMlp(arch, InitOptions{}, 1);
  const Eigen::MatrixXd x = RandomMatrix(6, kBatch, 2);
  const Eigen::MatrixXd gy = RandomMatrix(6, kBatch, 3);
  MlpWorkspace ws(arch, kBatch, (kBatch + threads - 1) / threads, false);
  Eigen::MatrixXd y, gx;
  Eigen::VectorXd grad(net.num_parameters());
  for (auto _ : state) {
    net.Forward(x, &y, nullptr, &ws, threads);
    net.Backward(gy, Eigen::MatrixXd(), &grad, &gx, &ws, threads);
    benchmark::DoNotOptimize(grad.data());
  }
  state.counters["GFLOP/s"] = benchmark::Counter(ForwardBackwardFlops(arch, kBatch) * 1e-9,
                                                 benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_ForwardBackward)
    ->ArgsProduct({{1, 2}, {0, 1}})
    ->ArgNames({"threads", "relu"})
    ->UseRealTime()
    ->Unit(benchmark::kMicrosecond);

// The peak candidates (peak_dgemm.h): Eigen and OpenBLAS, C = A B at 2048^3 on two threads.
void BM_PeakDgemmEigenTwoThreads(benchmark::State& state) { bench::PeakDgemm2Threads(state); }
BENCHMARK(BM_PeakDgemmEigenTwoThreads)->UseRealTime()->Unit(benchmark::kMillisecond)->MinTime(1.0);

void BM_PeakDgemmOpenBlasTwoThreads(benchmark::State& state) {
  bench::PeakDgemmOpenBlas2Threads(state);
}
BENCHMARK(BM_PeakDgemmOpenBlasTwoThreads)->UseRealTime()->Unit(benchmark::kMillisecond)->MinTime(1.0);

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
  double peak = 0.0;
  std::string peak_name;
  std::map<std::string, std::pair<double, std::string>> best;  // per activation
  for (const auto& [name, value] : reporter.gflops) {
    if (name.find("PeakDgemm") != std::string::npos && value > peak) peak = value, peak_name = name;
    if (name.find("ForwardBackward") != std::string::npos) {
      const std::string act = name.find("relu:1") != std::string::npos ? "relu" : "softplus";
      if (value > best[act].first) best[act] = {value, name};
    }
  }
  if (peak > 0.0) {
    std::printf("peak (best two-thread dgemm 2048^3): %.1f GFLOP/s (%s)\n", peak, peak_name.c_str());
    for (const auto& [act, run] : best) {
      std::printf("forward+backward best, %s: %.1f GFLOP/s (%s) = %.0f%% of peak\n", act.c_str(),
                  run.first, run.second.c_str(), 100.0 * run.first / peak);
    }
  }
  return 0;
}
