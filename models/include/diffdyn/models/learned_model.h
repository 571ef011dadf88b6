// The four learned transition models of the NeuralODE-Panda paper, for any system.
//
// State x (n components) and action u (m) are those of a SystemDescription
// (system_description.h); pushing (x, y, theta; push location, angle, length) is
// one system among others. Each model is x_{t+1} = F(x_t, u_t):
//
//   abs-nn     F = N(phi([x; u]))              N: MLP f-h-h-n
//   res-nn     F = x + N(phi([x; u]))
//   abs-node   F = P z(1)                      z(0) = [x; u] in R^(n+m),  dz/dt = M(phi(z)),
//   res-node   F = x + P z(1)                  z(0) = [wrap(x); u],  M: MLP f-h-h-(n+m),
//                                              P = [I_n 0]
//
// phi is the description's feature map: the identity, except that with
// angle_features = sincos each angle component x_i becomes (sin x_i, cos x_i), so f =
// n + m + (number of angles). The NeuralODE is autonomous and the action rides along
// as ODE state; the ODE state stays [x; u], only the network sees features.
//
// res-node on angles. Its flow must carry z from x_t to x_{t+1} - x_t, i.e. move each
// angle by about -x_i. A field periodic in x_i (sin/cos features) moves x_i and
// x_i + 2 pi by the same amount, so no such field can do that on the whole circle;
// and a raw angle of many turns would make the move unbounded. So res-node starts
// from wrap(x), each angle component wrapped to (-pi, pi] (the identity on states
// that are not angles or already lie there), and needs raw angle features
// (LearnedModelConfig::Validate). F stays x_t + P z(1) exactly, and shifting an
// angle by 2 pi shifts the prediction by 2 pi. wrap has derivative 1 almost
// everywhere, so gradients are those of the unwrapped start.
// z(1) comes from one Runge-Kutta method (butcher.h) on t in [0, 1]: a fixed-step
// method takes steps - 1 equal steps h = 1 / (steps - 1) (`steps` grid points, as the
// paper's torch.linspace(0, 1, steps)); dopri5 is adaptive with abs = rel tolerance
// 1e-8 and integrates straight to t = 1 (torchdiffeq interpolates the grid; only
// z(1) is used, so the grid does not matter). Outputs are not wrapped: losses
// compare angle components on the circle.
//
// Optional scalings (Scaling, fitted to the data by FitScaling) put the network's
// inputs and outputs on unit scale, as state components in SI units (a cart's
// metres, a joint's rad/s, torques in N m) are not: the network sees
// (phi - mu_in) / sigma_in, and N(.) above stands for mu_out + sigma_out * MLP(.).
// Without them (the paper's pushing models) both maps are the identity.
//
// Three paths compute F:
//
// 1. PredictBatch (TransitionModel): B samples at once, samples in columns, as
//    GEMMs through the MLP (BatchedOdeSolver for the NeuralODEs). For MPPI and eval.
// 2. Forward / Backward (training): Forward records a tape in the workspace;
//    Backward takes gbar = dL/dx_{t+1} (n x B) and returns
//
//      dL/dtheta += sum_b (dF/dtheta)^T gbar_b,      dL/dx_t = (dF/dx_t)^T gbar,
//
//    by the MLP's batched VJPs (and phi's); for the NeuralODEs through the discrete
//    adjoint of the solver (adjoint.h), i.e. the exact gradient of the discrete map,
//    with the adjoint seeded as dL/dz(1) = [gbar; 0]; the residual variants add gbar
//    to dL/dx_t. dL/dx_t lets multi-step rollouts x^_{k+1} = F(x^_k, u_k) backpropagate.
// 3. Predict and PredictLearned<P>: one sample on any scalar (double or ceres::Jet,
//    in the state, the action, or the parameters via Mlp<P>), the NODE integrated by
//    odeint (integrate.h) on Jet states. Tests pin 1 = 2 = 3.
//
// The batched paths never allocate once the workspace has seen the batch size.
//
//   LearnedModelConfig config{.type = LearnedKind::kAbsNode, .system = pendulum};
//   LearnedModel model = LearnedModel::Initialized(config, 7);
//   auto ws = model.MakeWorkspace(500);
//   model.Forward(states, actions, next, *ws);               // n x B, m x B, n x B
//   model.Backward(dl_dnext, *ws, &grad_theta, &dl_dstates);  // accumulates grad_theta
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <filesystem>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <numeric>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "diffdyn/autodiff_ode/adjoint.h"
#include "diffdyn/autodiff_ode/butcher.h"
#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/autodiff_ode/integrate.h"
#include "diffdyn/models/init.h"
#include "diffdyn/models/input_features.h"
#include "diffdyn/models/mlp.h"
#include "diffdyn/models/model_file.h"
#include "diffdyn/models/precision.h"
#include "diffdyn/models/system_description.h"
#include "diffdyn/models/transition_model.h"

