// 1000 input Jacobians (3 x 6) of a 6-100-100-3 softplus network, double:
// closed-form forward chain, batched reverse mode, per-sample closed form and
// Jets. The PyTorch reference is bench/models_jacobian_torch.py.
//
//   OPENBLAS_NUM_THREADS=1 build/bench/bench_models_jacobian
#include <benchmark/benchmark.h>

#include <ceres/jet.h>

#include "diffdyn/models/init.h"
#include "diffdyn/models/mlp.h"

namespace diffdyn {
namespace {

constexpr int kBatch = 1000;

struct Problem {
  Mlp<double> net;
  Eigen::MatrixXd x;
};

const Problem& GetProblem() {
  static const Problem problem = [] {
    const MlpArchitecture arch{{6, 100, 100, 3}, {Activation::Softplus(), Activation::Softplus()}};
    Problem p{MakeInitializedMlp(arch, InitOptions{}, 1), Eigen::MatrixXd(6, kBatch)};
    Rng rng(2);
    for (Eigen::Index i = 0; i < p.x.size(); ++i) p.x.data()[i] = StandardNormal(rng);
    return p;
  }();
  return problem;
}

// Forward chain U_l = W_l Z_l over the batch (one GEMM per layer).
void BM_JacobianClosedFormChain(benchmark::State& state) {
  const Problem& p = GetProblem();
  const int threads = static_cast<int>(state.range(0));
  MlpWorkspace ws(p.net.architecture(), kBatch, (kBatch + threads - 1) / threads);
  Eigen::MatrixXd y, jac;
  for (auto _ : state) {
    p.net.Forward(p.x, &y, &jac, &ws, threads);
    benchmark::DoNotOptimize(jac.data());
  }
  state.counters["jacobians/s"] =
      benchmark::Counter(kBatch, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_JacobianClosedFormChain)->Arg(1)->Arg(2)->UseRealTime()->Unit(benchmark::kMicrosecond);

// Three stacked backward sweeps (n_L = 3 < n_0 = 6).
void BM_JacobianBatchedReverse(benchmark::State& state) {
  const Problem& p = GetProblem();
  const int threads = static_cast<int>(state.range(0));
  // Chunks of 250 samples: the three stacked sweeps (100 x 750) stay in L2.
  MlpWorkspace ws(p.net.architecture(), kBatch, kBatch / 4, false);
  Eigen::MatrixXd y, jac;
  for (auto _ : state) {
    p.net.InputJacobianReverse(p.x, &y, &jac, &ws, threads);
    benchmark::DoNotOptimize(jac.data());
  }
  state.counters["jacobians/s"] =
      benchmark::Counter(kBatch, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_JacobianBatchedReverse)->Arg(1)->Arg(2)->UseRealTime()->Unit(benchmark::kMicrosecond);

// The closed-form chain one sample at a time (no batching).
void BM_JacobianPerSampleClosedForm(benchmark::State& state) {
  const Problem& p = GetProblem();
  Eigen::VectorXd y;
  Eigen::MatrixXd jac;
  for (auto _ : state) {
    for (int b = 0; b < kBatch; ++b) {
      p.net.ValueAndJacobian(p.x.col(b), &y, &jac);
      benchmark::DoNotOptimize(jac.data());
    }
  }
  state.counters["jacobians/s"] =
      benchmark::Counter(kBatch, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_JacobianPerSampleClosedForm)->Unit(benchmark::kMicrosecond);

// Forward-mode Jets (6 directions) through the generic templated path.
void BM_JacobianJets(benchmark::State& state) {
  using Jet6 = ceres::Jet<double, 6>;
  const Problem& p = GetProblem();
  Eigen::Matrix<Jet6, Eigen::Dynamic, 1> x(6);
  Eigen::MatrixXd jac(3, 6);
  for (auto _ : state) {
    for (int b = 0; b < kBatch; ++b) {
      for (int i = 0; i < 6; ++i) x[i] = Jet6(p.x(i, b), i);
      const auto y = p.net(x);
      for (int k = 0; k < 3; ++k) jac.row(k) = y[k].v.transpose();
      benchmark::DoNotOptimize(jac.data());
    }
  }
  state.counters["jacobians/s"] =
      benchmark::Counter(kBatch, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_JacobianJets)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace diffdyn

BENCHMARK_MAIN();
