// One training epoch of the absolute NeuralODE (6-100-100-6 ReLU, rk4 3/8 rule on 10
// grid points = 9 steps, double) on 1000 transitions of the shared PyBullet data in
// batches of 500 with Adam, on 1 and 2 threads and for several chunk sizes (samples
// per thread task, TrainOptions::chunk_size); the same with dopri5 (tolerance 1e-8)
// for the dopri5 / rk4 ratio; the rk4 and dopri5 epochs in float32; and the machine's peak:
// the best two-thread matrix product at 2048^3 (double: Eigen with columns split over
// two threads, and OpenBLAS; float: OpenBLAS).
// The PyTorch reference of the same epoch is bench/pushing_epoch_torch.py.
//
// Counters: "GFLOP/s" counts the useful matrix flops of an epoch as PyTorch does
// them (forward + 2 x forward for backward = 3 x 2 x 11,200 per MLP evaluation, 36
// evaluations per sample with rk4; ours keeps every stage's activations, so it does
// no more); divide by the same precision's best BM_Peak* GFLOP/s for the fraction of peak. CPU
// times are of the whole process (all threads).
//
//   OPENBLAS_NUM_THREADS=1 build/bench/bench_pushing_epoch   (from the repository root;
//   DIFFDYN_PUSHING_CSV=path overrides the data file)
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdlib>
#include <numeric>
#include <string>
#include <vector>

#include "diffdyn/models/learned_model.h"
#include "diffdyn/models/parallel.h"
#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/training.h"
#include "peak_dgemm.h"

namespace diffdyn {
namespace {

constexpr int kTransitions = 1000;

const Windows& Data() {
  static const Windows data = [] {
    // Run from the repository root (scripts/run-bench does), or name the file.
    const char* env = std::getenv("DIFFDYN_PUSHING_CSV");
    const std::string path = env ? env : "../shared/data/pybullet_pushing/collected_data.csv";
    const auto all = MakeWindows(ReadDataset(path), 1);
    std::vector<int> first(kTransitions);
    std::iota(first.begin(), first.end(), 0);
    return SelectWindows(all, first);
  }();
  return data;
}

// Multiply-adds of one MLP evaluation 6-100-100-6, times 2 flops.
constexpr double kFlopsPerEval = 2.0 * (6 * 100 + 100 * 100 + 100 * 6);

void RunEpochs(benchmark::State& state, Method method, Precision precision = Precision::kF64) {
  const int threads = static_cast<int>(state.range(0));
  const int chunk_size = static_cast<int>(state.range(1));
  LearnedModelConfig config;
  config.type = LearnedKind::kAbsNode;
  config.method = method;
  config.steps = 10;
  config.hidden = 100;
  config.precision = precision;
  LearnedModel model = LearnedModel::Initialized(config, 1);
  TrainOptions options;
  options.epochs = 1;
  options.batch_size = 500;
  options.val_fraction = 0.0;
  options.threads = threads;
  options.chunk_size = chunk_size;
  options.progress = false;
  Trainer trainer(&model, options);
  trainer.Train(Data());  // warm-up: buffers sized
  // Solver steps per timed epoch, summed over the chunks (each chunk of an adaptive
  // method picks its own step sizes): accepted and rejected.
  double accepted = 0.0, rejected = 0.0;
  for (auto _ : state) {
    const TrainResult r = trainer.Train(Data());
    benchmark::DoNotOptimize(r.final_train_loss);
    accepted += static_cast<double>(r.solver_steps);
    rejected += static_cast<double>(r.rejected_steps);
  }
  state.counters["steps"] = benchmark::Counter(accepted, benchmark::Counter::kAvgIterations);
  state.counters["rejected"] = benchmark::Counter(rejected, benchmark::Counter::kAvgIterations);
  if (method == Method::kRk4) {
    const double flops = 3.0 * kFlopsPerEval * 36 * kTransitions;
    state.counters["GFLOP/s"] =
        benchmark::Counter(flops * 1e-9, benchmark::Counter::kIsIterationInvariantRate);
    state.counters["epoch_flops_G"] = flops * 1e-9;
  }
}

void BM_EpochAbsNodeRk4(benchmark::State& state) { RunEpochs(state, Method::kRk4); }
BENCHMARK(BM_EpochAbsNodeRk4)
    ->ArgNames({"threads", "chunk"})
    ->Args({1, 250})
    ->Args({2, 250})
    ->Args({2, 125})
    ->Args({2, 100})
    ->Args({2, 64})
    ->Args({2, 50})
    ->MeasureProcessCPUTime()
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond)
    ->MinTime(2.0);

// The same epoch with the network, solver and adjoint in float32 (parameters, Adam
// and the loss sums stay double).
void BM_EpochAbsNodeRk4F32(benchmark::State& state) {
  RunEpochs(state, Method::kRk4, Precision::kF32);
}
BENCHMARK(BM_EpochAbsNodeRk4F32)
    ->ArgNames({"threads", "chunk"})
    ->Args({1, 250})
    ->Args({2, 250})
    ->MeasureProcessCPUTime()
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond)
    ->MinTime(2.0);