namespace diffdyn {

/// The four model types; their command-line / model-file names are
/// "abs-nn", "res-nn", "abs-node", "res-node".
enum class LearnedKind { kAbsNn, kResNn, kAbsNode, kResNode };

/// The name of `type` ("abs-nn", ...).
inline std::string LearnedKindName(LearnedKind type) {
  switch (type) {
    case LearnedKind::kAbsNn:
      return "abs-nn";
    case LearnedKind::kResNn:
      return "res-nn";
    case LearnedKind::kAbsNode:
      return "abs-node";
    case LearnedKind::kResNode:
      return "res-node";
  }
  return "abs-nn";
}

/// Parses "abs-nn", "res-nn", "abs-node" or "res-node"; throws diffdyn::Error
/// naming `option` and the bad value otherwise.
inline LearnedKind ParseLearnedKind(const std::string& name,
                                    const std::string& option = "--model") {
  for (LearnedKind t :
       {LearnedKind::kAbsNn, LearnedKind::kResNn, LearnedKind::kAbsNode, LearnedKind::kResNode}) {
    if (name == LearnedKindName(t)) return t;
  }
  throw Error(StrCat(option, ": unknown model '", name,
                     "' (expected abs-nn, res-nn, abs-node or res-node)"));
}

/// Whether `type` is a NeuralODE (abs-node, res-node).
inline bool IsNeuralOde(LearnedKind type) {
  return type == LearnedKind::kAbsNode || type == LearnedKind::kResNode;
}

/// Whether `type` adds x_t to the network output (res-nn, res-node).
inline bool IsResidual(LearnedKind type) {
  return type == LearnedKind::kResNn || type == LearnedKind::kResNode;
}

/// Whether `type` starts its flow from the wrapped angles (res-node; file comment).
inline bool StartsFromWrappedAngles(LearnedKind type) { return type == LearnedKind::kResNode; }

/// How `type` sees angles unless told otherwise: raw for res-node, whose field must
/// not be periodic (file comment), (sin, cos) for the others.
inline AngleFeatures DefaultAngleFeatures(LearnedKind type) {
  return StartsFromWrappedAngles(type) ? AngleFeatures::kRaw : AngleFeatures::kSinCos;
}

/// a wrapped to (-pi, pi] on any scalar: a double, or a Jet whose value is wrapped
/// and whose derivative parts are kept (the wrap's derivative is 1).
template <typename T>
T WrappedAngle(const T& a) {
  if constexpr (std::is_same_v<T, double>) {
    return WrapAngle(a);
  } else {
    T w = a;
    w.a = WrapAngle(a.a);
    return w;
  }
}

/// Affine maps around a learned model's network (see the file comment): the network
/// input is (phi - input_shift) / input_scale (f entries each), its output
/// output_shift + output_scale * MLP (the MLP's outputs each). Empty vectors: identity.
struct Scaling {
  Eigen::VectorXd input_shift, input_scale, output_shift, output_scale;

  bool has_input() const { return input_scale.size() > 0; }
  bool has_output() const { return output_scale.size() > 0; }

  /// Throws diffdyn::Error unless each pair is empty or of the given size, finite,
  /// with positive scales.
  void Validate(int inputs, int outputs) const {
    const auto check = [](const Eigen::VectorXd& shift, const Eigen::VectorXd& scale, int size,
                          const char* what) {
      if (shift.size() == 0 && scale.size() == 0) return;
      DIFFDYN_CHECK(shift.size() == size && scale.size() == size, "scaling: ", what, " needs ",
                    size, " shifts and scales, got ", shift.size(), " and ", scale.size());
      DIFFDYN_CHECK(shift.allFinite() && scale.allFinite() && (scale.array() > 0).all(),
                    "scaling: ", what, " shifts must be finite and scales positive");
    };
    check(input_shift, input_scale, inputs, "input");
    check(output_shift, output_scale, outputs, "output");
  }
};

/// Everything that fixes a model's function apart from its parameters.
struct LearnedModelConfig {
  /// Widest hidden layer accepted (a 4096-wide square layer holds 16.8 M parameters).
  static constexpr int kMaxHidden = 4096;
  /// Most NeuralODE grid points accepted.
  static constexpr int kMaxSteps = 10000;

