// Throughput of the ODE-engine pusher on one thread: random pushes (uniform
// actions) from the seed's start pose, as `diffdyn collect` runs them. The
// counter pushes_per_second is per CPU second of this one thread (target >= 50).
//
//   ./build/bench/bench_physics_pusher --benchmark_min_time=5
#include <numbers>

#include <benchmark/benchmark.h>

#include "diffdyn/physics/pushing/collect.h"
#include "diffdyn/physics/pushing/env.h"

namespace {

// One push per iteration; a fresh trajectory every 10 pushes.
void BM_PushOneThread(benchmark::State& state) {
  diffdyn::PushingConfig config;
  config.obstacle = false;
  diffdyn::PushingEnv env(config);
  diffdyn::Rng rng(7);
  int k = 0;
  long steps = 0;
  for (auto _ : state) {
    if (k % 10 == 0) env.Reset({0.4, 0.0, 0.2 * std::numbers::pi});
    const auto r = env.Step(diffdyn::SamplePushAction(rng));
    steps += r.steps;
    k = r.status == diffdyn::PushStatus::kOk ? k + 1 : 0;
    benchmark::DoNotOptimize(r.pose);
  }
  state.counters["pushes_per_second"] = benchmark::Counter(
      static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["world_steps_per_push"] =
      static_cast<double>(steps) / static_cast<double>(state.iterations());
}
BENCHMARK(BM_PushOneThread)->Unit(benchmark::kMillisecond);

// CollectPushingData on one thread: 20 trajectories of 10 pushes per iteration.
void BM_CollectOneThread(benchmark::State& state) {
  diffdyn::CollectOptions options;
  options.trajectories = 20;
  options.length = 10;
  options.threads = 1;
  options.world.obstacle = false;
  long pushes = 0;
  for (auto _ : state) {
    diffdyn::CollectStats stats;
    benchmark::DoNotOptimize(diffdyn::CollectPushingData(options, &stats));
    pushes += stats.pushes;
  }
  state.counters["pushes_per_second"] =
      benchmark::Counter(static_cast<double>(pushes), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_CollectOneThread)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
