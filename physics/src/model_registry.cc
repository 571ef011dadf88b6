#include "diffdyn/physics/model_registry.h"

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/physics/panda_dynamics.h"
#include "diffdyn/physics/simple_models.h"

// The adapters (every model's dynamics on double and on Jets) are instantiated
// here once, not in every file that names a model.
namespace diffdyn {

std::vector<std::string> AnalyticModelNames() {
  return {"pendulum", "cartpole", "double-pendulum", "arm2", "panda"};
}

std::shared_ptr<const AnalyticModel> MakeAnalyticModel(const std::string& name) {
  if (name == "pendulum") return std::make_shared<AnalyticModelAdapter<PendulumModel>>();
  if (name == "cartpole") return std::make_shared<AnalyticModelAdapter<CartPoleModel>>();
  if (name == "double-pendulum") return std::make_shared<AnalyticModelAdapter<DoublePendulumModel>>();
  if (name == "arm2") return std::make_shared<AnalyticModelAdapter<Arm2Model>>();
  if (name == "panda") return std::make_shared<AnalyticModelAdapter<PandaModel>>();
  throw Error(StrCat("--model ", name,
                     ": unknown model (choose pendulum, cartpole, double-pendulum, arm2, panda)"));
}

}  // namespace diffdyn