  LearnedKind type = LearnedKind::kAbsNode;
  /// h, the width of both hidden layers, 1 to kMaxHidden.
  int hidden = 100;
  /// NeuralODE solver (ignored by the NNs).
  Method method = Method::kRk4;
  /// NeuralODE grid points on [0, 1] (2 to kMaxSteps): steps - 1 fixed steps; dopri5's first
  /// trial step is 1 / (steps - 1).
  int steps = 10;
  /// dopri5 absolute = relative tolerance.
  double tolerance = 1e-8;
  /// Hidden activation (the paper: ReLU). A smooth one (tanh) makes the NeuralODE's
  /// flow smooth in theta, which adaptive solvers' error control assumes.
  Activation activation = Activation::Relu();
  /// The system: n, m and the angle features (default: 3 unnamed states and actions).
  SystemDescription system = SystemDescription::Unnamed(3, 3);
  /// Input and output scalings of the network (default: none).
  Scaling scaling{};
  /// The batched paths' precision (precision.h); parameters stay double.
  Precision precision = Precision::kF64;

  /// Sizes (f, h, h, n) for the NNs, (f, h, h, n + m) for the NeuralODEs, f the
  /// system's feature size; `activation` on both hidden layers.
  MlpArchitecture Architecture() const {
    const int n = system.state_size(), m = system.action_size();
    const int out = IsNeuralOde(type) ? n + m : n;
    return {{system.feature_size(), hidden, hidden, out}, {activation, activation}};
  }

  /// Throws diffdyn::Error naming the option for hidden outside [1, kMaxHidden], steps
  /// outside [2, kMaxSteps] or tolerance <= 0, or for an invalid system.
  void Validate() const {
    system.Validate();
    DIFFDYN_CHECK(hidden >= 1 && hidden <= kMaxHidden, "--hidden must be in [1, ", kMaxHidden,
                  "], got ", hidden);
    DIFFDYN_CHECK(steps >= 2 && steps <= kMaxSteps, "--steps must be in [2, ", kMaxSteps,
                  "] (grid points on [0, 1]), got ", steps);
    DIFFDYN_CHECK(tolerance > 0 && std::isfinite(tolerance), "tolerance must be positive, got ",
                  tolerance);
    DIFFDYN_CHECK(!(StartsFromWrappedAngles(type) && system.encodes_angles()),
                  LearnedKindName(type),
                  ": angles must be raw features (--angle-features raw): a field periodic in an "
                  "angle cannot carry it to x_{t+1} - x_t");
    const MlpArchitecture arch = Architecture();
    scaling.Validate(arch.sizes.front(), arch.sizes.back());
  }

  /// Solver options: dt = 1 / (steps - 1); for dopri5 also abs = rel = tolerance.
  OdeOptions ode_options() const {
    OdeOptions o;
    o.method = method;
    o.dt = 1.0 / (steps - 1);
    o.abs_tol = tolerance;
    o.rel_tol = tolerance;
    return o;
  }
};

/// The network input (phi([x; u]) - input_shift) / input_scale of a learned model
/// (see the file comment). Built once from the description and the scaling;
/// `identity()` when no angle is encoded and there is no input scaling.
class FeatureMap {
 public:
  FeatureMap() = default;
  explicit FeatureMap(const SystemDescription& system, const Scaling& scaling = {})
      : inputs_(system.state_size() + system.action_size()), features_(system.feature_size()) {
    if (scaling.has_input()) {
      shift_ = scaling.input_shift;
      inv_scale_ = scaling.input_scale.cwiseInverse();
    }
    if (!system.encodes_angles()) return;
    for (int i = 0; i < inputs_; ++i) {
      if (i < system.state_size() && system.is_angle(i)) angles_.periodic.push_back(i);
    }
  }

  /// Whether the map is the identity.
  bool identity() const { return angles_.periodic.empty() && shift_.size() == 0; }
  /// f, the number of features.
  int features() const { return features_; }

