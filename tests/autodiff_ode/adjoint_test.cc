// Discrete and continuous adjoints on a tiny MLP-driven system, against Jets through the
// same solver steps and central differences.
#include "diffdyn/autodiff_ode/adjoint.h"

#include <cmath>
#include <cstdio>
#include <limits>
#include <vector>

#include <gtest/gtest.h>

#include "diffdyn/autodiff_ode/jacobian.h"
#include "diffdyn/models/random.h"

namespace diffdyn {
namespace {

// dz/dt = W2 tanh(W1 z + b1 + t v) + b2 with theta = [W1 (h x n), b1, W2 (n x h), b2]
// (column-major); v is a fixed time direction, not a parameter.
template <typename S>
class TinyMlpT {
 public:
  using Scalar = S;
  using Mat = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;
  using Vec = Eigen::Matrix<S, Eigen::Dynamic, 1>;
  struct Workspace {
    Mat act, grad_pre;
  };
  TinyMlpT(int n, int h, std::uint64_t seed) : n_(n), h_(h), theta_(h * n + h + n * h + n), v_(h) {
    Rng rng(seed);
    for (S& x : theta_) x = S(0.6 * StandardNormal(rng));
    for (S& x : v_) x = S(StandardNormal(rng));
  }
  int state_size() const { return n_; }
  int num_params() const { return static_cast<int>(theta_.size()); }
  const Vec& theta() const { return theta_; }
  void set_theta(const Eigen::VectorXd& theta) { theta_ = theta.cast<S>(); }
  Workspace MakeWorkspace(int batch) const { return {Mat(h_, batch), Mat(h_, batch)}; }

  void Eval(const Eigen::Ref<const Mat>& z, double t, Eigen::Ref<Mat> dzdt, Workspace& ws) const {
    Forward(z, t, ws);
    dzdt.noalias() = W2() * ws.act;
    dzdt.colwise() += b2();
  }

  void Vjp(const Eigen::Ref<const Mat>& z, double t, const Eigen::Ref<const Mat>& lambda,
           Eigen::Ref<Mat> vjp_z, Eigen::Ref<Vec> grad, Workspace& ws) const {
    Forward(z, t, ws);
    // Gradient of the pre-activation: (W2^T lambda) * (1 - tanh^2).
    ws.grad_pre.noalias() = W2().transpose() * lambda;
    ws.grad_pre.array() *= S(1) - ws.act.array().square();
    vjp_z.noalias() = W1().transpose() * ws.grad_pre;
    Eigen::Map<Mat>(grad.data(), h_, n_).noalias() += ws.grad_pre * z.transpose();
    grad.segment(h_ * n_, h_) += ws.grad_pre.rowwise().sum();
    Eigen::Map<Mat>(grad.data() + h_ * n_ + h_, n_, h_).noalias() += lambda * ws.act.transpose();
    grad.tail(n_) += lambda.rowwise().sum();
  }

  // Single-sample dynamics on any scalar with parameters theta (p) of that scalar.
  template <typename T>
  void Rhs(const VectorX<T>& theta, const VectorX<T>& z, double t, VectorX<T>& dz) const {
    using M = Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic>;
    const Eigen::Map<const M> w1(theta.data(), h_, n_);
    const Eigen::Map<const M> w2(theta.data() + h_ * n_ + h_, n_, h_);
    VectorX<T> pre = w1 * z + theta.segment(h_ * n_, h_) + v_.template cast<T>() * T(t);
    for (int i = 0; i < h_; ++i) pre[i] = tanh(pre[i]);
    dz = w2 * pre + theta.tail(n_);
  }

 private:
  void Forward(const Eigen::Ref<const Mat>& z, double t, Workspace& ws) const {
    ws.act.noalias() = W1() * z;
    ws.act.colwise() += b1() + S(t) * v_;
    ws.act = ws.act.array().tanh();
  }
  Eigen::Map<const Mat> W1() const { return {theta_.data(), h_, n_}; }
  Eigen::VectorBlock<const Vec> b1() const { return theta_.segment(h_ * n_, h_); }
  Eigen::Map<const Mat> W2() const { return {theta_.data() + h_ * n_ + h_, n_, h_}; }
  Eigen::VectorBlock<const Vec> b2() const { return theta_.tail(n_); }

