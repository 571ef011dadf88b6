#include "diffdyn/physics/pushing/oracle.h"

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {
namespace {

struct OracleWorkspace : TransitionWorkspace {
  OracleWorkspace(const PushingConfig& config, int max_batch) : env(config), max_batch(max_batch) {}
  PushingEnv env;
  int max_batch;
};

}  // namespace

std::unique_ptr<TransitionWorkspace> PushingOracle::MakeWorkspace(int max_batch) const {
  DIFFDYN_CHECK(max_batch >= 1, "oracle: max_batch must be at least 1, got ", max_batch);
  return std::make_unique<OracleWorkspace>(config_, max_batch);
}

void PushingOracle::PredictBatch(const Eigen::Ref<const Eigen::MatrixXd>& states,
                                 const Eigen::Ref<const Eigen::MatrixXd>& actions,
                                 Eigen::Ref<Eigen::MatrixXd> next, TransitionWorkspace& ws) const {
  CheckBatchSizes(states, actions, next);
  auto* workspace = dynamic_cast<OracleWorkspace*>(&ws);
  DIFFDYN_CHECK(workspace != nullptr, "oracle: the workspace was not made by this model");
  DIFFDYN_CHECK(states.cols() <= workspace->max_batch, "oracle: batch of ", states.cols(),
                " exceeds the workspace's max_batch ", workspace->max_batch);
  for (Eigen::Index b = 0; b < states.cols(); ++b) {
    const Eigen::Vector3d state = states.col(b);
    const Eigen::Vector3d action = actions.col(b);
    PushingEnv::ValidateAction(action);
    const bool holdable =
        state.allFinite() && PushingEnv::OnTable(state.x(), state.y()) &&
        (!config_.obstacle || PushingEnv::ObstaclePenetration(state, config_.block_size) == 0);
    Eigen::Vector3d result = state;
    if (holdable) {
      workspace->env.Reset(state);
      const PushResult r = workspace->env.Step(action);
      if (r.status != PushStatus::kUnreachable) result = r.pose;
    }
    // Element-wise copy (a 3-vector into a dynamic block trips g++'s AVX-512 bounds check).
    for (int k = 0; k < 3; ++k) next(k, b) = result[k];
  }
}

}  // namespace diffdyn
