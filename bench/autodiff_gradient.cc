// Gradient of L = sum_b <w_b, z_b(1)> with respect to the parameters of an MLP ODE
// dz/dt = MLP(z), three ways: forward Jets (chunks of 8 directions, one integration
// per chunk and sample), the discrete adjoint and the continuous adjoint
// (BatchedOdeSolver). All through the rk4 (3/8) solver with 10 steps on [0, 1]; the
// continuous adjoint integrates backward with the same 10 steps.
//
// Crossover: a 2-h-2 tanh network with h = 1, 2, 20, 2000 (p = 7, 12, 102, 10,002), batch 4.
// Training scale: a 3-100-100-3 tanh network (p = 10,803), batch 500, rk4 and dopri5.
//
//   build-ad/bench/bench_autodiff_gradient
//   OPENBLAS_NUM_THREADS=1 /usr/bin/python3 bench/autodiff_gradient_torch.py
#include <benchmark/benchmark.h>

#include <array>
#include <cmath>
#include <vector>

#include "diffdyn/autodiff_ode/adjoint.h"
#include "diffdyn/autodiff_ode/jacobian.h"
#include "diffdyn/models/random.h"

namespace diffdyn {
namespace {

// tanh on doubles, vectorized. Eigen 3.4 vectorizes exp for double but calls scalar
// std::tanh (it dominated this benchmark, as it would any double tanh network). For
// |x| >= 0.3: tanh x = sign(x) (1 - 2 / (exp(2|x|) + 1)) (at most ~2 bits lost to
// cancellation); for |x| < 0.3 the Taylor series x sum_k t_k x^(2k), whose terms shrink
// by (0.3 / (pi/2))^2 < 0.04, so 12 terms reach rounding. t_k from tanh' = 1 - tanh^2.
constexpr int kTanhTerms = 12;
std::array<double, kTanhTerms> TanhTaylor() {
  std::array<double, 2 * kTanhTerms + 1> a{};  // a[n]: coefficient of x^n
  a[1] = 1.0;
  for (int n = 1; n < 2 * kTanhTerms; ++n) {
    double sum = 0;
    for (int i = 0; i <= n; ++i) sum += a[i] * a[n - i];
    a[n + 1] = -sum / (n + 1);
  }
  std::array<double, kTanhTerms> t{};
  for (int k = 0; k < kTanhTerms; ++k) t[k] = a[2 * k + 1];
  return t;
}
const std::array<double, kTanhTerms> kTanhT = TanhTaylor();

// a <- tanh(a) in packets of Eigen's SIMD primitives (Eigen's array select and sign
// do not vectorize on doubles); a must be contiguous; the tail uses std::tanh.
void TanhInPlace(Eigen::Ref<Eigen::MatrixXd> a) {
  namespace ei = Eigen::internal;
  using Packet = ei::packet_traits<double>::type;
  constexpr int kWidth = ei::packet_traits<double>::size;
  double* data = a.data();
  const Eigen::Index n = a.size();
  const Packet one = ei::pset1<Packet>(1.0), two = ei::pset1<Packet>(2.0);
  const Packet threshold = ei::pset1<Packet>(0.3), zero = ei::pset1<Packet>(0.0);
  Eigen::Index i = 0;
  for (; i + kWidth <= n; i += kWidth) {
    const Packet x = ei::ploadu<Packet>(data + i);
    const Packet y = ei::pabs(x);
    const Packet y2 = ei::pmul(y, y);
    Packet series = ei::pset1<Packet>(kTanhT[kTanhTerms - 1]);
    for (int k = kTanhTerms - 2; k >= 0; --k) {
      series = ei::pmadd(series, y2, ei::pset1<Packet>(kTanhT[k]));
    }
    const Packet small = ei::pmul(y, series);
    const Packet big = ei::psub(one, ei::pdiv(two, ei::padd(ei::pexp(ei::padd(y, y)), one)));
    const Packet r = ei::pselect(ei::pcmp_lt(y, threshold), small, big);
    ei::pstoreu(data + i, ei::pselect(ei::pcmp_lt(x, zero), ei::pnegate(r), r));
  }
  for (; i < n; ++i) data[i] = std::tanh(data[i]);
}

// dz/dt = W_L tanh(... tanh(W_1 z + b_1) ...) + b_L, theta = [W_1, b_1, ..., W_L, b_L].
class MlpOde {
 public:
  struct Workspace {
    std::vector<Eigen::MatrixXd> act;  // act[0] = z, act[l] = output of hidden layer l
    Eigen::MatrixXd grad, next;
  };