  /// f = phi(z) for a batch: z (n + m) x B, f (f x B; resized); float or double, f's
  /// scalar that of z.
  template <typename DZ, typename F>
  void Apply(const Eigen::MatrixBase<DZ>& z, F& f) const {
    using S = typename F::Scalar;
    angles_.Encode(z, &f);
    if (shift_.size() > 0) {
      f = (f.colwise() - shift_.cast<S>()).array().colwise() * inv_scale_.cast<S>().array();
    }
  }

  /// g_z = (dphi/dz)^T g_f at z, per column: g_z (n + m) x B (resized), g_f f x B.
  template <typename DZ, typename DG, typename G>
  void Vjp(const Eigen::MatrixBase<DZ>& z, const Eigen::MatrixBase<DG>& g_f, G& g_z) const {
    angles_.PullBack(z, g_f, &g_z, inv_scale_);
  }

  /// phi(z) for one sample on any scalar (Jets for derivatives).
  template <typename T>
  VectorX<T> operator()(const VectorX<T>& z) const {
    if (identity()) return z;
    VectorX<T> f = angles_.EncodeOne<T>(z);
    for (int r = 0; r < shift_.size(); ++r) f[r] = (f[r] - shift_[r]) * inv_scale_[r];
    return f;
  }

 private:
  int inputs_ = 0, features_ = 0;
  InputFeatures angles_;               // the encoded angles of z, increasing
  Eigen::VectorXd shift_, inv_scale_;  // input scaling (empty: none)
};

/// y -> output_shift + output_scale * y, the network's output map (see Scaling).
class OutputMap {
 public:
  OutputMap() = default;
  explicit OutputMap(const Scaling& scaling)
      : shift_(scaling.output_shift), scale_(scaling.output_scale) {}

  /// Whether the map is the identity.
  bool identity() const { return scale_.size() == 0; }

  /// y = shift + scale * y for a batch (rows: the network's outputs), in place; float or
  /// double (a block or Ref may be passed as a temporary).
  template <typename D>
  void Apply(const Eigen::MatrixBase<D>& y_out) const {
    using S = typename D::Scalar;
    if (identity()) return;
    auto& y = y_out.const_cast_derived();
    y = (y.array().colwise() * scale_.cast<S>().array()).colwise() + shift_.cast<S>().array();
  }

  /// g = scale * g in place: the cotangent of the MLP's output from that of the map's.
  template <typename D>
  void Pullback(const Eigen::MatrixBase<D>& g_out) const {
    using S = typename D::Scalar;
    auto& g = g_out.const_cast_derived();
    if (!identity()) g = g.array().colwise() * scale_.cast<S>().array();
  }

  /// The map for one sample on any scalar.
  template <typename T>
  VectorX<T> operator()(VectorX<T> y) const {
    for (int r = 0; r < scale_.size(); ++r) y[r] = T(shift_[r]) + scale_[r] * y[r];
    return y;
  }

 private:
  Eigen::VectorXd shift_, scale_;
};

/// The MLP forward passes of one taped solve, kept so that the backward pass need not
/// recompute them: entry k holds the input z and the MLP workspace (activations) of
/// the k-th Eval since Start. At most 64 entries and `budget_bytes` of workspaces (an
/// MLP workspace of B samples holds about 8 B (2 sum_l n_l + 2 w) bytes, w the widest
/// layer: ~1.3 MB for h = 100, B = 250); later Evals are not kept and their Vjps
/// recompute.
template <typename S>
struct BasicMlpForwardCache {
  std::vector<MatrixX<S>> inputs;
  std::vector<BasicMlpWorkspace<S>> workspaces;
  int count = 0;
  bool recording = false;
  double budget_bytes = 192e6;

  /// Entries that fit the budget for batches of `batch` samples of `arch`.
  int Capacity(const MlpArchitecture& arch, int batch) const {
    const double sum = std::accumulate(arch.sizes.begin(), arch.sizes.end(), 0.0);
    const double bytes =
        static_cast<double>(sizeof(S)) * batch * (2 * sum + 2.0 * arch.max_width());
    return static_cast<int>(std::min(64.0, budget_bytes / std::max(bytes, 1.0)));
  }

