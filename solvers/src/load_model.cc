#include "diffdyn/solvers/load_model.h"

#include <filesystem>
#include <utility>

#include "diffdyn/models/delan.h"
#include "diffdyn/models/io.h"
#include "diffdyn/models/learned_model.h"
#include "diffdyn/models/model_file.h"
#include "diffdyn/physics/effects.h"
#include "diffdyn/physics/model_registry.h"
#include "diffdyn/physics/pushing/oracle.h"
#include "diffdyn/solvers/extended_model_file.h"
#include "diffdyn/solvers/pushing/world_file.h"

namespace diffdyn {
namespace {

// An extended model (an analytic one without effects included) through the adapter.
std::unique_ptr<TransitionModel> Continuous(std::shared_ptr<const ExtendedModel> model,
                                           const std::string& spec, const std::string& kind,
                                           const LoadModelOptions& options) {
  DIFFDYN_CHECK(options.dt > 0, "--model ", spec, ": a continuous-time model (", kind,
                ") needs a transition time step (--dt)");
  SystemDescription system = AnalyticSystem(model->model());
  try {
    return std::make_unique<ContinuousTransitionModel<ExtendedDynamics>>(
        ExtendedDynamics(std::move(model)), std::move(system), Eigen::VectorXd(),
        ContinuousOptions{.method = options.method, .dt = options.dt, .substeps = options.substeps},
        kind);
  } catch (const Error& e) {
    throw Error(StrCat("--model ", spec, ": ", e.what()));
  }
}

// A DeLaN's forward dynamics through the adapter: x = (q1..qn, qd1..qdn), u = the
// torques of options.actuated (all joints when empty).
std::unique_ptr<TransitionModel> DelanTransitionModel(Delan delan, const std::string& spec,
                                                     const LoadModelOptions& options) {
  DIFFDYN_CHECK(options.dt > 0, "--model ", spec, ": a continuous-time model (delan) needs a "
                "transition time step (--dt)");
  SystemDescription system;
  system.name = "delan";
  const int n = delan.dof();
  for (int j = 1; j <= n; ++j) system.state_names.push_back(StrCat("q", j));
  for (int j = 1; j <= n; ++j) system.state_names.push_back(StrCat("qd", j));
  for (std::size_t k = 0; k < options.actuated.size(); ++k) {
    DIFFDYN_CHECK(options.actuated[k] >= 0 && options.actuated[k] < n &&
                      (k == 0 || options.actuated[k] > options.actuated[k - 1]),
                  "--model ", spec, ": actuated joint ", options.actuated[k] + 1, " is not one of its ", n,
                  " joints in increasing order");
  }
  if (options.actuated.empty()) {
    for (int j = 1; j <= n; ++j) system.action_names.push_back(StrCat("tau", j));
  } else {
    for (int j : options.actuated) system.action_names.push_back(StrCat("tau", j + 1));
  }
  const std::string kind = delan.options().kind();
  return std::make_unique<ContinuousTransitionModel<DelanDynamics>>(
      DelanDynamics{std::make_shared<const Delan>(std::move(delan)), options.actuated}, std::move(system),
      Eigen::VectorXd(), ContinuousOptions{.method = options.method, .dt = options.dt, .substeps = options.substeps},
      kind);
}

// The model `spec` names, in the precision its file records (float64 for the others).
std::unique_ptr<TransitionModel> OpenModel(const std::string& spec,
                                           const LoadModelOptions& options) {
  DIFFDYN_CHECK(!spec.empty(), "--model: empty (a model file, an analytic model name or 'oracle')");
  if (spec == "oracle") return std::make_unique<PushingOracle>(options.world);
  for (const std::string& name : AnalyticModelNames()) {
    if (spec != name) continue;
    std::shared_ptr<const AnalyticModel> analytic = MakeAnalyticModel(name);
    auto nominal = std::make_shared<const ExtendedModel>(analytic, analytic->DefaultParams(),
                                                         std::vector<Effect>{});
    return Continuous(std::move(nominal), spec, name, options);
  }
  DIFFDYN_CHECK(std::filesystem::exists(spec), "--model ", spec,
                ": no such file, and not oracle or an analytic model (pendulum, cartpole, "
                "double-pendulum, arm2, panda)");
  try {
    CheckInputPath(spec);
  } catch (const Error& e) {
    throw Error(StrCat("--model ", e.what()));
  }
  RegisterLearnedModelKinds();
  RegisterExtendedPhysicsKind();
  RegisterDelanKind();
  RegisterPusherWorldKind();
  const ModelFile file = LoadModelFile(spec);
  if (file.kind == "oracle")
    return std::make_unique<PushingOracle>(LoadPusherWorld(spec, options.world));
  if (IsDelanKind(file.kind)) return DelanTransitionModel(LoadDelan(spec), spec, options);
  if (file.kind == "extended-physics") {
    auto extended = std::make_shared<const ExtendedModel>(LoadExtendedModel(spec));
    return Continuous(std::move(extended), spec, file.kind, options);
  }
  if (file.kind == "abs-nn" || file.kind == "res-nn" || file.kind == "abs-node" ||
      file.kind == "res-node") {
    return std::make_unique<LearnedModel>(LoadLearnedModel(spec));
  }
  throw Error(StrCat("--model ", spec, ": a model of kind '", file.kind,
                     "' is not a dynamics model (expected abs-nn, res-nn, abs-node, res-node, "
                     "extended-physics, delan, delan-friction or a pusher world, kind oracle)"));
}

}  // namespace

std::unique_ptr<TransitionModel> LoadTransitionModel(const std::string& spec,
                                                     const LoadModelOptions& options) {
  std::unique_ptr<TransitionModel> model = OpenModel(spec, options);
  if (options.precision && !model->SetPrecision(*options.precision)) {
    throw Error(StrCat("--precision ", PrecisionName(*options.precision), ": --model ", spec,
                       " is a ", model->kind(),
                       " model, which computes in float64 only (float32: abs-nn, res-nn, "
                       "abs-node, res-node)"));
  }
  return model;
}

}  // namespace diffdyn