void BM_EpochAbsNodeDopri5(benchmark::State& state) { RunEpochs(state, Method::kDopri5); }
BENCHMARK(BM_EpochAbsNodeDopri5)
    ->ArgNames({"threads", "chunk"})
    ->Args({2, 250})
    ->MeasureProcessCPUTime()
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond)
    ->MinTime(2.0);

// dopri5 in float32 at the same tolerance, 1e-8 absolute and relative (below the
// float's resolution, 6e-8: the error control then also sees rounding; the counters
// "steps" (accepted) and "rejected" show what it chose, e.g. 48 + 3 per epoch against
// 42 + 0 in float64 on 2026-12-02).
void BM_EpochAbsNodeDopri5F32(benchmark::State& state) {
  RunEpochs(state, Method::kDopri5, Precision::kF32);
}
BENCHMARK(BM_EpochAbsNodeDopri5F32)
    ->ArgNames({"threads", "chunk"})
    ->Args({2, 250})
    ->MeasureProcessCPUTime()
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond)
    ->MinTime(2.0);

// The peak: C = A B at 2048^3 on two threads, Eigen and OpenBLAS (peak_dgemm.h); each
// row timed as PeakRow sets.
void PeakRow(benchmark::internal::Benchmark* row) {
  row->MeasureProcessCPUTime()->UseRealTime()->Unit(benchmark::kMillisecond)->MinTime(2.0);
}

void BM_PeakDgemm2Threads(benchmark::State& state) { bench::PeakGemm2Threads<double>(state); }
BENCHMARK(BM_PeakDgemm2Threads)->Apply(PeakRow);

void BM_PeakDgemmOpenBlas2Threads(benchmark::State& state) {
  bench::PeakGemmOpenBlas2Threads<double>(state);
}
BENCHMARK(BM_PeakDgemmOpenBlas2Threads)->Apply(PeakRow);

// OpenBLAS's AVX-512 kernels whatever its own choice (skipped without AVX-512).
void BM_PeakDgemmOpenBlasAvx512Kernels2Threads(benchmark::State& state) {
  bench::PeakGemmOpenBlasAvx512Kernels2Threads<double>(state);
}
BENCHMARK(BM_PeakDgemmOpenBlasAvx512Kernels2Threads)->Apply(PeakRow);

// The float32 peak, for BM_EpochAbsNodeRk4F32's fraction.
void BM_PeakSgemmOpenBlas2Threads(benchmark::State& state) {
  bench::PeakGemmOpenBlas2Threads<float>(state);
}
BENCHMARK(BM_PeakSgemmOpenBlas2Threads)->Apply(PeakRow);

void BM_PeakSgemmOpenBlasAvx512Kernels2Threads(benchmark::State& state) {
  bench::PeakGemmOpenBlasAvx512Kernels2Threads<float>(state);
}
BENCHMARK(BM_PeakSgemmOpenBlasAvx512Kernels2Threads)->Apply(PeakRow);

}  // namespace
}  // namespace diffdyn

BENCHMARK_MAIN();