  int n_, h_;
  Vec theta_, v_;
};

using TinyMlp = TinyMlpT<double>;

static_assert(BatchedVjpSystem<TinyMlp>);

constexpr int kN = 3, kHidden = 6, kBatch = 4;
const std::vector<double> kTimes{0.0, 0.3, 0.7, 1.0};

struct Problem {
  TinyMlp mlp{kN, kHidden, 7};
  Eigen::MatrixXd z0;
  std::vector<Eigen::MatrixXd> weights;  // L = sum_i <weights[i], z(t_i)>, so dL/dz(t_i) = weights[i]
  Problem() {
    Rng rng(11);
    z0.resize(kN, kBatch);
    for (double& x : z0.reshaped()) x = StandardNormal(rng);
    for (size_t i = 0; i < kTimes.size(); ++i) {
      Eigen::MatrixXd w(kN, kBatch);
      for (double& x : w.reshaped()) x = StandardNormal(rng);
      weights.push_back(i == 1 ? Eigen::MatrixXd() : w);  // no loss at t_1: empty allowed
    }
  }
  template <typename T>
  T Loss(const std::vector<VectorX<T>>& outputs, int b) const {
    T loss(0.0);
    for (size_t i = 0; i < outputs.size(); ++i) {
      if (weights[i].size() == 0) continue;
      for (int j = 0; j < kN; ++j) loss += weights[i](j, b) * outputs[i][j];
    }
    return loss;
  }
};

// Loss of one sample through fixed steps of `options` (IntegrateTimes), any scalar.
template <typename T>
T FixedStepLoss(const Problem& pr, const VectorX<T>& theta, const VectorX<T>& z0, int b,
                const OdeOptions& options) {
  auto sys = [&](const VectorX<T>& z, VectorX<T>& dz, double t) { pr.mlp.Rhs(theta, z, t, dz); };
  std::vector<VectorX<T>> outs;
  VectorX<T> z = z0;
  IntegrateTimes(sys, z, kTimes, options, [&](int, double, const VectorX<T>& x) { outs.push_back(x); });
  return pr.Loss(outs, b);
}

// Loss of one sample replaying the recorded steps of `solver` with the tableau's b.
template <Method M, typename T>
T ReplayLoss(const Problem& pr, const BatchedOdeSolver<TinyMlp>& solver, const VectorX<T>& theta,
             const VectorX<T>& z0, int b) {
  auto sys = [&](const VectorX<T>& z, VectorX<T>& dz, double t) { pr.mlp.Rhs(theta, z, t, dz); };
  auto stepper = MakeFixedStepper<M, VectorX<T>>();
  std::vector<VectorX<T>> outs{z0};
  VectorX<T> z = z0;
  for (size_t i = 1; i < kTimes.size(); ++i) {
    for (int k = solver.output_steps()[i - 1]; k < solver.output_steps()[i]; ++k) {
      stepper.do_step(sys, z, solver.step_times()[k], solver.step_sizes()[k]);
    }
    outs.push_back(z);
  }
  return pr.Loss(outs, b);
}

// Gradients (dL/dtheta, dL/dz0) of a per-sample loss by Jets, in chunks of 8.
template <typename LossFn>
void JetGradients(const Problem& pr, LossFn loss, Eigen::VectorXd* g_theta, Eigen::MatrixXd* g_z0) {
  const Eigen::VectorXd theta = pr.mlp.theta();
  g_theta->setZero(theta.size());
  g_z0->resize(kN, kBatch);
  for (int b = 0; b < kBatch; ++b) {
    const Eigen::VectorXd z0 = pr.z0.col(b);
    *g_theta += JacobianDynamic<8>(
                    [&](const VectorX<JetK<8>>& th) {
                      return VectorX<JetK<8>>::Constant(1, loss(th, z0.cast<JetK<8>>().eval(), b));
                    },
                    theta)
                    .row(0)
                    .transpose();
    g_z0->col(b) = JacobianDynamic<8>(
                       [&](const VectorX<JetK<8>>& z) {
                         return VectorX<JetK<8>>::Constant(1, loss(theta.cast<JetK<8>>().eval(), z, b));
                       },
                       z0)
                       .row(0)
                       .transpose();
  }
}

double RelErr(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return (a - b).norm() / b.norm();
}

TEST(DiscreteAdjoint, EqualsJetsForEveryFixedStepMethod) {
  const Problem pr;
  for (Method m : {Method::kEuler, Method::kMidpoint, Method::kRk4Classic, Method::kRk4}) {
    OdeOptions options;
    options.method = m;
    options.dt = 0.1;
    BatchedOdeSolver<TinyMlp> solver(pr.mlp, options);
    std::vector<Eigen::MatrixXd> outputs;
    solver.Forward(pr.z0, kTimes, &outputs);
    EXPECT_EQ(solver.num_steps(), 10);
    Eigen::MatrixXd g_z0;
    Eigen::VectorXd g_theta;
    solver.BackwardDiscrete(pr.weights, &g_z0, &g_theta);
    Eigen::VectorXd jet_theta;
    Eigen::MatrixXd jet_z0;
    JetGradients(pr, [&](const auto& th, const auto& z0, int b) {
      return FixedStepLoss(pr, th, z0, b, options);
    }, &jet_theta, &jet_z0);
    EXPECT_LT(RelErr(g_theta, jet_theta), 1e-10) << MethodName(m);
    EXPECT_LT(RelErr(g_z0, jet_z0), 1e-10) << MethodName(m);
    // Central differences of the batched forward loss.
    auto loss_of_theta = [&](const Eigen::VectorXd& th) {
      TinyMlp mlp = pr.mlp;
      mlp.set_theta(th);
      BatchedOdeSolver<TinyMlp> s(mlp, options);
      std::vector<Eigen::MatrixXd> outs;
      s.Forward(pr.z0, kTimes, &outs, false);
      double loss = 0;
      for (size_t i = 0; i < outs.size(); ++i) {
        if (pr.weights[i].size() > 0) loss += (pr.weights[i].array() * outs[i].array()).sum();
      }
      return Eigen::VectorXd::Constant(1, loss);
    };
    const Eigen::VectorXd fd = JacobianCentralDifference(loss_of_theta, pr.mlp.theta()).row(0);
    EXPECT_LT(RelErr(fd, g_theta), 1e-6) << MethodName(m);
  }
}

template <Method M>
void CheckAdaptiveRecordedSteps(double tol) {
  const Problem pr;
  OdeOptions options;
  options.method = M;
  options.abs_tol = options.rel_tol = tol;
  options.dt = 0.05;
  BatchedOdeSolver<TinyMlp> solver(pr.mlp, options);
  std::vector<Eigen::MatrixXd> outputs;
  const IntegrationStats stats = solver.Forward(pr.z0, kTimes, &outputs);
  EXPECT_GT(stats.accepted_steps, 3);
  Eigen::MatrixXd g_z0;
  Eigen::VectorXd g_theta;
  solver.BackwardDiscrete(pr.weights, &g_z0, &g_theta);
  Eigen::VectorXd jet_theta;
  Eigen::MatrixXd jet_z0;
  JetGradients(pr, [&](const auto& th, const auto& z0, int b) {
    return ReplayLoss<M>(pr, solver, th, z0, b);
  }, &jet_theta, &jet_z0);
  EXPECT_LT(RelErr(g_theta, jet_theta), 1e-10) << MethodName(M);
  EXPECT_LT(RelErr(g_z0, jet_z0), 1e-10) << MethodName(M);
  // Forward outputs agree with the single-sample replay on doubles.
  for (int b = 0; b < kBatch; ++b) {
    const double replay = ReplayLoss<M>(pr, solver, pr.mlp.theta(), Eigen::VectorXd(pr.z0.col(b)), b);
    double batched = 0;
    for (size_t i = 0; i < outputs.size(); ++i) {
      if (pr.weights[i].size() > 0) batched += pr.weights[i].col(b).dot(outputs[i].col(b));
    }
    EXPECT_NEAR(batched, replay, 1e-12 * std::max(1.0, std::abs(replay)));
  }
}

TEST(DiscreteAdjoint, Dopri5RecordedStepsEqualJets) { CheckAdaptiveRecordedSteps<Method::kDopri5>(1e-6); }
TEST(DiscreteAdjoint, CashKarpRecordedStepsEqualJets) { CheckAdaptiveRecordedSteps<Method::kCashKarp>(1e-6); }

TEST(DiscreteAdjoint, BatchedForwardMatchesOdeintDopri5) {
  // Same tableau, different controllers: both are within the tolerance of the true flow.
  const Problem pr;
  OdeOptions options;
  options.abs_tol = options.rel_tol = 1e-10;
  BatchedOdeSolver<TinyMlp> solver(pr.mlp, options);
  std::vector<Eigen::MatrixXd> outputs;
  solver.Forward(pr.z0, kTimes, &outputs, false);
  for (int b = 0; b < kBatch; ++b) {
    auto sys = [&](const Eigen::VectorXd& z, Eigen::VectorXd& dz, double t) {
      pr.mlp.Rhs(pr.mlp.theta(), z, t, dz);
    };
    Eigen::VectorXd z = pr.z0.col(b);
    IntegrateTimes(sys, z, kTimes, options, [&](int i, double, const Eigen::VectorXd& x) {
      EXPECT_LT((x - outputs[i].col(b)).norm(), 1e-8) << "sample " << b << " time " << i;
    });
  }
}

TEST(ContinuousAdjoint, ConvergesToDopri5GradientAsToleranceTightens) {
  const Problem pr;
  // Reference: discrete adjoint through dopri5 at tolerance 1e-12 (= Jets through those steps).
  OdeOptions tight;
  tight.abs_tol = tight.rel_tol = 1e-12;
  BatchedOdeSolver<TinyMlp> reference(pr.mlp, tight);
  std::vector<Eigen::MatrixXd> outputs;
  reference.Forward(pr.z0, kTimes, &outputs);
  Eigen::MatrixXd ref_z0;
  Eigen::VectorXd ref_theta;
  reference.BackwardDiscrete(pr.weights, &ref_z0, &ref_theta);

  std::vector<double> errors;
  for (double tol : {1e-4, 1e-6, 1e-8, 1e-10}) {
    OdeOptions options;
    options.abs_tol = options.rel_tol = tol;
    BatchedOdeSolver<TinyMlp> solver(pr.mlp, options);
    solver.Forward(pr.z0, kTimes, &outputs, /*record_tape=*/false);
    Eigen::MatrixXd g_z0;
    Eigen::VectorXd g_theta;
    solver.BackwardContinuous(pr.weights, options, &g_z0, &g_theta);
    errors.push_back(std::max(RelErr(g_theta, ref_theta), RelErr(g_z0, ref_z0)));
    std::printf("continuous adjoint, tolerance %.0e: relative error %.2e\n", tol, errors.back());
  }
  for (size_t i = 1; i < errors.size(); ++i) EXPECT_LT(errors[i], errors[i - 1]) << i;
  EXPECT_GT(errors.front(), 1e-7);  // loose tolerance: visibly different
  EXPECT_LT(errors.back(), 1e-7);
  // Central differences of the loss through the tight forward pass, a few parameters.
  for (int k : {0, 17, 40}) {
    auto loss = [&](double delta) {
      TinyMlp mlp = pr.mlp;
      Eigen::VectorXd th = mlp.theta();
      th[k] += delta;
      mlp.set_theta(th);
      BatchedOdeSolver<TinyMlp> s(mlp, tight);
      std::vector<Eigen::MatrixXd> outs;
      s.Forward(pr.z0, kTimes, &outs, false);
      double l = 0;
      for (size_t i = 0; i < outs.size(); ++i) {
        if (pr.weights[i].size() > 0) l += (pr.weights[i].array() * outs[i].array()).sum();
      }
      return l;
    };
    const double fd = (loss(1e-5) - loss(-1e-5)) / 2e-5;
    EXPECT_NEAR(fd, ref_theta[k], 1e-6 * std::max(1.0, std::abs(fd))) << "parameter " << k;
  }
}

TEST(ContinuousAdjoint, FixedStepBackwardSolver) {
  const Problem pr;
  OdeOptions forward;
  forward.abs_tol = forward.rel_tol = 1e-12;
  BatchedOdeSolver<TinyMlp> solver(pr.mlp, forward);
  std::vector<Eigen::MatrixXd> outputs;
  solver.Forward(pr.z0, kTimes, &outputs);
  Eigen::MatrixXd ref_z0, g_z0;
  Eigen::VectorXd ref_theta, g_theta;
  solver.BackwardDiscrete(pr.weights, &ref_z0, &ref_theta);
  OdeOptions backward;
  backward.method = Method::kRk4;
  backward.dt = 0.01;
  solver.BackwardContinuous(pr.weights, backward, &g_z0, &g_theta);
  EXPECT_LT(RelErr(g_theta, ref_theta), 1e-6);
  EXPECT_LT(RelErr(g_z0, ref_z0), 1e-6);
}

TEST(Adjoint, SizeErrorsNameSizes) {
  const Problem pr;
  OdeOptions options;
  BatchedOdeSolver<TinyMlp> solver(pr.mlp, options);
  std::vector<Eigen::MatrixXd> outputs;
  try {
    solver.Forward(Eigen::MatrixXd::Zero(2, 5), kTimes, &outputs);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("z0 has 2 rows, the system's state has 3"), std::string::npos)
        << e.what();
  }
  solver.Forward(pr.z0, kTimes, &outputs);
  std::vector<Eigen::MatrixXd> bad = pr.weights;
  bad[2] = Eigen::MatrixXd::Zero(3, 2);
  Eigen::MatrixXd g_z0;
  Eigen::VectorXd g_theta;
  try {
    solver.BackwardDiscrete(bad, &g_z0, &g_theta);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("dL/dz[2] is 3 x 2, expected 3 x 4"), std::string::npos)
        << e.what();
  }
  bad.pop_back();
  EXPECT_THROW(solver.BackwardContinuous(bad, options, &g_z0, &g_theta), Error);
}