  /// Forgets all entries; records the following Evals if `record`.
  void Start(bool record) {
    count = 0;
    recording = record;
  }
};

/// The forward cache of double networks.
using MlpForwardCache = BasicMlpForwardCache<double>;

/// dz/dt = M(phi(z)) for a batch (n + m rows, one sample per column): the NeuralODE's
/// vector field as a BatchedVjpSystem (adjoint.h) on matrices of S (float or double). `net` and
/// `features` point at the model's MLP and feature map and are re-pointed before every use (the
/// model may have moved). With a `cache`, Evals of a taped solve keep their activations and the Vjp
/// at the same stage input (the solver's backward pass visits stages in reverse order) reuses them
/// instead of a second forward pass; a Vjp at an input not near the top of the cache recomputes.
template <typename S>
struct BasicMlpOdeSystem {
  /// The scalar of the batched matrices (BatchedVjpSystem).
  using Scalar = S;
  using Matrix = MatrixX<S>;
  const Mlp<S>* net = nullptr;
  const FeatureMap* features = nullptr;
  const OutputMap* output = nullptr;
  BasicMlpForwardCache<S>* cache = nullptr;

  /// Buffers for one batch: the MLP's workspace plus input / output / gradient copies.
  struct Workspace {
    BasicMlpWorkspace<S> mlp;
    Matrix input, output, grad_input, grad_features, lambda;
  };

