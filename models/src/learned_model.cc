// The batched paths of LearnedModel in float64 and float32, its Jacobian and its
// model files (learned_model.h). Compiled once here, so that programs using a
// LearnedModel do not instantiate its solvers and adjoints themselves.
#include "diffdyn/models/learned_model.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <mutex>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace diffdyn {
namespace {

// input's angle rows = the wrapped angle rows of states (wrapped in double, then rounded to S).
template <typename S>
void WrapAngleRows(const SystemDescription& system, const Eigen::Ref<const Eigen::MatrixXd>& states,
                   MatrixX<S>& input) {
  for (int i : system.angles) {
    for (Eigen::Index c = 0; c < states.cols(); ++c) {
      input(i, c) = static_cast<S>(WrapAngle(states(i, c)));
    }
  }
}

}  // namespace

Scaling FitScaling(const LearnedModelConfig& config,
                   const Eigen::Ref<const Eigen::MatrixXd>& states,
                   const Eigen::Ref<const Eigen::MatrixXd>& actions,
                   const Eigen::Ref<const Eigen::MatrixXd>& next) {
  const int n = config.system.state_size(), m = config.system.action_size();
  DIFFDYN_CHECK(states.rows() == n && actions.rows() == m && next.rows() == n &&
                    states.cols() >= 1 && actions.cols() == states.cols() &&
                    next.cols() == states.cols(),
                "FitScaling: expected states n x N, actions m x N, next n x N with N >= 1");
  // Mean and standard deviation of each row.
  const auto moments = [](const Eigen::MatrixXd& v, Eigen::VectorXd& mean, Eigen::VectorXd& sd) {
    mean = v.rowwise().mean();
    sd = ((v.colwise() - mean).array().square().rowwise().sum() / static_cast<double>(v.cols()))
             .sqrt();
    for (Eigen::Index r = 0; r < sd.size(); ++r) {
      if (!(sd[r] >= 1e-8 * (1.0 + std::abs(mean[r])))) sd[r] = 1.0;
    }
  };
  Scaling scaling;
  Eigen::MatrixXd z(n + m, states.cols()), phi;
  z.topRows(n) = states;
  z.bottomRows(m) = actions;
  if (StartsFromWrappedAngles(config.type)) WrapAngleRows(config.system, states, z);
  FeatureMap(config.system).Apply(z, phi);
  moments(phi, scaling.input_shift, scaling.input_scale);
  // What the network must output: x_{t+1}; else x_{t+1} - x_t (the NeuralODE's field: its
  // mean rate over unit time); res-node's flow goes from z(0) to x_{t+1} - x_t.
  Eigen::MatrixXd target = config.type == LearnedKind::kAbsNn ? next : next - states;
  if (StartsFromWrappedAngles(config.type)) target -= z.topRows(n);
  Eigen::VectorXd mean, sd;
  moments(target, mean, sd);
  const int outputs = IsNeuralOde(config.type) ? n + m : n;
  scaling.output_shift = Eigen::VectorXd::Zero(outputs);
  scaling.output_scale = Eigen::VectorXd::Ones(outputs);
  scaling.output_shift.head(n) = mean;
  scaling.output_scale.head(n) = sd;
  return scaling;
}

/// The buffers of a LearnedModel's batched paths in one precision S (double or
/// float): the MLP's tape (NN kinds), the NeuralODE's field, forward cache, solver
/// and tape, and [x; u], phi, outputs and gradients as S matrices.
template <typename S>
struct LearnedEngine {
  using Matrix = MatrixX<S>;
  // float: the model's parameters rounded to float at each Forward / PredictBatch
  // (the double parameters stay the master copy that optimisers change).
  Mlp<S> rounded;
  BasicMlpWorkspace<S> mlp;
  BasicMlpOdeSystem<S> system;
  BasicMlpForwardCache<S> cache;
  std::unique_ptr<BatchedOdeSolver<BasicMlpOdeSystem<S>>> solver;
  // input = [x; u]; features = phi(input) when angles are encoded (NN kinds).
  Matrix input, features, output, cotangent, grad_input, grad_z;
  VectorX<S> grad_params;
  std::vector<Matrix> outputs, dl_dz;
};

