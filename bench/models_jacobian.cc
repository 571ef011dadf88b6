// 1000 input Jacobians (3 x 6) of a 6-100-100-3 softplus network: closed-form
// forward chain and batched reverse mode in double and float, per-sample closed
// form and Jets in double. The PyTorch reference is bench/models_jacobian_torch.py.
//
//   OPENBLAS_NUM_THREADS=1 build/bench/bench_models_jacobian
#include <benchmark/benchmark.h>

#include <ceres/jet.h>

#include "diffdyn/models/init.h"
#include "diffdyn/models/mlp.h"

namespace diffdyn {
namespace {

constexpr int kBatch = 1000;

// The network and the 1000 inputs in scalar S.
template <typename S>
struct Problem {
  Mlp<S> net;
  Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic> x;
};

template <typename S>
const Problem<S>& GetProblem() {
  static const Problem<S> problem = [] {
    const MlpArchitecture arch{{6, 100, 100, 3}, {Activation::Softplus(), Activation::Softplus()}};
    Problem<S> p{MakeInitializedMlp(arch, InitOptions{}, 1).template cast<S>(),
                 Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>(6, kBatch)};
    Rng rng(2);
    for (Eigen::Index i = 0; i < p.x.size(); ++i) p.x.data()[i] = static_cast<S>(StandardNormal(rng));
    return p;
  }();
  return problem;
}

// Forward chain U_l = W_l Z_l over the batch (one GEMM per layer).
template <typename S>
void BM_JacobianClosedFormChain(benchmark::State& state) {
  const Problem<S>& p = GetProblem<S>();
  const int threads = static_cast<int>(state.range(0));
  BasicMlpWorkspace<S> ws(p.net.architecture(), kBatch, (kBatch + threads - 1) / threads);
  Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic> y, jac;
  for (auto _ : state) {
    p.net.Forward(p.x, &y, &jac, &ws, threads);
    benchmark::DoNotOptimize(jac.data());
  }
  state.counters["jacobians/s"] =
      benchmark::Counter(kBatch, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_JacobianClosedFormChain<double>)->Arg(1)->Arg(2)->UseRealTime()->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_JacobianClosedFormChain<float>)->Arg(1)->Arg(2)->UseRealTime()->Unit(benchmark::kMicrosecond);

// Three stacked backward sweeps (n_L = 3 < n_0 = 6).
template <typename S>
void BM_JacobianBatchedReverse(benchmark::State& state) {
  const Problem<S>& p = GetProblem<S>();
  const int threads = static_cast<int>(state.range(0));
  // Chunks of 250 samples: the three stacked sweeps (100 x 750) stay in L2.
  BasicMlpWorkspace<S> ws(p.net.architecture(), kBatch, kBatch / 4, false);
  Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic> y, jac;
  for (auto _ : state) {
    p.net.InputJacobianReverse(p.x, &y, &jac, &ws, threads);
    benchmark::DoNotOptimize(jac.data());
  }
  state.counters["jacobians/s"] =
      benchmark::Counter(kBatch, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_JacobianBatchedReverse<double>)->Arg(1)->Arg(2)->UseRealTime()->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_JacobianBatchedReverse<float>)->Arg(1)->Arg(2)->UseRealTime()->Unit(benchmark::kMicrosecond);

// The closed-form chain one sample at a time (no batching).
void BM_JacobianPerSampleClosedForm(benchmark::State& state) {
  const Problem<double>& p = GetProblem<double>();
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
  const Problem<double>& p = GetProblem<double>();
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
