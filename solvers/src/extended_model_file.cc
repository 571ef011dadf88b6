#include "diffdyn/solvers/extended_model_file.h"

#include <vector>

#include "diffdyn/models/model_file.h"
#include "diffdyn/physics/model_registry.h"

namespace diffdyn {
namespace {

// Parameter count the architecture implies; validates it.
Eigen::Index CountParameters(const nlohmann::json& arch) {
  DIFFDYN_CHECK(arch.is_object() && arch.contains("model") && arch["model"].is_string(),
                "architecture: missing string 'model'");
  const auto model = MakeAnalyticModel(arch["model"].get<std::string>());
  DIFFDYN_CHECK(arch.contains("model_params") && arch["model_params"].is_object(),
                "architecture: missing object 'model_params'");
  for (const auto& [name, value] : arch["model_params"].items()) {
    DIFFDYN_CHECK(model->ParamIndex(name) >= 0, "architecture: model ", model->name(),
                  " has no parameter '", name, "'");
    DIFFDYN_CHECK(value.is_number(), "architecture: model_params.", name, " is not a number");
  }
  DIFFDYN_CHECK(arch.contains("effects") && arch["effects"].is_array(),
                "architecture: missing list 'effects'");
  Eigen::Index count = 0;
  for (const auto& e : arch["effects"]) {
    DIFFDYN_CHECK(e.is_object() && e.contains("kind") && e["kind"].is_string() &&
                      e.contains("joint") && e["joint"].is_number_integer(),
                  "architecture: each effect needs 'kind' and integer 'joint'");
    const EffectKindInfo& info = Info(ParseEffectKind(e["kind"].get<std::string>()));
    DIFFDYN_CHECK(info.kind != EffectKind::kResidual, "architecture: the residual goes in 'residual'");
    const int joint = static_cast<int>(JsonInt(e["joint"], 0, 1 << 20, "architecture: effect 'joint'"));
    DIFFDYN_CHECK(info.per_joint ? (joint >= 1 && joint <= model->dof()) : joint == 0,
                  "architecture: effect ", info.name, " has joint ", joint);
    count += static_cast<Eigen::Index>(info.params.size());
  }
  if (arch.contains("residual") && !arch["residual"].is_null()) {
    const auto& r = arch["residual"];
    DIFFDYN_CHECK(r.is_object() && r.contains("hidden"), "architecture: residual needs an integer 'hidden'");
    const Eigen::Index n = model->dof(), h = JsonInt(r["hidden"], 1, 4096, "architecture: residual 'hidden'");
    count += 6 * n + ResidualNetwork::Architecture(static_cast<int>(n), static_cast<int>(h)).num_parameters();
  }
  return count;
}

}  // namespace

void RegisterExtendedPhysicsKind() {
  if (!IsModelKindRegistered("extended-physics")) {
    RegisterModelKind("extended-physics", CountParameters);
  }
}

void SaveExtendedModel(const std::filesystem::path& path, const ExtendedModel& model,
                       const nlohmann::json& provenance, const nlohmann::json& metrics) {
  RegisterExtendedPhysicsKind();
  nlohmann::json arch;
  arch["model"] = model.model().name();
  nlohmann::json params = nlohmann::json::object();
  for (std::size_t i = 0; i < model.model().param_specs().size(); ++i) {
    params[model.model().param_specs()[i].name] = model.params()[static_cast<int>(i)];
  }
  arch["model_params"] = params;
  nlohmann::json effects = nlohmann::json::array();
  for (const Effect& e : model.effects()) {
    const EffectKindInfo& info = Info(e.kind);
    const bool prismatic = e.joint > 0 && model.model().prismatic(e.joint - 1);
    effects.push_back({{"kind", info.name},
                       {"joint", e.joint},
                       {"params", info.params},
                       {"units", prismatic ? info.prismatic_units : info.units},
                       {"stderr", e.stderrs}});
  }
  arch["effects"] = effects;
  std::vector<double> theta;
  const Eigen::VectorXd effect_params = model.EffectParams();
  theta.assign(effect_params.data(), effect_params.data() + effect_params.size());
  if (const ResidualNetwork* net = model.residual()) {
    const int n = model.dof();
    arch["residual"] = {{"inputs", 3 * n}, {"hidden", net->hidden()}, {"outputs", n}, {"activation", "tanh"}};
    // in_mean, in_scale, then the network's flat parameters [vec(W1), b1, vec(W2), b2].
    const auto append = [&theta](const Eigen::VectorXd& v) { theta.insert(theta.end(), v.data(), v.data() + v.size()); };
    append(net->in_mean);
    append(net->in_scale);
    append(net->net.parameters());
  } else {
    arch["residual"] = nullptr;
  }
  ModelFile file{"extended-physics", arch,
                 Eigen::Map<const Eigen::VectorXd>(theta.data(), static_cast<int>(theta.size())),
                 provenance, metrics};
  SaveModelFile(path, file);
}

ExtendedModel LoadExtendedModel(const std::filesystem::path& path) {
  RegisterExtendedPhysicsKind();
  const ModelFile file = LoadModelFile(path);
  DIFFDYN_CHECK(file.kind == "extended-physics", path.string(), ": model kind is '", file.kind,
                "', expected 'extended-physics'");
  const nlohmann::json& arch = file.architecture;
  const auto model = MakeAnalyticModel(arch["model"].get<std::string>());
  Eigen::VectorXd params = model->DefaultParams();
  for (const auto& [name, value] : arch["model_params"].items()) {
    params[model->ParamIndex(name)] = value.get<double>();
  }
  std::vector<Effect> effects;
  int k = 0;
  for (const auto& e : arch["effects"]) {
    Effect effect;
    effect.kind = ParseEffectKind(e["kind"].get<std::string>());
    effect.joint = e["joint"].get<int>();
    const std::size_t count = Info(effect.kind).params.size();
    for (std::size_t i = 0; i < count; ++i) effect.params.push_back(file.parameters[k++]);
    if (e.contains("stderr") && e["stderr"].is_array() && e["stderr"].size() == count) {
      for (const auto& s : e["stderr"]) effect.stderrs.push_back(s.get<double>());
    }
    effects.push_back(effect);
  }
  std::shared_ptr<const ResidualNetwork> residual;
  if (arch.contains("residual") && !arch["residual"].is_null()) {
    const int n = model->dof(), h = arch["residual"]["hidden"].get<int>();
    auto net = std::make_shared<ResidualNetwork>();
    auto take = [&](Eigen::Index count) {
      Eigen::VectorXd v = file.parameters.segment(k, count);
      k += static_cast<int>(count);
      return v;
    };
    net->in_mean = take(3 * n);
    net->in_scale = take(3 * n);
    const MlpArchitecture arch_net = ResidualNetwork::Architecture(n, h);
    net->net = Mlp<double>(arch_net, take(arch_net.num_parameters()));
    residual = net;
  }
  try {
    return ExtendedModel(model, params, effects, residual);
  } catch (const Error& e) {
    throw Error(StrCat(path.string(), ": ", e.what()));
  }
}

}  // namespace diffdyn
