// Analytic toy transition models shared by the solver tests (MPPI, pushing cost and
// pushing trials): they show the controller is model-agnostic.
#pragma once

#include <memory>
#include <string>
#include <utility>

#include <Eigen/Core>

#include "diffdyn/models/transition_model.h"

namespace diffdyn::toy {

/// A stateless model of fixed sizes: subclasses only implement PredictBatch.
class ToyModel : public TransitionModel {
 public:
  ToyModel(int state_size, int action_size, std::string kind)
      : state_size_(state_size), action_size_(action_size), kind_(std::move(kind)) {}
  int state_size() const override { return state_size_; }
  int action_size() const override { return action_size_; }
  std::string kind() const override { return kind_; }
  std::unique_ptr<TransitionWorkspace> MakeWorkspace(int) const override {
    return std::make_unique<TransitionWorkspace>();
  }

 private:
  int state_size_, action_size_;
  std::string kind_;
};

/// x_{t+1} = x_t + 0.1 u_t with n-dimensional states and actions.
class DriftModel : public ToyModel {
 public:
  explicit DriftModel(int n) : ToyModel(n, n, "drift") {}
  void PredictBatch(const Eigen::Ref<const Eigen::MatrixXd>& states,
                    const Eigen::Ref<const Eigen::MatrixXd>& actions,
                    Eigen::Ref<Eigen::MatrixXd> next, TransitionWorkspace&) const override {
    CheckBatchSizes(states, actions, next);
    next = states + 0.1 * actions;
  }
};

}  // namespace diffdyn::toy