  /// n + m, the ODE state's size (the MLP's output size).
  int state_size() const { return net->num_outputs(); }
  /// p, the MLP's parameter count.
  int num_params() const { return static_cast<int>(net->num_parameters()); }
  /// Workspace for batches of `batch` samples (one MLP chunk per batch, no Jacobians).
  Workspace MakeWorkspace(int batch) const {
    Workspace ws;
    ws.mlp =
        BasicMlpWorkspace<S>(net->architecture(), batch, std::max(batch, 1), /*jacobian=*/false);
    return ws;
  }
  /// dzdt = M(phi(z)), z and dzdt (n + m) x B.
  void Eval(const Eigen::Ref<const Matrix>& z, double, Eigen::Ref<Matrix> dzdt,
            Workspace& ws) const {
    const bool encoded = features != nullptr && !features->identity();
    if (cache && cache->recording &&
        cache->count < cache->Capacity(net->architecture(), static_cast<int>(z.cols()))) {
      // Keep this forward pass for the backward one.
      const int k = cache->count++;
      if (static_cast<int>(cache->inputs.size()) <= k) {
        cache->inputs.emplace_back();
        cache->workspaces.emplace_back(net->architecture(), static_cast<int>(z.cols()),
                                       std::max(static_cast<int>(z.cols()), 1), false);
      }
      if (encoded) {
        features->Apply(z, cache->inputs[k]);
      } else {
        cache->inputs[k] = z;
      }
      net->Forward(cache->inputs[k], &ws.output, nullptr, &cache->workspaces[k]);
      dzdt = ws.output;
    } else if (encoded) {
      // Not kept for a backward pass (a Vjp here recomputes): values only.
      features->Apply(z, ws.input);
      net->Evaluate(ws.input, dzdt, &ws.mlp);
    } else {
      net->Evaluate(z, dzdt, &ws.mlp);
    }
    if (output != nullptr) output->Apply(dzdt);
  }
  /// vjp_z = (d M(phi(z)) / dz)^T lambda per column ((n + m) x B); grad_theta +=
  /// sum_b (dM/dtheta)^T lambda_b. Reuses a cached forward pass at exactly this input
  /// (searching down from the most recent entry and dropping the ones above it:
  /// rejected or unneeded stages), else recomputes.
  void Vjp(const Eigen::Ref<const Matrix>& z, double, const Eigen::Ref<const Matrix>& lambda,
           Eigen::Ref<Matrix> vjp_z, Eigen::Ref<VectorX<S>> grad_theta, Workspace& ws) const {
    constexpr int kSearch = 8;
    const bool encoded = features != nullptr && !features->identity();
    if (encoded) features->Apply(z, ws.input);
    const auto cached_at = [&](int k) {
      const Matrix& in = cache->inputs[k];
      return in.cols() == z.cols() && (encoded ? in == ws.input : in == z);
    };
    BasicMlpWorkspace<S>* forward = nullptr;
    if (cache) {
      for (int k = cache->count - 1; k >= std::max(0, cache->count - kSearch); --k) {
        if (cached_at(k)) {
          forward = &cache->workspaces[k];
          cache->count = k;
          break;
        }
      }
    }
    if (forward == nullptr) {
      if (!encoded) ws.input = z;
      net->Forward(ws.input, &ws.output, nullptr, &ws.mlp);
      forward = &ws.mlp;
    }
    // dL/dtheta goes straight into grad_theta (the sum over the solver's stages).
    // The cotangent buffers of ws.mlp serve every cached stage (when wide enough).
    const bool shared = forward != &ws.mlp && ws.mlp.chunk_size() >= forward->chunk_size();
    if (output != nullptr && !output->identity()) {
      ws.lambda = lambda;
      output->Pullback(ws.lambda);
      net->BackwardAccumulate(ws.lambda, grad_theta, &ws.grad_input, forward, 1,
                              shared ? &ws.mlp : nullptr);
    } else {
      net->BackwardAccumulate(lambda, grad_theta, &ws.grad_input, forward, 1,
                              shared ? &ws.mlp : nullptr);
    }
    if (encoded) {
      features->Vjp(z, ws.grad_input, ws.grad_features);
      vjp_z = ws.grad_features;
    } else {
      vjp_z = ws.grad_input;
    }
  }
};

/// The NeuralODE field of double networks.
using MlpOdeSystem = BasicMlpOdeSystem<double>;

/// One-sample vector field for odeint on any scalar: dz/dt = M(phi(z)) with an Mlp<P>.
template <typename P>
struct MlpOdeFunction {
  const Mlp<P>* net;
  const FeatureMap* features;
  const OutputMap* output;
  template <typename T>
  void operator()(const VectorX<T>& z, VectorX<T>& dzdt, double) const {
    dzdt = (*output)(VectorX<T>((*net)((*features)(z))));
  }
};

/// F(x, u) of one sample on any scalars (the templated path): parameters of type P
/// (an Mlp<P>, e.g. net.cast<Jet>() for parameter derivatives), state / action of
/// type S; the result has the product scalar R. NeuralODEs are integrated by odeint
/// (integrate.h) with config.ode_options(). x: n entries, u: m entries.
template <typename P, typename DX, typename DU,
          typename R = typename Mlp<P>::template ResultScalar<typename DX::Scalar>>
VectorX<R> PredictLearned(const Mlp<P>& net, const LearnedModelConfig& config,
                          const FeatureMap& features, const OutputMap& output,
                          const Eigen::MatrixBase<DX>& x, const Eigen::MatrixBase<DU>& u) {
  const int n = config.system.state_size(), m = config.system.action_size();
  DIFFDYN_CHECK(x.size() == n && u.size() == m, LearnedKindName(config.type), ": Predict got x of ",
                x.size(), " and u of ", u.size(), " entries, expected ", n, " and ", m);
  VectorX<R> z(n + m);
  for (int i = 0; i < n; ++i) z[i] = R(x[i]);
  for (int i = 0; i < m; ++i) z[n + i] = R(u[i]);
  if (StartsFromWrappedAngles(config.type)) {
    for (int i : config.system.angles) z[i] = WrappedAngle(z[i]);
  }
  VectorX<R> out(n);
  if (IsNeuralOde(config.type)) {
    const MlpOdeFunction<P> f{&net, &features, &output};
    Integrate(f, z, 0.0, 1.0, config.ode_options());
    out = z.head(n);
  } else {
    out = output(VectorX<R>(net(features(z))));
  }
  if (IsResidual(config.type)) {
    for (int i = 0; i < n; ++i) out[i] += R(x[i]);
  }
  return out;
}

/// The scaling that puts a model's network inputs and outputs on unit scale for the
/// transitions (states, actions, next) (n x N, m x N, n x N, N >= 1): the input shift
/// and scale are the mean and standard deviation of phi(z(0)), z(0) = [x; u] (res-node:
/// [wrap(x); u]); the output's those of what the network must produce: x_{t+1}
/// (abs-nn), x_{t+1} - x_t (res-nn, and abs-node's flow over unit time: its field's
/// mean), x_{t+1} - x_t - wrap(x_t) (res-node's flow from wrap(x_t) to x_{t+1} - x_t);
/// the action part of a NeuralODE's output keeps shift 0 and scale 1. A standard
/// deviation below 1e-8 (1 + |mean|) (a constant) becomes 1.
Scaling FitScaling(const LearnedModelConfig& config,
                   const Eigen::Ref<const Eigen::MatrixXd>& states,
                   const Eigen::Ref<const Eigen::MatrixXd>& actions,
                   const Eigen::Ref<const Eigen::MatrixXd>& next);

// The per-precision buffers and the workspace class of the batched paths
// (learned_model.cc).
template <typename S>
struct LearnedEngine;
class LearnedWorkspace;

/// One of the four learned models: config + MLP parameters (see the file comment).
/// Immutable during prediction; training changes mutable_parameters() between calls.
class LearnedModel final : public DifferentiableTransitionModel {
 public:
  /// A model with the given MLP, whose architecture must equal config.Architecture().
  LearnedModel(const LearnedModelConfig& config, Mlp<double> net)
      : config_(config),
        net_(std::move(net)),
        features_(config_.system, config_.scaling),
        output_(config_.scaling) {
    config_.Validate();
    DIFFDYN_CHECK(net_.architecture() == config_.Architecture(), LearnedKindName(config.type),
                  ": the network architecture does not match the configuration");
  }