  explicit MlpOde(std::vector<int> sizes) : sizes_(std::move(sizes)) {
    int p = 0;
    for (size_t l = 0; l + 1 < sizes_.size(); ++l) {
      offsets_.push_back(p);
      p += sizes_[l + 1] * sizes_[l] + sizes_[l + 1];
    }
    theta_.resize(p);
    Rng rng(5);
    for (size_t l = 0; l + 1 < sizes_.size(); ++l) {
      for (int k = 0; k < sizes_[l + 1] * sizes_[l]; ++k) {
        theta_[offsets_[l] + k] = StandardNormal(rng) / std::sqrt(sizes_[l]);
      }
      for (int k = 0; k < sizes_[l + 1]; ++k) {
        theta_[offsets_[l] + sizes_[l + 1] * sizes_[l] + k] = 0.1 * StandardNormal(rng);
      }
    }
  }
  int state_size() const { return sizes_.front(); }
  int num_params() const { return static_cast<int>(theta_.size()); }
  const Eigen::VectorXd& theta() const { return theta_; }

  Workspace MakeWorkspace(int batch) const {
    Workspace ws;
    for (size_t l = 0; l + 1 < sizes_.size(); ++l) ws.act.emplace_back(sizes_[l], batch);
    int widest = 0;
    for (int s : sizes_) widest = std::max(widest, s);
    ws.grad.resize(widest, batch);
    ws.next.resize(widest, batch);
    return ws;
  }

  void Eval(const Eigen::Ref<const Eigen::MatrixXd>& z, double, Eigen::Ref<Eigen::MatrixXd> dzdt,
            Workspace& ws) const {
    const int layers = static_cast<int>(sizes_.size()) - 1;
    Hidden(z, ws);
    dzdt.noalias() = W(layers - 1) * ws.act[layers - 1];
    dzdt.colwise() += B(layers - 1);
  }

  void Vjp(const Eigen::Ref<const Eigen::MatrixXd>& z, double,
           const Eigen::Ref<const Eigen::MatrixXd>& lambda, Eigen::Ref<Eigen::MatrixXd> vjp_z,
           Eigen::Ref<Eigen::VectorXd> grad, Workspace& ws) const {
    const int layers = static_cast<int>(sizes_.size()) - 1;
    Hidden(z, ws);
    // Backward through the layers; g holds dL/d(output of layer l).
    ws.grad.topRows(sizes_[layers]) = lambda;
    for (int l = layers - 1; l >= 0; --l) {
      auto g = ws.grad.topRows(sizes_[l + 1]);
      GradW(l, grad).noalias() += g * ws.act[l].transpose();
      GradB(l, grad) += g.rowwise().sum();
      auto next = ws.next.topRows(sizes_[l]);
      next.noalias() = W(l).transpose() * g;
      if (l > 0) {
        next.array() *= 1.0 - ws.act[l].array().square();
        ws.grad.topRows(sizes_[l]) = next;
      } else {
        vjp_z = next;
      }
    }
  }

  // Single sample, any scalar, parameters of that scalar (the forward-Jet path).
  template <typename T>
  void Rhs(const VectorX<T>& theta, const VectorX<T>& z, VectorX<T>& dz) const {
    VectorX<T> a = z;
    const int layers = static_cast<int>(sizes_.size()) - 1;
    for (int l = 0; l < layers; ++l) {
      const int rows = sizes_[l + 1], cols = sizes_[l];
      const T* w = theta.data() + offsets_[l];
      VectorX<T> y = Eigen::Map<const VectorX<T>>(w + rows * cols, rows);
      for (int j = 0; j < cols; ++j) {
        for (int i = 0; i < rows; ++i) y[i] += w[i + rows * j] * a[j];
      }
      if (l + 1 < layers) {
        using std::tanh;
        for (int i = 0; i < rows; ++i) y[i] = tanh(y[i]);
      }
      a = std::move(y);
    }
    dz = a;
  }

