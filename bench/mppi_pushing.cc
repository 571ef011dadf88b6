// Time per MPPI command on the obstacle pushing task (PushingCost with the 100 x
// collision term, action bounds of the seed, Sigma = 0.5 I, lambda = 0.01), K = 1000
// samples, from the task's start pose (0.4, 0, -0.2 pi):
//
//   BM_MppiAbsNode/T/threads   abs-NODE 6-100-100-6 ReLU, rk4 3/8 rule on 10 grid
//                              points (9 steps), T = 20 and 30, 1 and 2 threads
//   BM_MppiResNn/30/threads    res-NN 6-100-100-3 ReLU, T = 30
//   BM_MppiAbsNodeF32, BM_MppiResNnF32   the same in float32 (the models' batched
//                              paths in float, LearnedModelConfig::precision)
//   (a third argument is the chunk size, 0 = MppiOptions' default; BM_MppiChunks
//    tries others at T = 20 on 2 threads)
//   BM_PeakDgemm*2Threads      the machine's two-thread dgemm peak, Eigen and OpenBLAS
//                              (peak_dgemm.h); the best of the two is the peak
//
// The models have fixed-seed random weights; they are written as model files
// (mppi_abs_node.json, mppi_res_nn.json) next to the benchmark output (the directory
// of --benchmark_out, else $BENCH_OUT, else build/bench-results) so that the PyTorch
// reference bench/mppi_pushing_torch.py runs the SAME models.
//
// Counters: "GFLOP/s" counts the dense matrix flops of a command, 2 x (multiply-adds
// of one MLP evaluation) x K x T x (evaluations per step: 36 for rk4 on 9 steps, 1 for
// the NN), what PyTorch computes; the layer kernel skips ReLU units that are zero for a
// whole block of 32 samples, so this rate can exceed the machine's dgemm peak; cpu_time
// is the whole process's CPU time (both threads).
//
//   OPENBLAS_NUM_THREADS=1 build/bench/bench_mppi_pushing   (from the repository root)
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <filesystem>
#include <numbers>
#include <string>
#include <string_view>

#include "diffdyn/models/learned_model.h"
#include "diffdyn/solvers/mppi.h"
#include "diffdyn/solvers/pushing/cost.h"
#include "peak_dgemm.h"

