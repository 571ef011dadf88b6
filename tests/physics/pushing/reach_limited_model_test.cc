// ReachLimitedModel: the inner model's prediction where the arm reaches the push,
// the unchanged pose where it does not.
#include "diffdyn/physics/pushing/reach_limited_model.h"

#include <memory>
#include <string>

#include <gtest/gtest.h>

#include "diffdyn/models/learned_model.h"
#include "diffdyn/models/random.h"

namespace diffdyn {
namespace {

TEST(ReachLimitedModel, KeepsThePoseExactlyWhereThePushIsUnreachable) {
  const LearnedModel model =
      LearnedModel::Initialized({.type = LearnedKind::kResNn, .hidden = 8}, 3);
  const PushReach reach{0.27, 0.8};
  const ReachLimitedModel limited(model, reach);
  EXPECT_EQ(limited.kind(), model.kind());
  // Poses over the table from near the base to beyond the reach, random actions.
  Rng rng(11);
  const int n = 400;
  Eigen::MatrixXd states(3, n), actions(3, n), raw(3, n), next(3, n);
  for (int b = 0; b < n; ++b) {
    states.col(b) << Uniform(rng, 0.2, 0.95), Uniform(rng, -0.45, 0.45), Uniform(rng, -3.1, 3.1);
    actions.col(b) << Uniform(rng, -1, 1), Uniform(rng, -1.5, 1.5), Uniform(rng, 0, 1);
  }
  auto ws = limited.MakeWorkspace(n);
  model.PredictBatch(states, actions, raw, *ws);
  limited.PredictBatch(states, actions, next, *ws);
  int unreachable = 0;
  for (int b = 0; b < n; ++b) {
    const bool in = reach.Contains(PushingEnv::PlanarPath(states.col(b), actions.col(b)));
    unreachable += !in;
    EXPECT_EQ(next.col(b), in ? raw.col(b) : states.col(b).eval()) << "column " << b;
  }
  // Both cases occur often enough to test.
  EXPECT_GT(unreachable, 40);
  EXPECT_LT(unreachable, n - 40);
}

// x' = x + u for states and actions of size 2: not a pushing model.
class PlanarDrift : public TransitionModel {
 public:
  int state_size() const override { return 2; }
  int action_size() const override { return 2; }
  std::string kind() const override { return "planar-drift"; }
  std::unique_ptr<TransitionWorkspace> MakeWorkspace(int) const override {
    return std::make_unique<TransitionWorkspace>();
  }
  void PredictBatch(const Eigen::Ref<const Eigen::MatrixXd>& states,
                    const Eigen::Ref<const Eigen::MatrixXd>& actions,
                    Eigen::Ref<Eigen::MatrixXd> next, TransitionWorkspace&) const override {
    next = states + actions;
  }
};

TEST(ReachLimitedModel, RejectsModelsThatAreNotPushingModels) {
  const PlanarDrift drift;
  try {
    ReachLimitedModel limited(drift, {0.2, 0.8});
    ADD_FAILURE() << "no error for a model of state size 2";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("planar-drift"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace diffdyn