 private:
  void Hidden(const Eigen::Ref<const Eigen::MatrixXd>& z, Workspace& ws) const {
    ws.act[0] = z;
    for (size_t l = 1; l + 1 < sizes_.size(); ++l) {
      ws.act[l].noalias() = W(l - 1) * ws.act[l - 1];
      ws.act[l].colwise() += B(l - 1);
      TanhInPlace(ws.act[l]);
    }
  }
  Eigen::Map<const Eigen::MatrixXd> W(int l) const {
    return {theta_.data() + offsets_[l], sizes_[l + 1], sizes_[l]};
  }
  Eigen::Map<const Eigen::VectorXd> B(int l) const {
    return {theta_.data() + offsets_[l] + sizes_[l + 1] * sizes_[l], sizes_[l + 1]};
  }
  Eigen::Map<Eigen::MatrixXd> GradW(int l, Eigen::Ref<Eigen::VectorXd>& g) const {
    return {g.data() + offsets_[l], sizes_[l + 1], sizes_[l]};
  }
  Eigen::Map<Eigen::VectorXd> GradB(int l, Eigen::Ref<Eigen::VectorXd>& g) const {
    return {g.data() + offsets_[l] + sizes_[l + 1] * sizes_[l], sizes_[l + 1]};
  }

  std::vector<int> sizes_;
  std::vector<int> offsets_;
  Eigen::VectorXd theta_;
};

struct Setup {
  MlpOde ode;
  Eigen::MatrixXd z0, weight;
  Setup(std::vector<int> sizes, int batch) : ode(std::move(sizes)) {
    Rng rng(9);
    const int n = ode.state_size();
    z0.resize(n, batch);
    weight.resize(n, batch);
    for (double& x : z0.reshaped()) x = StandardNormal(rng);
    for (double& x : weight.reshaped()) x = StandardNormal(rng);
  }
};

const std::vector<double> kTimes{0.0, 1.0};

OdeOptions Rk4TenSteps() {
  OdeOptions o;
  o.method = Method::kRk4;
  o.dt = 0.1;
  return o;
}

OdeOptions Dopri5() {
  OdeOptions o;
  o.method = Method::kDopri5;
  o.abs_tol = o.rel_tol = 1e-6;
  o.dt = 0.1;
  return o;
}

// Crossover networks 2-h-2, batch 4 (h = 1: p = 7 fits one Jet chunk of 8).
constexpr int kSmallBatch = 4;
void CrossoverArgs(benchmark::internal::Benchmark* b) { b->Arg(1)->Arg(2)->Arg(20)->Arg(2000); }

// dL/dtheta by forward Jets: ceil(p / 8) chunks, each integrating every sample.
void GradientByJets(const Setup& s, Eigen::VectorXd* grad) {
  constexpr int kK = 8;
  const int p = s.ode.num_params();
  grad->resize(p);
  VectorX<JetK<kK>> theta;
  for (int offset = 0; offset < p; offset += kK) {
    SeedJets<kK>(s.ode.theta(), offset, &theta);
    auto sys = [&](const VectorX<JetK<kK>>& z, VectorX<JetK<kK>>& dz, double) {
      s.ode.Rhs(theta, z, dz);
    };
    JetK<kK> loss(0.0);
    for (int b = 0; b < kSmallBatch; ++b) {
      VectorX<JetK<kK>> z = s.z0.col(b).cast<JetK<kK>>();
      IntegrateFixedSteps(Method::kRk4, sys, z, 0.0, 1.0, 10);
      for (int i = 0; i < z.size(); ++i) loss += s.weight(i, b) * z[i];
    }
    const int width = std::min(kK, p - offset);
    grad->segment(offset, width) = loss.v.head(width);
  }
}

void BM_GradientForwardJets(benchmark::State& state) {
  const Setup s({2, static_cast<int>(state.range(0)), 2}, kSmallBatch);
  Eigen::VectorXd grad;
  for (auto _ : state) {
    GradientByJets(s, &grad);
    benchmark::DoNotOptimize(grad.data());
  }
  state.counters["params"] = s.ode.num_params();
}
BENCHMARK(BM_GradientForwardJets)->Apply(CrossoverArgs)->Unit(benchmark::kMillisecond);

template <bool kContinuous>
void GradientAdjoint(benchmark::State& state, const Setup& s, const OdeOptions& options) {
  BatchedOdeSolver<MlpOde> solver(s.ode, options);
  std::vector<Eigen::MatrixXd> outputs;
  const std::vector<Eigen::MatrixXd> dl_dz{Eigen::MatrixXd(), s.weight};
  Eigen::MatrixXd g_z0;
  Eigen::VectorXd g_theta;
  for (auto _ : state) {
    solver.Forward(s.z0, kTimes, &outputs, /*record_tape=*/!kContinuous);
    if constexpr (kContinuous) {
      solver.BackwardContinuous(dl_dz, options, &g_z0, &g_theta);
    } else {
      solver.BackwardDiscrete(dl_dz, &g_z0, &g_theta);
    }
    benchmark::DoNotOptimize(g_theta.data());
  }
  state.counters["params"] = s.ode.num_params();
  state.counters["forward_steps"] = solver.num_steps();
}

void BM_GradientDiscreteAdjoint(benchmark::State& state) {
  const Setup s({2, static_cast<int>(state.range(0)), 2}, kSmallBatch);
  GradientAdjoint<false>(state, s, Rk4TenSteps());
}
BENCHMARK(BM_GradientDiscreteAdjoint)->Apply(CrossoverArgs)->Unit(benchmark::kMillisecond);

void BM_GradientContinuousAdjoint(benchmark::State& state) {
  const Setup s({2, static_cast<int>(state.range(0)), 2}, kSmallBatch);
  GradientAdjoint<true>(state, s, Rk4TenSteps());
}
BENCHMARK(BM_GradientContinuousAdjoint)->Apply(CrossoverArgs)->Unit(benchmark::kMillisecond);

// Not a timing: relative difference of the discrete-adjoint and Jet gradients (2-20-2).
void BM_CheckAdjointEqualsJets(benchmark::State& state) {
  const Setup s({2, 20, 2}, kSmallBatch);
  BatchedOdeSolver<MlpOde> solver(s.ode, Rk4TenSteps());
  std::vector<Eigen::MatrixXd> outputs;
  Eigen::MatrixXd g_z0;
  Eigen::VectorXd g_theta, jets;
  double diff = 0;
  for (auto _ : state) {
    solver.Forward(s.z0, kTimes, &outputs);
    solver.BackwardDiscrete({Eigen::MatrixXd(), s.weight}, &g_z0, &g_theta);
    GradientByJets(s, &jets);
    diff = (g_theta - jets).norm() / jets.norm();
  }
  state.counters["relative_difference"] = diff;
}
BENCHMARK(BM_CheckAdjointEqualsJets)->Iterations(1);

// Not a timing: largest relative error of TanhInPlace against std::tanh on [-25, 25].
void BM_CheckVectorizedTanh(benchmark::State& state) {
  Eigen::MatrixXd x(1, 100001);
  double worst = 0;
  for (auto _ : state) {
    for (Eigen::Index i = 0; i < x.size(); ++i) x(i) = -25.0 + 5e-4 * static_cast<double>(i);
    x(50000) = 1e-300;
    const Eigen::MatrixXd reference = x.array().tanh();
    TanhInPlace(x);
    worst = ((x - reference).array().abs() / reference.array().abs().max(1e-300)).maxCoeff();
  }
  state.counters["max_relative_error"] = worst;
}
BENCHMARK(BM_CheckVectorizedTanh)->Iterations(1);

// Training scale: 3-100-100-3, batch 500.
const Setup& TrainingSetup() {
  static const Setup s({3, 100, 100, 3}, 500);
  return s;
}

void BM_TrainScaleDiscreteRk4(benchmark::State& state) {
  GradientAdjoint<false>(state, TrainingSetup(), Rk4TenSteps());
}
BENCHMARK(BM_TrainScaleDiscreteRk4)->Unit(benchmark::kMillisecond);

void BM_TrainScaleContinuousRk4(benchmark::State& state) {
  GradientAdjoint<true>(state, TrainingSetup(), Rk4TenSteps());
}
BENCHMARK(BM_TrainScaleContinuousRk4)->Unit(benchmark::kMillisecond);

void BM_TrainScaleDiscreteDopri5(benchmark::State& state) {
  GradientAdjoint<false>(state, TrainingSetup(), Dopri5());
}
BENCHMARK(BM_TrainScaleDiscreteDopri5)->Unit(benchmark::kMillisecond);

void BM_TrainScaleContinuousDopri5(benchmark::State& state) {
  GradientAdjoint<true>(state, TrainingSetup(), Dopri5());
}
BENCHMARK(BM_TrainScaleContinuousDopri5)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace diffdyn

BENCHMARK_MAIN();
