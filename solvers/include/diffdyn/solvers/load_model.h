// One loader for every dynamics model a command takes with --model.
//
//   spec                         model (a TransitionModel)
//   a model file of kind         abs-nn, res-nn, abs-node, res-node: the LearnedModel;
//                                extended-physics (what diagnose writes): the extended
//                                model through the continuous-time adapter
//   pendulum, cartpole,          the analytic model with its default parameters
//   double-pendulum, arm2, panda (model_conventions.md) through the adapter
//   oracle                       the ODE-engine pusher (PushingOracle)
//   delan, delan-friction        a DeLaN's forward dynamics through the adapter
//                                (u = the torques of options.actuated)
//
// Continuous-time models (analytic and extended) integrate x = (q, qd) under a
// held torque over one transition of `dt` seconds (continuous_model.h); they need
// options.dt > 0, the others ignore it. options.precision (--precision) converts a
// learned model to float32 or float64; the others compute in float64 and refuse f32.
//
//   auto model = LoadTransitionModel("out/extended_model.json", {.dt = 0.004});
//   auto ws = model->MakeWorkspace(256);
//   model->PredictBatch(states, torques, next, *ws);   // 2n x B, n x B, 2n x B
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "diffdyn/models/continuous_model.h"
#include "diffdyn/models/transition_model.h"
#include "diffdyn/physics/pushing/env.h"

namespace diffdyn {

/// Settings of LoadTransitionModel.
struct LoadModelOptions {
  /// Transition time step (s) of continuous-time models; 0 = not given (refused for them).
  double dt = 0.0;
  /// Solver and solver steps per transition of continuous-time models.
  Method method = Method::kRk4Classic;
  int substeps = 4;
  /// 0-based joints a DeLaN's action drives, increasing (the others get torque 0);
  /// empty: every joint (u = tau). A control task passes its actuated joints.
  std::vector<int> actuated{};
  /// The world of the `oracle`.
  PushingConfig world{};
  /// The precision to compute in (--precision); unset: the model file's own, float64
  /// for the others. Only the learned kinds have a float32 path; f32 for another
  /// model is refused.
  std::optional<Precision> precision{};
};

/// The model `spec` names (see the file comment). Throws diffdyn::Error with one line
/// naming --model (and the file) for an unknown name, a missing or bad file, a
/// continuous-time model without dt, or an extended model with a delay effect.
std::unique_ptr<TransitionModel> LoadTransitionModel(const std::string& spec,
                                                     const LoadModelOptions& options = {});

}  // namespace diffdyn