// dz/dt = (0, z_1^2, 0) per sample: entry 1 of a sample with z_1(0) = 2 blows up at t = 0.5.
struct BatchedBlowUp {
  struct Workspace {};
  int state_size() const { return 3; }
  int num_params() const { return 0; }
  Workspace MakeWorkspace(int) const { return {}; }
  void Eval(const Eigen::Ref<const Eigen::MatrixXd>& z, double, Eigen::Ref<Eigen::MatrixXd> dzdt,
            Workspace&) const {
    dzdt.setZero();
    dzdt.row(1) = z.row(1).array().square().matrix();
  }
  void Vjp(const Eigen::Ref<const Eigen::MatrixXd>& z, double,
           const Eigen::Ref<const Eigen::MatrixXd>& lambda, Eigen::Ref<Eigen::MatrixXd> vjp_z,
           Eigen::Ref<Eigen::VectorXd>, Workspace&) const {
    vjp_z.setZero();
    vjp_z.row(1) = 2.0 * z.row(1).cwiseProduct(lambda.row(1));
  }
};

TEST(Adjoint, NonFiniteStateNamesTimeEntryAndSample) {
  Eigen::MatrixXd z0 = Eigen::MatrixXd::Zero(3, 3);
  z0(1, 2) = 2.0;  // sample 2 blows up
  for (Method m : {Method::kRk4, Method::kDopri5}) {
    OdeOptions options;
    options.method = m;
    const BatchedBlowUp system;
    BatchedOdeSolver<BatchedBlowUp> solver(system, options);
    std::vector<Eigen::MatrixXd> outputs;
    try {
      solver.Forward(z0, {0.0, 1.0}, &outputs);
      FAIL() << MethodName(m);
    } catch (const NumericalError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find("entry 1 of sample 2"), std::string::npos) << msg;
      EXPECT_NE(msg.find("t = 0.5"), std::string::npos) << msg;
    }
  }
}

