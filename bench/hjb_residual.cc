// One step of the pendulum's HJB residual minimisation (solvers/hjb.h): for a
// mini-batch of 256 states, the value network's V and dV/dx in closed form (the
// structured value V = (z - z0)^T L L^T (z - z0), L from a 3-96-96-6 tanh network,
// HjbOptions' defaults), the residual F = rho V - q - p^T a + g~(-B^T p) at the final
// discount, and the gradient of mean F^2 in the 10,278 parameters by the network's
// reverse mode (ResidualLoss), in float64, on 1 and 2 threads, with the batch cut in
// chunks of 64 states (HjbOptions' default) and of 250 (TrainOptions' default, which
// leaves the second thread 6 of the 256). The PyTorch reference of the same step is
// bench/hjb_residual_torch.py. Counter "us_per_sample": microseconds per state.
//
//   build/bench/bench_hjb_residual
#include <benchmark/benchmark.h>

#include "diffdyn/models/random.h"
#include "diffdyn/physics/control_task.h"
#include "diffdyn/solvers/hjb.h"
#include "diffdyn/solvers/residual_solver.h"

namespace diffdyn {
namespace {

constexpr int kBatch = 256;

// A residual step on state.range(0) threads with chunks of state.range(1) states.
void BM_HjbResidualStep(benchmark::State& state) {
  const ControlTask task = ControlTaskByName("pendulum");
  const HjbOptions options;
  const ValueFunction value = MakeTaskValueFunction(task, options);
  const TaskHjb hjb(task, options.rho_final);
  Rng rng(1);
  Eigen::MatrixXd x(task.state_size(), kBatch);
  for (int j = 0; j < kBatch; ++j) {
    for (int i = 0; i < task.state_size(); ++i) x(i, j) = Uniform(rng, task.domain_low[i], task.domain_high[i]);
  }
  ValueWorkspace ws = value.MakeWorkspace(kBatch, static_cast<int>(state.range(1)));
  Eigen::VectorXd grad;
  const int threads = static_cast<int>(state.range(0));
  for (auto _ : state) benchmark::DoNotOptimize(ResidualLoss(hjb, value, x, &grad, &ws, threads));
  state.counters["us_per_sample"] = benchmark::Counter(
      kBatch * 1e-6, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_HjbResidualStep)
    ->ArgNames({"threads", "chunk"})
    ->Args({1, 250})
    ->Args({2, 250})
    ->Args({1, 64})
    ->Args({2, 64})
    ->Unit(benchmark::kMicrosecond)
    ->UseRealTime();

}  // namespace
}  // namespace diffdyn

BENCHMARK_MAIN();