  /// A model with PyTorch's default Linear initialisation drawn from Rng(seed).
  static LearnedModel Initialized(const LearnedModelConfig& config, std::uint64_t seed) {
    config.Validate();
    return LearnedModel(config, MakeInitializedMlp(config.Architecture(), InitOptions{}, seed));
  }

  const LearnedModelConfig& config() const { return config_; }
  const Mlp<double>& net() const { return net_; }
  /// theta, the MLP's flat parameters (size num_parameters()).
  const Eigen::VectorXd& parameters() const override { return net_.parameters(); }
  /// Mutable theta for optimisers (do not resize).
  Eigen::VectorXd& mutable_parameters() override { return net_.mutable_parameters(); }
  Eigen::Index num_parameters() const override { return net_.num_parameters(); }

  /// The system the model predicts (sizes, names, angle features).
  const SystemDescription& system() const { return config_.system; }
  int state_size() const override { return config_.system.state_size(); }
  int action_size() const override { return config_.system.action_size(); }
  std::string kind() const override { return LearnedKindName(config_.type); }
  /// The data's sample interval (s) recorded with the model, or 0.
  double time_step() const override { return time_step_; }
  /// The precision of the batched paths (PredictBatch, Forward, Backward).
  Precision precision() const override { return config_.precision; }
  /// Converts the model to compute in `p` (the parameters stay double; existing
  /// workspaces serve both precisions); always true.
  bool SetPrecision(Precision p) override {
    config_.precision = p;
    return true;
  }
  /// Records the sample interval of the training data (s, >= 0, finite).
  void set_time_step(double dt) {
    DIFFDYN_CHECK(dt >= 0 && std::isfinite(dt), "time step must be >= 0 and finite, got ", dt);
    time_step_ = dt;
  }
  SystemDescription description() const override { return config_.system; }

  std::unique_ptr<TransitionWorkspace> MakeWorkspace(int max_batch) const override;

  /// next = F(states, actions): n x B, m x B, n x B (no tape kept), computed in the
  /// configured precision.
  void PredictBatch(const Eigen::Ref<const Eigen::MatrixXd>& states,
                    const Eigen::Ref<const Eigen::MatrixXd>& actions,
                    Eigen::Ref<Eigen::MatrixXd> next, TransitionWorkspace& ws) const override;

  /// next = F(states, actions) (n x B, m x B, n x B), recording the tape for Backward in `ws`
  /// (a workspace from MakeWorkspace). Throws diffdyn::NumericalError if the solver
  /// fails (non-finite state, step-size underflow).
  void Forward(const Eigen::Ref<const Eigen::MatrixXd>& states,
               const Eigen::Ref<const Eigen::MatrixXd>& actions, Eigen::Ref<Eigen::MatrixXd> next,
               TransitionWorkspace& ws) const override;

  /// Reverse mode of the last Forward on `ws`: given dl_dnext = dL/dnext (n x B),
  /// adds dL/dtheta to *grad_params (size num_parameters(); may be null) and writes
  /// dL/dstates (n x B; resized; may be null). In float32 the cotangents and the
  /// per-call parameter gradient are float; the sum into *grad_params is double.
  void Backward(const Eigen::Ref<const Eigen::MatrixXd>& dl_dnext, TransitionWorkspace& ws,
                Eigen::VectorXd* grad_params, Eigen::MatrixXd* dl_dstates) const override;

  bool differentiable() const override { return true; }