// The float solver on the same system as the double one (weights rounded to float):
// states, dL/dz0 and dL/dtheta agree to float rounding, relative to max(1, |x|), and
// differ from the double ones somewhere (so the float path did run in float).
struct FloatRun {
  std::vector<Eigen::MatrixXd> outputs;
  Eigen::MatrixXd g_z0;
  Eigen::VectorXd g_theta;
  long steps = 0;
};

template <typename S>
FloatRun RunIn(const Problem& pr, const OdeOptions& options, bool continuous) {
  using Mat = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;
  TinyMlpT<S> system(kN, kHidden, 7);
  system.set_theta(pr.mlp.theta().template cast<float>().template cast<double>());
  BatchedOdeSolver<TinyMlpT<S>> solver(system, options);
  std::vector<Mat> outputs, weights;
  for (const Eigen::MatrixXd& w : pr.weights) weights.push_back(w.cast<S>());
  const Mat z0 = pr.z0.cast<float>().cast<S>();
  FloatRun run;
  run.steps = solver.Forward(z0, kTimes, &outputs, !continuous).accepted_steps;
  Mat g_z0;
  Eigen::Matrix<S, Eigen::Dynamic, 1> g_theta;
  if (continuous) {
    OdeOptions backward;
    backward.method = Method::kRk4;
    backward.dt = 0.01;
    solver.BackwardContinuous(weights, backward, &g_z0, &g_theta);
  } else {
    solver.BackwardDiscrete(weights, &g_z0, &g_theta);
  }
  for (const Mat& o : outputs) run.outputs.push_back(o.template cast<double>());
  run.g_z0 = g_z0.template cast<double>();
  run.g_theta = g_theta.template cast<double>();
  return run;
}

