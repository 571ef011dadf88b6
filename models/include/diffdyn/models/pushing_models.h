// The four learned block-pushing dynamics models of the NeuralODE-Panda paper.
//
// State x = (x, y, theta) (block pose), action u = (push_location, push_angle,
// push_length); both in R^3. Each model is x_{t+1} = F(x_t, u_t):
//
//   abs-nn     F = N([x; u])                 N: MLP 6-h-h-3, ReLU
//   res-nn     F = x + N([x; u])
//   abs-node   F = P z(1)                    z(0) = [x; u] in R^6,  dz/dt = M(z),
//   res-node   F = x + P z(1)                M: MLP 6-h-h-6, ReLU,  P = [I_3 0]
//
// The NeuralODE is autonomous and the action rides along as ODE state. z(1) comes
// from one Runge-Kutta method (butcher.h) on t in [0, 1]: a fixed-step method takes
// steps - 1 equal steps h = 1 / (steps - 1) (`steps` grid points, as the paper's
// torch.linspace(0, 1, steps)); dopri5 is adaptive with abs = rel tolerance 1e-8
// and integrates straight to t = 1 (torchdiffeq interpolates the grid; only z(1)
// is used, so the grid does not matter).
//
// Three paths compute F:
//
// 1. PredictBatch (TransitionModel): B samples at once, samples in columns, as
//    GEMMs through the MLP (BatchedOdeSolver for the NeuralODEs). For MPPI and eval.
// 2. Forward / Backward (training): Forward records a tape in the workspace;
//    Backward takes gbar = dL/dx_{t+1} (3 x B) and returns
//
//      dL/dtheta += sum_b (dF/dtheta)^T gbar_b,      dL/dx_t = (dF/dx_t)^T gbar,
//
//    by the MLP's batched VJPs; for the NeuralODEs through the discrete adjoint of
//    the solver (adjoint.h), i.e. the exact gradient of the discrete map, with the
//    adjoint seeded as dL/dz(1) = [gbar; 0]; the residual variants add gbar to
//    dL/dx_t. dL/dx_t lets multi-step rollouts x^_{k+1} = F(x^_k, u_k) backpropagate.
// 3. Predict<S> and PredictPushing<P, S>: one sample on any scalar (double or
//    ceres::Jet, in the state, the action, or the parameters via Mlp<P>), the NODE
//    integrated by odeint (integrate.h) on Jet states. Tests pin 1 = 2 = 3.
//
// The batched paths never allocate once the workspace has seen the batch size.
//
//   PushingModel model = PushingModel::Initialized({.type = PushingModelType::kAbsNode}, 7);
//   auto ws = model.MakeWorkspace(500);
//   model.Forward(states, actions, next, *ws);               // 3 x B each
//   model.Backward(dl_dnext, *ws, &grad_theta, &dl_dstates);  // accumulates grad_theta
#pragma once

#include <cmath>
#include <filesystem>
#include <memory>
#include <mutex>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "diffdyn/autodiff_ode/adjoint.h"
#include "diffdyn/autodiff_ode/butcher.h"
#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/autodiff_ode/integrate.h"
#include "diffdyn/models/init.h"
#include "diffdyn/models/mlp.h"
#include "diffdyn/models/model_file.h"
#include "diffdyn/models/transition_model.h"

