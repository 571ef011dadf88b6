// Input Jacobian (3 x 6) of one sample through a 6-100-100-3 tanh network: Jets
// (fixed-size Jacobian<6> and the chunked JacobianDynamic<8>) against central
// finite differences (12 evaluations on doubles, Eigen GEMV).
//
//   build-ad/bench/bench_autodiff_jacobian
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "diffdyn/autodiff_ode/jacobian.h"
#include "diffdyn/models/random.h"

namespace diffdyn {
namespace {

// y = W3 tanh(W2 tanh(W1 x + b1) + b2) + b3 with double weights, any input scalar.
struct Network {
  std::vector<Eigen::MatrixXd> w;
  std::vector<Eigen::VectorXd> b;

  Network() {
    const int sizes[] = {6, 100, 100, 3};
    Rng rng(3);
    for (int l = 0; l < 3; ++l) {
      Eigen::MatrixXd wl(sizes[l + 1], sizes[l]);
      for (double& x : wl.reshaped()) x = StandardNormal(rng) / std::sqrt(sizes[l]);
      Eigen::VectorXd bl(sizes[l + 1]);
      for (double& x : bl) x = 0.1 * StandardNormal(rng);
      w.push_back(wl);
      b.push_back(bl);
    }
  }

  // Dense layer: GEMV on doubles, an explicit double x Jet loop on Jets.
  template <typename T>
  static VectorX<T> Layer(const Eigen::MatrixXd& w, const Eigen::VectorXd& b, const VectorX<T>& x,
                          bool activate) {
    VectorX<T> y(w.rows());
    if constexpr (std::is_same_v<T, double>) {
      y.noalias() = w * x + b;
    } else {
      for (Eigen::Index i = 0; i < w.rows(); ++i) y[i] = T(b[i]);
      for (Eigen::Index j = 0; j < w.cols(); ++j) {
        for (Eigen::Index i = 0; i < w.rows(); ++i) y[i] += w(i, j) * x[j];
      }
    }
    if (activate) {
      for (Eigen::Index i = 0; i < y.size(); ++i) {
        using std::tanh;
        y[i] = tanh(y[i]);
      }
    }
    return y;
  }

  template <typename T>
  VectorX<T> operator()(const VectorX<T>& x) const {
    return Layer(w[2], b[2], Layer(w[1], b[1], Layer(w[0], b[0], x, true), true), false);
  }
  template <typename T>
  Eigen::Matrix<T, 3, 1> operator()(const Eigen::Matrix<T, 6, 1>& x) const {
    return (*this)(VectorX<T>(x));
  }
};

const Network& Net() {
  static const Network net;
  return net;
}

Eigen::Matrix<double, 6, 1> Input() {
  Eigen::Matrix<double, 6, 1> x;
  x << 0.3, -0.7, 1.1, 0.2, -0.4, 0.9;
  return x;
}

void BM_JacobianJetsFixed(benchmark::State& state) {
  const Eigen::Matrix<double, 6, 1> x = Input();
  for (auto _ : state) {
    auto jac = Jacobian<6>(Net(), x);
    benchmark::DoNotOptimize(jac.data());
  }
  state.counters["jacobians/s"] = benchmark::Counter(1, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_JacobianJetsFixed)->Unit(benchmark::kMicrosecond);

void BM_JacobianJetsChunked8(benchmark::State& state) {
  const Eigen::VectorXd x = Input();
  for (auto _ : state) {
    Eigen::MatrixXd jac = JacobianDynamic<8>(Net(), x);
    benchmark::DoNotOptimize(jac.data());
  }
  state.counters["jacobians/s"] = benchmark::Counter(1, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_JacobianJetsChunked8)->Unit(benchmark::kMicrosecond);

void BM_JacobianCentralDifferences(benchmark::State& state) {
  const Eigen::VectorXd x = Input();
  auto f = [](const Eigen::VectorXd& v) { return Net()(v); };
  for (auto _ : state) {
    Eigen::MatrixXd jac = JacobianCentralDifference(f, x);
    benchmark::DoNotOptimize(jac.data());
  }
  state.counters["jacobians/s"] = benchmark::Counter(1, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_JacobianCentralDifferences)->Unit(benchmark::kMicrosecond);

// Accuracy next to speed: max |J_jets - J_fd| (reported once as a counter).
void BM_JetsVsDifferencesMaxDiff(benchmark::State& state) {
  const Eigen::VectorXd x = Input();
  double diff = 0;
  for (auto _ : state) {
    const Eigen::MatrixXd fd =
        JacobianCentralDifference([](const Eigen::VectorXd& v) { return Net()(v); }, x);
    diff = (JacobianDynamic<8>(Net(), x) - fd).cwiseAbs().maxCoeff();
  }
  state.counters["max_abs_diff"] = diff;
}
BENCHMARK(BM_JetsVsDifferencesMaxDiff)->Iterations(1);

}  // namespace
}  // namespace diffdyn

BENCHMARK_MAIN();