// max_i |a_i - b_i| / max(1, |b_i|) in units of float's epsilon.
double FloatUlps(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  const double eps = std::numeric_limits<float>::epsilon();
  return ((a - b).array().abs() / b.array().abs().max(1.0)).maxCoeff() / eps;
}

TEST(BatchedOdeSolverFloat, StatesAndAdjointsMatchDoubleToFloatRounding) {
  const Problem pr;
  struct Case {
    Method method;
    bool continuous;
  };
  for (const Case c : {Case{Method::kRk4, false}, Case{Method::kEuler, false},
                       Case{Method::kDopri5, false}, Case{Method::kRk4, true}}) {
    OdeOptions options;
    options.method = c.method;
    options.dt = 0.05;
    options.abs_tol = options.rel_tol = 1e-4;
    const FloatRun f = RunIn<float>(pr, options, c.continuous);
    const FloatRun d = RunIn<double>(pr, options, c.continuous);
    const std::string label = MethodName(c.method) + (c.continuous ? " continuous" : " discrete");
    EXPECT_EQ(f.steps, d.steps) << label;
    double largest = 0;
    for (size_t i = 0; i < d.outputs.size(); ++i) {
      EXPECT_LT(FloatUlps(f.outputs[i], d.outputs[i]), 256) << label << ", output " << i;
      largest = std::max(largest, (f.outputs[i] - d.outputs[i]).cwiseAbs().maxCoeff());
    }
    EXPECT_LT(FloatUlps(f.g_z0, d.g_z0), 1024) << label;
    EXPECT_LT(FloatUlps(f.g_theta, d.g_theta), 1024) << label;
    EXPECT_GT(largest, 0.0) << label << ": the float solver gave the double result";
  }
}

}  // namespace
}  // namespace diffdyn