namespace diffdyn {

/// The four model types; their command-line / model-file names are
/// "abs-nn", "res-nn", "abs-node", "res-node".
enum class PushingModelType { kAbsNn, kResNn, kAbsNode, kResNode };

/// The name of `type` ("abs-nn", ...).
inline std::string PushingModelTypeName(PushingModelType type) {
  switch (type) {
    case PushingModelType::kAbsNn: return "abs-nn";
    case PushingModelType::kResNn: return "res-nn";
    case PushingModelType::kAbsNode: return "abs-node";
    case PushingModelType::kResNode: return "res-node";
  }
  return "abs-nn";
}

/// Parses "abs-nn", "res-nn", "abs-node" or "res-node"; throws diffdyn::Error
/// naming `option` and the bad value otherwise.
inline PushingModelType ParsePushingModelType(const std::string& name,
                                              const std::string& option = "--model") {
  for (PushingModelType t : {PushingModelType::kAbsNn, PushingModelType::kResNn,
                             PushingModelType::kAbsNode, PushingModelType::kResNode}) {
    if (name == PushingModelTypeName(t)) return t;
  }
  throw Error(StrCat(option, ": unknown model '", name,
                     "' (expected abs-nn, res-nn, abs-node or res-node)"));
}

/// Whether `type` is a NeuralODE (abs-node, res-node).
inline bool IsNeuralOde(PushingModelType type) {
  return type == PushingModelType::kAbsNode || type == PushingModelType::kResNode;
}

/// Whether `type` adds x_t to the network output (res-nn, res-node).
inline bool IsResidual(PushingModelType type) {
  return type == PushingModelType::kResNn || type == PushingModelType::kResNode;
}

/// Everything that fixes a model's function apart from its parameters.
struct PushingModelConfig {
  PushingModelType type = PushingModelType::kAbsNode;
  /// h, the width of both hidden layers.
  int hidden = 100;
  /// NeuralODE solver (ignored by the NNs).
  Method method = Method::kRk4;
  /// NeuralODE grid points on [0, 1] (>= 2): steps - 1 fixed steps; dopri5's first trial step
  /// is 1 / (steps - 1).
  int steps = 10;
  /// dopri5 absolute = relative tolerance.
  double tolerance = 1e-8;
  /// Hidden activation (the paper: ReLU). A smooth one (tanh) makes the NeuralODE's
  /// flow smooth in theta, which adaptive solvers' error control assumes.
  Activation activation = Activation::Relu();

  /// Sizes (6, h, h, 3) for the NNs, (6, h, h, 6) for the NeuralODEs; `activation` on
  /// both hidden layers.
  MlpArchitecture Architecture() const {
    const int out = IsNeuralOde(type) ? 6 : 3;
    return {{6, hidden, hidden, out}, {activation, activation}};
  }

