// MPPI on the pendulum swing-up task: one Command (K = 1000 samples, a 1-s horizon
// of 25 steps of 40 ms, rk4-classic with one step each, the task's log-cosine cost)
// through MppiController over the task's analytic model, from a hanging state, on 1
// and 2 threads.
//
//   build/bench/bench_control_mppi --benchmark_repetitions=5
#include <benchmark/benchmark.h>

#include "diffdyn/physics/control_task.h"
#include "diffdyn/solvers/control.h"

namespace diffdyn {
namespace {

void BM_MppiPendulumCommand(benchmark::State& state) {
  const ControlTask task = ControlTaskByName("pendulum");
  const auto model = TaskModel(task, 0.04, 1);
  MppiController mppi(task, *model, {.samples = 1000, .horizon_seconds = 1.0, .threads = static_cast<int>(state.range(0))});
  Eigen::VectorXd x(2);
  x << 0.3, 0.0;
  mppi.Reset(x, 1);
  for (auto _ : state) {
    Eigen::VectorXd u = mppi.Command(x);
    benchmark::DoNotOptimize(u.data());
  }
  state.counters["rollout_steps_per_s"] =
      benchmark::Counter(1000.0 * 25.0, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_MppiPendulumCommand)->Arg(1)->Arg(2)->ArgName("threads")->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace diffdyn

BENCHMARK_MAIN();