/// Scratch and tape of one LearnedModel for batches up to a size, one per thread
/// (and one per rollout step when training through rollouts).
class LearnedWorkspace : public TransitionWorkspace {
 public:
  LearnedWorkspace() = default;
  LearnedWorkspace(const LearnedWorkspace&) = delete;
  LearnedWorkspace& operator=(const LearnedWorkspace&) = delete;

  friend class LearnedModel;
  template <typename S>
  LearnedEngine<S>& engine() {
    if constexpr (std::is_same_v<S, float>) {
      return f32;
    } else {
      return f64;
    }
  }
  LearnedEngine<double> f64;
  LearnedEngine<float> f32;
  std::vector<double> times{0.0, 1.0};
  int batch = 0;
  bool taped = false;
};

std::unique_ptr<TransitionWorkspace> LearnedModel::MakeWorkspace(int max_batch) const {
  auto ws = std::make_unique<LearnedWorkspace>();
  Prepare(std::max(max_batch, 1), *ws);
  return ws;
}

void LearnedModel::PredictBatch(const Eigen::Ref<const Eigen::MatrixXd>& states,
                                const Eigen::Ref<const Eigen::MatrixXd>& actions,
                                Eigen::Ref<Eigen::MatrixXd> next, TransitionWorkspace& ws) const {
  CheckBatchSizes(states, actions, next);
  Run(states, actions, next, Cast(ws), /*tape=*/false);
}

void LearnedModel::Forward(const Eigen::Ref<const Eigen::MatrixXd>& states,
                           const Eigen::Ref<const Eigen::MatrixXd>& actions,
                           Eigen::Ref<Eigen::MatrixXd> next, TransitionWorkspace& ws) const {
  CheckBatchSizes(states, actions, next);
  Run(states, actions, next, Cast(ws), /*tape=*/true);
}

void LearnedModel::Backward(const Eigen::Ref<const Eigen::MatrixXd>& dl_dnext,
                            TransitionWorkspace& ws_base, Eigen::VectorXd* grad_params,
                            Eigen::MatrixXd* dl_dstates) const {
  LearnedWorkspace& ws = Cast(ws_base);
  DIFFDYN_CHECK(ws.taped, kind(), ": Backward needs a Forward on the same workspace");
  const int n = state_size();
  DIFFDYN_CHECK(dl_dnext.rows() == n && dl_dnext.cols() == ws.batch, kind(), ": Backward got a ",
                dl_dnext.rows(), " x ", dl_dnext.cols(), " cotangent, expected ", n, " x ",
                ws.batch);
  DIFFDYN_CHECK(grad_params == nullptr || grad_params->size() == num_parameters(), kind(),
                ": gradient vector has ", grad_params ? grad_params->size() : 0,
                " entries, expected ", num_parameters());
  if (config_.precision == Precision::kF32) {
    BackwardIn<float>(dl_dnext, ws, grad_params, dl_dstates);
  } else {
    BackwardIn<double>(dl_dnext, ws, grad_params, dl_dstates);
  }
}

Eigen::VectorXd LearnedModel::Jacobian(const Eigen::Ref<const Eigen::VectorXd>& x,
                                       const Eigen::Ref<const Eigen::VectorXd>& u,
                                       Eigen::MatrixXd* jac) const {
  return JetJacobian([this](const auto& xj, const auto& uj) { return Predict(xj, uj); }, x, u, jac);
}

LearnedWorkspace& LearnedModel::Cast(TransitionWorkspace& ws) const {
  auto* p = dynamic_cast<LearnedWorkspace*>(&ws);
  DIFFDYN_CHECK(p != nullptr, kind(), ": the workspace was not made by a LearnedModel");
  return *p;
}

