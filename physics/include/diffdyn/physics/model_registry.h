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

#include "diffdyn/physics/analytic_model.h"

namespace diffdyn {

/// The `--model` names, in a fixed order.
std::vector<std::string> AnalyticModelNames();

/// The model called `name`; throws diffdyn::Error naming --model and the choices.
/// Compiled once in physics/src/model_registry.cc: a file that includes this
/// header does not instantiate the five models' dynamics on Jets.
std::shared_ptr<const AnalyticModel> MakeAnalyticModel(const std::string& name);

}  // namespace diffdyn
