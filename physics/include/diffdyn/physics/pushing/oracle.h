// The "oracle" transition model: the ODE-engine simulation itself behind the
// TransitionModel interface, x_{t+1} = F(x_t, u_t) with x = block pose (3) and
// u = push action (3).
//
// Each column of a batch is simulated from rest: the workspace's PushingEnv is
// reset to states(:, b) and steps actions(:, b). Slow (milliseconds per sample);
// for tests and small comparisons with learned models.
//
//   diffdyn::PushingOracle oracle;                 // default PushingConfig
//   auto ws = oracle.MakeWorkspace(16);             // owns a PushingEnv; one per thread
//   oracle.PredictBatch(states, actions, next, *ws);
#pragma once

#include <memory>
#include <string>

#include "diffdyn/models/transition_model.h"
#include "diffdyn/physics/pushing/env.h"
#include "diffdyn/physics/pushing/system.h"

namespace diffdyn {

/// TransitionModel that runs the pushing simulation (kind "oracle").
class PushingOracle : public TransitionModel {
 public:
  explicit PushingOracle(const PushingConfig& config = {}) : config_(config) {}

  int state_size() const override { return 3; }
  int action_size() const override { return 3; }
  std::string kind() const override { return "oracle"; }
  SystemDescription description() const override { return PushingSystem(); }

  /// A workspace owning one PushingEnv (built with this model's config).
  std::unique_ptr<TransitionWorkspace> MakeWorkspace(int max_batch) const override;

  /// next(:, b) = pose after simulating actions(:, b) from rest at states(:, b).
  /// A state the world cannot hold (off the table, inside the obstacle) and an
  /// unreachable push give next = state. Throws diffdyn::Error on wrong sizes or
  /// an invalid action.
  void PredictBatch(const Eigen::Ref<const Eigen::MatrixXd>& states,
                    const Eigen::Ref<const Eigen::MatrixXd>& actions,
                    Eigen::Ref<Eigen::MatrixXd> next, TransitionWorkspace& ws) const override;

  const PushingConfig& config() const { return config_; }

 private:
  PushingConfig config_;
};

}  // namespace diffdyn
