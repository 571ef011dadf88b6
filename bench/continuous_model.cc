// The continuous-time adapter's overhead: a batched rollout of the analytic
// pendulum (AnalyticDynamics<PendulumModel>, x = (q, qd), u = tau) through
// ContinuousTransitionModel::PredictBatch (odeint's rk4-classic stepper), against a
// hand-written classic RK4 loop calling the same dynamics functor with preallocated
// buffers. 1000 samples, 50 transitions of dt = 0.01 s, 4 substeps each.
//
//   build/bench/bench_continuous_model
#include <benchmark/benchmark.h>

#include <vector>

#include "diffdyn/models/continuous_model.h"
#include "diffdyn/models/random.h"
#include "diffdyn/physics/analytic_model.h"
#include "diffdyn/physics/simple_models.h"

namespace diffdyn {
namespace {

constexpr int kSamples = 1000, kSteps = 50, kSubsteps = 4;
constexpr double kDt = 0.01;
using Dynamics = AnalyticDynamics<PendulumModel>;

struct Inputs {
  Eigen::MatrixXd x0, u;
  Eigen::VectorXd theta;
};

const Inputs& Data() {
  static const Inputs in = [] {
    Rng rng(1);
    Inputs d;
    d.x0.resize(2, kSamples);
    d.u.resize(1, kSamples);
    for (Eigen::Index i = 0; i < d.x0.size(); ++i) d.x0.data()[i] = StandardNormal(rng);
    for (Eigen::Index i = 0; i < d.u.size(); ++i) d.u.data()[i] = StandardNormal(rng);
    d.theta = AnalyticModelAdapter<PendulumModel>().DefaultParams();
    return d;
  }();
  return in;
}

void BM_Adapter(benchmark::State& state) {
  const Inputs& in = Data();
  const ContinuousTransitionModel<Dynamics> model(
      Dynamics{}, AnalyticSystem(AnalyticModelAdapter<PendulumModel>()), in.theta,
      {.method = Method::kRk4Classic, .dt = kDt, .substeps = kSubsteps});
  auto ws = model.MakeWorkspace(kSamples);
  Eigen::MatrixXd x(2, kSamples), next(2, kSamples);
  for (auto _ : state) {
    x = in.x0;
    for (int t = 0; t < kSteps; ++t) {
      model.PredictBatch(x, in.u, next, *ws);
      x.swap(next);
    }
    benchmark::DoNotOptimize(x.data());
  }
  state.counters["per_transition"] = benchmark::Counter(
      static_cast<double>(kSamples) * kSteps, benchmark::Counter::kIsIterationInvariantRate |
                                                  benchmark::Counter::kInvert);
}
BENCHMARK(BM_Adapter)->Unit(benchmark::kMillisecond);

void BM_HandWrittenRk4(benchmark::State& state) {
  const Inputs& in = Data();
  const Dynamics f;
  const double h = kDt / kSubsteps;
  Eigen::VectorXd x(2), u(1), k1(2), k2(2), k3(2), k4(2), tmp(2);
  Eigen::MatrixXd out(2, kSamples);
  for (auto _ : state) {
    for (int b = 0; b < kSamples; ++b) {
      x = in.x0.col(b);
      u = in.u.col(b);
      for (int t = 0; t < kSteps; ++t) {
        for (int s = 0; s < kSubsteps; ++s) {
          const double t0 = (t * kSubsteps + s) * h;
          f(x, u, in.theta, t0, k1);
          tmp = x + 0.5 * h * k1;
          f(tmp, u, in.theta, t0 + 0.5 * h, k2);
          tmp = x + 0.5 * h * k2;
          f(tmp, u, in.theta, t0 + 0.5 * h, k3);
          tmp = x + h * k3;
          f(tmp, u, in.theta, t0 + h, k4);
          x += (h / 6) * (k1 + 2 * k2 + 2 * k3 + k4);
        }
      }
      out.col(b) = x;
    }
    benchmark::DoNotOptimize(out.data());
  }
  state.counters["per_transition"] = benchmark::Counter(
      static_cast<double>(kSamples) * kSteps, benchmark::Counter::kIsIterationInvariantRate |
                                                  benchmark::Counter::kInvert);
}
BENCHMARK(BM_HandWrittenRk4)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace diffdyn

BENCHMARK_MAIN();
