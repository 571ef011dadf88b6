// The analytic models by `--model` name.
//
//   std::shared_ptr<const AnalyticModel> m = MakeAnalyticModel("cartpole");
//
// Names: pendulum, cartpole, double-pendulum, arm2, panda (simple_models.h,
// panda_dynamics.h). Each returns the runtime interface of analytic_model.h,
// whose inverse dynamics tau = ID(q, qd, qdd; p) evaluates on double and Jets.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/physics/analytic_model.h"
#include "diffdyn/physics/panda_dynamics.h"
#include "diffdyn/physics/simple_models.h"

namespace diffdyn {

/// The `--model` names, in a fixed order.
inline std::vector<std::string> AnalyticModelNames() {
  return {"pendulum", "cartpole", "double-pendulum", "arm2", "panda"};
}

/// The model called `name`; throws diffdyn::Error naming --model and the choices.
inline std::shared_ptr<const AnalyticModel> MakeAnalyticModel(const std::string& name) {
  if (name == "pendulum") return std::make_shared<AnalyticModelAdapter<PendulumModel>>();
  if (name == "cartpole") return std::make_shared<AnalyticModelAdapter<CartPoleModel>>();
  if (name == "double-pendulum") {
    return std::make_shared<AnalyticModelAdapter<DoublePendulumModel>>();
  }
  if (name == "arm2") return std::make_shared<AnalyticModelAdapter<Arm2Model>>();
  if (name == "panda") return std::make_shared<AnalyticModelAdapter<PandaModel>>();
  throw Error(StrCat("--model ", name,
                     ": unknown model (choose pendulum, cartpole, double-pendulum, arm2, panda)"));
}

}  // namespace diffdyn
