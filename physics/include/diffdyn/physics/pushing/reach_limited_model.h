// ReachLimitedModel: a pushing model that knows which pushes the arm can execute.
//
// A learned pushing model predicts a motion for every action, including pushes
// whose tool path the arm cannot reach; PushingEnv::Step reports those as
// unreachable and moves nothing. This wrapper gives the inner model's prediction
// where the push stays in the reach annulus and leaves the block where it is
// otherwise:
//
//   F_r(x, u) = F(x, u)   if reach.Contains(PushingEnv::PlanarPath(x, u)),
//               x         otherwise.
//
// A planner rolling out F_r cannot count on a push the arm cannot make, so it
// does not steer the block to where only such a push would finish the task.
//
//   diffdyn::ReachLimitedModel limited(model, diffdyn::PushingEnv::Reach());
//   diffdyn::Mppi mppi(limited, cost, options, seed);
#pragma once

#include <memory>
#include <string>

#include <Eigen/Core>

#include "diffdyn/models/transition_model.h"
#include "diffdyn/physics/pushing/env.h"

namespace diffdyn {

/// F_r of the file comment around a pushing model (state and action size 3).
class ReachLimitedModel : public TransitionModel {
 public:
  /// Keeps a reference to `model`, which must outlive the wrapper.
  ReachLimitedModel(const TransitionModel& model, const PushReach& reach)
      : model_(model), reach_(reach) {
    DIFFDYN_CHECK(model.state_size() == 3 && model.action_size() == 3, "ReachLimitedModel: model ",
                  model.kind(), " has state size ", model.state_size(), " and action size ",
                  model.action_size(), "; pushing needs 3 and 3");
  }

  int state_size() const override { return 3; }
  int action_size() const override { return 3; }
  /// The inner model's kind: the wrapper changes no model file.
  std::string kind() const override { return model_.kind(); }
  SystemDescription description() const override { return model_.description(); }
  Precision precision() const override { return model_.precision(); }
  std::unique_ptr<TransitionWorkspace> MakeWorkspace(int max_batch) const override {
    return model_.MakeWorkspace(max_batch);
  }

  /// next = F_r(states, actions) column by column (3 x B each).
  void PredictBatch(const Eigen::Ref<const Eigen::MatrixXd>& states,
                    const Eigen::Ref<const Eigen::MatrixXd>& actions,
                    Eigen::Ref<Eigen::MatrixXd> next, TransitionWorkspace& ws) const override {
    model_.PredictBatch(states, actions, next, ws);
    for (Eigen::Index b = 0; b < states.cols(); ++b) {
      const Eigen::Vector3d x(states(0, b), states(1, b), states(2, b));
      const Eigen::Vector3d u(actions(0, b), actions(1, b), actions(2, b));
      if (reach_.Contains(PushingEnv::PlanarPath(x, u))) continue;
      for (int i = 0; i < 3; ++i) next(i, b) = x[i];
    }
  }

  const PushReach& reach() const { return reach_; }

 private:
  const TransitionModel& model_;
  PushReach reach_;
};

}  // namespace diffdyn