// The network the batched paths of precision S use: the model's own (double) or
// the engine's float copy, rounded from the current parameters when `refresh`.
template <typename S>
const Mlp<S>& LearnedModel::Network(LearnedEngine<S>& e, bool refresh) const {
  if constexpr (std::is_same_v<S, double>) {
    return net_;
  } else {
    if (refresh) {
      if (!(e.rounded.architecture() == net_.architecture())) e.rounded = net_.template cast<S>();
      e.rounded.mutable_parameters() = net_.parameters().template cast<S>();
    }
    return e.rounded;
  }
}

// Points the NeuralODE field of engine `e` at the network, maps and cache.
template <typename S>
void LearnedModel::Attach(LearnedEngine<S>& e, const Mlp<S>& net) const {
  e.system.net = &net;
  e.system.features = &features_;
  e.system.output = &output_;
  e.system.cache = &e.cache;
}

// Sizes the engine's buffers for a batch of b (allocates only when b changes).
template <typename S>
void LearnedModel::Prepare(int b, LearnedEngine<S>& e, const Mlp<S>& net) const {
  Attach(e, net);
  if (IsNeuralOde(config_.type)) {
    if (!e.solver) {
      e.solver =
          std::make_unique<BatchedOdeSolver<BasicMlpOdeSystem<S>>>(e.system, config_.ode_options());
    }
  } else {
    e.mlp.Reserve(net.architecture(), b, /*jacobian=*/false);
  }
  const int z = state_size() + action_size();
  if (e.input.cols() == b && e.input.rows() == z) return;
  e.input.resize(z, b);
  e.dl_dz.assign(2, MatrixX<S>());
  e.dl_dz[1].resize(z, b);
}

// Sizes a workspace for batches of b in the configured precision.
void LearnedModel::Prepare(int b, LearnedWorkspace& ws) const {
  if (config_.precision == Precision::kF32) {
    Prepare(b, ws.f32, Network(ws.f32, /*refresh=*/true));
  } else {
    Prepare(b, ws.f64, Network(ws.f64, /*refresh=*/true));
  }
  ws.batch = b;
}

void LearnedModel::Run(const Eigen::Ref<const Eigen::MatrixXd>& states,
                       const Eigen::Ref<const Eigen::MatrixXd>& actions,
                       Eigen::Ref<Eigen::MatrixXd> next, LearnedWorkspace& ws, bool tape) const {
  if (config_.precision == Precision::kF32) {
    RunIn<float>(states, actions, next, ws, tape);
  } else {
    RunIn<double>(states, actions, next, ws, tape);
  }
  if (IsResidual(config_.type)) next += states;
  ws.batch = static_cast<int>(states.cols());
  ws.taped = tape;
}

// next = F(states, actions) but the residual term, computed in S; [x; u] is rounded
// to S on entry and the result widened to double on exit.
template <typename S>
void LearnedModel::RunIn(const Eigen::Ref<const Eigen::MatrixXd>& states,
                         const Eigen::Ref<const Eigen::MatrixXd>& actions,
                         Eigen::Ref<Eigen::MatrixXd> next, LearnedWorkspace& ws, bool tape) const {
  LearnedEngine<S>& e = ws.engine<S>();
  const Mlp<S>& net = Network(e, /*refresh=*/true);
  const int b = static_cast<int>(states.cols());
  Prepare(b, e, net);
  const int n = state_size();
  e.input.topRows(n) = states.template cast<S>();
  e.input.bottomRows(action_size()) = actions.template cast<S>();
  if (StartsFromWrappedAngles(config_.type)) WrapAngleRows(system(), states, e.input);
  if (IsNeuralOde(config_.type)) {
    e.cache.Start(tape);
    const IntegrationStats stats = e.solver->Forward(e.input, ws.times, &e.outputs, tape);
    ws.accepted_steps += stats.accepted_steps;
    ws.rejected_steps += stats.rejected_steps;
    e.cache.recording = false;
    next = e.outputs[1].topRows(n).template cast<double>();
    return;
  }
  if (!features_.identity()) features_.Apply(e.input, e.features);
  const MatrixX<S>& input = features_.identity() ? e.input : e.features;
  if (tape) {
    net.Forward(input, &e.output, nullptr, &e.mlp);
  } else {
    if (e.output.rows() != n || e.output.cols() != b) e.output.resize(n, b);
    net.Evaluate(input, e.output, &e.mlp);
  }
  output_.Apply(e.output);
  next = e.output.template cast<double>();
}