  /// [dF/dx, dF/du] (n x (n + m)) by Jets through the network (and a NeuralODE's solver).
  Eigen::VectorXd Jacobian(const Eigen::Ref<const Eigen::VectorXd>& x,
                           const Eigen::Ref<const Eigen::VectorXd>& u,
                           Eigen::MatrixXd* jac) const override;

  /// F(x, u) for one sample (x: n, u: m entries) on any scalar (Jets for input
  /// derivatives).
  template <typename DX, typename DU>
  VectorX<typename DX::Scalar> Predict(const Eigen::MatrixBase<DX>& x,
                                       const Eigen::MatrixBase<DU>& u) const {
    return PredictLearned(net_, config_, features_, output_, x, u);
  }

  /// The feature map phi of the model's system.
  const FeatureMap& features() const { return features_; }
  /// The network's output map.
  const OutputMap& output_map() const { return output_; }

 private:
  LearnedWorkspace& Cast(TransitionWorkspace& ws) const;
  // The network the batched paths of precision S use: the model's own (double) or
  // the engine's float copy, rounded from the current parameters when `refresh`.
  template <typename S>
  const Mlp<S>& Network(LearnedEngine<S>& e, bool refresh) const;
  // Points the NeuralODE field of engine `e` at the network, maps and cache.
  template <typename S>
  void Attach(LearnedEngine<S>& e, const Mlp<S>& net) const;
  // Sizes the engine's buffers for a batch of b (allocates only when b changes).
  template <typename S>
  void Prepare(int b, LearnedEngine<S>& e, const Mlp<S>& net) const;
  // Sizes a workspace for batches of b in the configured precision.
  void Prepare(int b, LearnedWorkspace& ws) const;
  void Run(const Eigen::Ref<const Eigen::MatrixXd>& states,
           const Eigen::Ref<const Eigen::MatrixXd>& actions, Eigen::Ref<Eigen::MatrixXd> next,
           LearnedWorkspace& ws, bool tape) const;
  // next = F(states, actions) but the residual term, computed in S.
  template <typename S>
  void RunIn(const Eigen::Ref<const Eigen::MatrixXd>& states,
             const Eigen::Ref<const Eigen::MatrixXd>& actions, Eigen::Ref<Eigen::MatrixXd> next,
             LearnedWorkspace& ws, bool tape) const;
  // Backward in precision S (see Backward).
  template <typename S>
  void BackwardIn(const Eigen::Ref<const Eigen::MatrixXd>& dl_dnext, LearnedWorkspace& ws,
                  Eigen::VectorXd* grad_params, Eigen::MatrixXd* dl_dstates) const;

  LearnedModelConfig config_;
  Mlp<double> net_;
  FeatureMap features_;
  OutputMap output_;
  double time_step_ = 0.0;
};

// -----------------------------------------------------------------------------
// Model files: kinds abs-nn, res-nn, abs-node, res-node.

/// The "architecture" object of a learned model file:
/// {"mlp": {sizes, activations}, "hidden": h, "solver": name, "steps": N, "tolerance": tol}.
nlohmann::json LearnedArchitectureToJson(const LearnedModelConfig& config);

/// Inverse of LearnedArchitectureToJson for a file of `kind` whose system is
/// `system`; throws diffdyn::Error (without the file name) for a missing or
/// inconsistent field.
LearnedModelConfig LearnedConfigFromJson(const std::string& kind, const nlohmann::json& j,
                                         const SystemDescription& system);

/// The system of a learned model file: its "system" object, or, in files written
/// before systems were recorded, 3 unnamed states and 3 actions without encoded angles
/// (the layout every such file has).
SystemDescription LearnedFileSystem(const ModelFile& file);

/// Registers the four learned kinds with the model-file loader (idempotent). The
/// parameter count follows from the architecture's "mlp"; LoadLearnedModel checks it
/// against the system.
void RegisterLearnedModelKinds();

/// Saves `model` atomically to `path` with provenance and metrics objects.
void SaveLearnedModel(const std::filesystem::path& path, const LearnedModel& model,
                      const nlohmann::json& provenance = nlohmann::json::object(),
                      const nlohmann::json& metrics = nlohmann::json::object());

/// Loads a learned model file; throws diffdyn::Error with one line naming the path
/// for a bad file or a kind that is not one of the four.
LearnedModel LoadLearnedModel(const std::filesystem::path& path, ModelFile* contents = nullptr);

}  // namespace diffdyn