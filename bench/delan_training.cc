// Training epochs of DeLaN (models/delan.h: 2 joints, trunk 2-64-64 softplus,
// heads for V and L) on the 2459 training samples of the DeLaN characters in
// batches of 512, Adam with AMSGrad (the authors' settings), in float64 and float32
// (Delan::SetPrecision: the batched network and heads in float), on 1 and 2
// threads. One iteration is a TrainDelan call of kEpochs epochs, so the workspace's
// first touch is spread as in a real run (10,000 epochs in one call). The PyTorch
// reference of the same formulation and epoch is bench/delan_training_torch.py.
// Counters: "epoch_s", wall seconds per epoch; "us_per_sample", microseconds per
// training sample.
//
//   build/bench/bench_delan_training   (from the repository root;
//   DIFFDYN_DELAN_DATA=path overrides the data folder)
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <string>

#include "diffdyn/models/delan.h"
#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/delan_training.h"

namespace diffdyn {
namespace {

const DelanSamples& TrainingSamples() {
  static const DelanSamples data = [] {
    const char* env = std::getenv("DIFFDYN_DELAN_DATA");
    const std::string path = env ? env : "../shared/data/delan_characters";
    return SplitForDelan(ReadDataset(path), 0.2, 0).train;
  }();
  return data;
}

constexpr int kEpochs = 50;

// Epochs of TrainDelan in `precision` on state.range(0) threads.
void RunDelanEpochs(benchmark::State& state, Precision precision) {
  const DelanSamples& train = TrainingSamples();
  Delan model = Delan::Initialized({.dof = 2}, 0);
  model.SetPrecision(precision);
  TrainOptions options = DelanTrainDefaults();
  options.epochs = kEpochs;
  options.progress = false;
  options.threads = static_cast<int>(state.range(0));
  const DelanSamples none;
  for (auto _ : state) TrainDelan(&model, train, none, options);
  const auto per = [](double count) {
    return benchmark::Counter(count, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  };
  state.counters["epoch_s"] = per(kEpochs);
  state.counters["us_per_sample"] = per(kEpochs * static_cast<double>(train.size()) * 1e-6);
}

void BM_DelanEpoch(benchmark::State& state) { RunDelanEpochs(state, Precision::kF64); }
void BM_DelanEpochF32(benchmark::State& state) { RunDelanEpochs(state, Precision::kF32); }
BENCHMARK(BM_DelanEpoch)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_DelanEpochF32)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace diffdyn

BENCHMARK_MAIN();