// Backward in precision S (see Backward).
template <typename S>
void LearnedModel::BackwardIn(const Eigen::Ref<const Eigen::MatrixXd>& dl_dnext,
                              LearnedWorkspace& ws, Eigen::VectorXd* grad_params,
                              Eigen::MatrixXd* dl_dstates) const {
  LearnedEngine<S>& e = ws.engine<S>();
  const Mlp<S>& net = Network(e, /*refresh=*/false);  // the network of the Forward
  const int n = state_size(), b = ws.batch;
  if (IsNeuralOde(config_.type)) {
    // Adjoint seed dL/dz(1) = [gbar; 0]; dL/dx_t = top rows of dL/dz(0).
    Attach(e, net);
    MatrixX<S>& seed = e.dl_dz[1];
    seed.topRows(n) = dl_dnext.template cast<S>();
    seed.bottomRows(action_size()).setZero();
    e.solver->BackwardDiscrete(e.dl_dz, &e.grad_input, &e.grad_params);
  } else {
    static const MatrixX<S> kNone;
    e.cotangent = dl_dnext.template cast<S>();
    output_.Pullback(e.cotangent);
    net.Backward(e.cotangent, kNone, &e.grad_params, &e.grad_input, &e.mlp);
    // dL/d[x; u] from dL/dphi.
    if (!features_.identity()) {
      features_.Vjp(e.input, e.grad_input, e.grad_z);
      e.grad_input.swap(e.grad_z);
    }
  }
  if (grad_params) *grad_params += e.grad_params.template cast<double>();
  if (dl_dstates) {
    if (dl_dstates->rows() != n || dl_dstates->cols() != b) dl_dstates->resize(n, b);
    *dl_dstates = e.grad_input.topRows(n).template cast<double>();
    if (IsResidual(config_.type)) *dl_dstates += dl_dnext;
  }
}

// -----------------------------------------------------------------------------
// Model files: kinds abs-nn, res-nn, abs-node, res-node.

nlohmann::json LearnedArchitectureToJson(const LearnedModelConfig& config) {
  nlohmann::json j = {{"mlp", MlpArchitectureToJson(config.Architecture())},
                      {"hidden", config.hidden},
                      {"solver", MethodName(config.method)},
                      {"steps", config.steps},
                      {"tolerance", config.tolerance}};
  const auto list = [](const Eigen::VectorXd& v) {
    return std::vector<double>(v.data(), v.data() + v.size());
  };
  const Scaling& s = config.scaling;
  if (s.has_input() || s.has_output()) {
    j["scaling"] = {{"input_shift", list(s.input_shift)},
                    {"input_scale", list(s.input_scale)},
                    {"output_shift", list(s.output_shift)},
                    {"output_scale", list(s.output_scale)}};
  }
  return j;
}