namespace diffdyn {
namespace {

constexpr int kSamples = 1000;

LearnedModel MakeModel(LearnedKind type, Precision precision) {
  LearnedModelConfig config;
  config.type = type;
  config.hidden = 100;
  config.method = Method::kRk4;
  config.steps = 10;
  config.precision = precision;
  return LearnedModel::Initialized(config, 42);
}

// The same weights in either precision (the parameters stay double).
const LearnedModel& AbsNode(Precision precision = Precision::kF64) {
  static const LearnedModel f64 = MakeModel(LearnedKind::kAbsNode, Precision::kF64);
  static const LearnedModel f32 = MakeModel(LearnedKind::kAbsNode, Precision::kF32);
  return precision == Precision::kF32 ? f32 : f64;
}

const LearnedModel& ResNn(Precision precision = Precision::kF64) {
  static const LearnedModel f64 = MakeModel(LearnedKind::kResNn, Precision::kF64);
  static const LearnedModel f32 = MakeModel(LearnedKind::kResNn, Precision::kF32);
  return precision == Precision::kF32 ? f32 : f64;
}

// The seed's MPPI settings for the obstacle task.
MppiOptions TaskOptions(int horizon, int threads) {
  MppiOptions o;
  o.samples = kSamples;
  o.horizon = horizon;
  o.lambda = 0.01;
  o.noise_variance = 0.5;
  o.u_min.resize(3);
  o.u_max.resize(3);
  o.u_min << -1, -std::numbers::pi / 2, 0;
  o.u_max << 1, std::numbers::pi / 2, 1;
  o.threads = threads;
  return o;
}

// The third argument overrides MppiOptions::chunk_size (0: the default).

// Multiply-adds of one evaluation of an MLP 6-100-100-out, times 2.
double FlopsPerEval(int out) { return 2.0 * (6 * 100 + 100 * 100 + 100 * out); }

void RunCommands(benchmark::State& state, const LearnedModel& model, double evals_per_step) {
  const int horizon = static_cast<int>(state.range(0));
  const int threads = static_cast<int>(state.range(1));
  const PushingCost cost({0.8, -0.1, 0.0}, /*obstacle=*/true);
  MppiOptions options = TaskOptions(horizon, threads);
  if (state.range(2) > 0) options.chunk_size = static_cast<int>(state.range(2));
  Mppi mppi(model, cost, options, 7);
  const Eigen::Vector3d x(0.4, 0.0, -0.2 * std::numbers::pi);
  benchmark::DoNotOptimize(mppi.Command(x).data());  // warm-up
  for (auto _ : state) {
    Eigen::VectorXd u = mppi.Command(x);
    benchmark::DoNotOptimize(u.data());
  }
  const int out = model.config().type == LearnedKind::kAbsNode ? 6 : 3;
  const double flops = FlopsPerEval(out) * evals_per_step * kSamples * horizon;
  state.counters["GFLOP/s"] =
      benchmark::Counter(flops * 1e-9, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["command_flops_G"] = flops * 1e-9;
}

void BM_MppiAbsNode(benchmark::State& state) { RunCommands(state, AbsNode(), 36); }
BENCHMARK(BM_MppiAbsNode)
    ->Args({20, 1, 0})->Args({20, 2, 0})->Args({30, 1, 0})->Args({30, 2, 0})
    ->UseRealTime()->MeasureProcessCPUTime()->Unit(benchmark::kMillisecond)->MinTime(1.0);

void BM_MppiResNn(benchmark::State& state) { RunCommands(state, ResNn(), 1); }
BENCHMARK(BM_MppiResNn)
    ->Args({30, 1, 0})->Args({30, 2, 0})
    ->UseRealTime()->MeasureProcessCPUTime()->Unit(benchmark::kMillisecond)->MinTime(0.5);

void BM_MppiAbsNodeF32(benchmark::State& state) { RunCommands(state, AbsNode(Precision::kF32), 36); }
BENCHMARK(BM_MppiAbsNodeF32)
    ->Args({20, 1, 0})->Args({20, 2, 0})->Args({30, 1, 0})->Args({30, 2, 0})
    ->UseRealTime()->MeasureProcessCPUTime()->Unit(benchmark::kMillisecond)->MinTime(1.0);

void BM_MppiResNnF32(benchmark::State& state) { RunCommands(state, ResNn(Precision::kF32), 1); }
BENCHMARK(BM_MppiResNnF32)
    ->Args({30, 1, 0})->Args({30, 2, 0})
    ->UseRealTime()->MeasureProcessCPUTime()->Unit(benchmark::kMillisecond)->MinTime(0.5);

void BM_MppiChunks(benchmark::State& state) { RunCommands(state, AbsNode(), 36); }
BENCHMARK(BM_MppiChunks)
    ->Args({20, 2, 125})->Args({20, 2, 500})
    ->UseRealTime()->MeasureProcessCPUTime()->Unit(benchmark::kMillisecond)->MinTime(1.0);

void BM_PeakDgemm2Threads(benchmark::State& state) { bench::PeakGemm2Threads<double>(state); }
BENCHMARK(BM_PeakDgemm2Threads)->UseRealTime()->Unit(benchmark::kMillisecond)->MinTime(1.0);

void BM_PeakDgemmOpenBlas2Threads(benchmark::State& state) {
  bench::PeakGemmOpenBlas2Threads<double>(state);
}
BENCHMARK(BM_PeakDgemmOpenBlas2Threads)->UseRealTime()->Unit(benchmark::kMillisecond)->MinTime(1.0);

// The directory the results go to: that of --benchmark_out=..., else $BENCH_OUT,
// else build/bench-results (scripts/run-bench's default).
std::filesystem::path FindOutputDir(int argc, char** argv) {
  constexpr std::string_view kFlag = "--benchmark_out=";
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg.substr(0, kFlag.size()) == kFlag) {
      const std::filesystem::path p(std::string(arg.substr(kFlag.size())));
      return p.has_parent_path() ? p.parent_path() : std::filesystem::path(".");
    }
  }
  if (const char* env = std::getenv("BENCH_OUT")) return env;
  return "build/bench-results";
}

}  // namespace
}  // namespace diffdyn

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  const fs::path dir = diffdyn::FindOutputDir(argc, argv);
  fs::create_directories(dir);
  const nlohmann::json provenance = {{"program", "bench_mppi_pushing"}, {"seed", 42}};
  diffdyn::SaveLearnedModel(dir / "mppi_abs_node.json", diffdyn::AbsNode(), provenance);
  diffdyn::SaveLearnedModel(dir / "mppi_res_nn.json", diffdyn::ResNn(), provenance);
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