  /// Throws diffdyn::Error naming the option for hidden < 1, steps < 2 or tolerance <= 0.
  void Validate() const {
    DIFFDYN_CHECK(hidden >= 1, "--hidden must be >= 1, got ", hidden);
    DIFFDYN_CHECK(steps >= 2, "--steps must be >= 2 (grid points on [0, 1]), got ", steps);
    DIFFDYN_CHECK(tolerance > 0 && std::isfinite(tolerance), "tolerance must be positive, got ",
                  tolerance);
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

/// The MLP forward passes of one taped solve, kept so that the backward pass need not
/// recompute them: entry k holds the input z and the MLP workspace (activations) of
/// the k-th Eval since Start. At most 64 entries and `budget_bytes` of workspaces (an
/// MLP workspace of B samples holds about 8 B (2 sum_l n_l + 2 w) bytes, w the widest
/// layer: ~1.3 MB for h = 100, B = 250); later Evals are not kept and their Vjps
/// recompute.
struct MlpForwardCache {
  std::vector<Eigen::MatrixXd> inputs;
  std::vector<MlpWorkspace> workspaces;
  int count = 0;
  bool recording = false;
  double budget_bytes = 192e6;

  /// Entries that fit the budget for batches of `batch` samples of `arch`.
  int Capacity(const MlpArchitecture& arch, int batch) const {
    const double sum = std::accumulate(arch.sizes.begin(), arch.sizes.end(), 0.0);
    const double bytes = 8.0 * batch * (2 * sum + 2.0 * arch.max_width());
    return static_cast<int>(std::min(64.0, budget_bytes / std::max(bytes, 1.0)));
  }

  /// Forgets all entries; records the following Evals if `record`.
  void Start(bool record) {
    count = 0;
    recording = record;
  }
};

/// dz/dt = M(z) for a batch (n = 6 rows, one sample per column): the NeuralODE's
/// vector field as a BatchedVjpSystem (adjoint.h). `net` points at the model's MLP
/// and is re-pointed before every use (the model may have moved). With a `cache`,
/// Evals of a taped solve keep their activations and the Vjp at the same stage input
/// (the solver's backward pass visits stages in reverse order) reuses them instead of
/// a second forward pass; a Vjp at an input not near the top of the cache recomputes.
struct MlpOdeSystem {
  const Mlp<double>* net = nullptr;
  MlpForwardCache* cache = nullptr;

  /// Buffers for one batch: the MLP's workspace plus input / output / gradient copies.
  struct Workspace {
    MlpWorkspace mlp;
    Eigen::MatrixXd input, output, grad_input;
  };

  /// n = 6.
  int state_size() const { return net->num_inputs(); }
  /// p, the MLP's parameter count.
  int num_params() const { return static_cast<int>(net->num_parameters()); }
  /// Workspace for batches of `batch` samples (one MLP chunk per batch, no Jacobians).
  Workspace MakeWorkspace(int batch) const {
    Workspace ws;
    ws.mlp = MlpWorkspace(net->architecture(), batch, std::max(batch, 1), /*jacobian=*/false);
    return ws;
  }
  /// dzdt = M(z), z and dzdt 6 x B.
  void Eval(const Eigen::Ref<const Eigen::MatrixXd>& z, double, Eigen::Ref<Eigen::MatrixXd> dzdt,
            Workspace& ws) const {
    if (cache && cache->recording &&
        cache->count < cache->Capacity(net->architecture(), static_cast<int>(z.cols()))) {
      // Keep this forward pass for the backward one.
      const int k = cache->count++;
      if (static_cast<int>(cache->inputs.size()) <= k) {
        cache->inputs.emplace_back();
        cache->workspaces.emplace_back(net->architecture(), static_cast<int>(z.cols()),
                                       std::max(static_cast<int>(z.cols()), 1), false);
      }
      cache->inputs[k] = z;
      net->Forward(cache->inputs[k], &ws.output, nullptr, &cache->workspaces[k]);
      dzdt = ws.output;
    } else {
      // Not kept for a backward pass (a Vjp here recomputes): values only.
      net->Evaluate(z, dzdt, &ws.mlp);
    }
  }
  /// vjp_z = (dM/dz)^T lambda per column (6 x B); grad_theta += sum_b (dM/dtheta)^T lambda_b.
  /// Reuses a cached forward pass at exactly this z (searching down from the most recent
  /// entry and dropping the ones above it: rejected or unneeded stages), else recomputes.
  void Vjp(const Eigen::Ref<const Eigen::MatrixXd>& z, double,
           const Eigen::Ref<const Eigen::MatrixXd>& lambda, Eigen::Ref<Eigen::MatrixXd> vjp_z,
           Eigen::Ref<Eigen::VectorXd> grad_theta, Workspace& ws) const {
    constexpr int kSearch = 8;
    MlpWorkspace* forward = nullptr;
    if (cache) {
      for (int k = cache->count - 1; k >= std::max(0, cache->count - kSearch); --k) {
        if (cache->inputs[k].cols() == z.cols() && cache->inputs[k] == z) {
          forward = &cache->workspaces[k];
          cache->count = k;
          break;
        }
      }
    }
    if (forward == nullptr) {
      ws.input = z;
      net->Forward(ws.input, &ws.output, nullptr, &ws.mlp);
      forward = &ws.mlp;
    }
    // dL/dtheta goes straight into grad_theta (the sum over the solver's stages).
    // The cotangent buffers of ws.mlp serve every cached stage (when wide enough).
    const bool shared = forward != &ws.mlp && ws.mlp.chunk_size() >= forward->chunk_size();
    net->BackwardAccumulate(lambda, grad_theta, &ws.grad_input, forward, 1,
                            shared ? &ws.mlp : nullptr);
    vjp_z = ws.grad_input;
  }
};

/// One-sample vector field for odeint on any scalar: dz/dt = M(z) with an Mlp<P>.
template <typename P>
struct MlpOdeFunction {
  const Mlp<P>* net;
  template <typename T>
  void operator()(const VectorX<T>& z, VectorX<T>& dzdt, double) const {
    dzdt = (*net)(z);
  }
};

/// F(x, u) of one sample on any scalars (the templated path): parameters of type P
/// (an Mlp<P>, e.g. net.cast<Jet>() for parameter derivatives), state / action of
/// type S; the result has the product scalar R. NeuralODEs are integrated by odeint
/// (integrate.h) with config.ode_options(). x, u: 3 entries each.
template <typename P, typename S, typename R = typename Mlp<P>::template ResultScalar<S>>
Eigen::Matrix<R, 3, 1> PredictPushing(const Mlp<P>& net, const PushingModelConfig& config,
                                      const Eigen::Matrix<S, 3, 1>& x,
                                      const Eigen::Matrix<S, 3, 1>& u) {
  VectorX<R> z(6);
  for (int i = 0; i < 3; ++i) {
    z[i] = R(x[i]);
    z[i + 3] = R(u[i]);
  }
  Eigen::Matrix<R, 3, 1> out;
  if (IsNeuralOde(config.type)) {
    const MlpOdeFunction<P> f{&net};
    Integrate(f, z, 0.0, 1.0, config.ode_options());
    for (int i = 0; i < 3; ++i) out[i] = z[i];
  } else {
    const VectorX<R> y = net(z);
    for (int i = 0; i < 3; ++i) out[i] = y[i];
  }
  if (IsResidual(config.type)) {
    for (int i = 0; i < 3; ++i) out[i] += R(x[i]);
  }
  return out;
}

/// Scratch and tape of one PushingModel for batches up to a size, one per thread
/// (and one per rollout step when training through rollouts).
class PushingWorkspace : public TransitionWorkspace {
 public:
  PushingWorkspace() = default;
  PushingWorkspace(const PushingWorkspace&) = delete;
  PushingWorkspace& operator=(const PushingWorkspace&) = delete;

 private:
  friend class PushingModel;
  // NN: the MLP's tape; NODE: the solver (which references `system`) and its tape.
  MlpWorkspace mlp;
  MlpOdeSystem system;
  MlpForwardCache cache;
  std::unique_ptr<BatchedOdeSolver<MlpOdeSystem>> solver;
  Eigen::MatrixXd input, output, cotangent, grad_input;
  Eigen::VectorXd grad_params;
  std::vector<double> times{0.0, 1.0};
  std::vector<Eigen::MatrixXd> outputs, dl_dz;
  int batch = 0;
  bool taped = false;
};

/// One of the four pushing models: config + MLP parameters (see the header comment).
/// Immutable during prediction; training changes mutable_parameters() between calls.
class PushingModel final : public TransitionModel {
 public:
  /// A model with the given MLP, whose architecture must equal config.Architecture().
  PushingModel(const PushingModelConfig& config, Mlp<double> net)
      : config_(config), net_(std::move(net)) {
    config_.Validate();
    DIFFDYN_CHECK(net_.architecture() == config_.Architecture(), PushingModelTypeName(config.type),
                  ": the network architecture does not match the configuration");
  }

  /// A model with PyTorch's default Linear initialisation drawn from Rng(seed).
  static PushingModel Initialized(const PushingModelConfig& config, std::uint64_t seed) {
    config.Validate();
    return PushingModel(config, MakeInitializedMlp(config.Architecture(), InitOptions{}, seed));
  }

  const PushingModelConfig& config() const { return config_; }
  const Mlp<double>& net() const { return net_; }
  /// theta, the MLP's flat parameters (size num_parameters()).
  const Eigen::VectorXd& parameters() const { return net_.parameters(); }
  /// Mutable theta for optimisers (do not resize).
  Eigen::VectorXd& mutable_parameters() { return net_.mutable_parameters(); }
  Eigen::Index num_parameters() const { return net_.num_parameters(); }

  int state_size() const override { return 3; }
  int action_size() const override { return 3; }
  std::string kind() const override { return PushingModelTypeName(config_.type); }

  std::unique_ptr<TransitionWorkspace> MakeWorkspace(int max_batch) const override {
    auto ws = std::make_unique<PushingWorkspace>();
    Prepare(std::max(max_batch, 1), *ws);
    return ws;
  }

  /// next = F(states, actions), each 3 x B (no tape kept).
  void PredictBatch(const Eigen::Ref<const Eigen::MatrixXd>& states,
                    const Eigen::Ref<const Eigen::MatrixXd>& actions, Eigen::Ref<Eigen::MatrixXd> next,
                    TransitionWorkspace& ws) const override {
    CheckBatchSizes(states, actions, next);
    Run(states, actions, next, Cast(ws), /*tape=*/false);
  }

  /// next = F(states, actions), each 3 x B, recording the tape for Backward in `ws`
  /// (a workspace from MakeWorkspace). Throws diffdyn::NumericalError if the solver
  /// fails (non-finite state, step-size underflow).
  void Forward(const Eigen::Ref<const Eigen::MatrixXd>& states,
               const Eigen::Ref<const Eigen::MatrixXd>& actions, Eigen::Ref<Eigen::MatrixXd> next,
               TransitionWorkspace& ws) const {
    CheckBatchSizes(states, actions, next);
    Run(states, actions, next, Cast(ws), /*tape=*/true);
  }

  /// Reverse mode of the last Forward on `ws`: given dl_dnext = dL/dnext (3 x B),
  /// adds dL/dtheta to *grad_params (size num_parameters(); may be null) and writes
  /// dL/dstates (3 x B; resized; may be null).
  void Backward(const Eigen::Ref<const Eigen::MatrixXd>& dl_dnext, TransitionWorkspace& ws_base,
                Eigen::VectorXd* grad_params, Eigen::MatrixXd* dl_dstates) const {
    PushingWorkspace& ws = Cast(ws_base);
    DIFFDYN_CHECK(ws.taped, kind(), ": Backward needs a Forward on the same workspace");
    DIFFDYN_CHECK(dl_dnext.rows() == 3 && dl_dnext.cols() == ws.batch, kind(),
                  ": Backward got a ", dl_dnext.rows(), " x ", dl_dnext.cols(),
                  " cotangent, expected 3 x ", ws.batch);
    DIFFDYN_CHECK(grad_params == nullptr || grad_params->size() == num_parameters(), kind(),
                  ": gradient vector has ", grad_params ? grad_params->size() : 0, " entries, expected ",
                  num_parameters());
    const int b = ws.batch;
    if (IsNeuralOde(config_.type)) {
      // Adjoint seed dL/dz(1) = [gbar; 0]; dL/dx_t = top rows of dL/dz(0).
      ws.system.net = &net_;
      ws.system.cache = &ws.cache;
      Eigen::MatrixXd& seed = ws.dl_dz[1];
      seed.topRows(3) = dl_dnext;
      seed.bottomRows(3).setZero();
      ws.solver->BackwardDiscrete(ws.dl_dz, &ws.grad_input, &ws.grad_params);
    } else {
      static const Eigen::MatrixXd kNone;
      ws.cotangent = dl_dnext;
      net_.Backward(ws.cotangent, kNone, &ws.grad_params, &ws.grad_input, &ws.mlp);
    }
    if (grad_params) *grad_params += ws.grad_params;
    if (dl_dstates) {
      if (dl_dstates->rows() != 3 || dl_dstates->cols() != b) dl_dstates->resize(3, b);
      *dl_dstates = ws.grad_input.topRows(3);
      if (IsResidual(config_.type)) *dl_dstates += dl_dnext;
    }
  }

  /// F(x, u) for one sample on any scalar S (Jets for input derivatives).
  template <typename S>
  Eigen::Matrix<S, 3, 1> Predict(const Eigen::Matrix<S, 3, 1>& x,
                                 const Eigen::Matrix<S, 3, 1>& u) const {
    return PredictPushing(net_, config_, x, u);
  }

 private:
  PushingWorkspace& Cast(TransitionWorkspace& ws) const {
    auto* p = dynamic_cast<PushingWorkspace*>(&ws);
    DIFFDYN_CHECK(p != nullptr, kind(), ": the workspace was not made by a PushingModel");
    return *p;
  }

  // Sizes the workspace buffers for a batch of b (allocates only when b changes).
  void Prepare(int b, PushingWorkspace& ws) const {
    ws.system.net = &net_;
    ws.system.cache = &ws.cache;
    if (IsNeuralOde(config_.type)) {
      if (!ws.solver) {
        ws.solver = std::make_unique<BatchedOdeSolver<MlpOdeSystem>>(ws.system, config_.ode_options());
      }
    } else {
      ws.mlp.Reserve(net_.architecture(), b, /*jacobian=*/false);
    }
    if (ws.batch == b) return;
    ws.batch = b;
    ws.input.resize(6, b);
    ws.dl_dz.assign(2, Eigen::MatrixXd());
    ws.dl_dz[1].resize(6, b);
  }

  void Run(const Eigen::Ref<const Eigen::MatrixXd>& states,
           const Eigen::Ref<const Eigen::MatrixXd>& actions, Eigen::Ref<Eigen::MatrixXd> next,
           PushingWorkspace& ws, bool tape) const {
    const int b = static_cast<int>(states.cols());
    Prepare(b, ws);
    ws.input.topRows(3) = states;
    ws.input.bottomRows(3) = actions;
    if (IsNeuralOde(config_.type)) {
      ws.cache.Start(tape);
      ws.solver->Forward(ws.input, ws.times, &ws.outputs, tape);
      ws.cache.recording = false;
      next = ws.outputs[1].topRows(3);
    } else if (tape) {
      net_.Forward(ws.input, &ws.output, nullptr, &ws.mlp);
      next = ws.output;
    } else {
      net_.Evaluate(ws.input, next, &ws.mlp);
    }
    if (IsResidual(config_.type)) next += states;
    ws.taped = tape;
  }

  PushingModelConfig config_;
  Mlp<double> net_;
};

// -----------------------------------------------------------------------------
// Model files: kinds abs-nn, res-nn, abs-node, res-node.

/// The "architecture" object of a pushing model file:
/// {"mlp": {sizes, activations}, "hidden": h, "solver": name, "steps": N, "tolerance": tol}.
inline nlohmann::json PushingArchitectureToJson(const PushingModelConfig& config) {
  return {{"mlp", MlpArchitectureToJson(config.Architecture())},
          {"hidden", config.hidden},
          {"solver", MethodName(config.method)},
          {"steps", config.steps},
          {"tolerance", config.tolerance}};
}

/// Inverse of PushingArchitectureToJson for a file of `kind`; throws diffdyn::Error
/// (without the file name) for a missing or inconsistent field.
inline PushingModelConfig PushingConfigFromJson(const std::string& kind, const nlohmann::json& j) {
  DIFFDYN_CHECK(j.is_object(), "architecture must be an object");
  PushingModelConfig config;
  config.type = ParsePushingModelType(kind, "kind");
  auto field = [&](const char* key) -> const nlohmann::json& {
    DIFFDYN_CHECK(j.contains(key), "architecture: missing '", key, "'");
    return j[key];
  };
  DIFFDYN_CHECK(field("hidden").is_number_integer(), "architecture: 'hidden' must be an integer");
  DIFFDYN_CHECK(field("solver").is_string(), "architecture: 'solver' must be a string");
  DIFFDYN_CHECK(field("steps").is_number_integer(), "architecture: 'steps' must be an integer");
  DIFFDYN_CHECK(field("tolerance").is_number(), "architecture: 'tolerance' must be a number");
  config.hidden = j["hidden"].get<int>();
  config.method = ParseMethod(j["solver"].get<std::string>(), "architecture: solver");
  config.steps = j["steps"].get<int>();
  config.tolerance = j["tolerance"].get<double>();
  config.Validate();
  const MlpArchitecture mlp = MlpArchitectureFromJson(field("mlp"));
  if (!mlp.activations.empty()) config.activation = mlp.activations.front();
  DIFFDYN_CHECK(mlp == config.Architecture(),
                "architecture: 'mlp' does not match a ", kind, " with hidden ", config.hidden);
  return config;
}

/// Registers the four pushing kinds with the model-file loader (idempotent).
inline void RegisterPushingModelKinds() {
  static std::once_flag once;
  std::call_once(once, [] {
    for (const char* kind : {"abs-nn", "res-nn", "abs-node", "res-node"}) {
      const std::string name = kind;
      RegisterModelKind(name, [name](const nlohmann::json& j) {
        return PushingConfigFromJson(name, j).Architecture().num_parameters();
      });
    }
  });
}

/// Saves `model` atomically to `path` with provenance and metrics objects.
inline void SavePushingModel(const std::filesystem::path& path, const PushingModel& model,
                             const nlohmann::json& provenance = nlohmann::json::object(),
                             const nlohmann::json& metrics = nlohmann::json::object()) {
  RegisterPushingModelKinds();
  SaveModelFile(path, ModelFile{model.kind(), PushingArchitectureToJson(model.config()),
                                model.parameters(), provenance, metrics});
}

/// Loads a pushing model file; throws diffdyn::Error with one line naming the path
/// for a bad file or a kind that is not one of the four.
inline PushingModel LoadPushingModel(const std::filesystem::path& path,
                                     ModelFile* contents = nullptr) {
  RegisterPushingModelKinds();
  ModelFile file = LoadModelFile(path);
  const bool known = file.kind == "abs-nn" || file.kind == "res-nn" || file.kind == "abs-node" ||
                     file.kind == "res-node";
  DIFFDYN_CHECK(known, path.string(), ": model kind is '", file.kind,
                "', expected abs-nn, res-nn, abs-node or res-node");
  const PushingModelConfig config = PushingConfigFromJson(file.kind, file.architecture);
  PushingModel model(config, Mlp<double>(config.Architecture(), file.parameters));
  if (contents) *contents = std::move(file);
  return model;
}

}  // namespace diffdyn