LearnedModelConfig LearnedConfigFromJson(const std::string& kind, const nlohmann::json& j,
                                         const SystemDescription& system) {
  DIFFDYN_CHECK(j.is_object(), "architecture must be an object");
  LearnedModelConfig config;
  config.type = ParseLearnedKind(kind, "kind");
  config.system = system;
  auto field = [&](const char* key) -> const nlohmann::json& {
    DIFFDYN_CHECK(j.contains(key), "architecture: missing '", key, "'");
    return j[key];
  };
  DIFFDYN_CHECK(field("solver").is_string(), "architecture: 'solver' must be a string");
  DIFFDYN_CHECK(field("tolerance").is_number(), "architecture: 'tolerance' must be a number");
  config.hidden = static_cast<int>(
      JsonInt(field("hidden"), 1, LearnedModelConfig::kMaxHidden, "architecture: 'hidden'"));
  config.method = ParseMethod(j["solver"].get<std::string>(), "architecture: solver");
  config.steps = static_cast<int>(
      JsonInt(field("steps"), 2, LearnedModelConfig::kMaxSteps, "architecture: 'steps'"));
  config.tolerance = j["tolerance"].get<double>();
  if (j.contains("scaling")) {
    const nlohmann::json& sc = j["scaling"];
    const auto numbers = [&](const char* key) {
      DIFFDYN_CHECK(sc.is_object() && sc.contains(key) && sc[key].is_array(),
                    "architecture: scaling: '", key, "' must be a list of numbers");
      Eigen::VectorXd v(static_cast<Eigen::Index>(sc[key].size()));
      for (std::size_t i = 0; i < sc[key].size(); ++i) {
        DIFFDYN_CHECK(sc[key][i].is_number(), "architecture: scaling: '", key,
                      "' must hold numbers");
        v[static_cast<Eigen::Index>(i)] = sc[key][i].get<double>();
      }
      return v;
    };
    config.scaling = {numbers("input_shift"), numbers("input_scale"), numbers("output_shift"),
                      numbers("output_scale")};
  }
  config.Validate();
  const MlpArchitecture mlp = MlpArchitectureFromJson(field("mlp"));
  if (!mlp.activations.empty()) config.activation = mlp.activations.front();
  DIFFDYN_CHECK(mlp == config.Architecture(), "architecture: 'mlp' does not match a ", kind,
                " with hidden ", config.hidden, " for ", system.state_size(), " states and ",
                system.action_size(), " actions");
  return config;
}

SystemDescription LearnedFileSystem(const ModelFile& file) {
  return file.system.is_null() ? SystemDescription::Unnamed(3, 3) : SystemFromJson(file.system);
}

void RegisterLearnedModelKinds() {
  static std::once_flag once;
  std::call_once(once, [] {
    for (const char* kind : {"abs-nn", "res-nn", "abs-node", "res-node"}) {
      RegisterModelKind(kind, [](const nlohmann::json& j) {
        DIFFDYN_CHECK(j.is_object() && j.contains("mlp"), "architecture: missing 'mlp'");
        return MlpArchitectureFromJson(j["mlp"]).num_parameters();
      });
    }
  });
}

void SaveLearnedModel(const std::filesystem::path& path, const LearnedModel& model,
                      const nlohmann::json& provenance, const nlohmann::json& metrics) {
  RegisterLearnedModelKinds();
  SaveModelFile(
      path, ModelFile{model.kind(), LearnedArchitectureToJson(model.config()), model.parameters(),
                      provenance, metrics, SystemToJson(model.system()), model.config().precision});
}

LearnedModel LoadLearnedModel(const std::filesystem::path& path, ModelFile* contents) {
  RegisterLearnedModelKinds();
  ModelFile file = LoadModelFile(path);
  const bool known = file.kind == "abs-nn" || file.kind == "res-nn" || file.kind == "abs-node" ||
                     file.kind == "res-node";
  DIFFDYN_CHECK(known, path.string(), ": model kind is '", file.kind,
                "', expected abs-nn, res-nn, abs-node or res-node");
  LearnedModelConfig config;
  try {
    config = LearnedConfigFromJson(file.kind, file.architecture, LearnedFileSystem(file));
  } catch (const Error& e) {
    throw Error(StrCat(path.string(), ": ", e.what()));
  }
  config.precision = file.precision;
  LearnedModel model(config, Mlp<double>(config.Architecture(), file.parameters));
  // The training data's sample interval, where the file records it (diffdyn train does).
  const nlohmann::json& dt =
      file.provenance.contains("dt") ? file.provenance["dt"] : nlohmann::json();
  if (dt.is_number() && std::isfinite(dt.get<double>()) && dt.get<double>() > 0)
    model.set_time_step(dt.get<double>());
  if (contents) *contents = std::move(file);
  return model;
}

}  // namespace diffdyn
