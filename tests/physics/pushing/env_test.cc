// The ODE-engine pushing world: the quick version of the 10,000-push check,
// determinism across thread counts, action validation, off_table, the oracle
// and the IK it relies on.
#include "diffdyn/physics/pushing/env.h"

#include <cmath>
#include <numbers>
#include <sstream>

#include <gtest/gtest.h>

#include "diffdyn/physics/pushing/collect.h"
#include "diffdyn/physics/pushing/oracle.h"
#include "diffdyn/physics/pushing/panda_ik.h"

namespace diffdyn {
namespace {

TEST(PandaIk, ReachesPushingTargetsWithinLimits) {
  PandaIk ik;
  for (const Eigen::Vector3d& target : {Eigen::Vector3d(0.5, 0.0, 0.02), Eigen::Vector3d(0.7, 0.3, 0.02),
                                       Eigen::Vector3d(0.35, -0.3, 0.05)}) {
    const auto sol = ik.Solve(target, Eigen::Vector3d(0, 0, -1), ik.options().nominal);
    ASSERT_TRUE(sol.converged) << target.transpose();
    const auto tool = Panda::Tool<double>(sol.q, ik.options().tool_length);
    EXPECT_LT((tool.p - target).norm(), 1e-6);
    EXPECT_NEAR(tool.R(2, 2), -1.0, 1e-9);
    EXPECT_TRUE(Panda::WithinLimits(sol.q));
  }
  // Beyond the arm's reach: reported, not converged.
  EXPECT_FALSE(ik.Solve({1.3, 0, 0.02}, {0, 0, -1}, ik.options().nominal).converged);
}

// Quick version of the separate 10,000-push check (examples/pushing_world.cc):
// task starts with the obstacle, random actions.
TEST(PushingEnv, QuickCheckOfRandomPushes) {
  CollectOptions options;
  options.trajectories = 10;
  options.length = 8;
  options.seed = 21;
  options.threads = 2;
  options.starts = StartDistribution::kTask;
  options.world.obstacle = true;
  CollectStats stats;
  const auto data = CollectPushingData(options, &stats);
  EXPECT_GE(stats.pushes, 40);
  EXPECT_GT(stats.min_block_z, -0.005);       // no tunnelling into the table
  EXPECT_LT(stats.max_block_z, 0.005);        // no tipping or flying
  EXPECT_LT(stats.max_block_speed, 1.0);      // no explosion (tip moves at <= 0.3 m/s)
  EXPECT_LT(stats.max_limit_violation, 1e-3); // joint limits kept
  EXPECT_LE(stats.max_tracking_error, 2e-3);  // pushes where the tip kept off the obstacle
  for (const auto& t : data) {
    for (Eigen::Index k = 0; k < t.states.cols(); ++k) {
      const Eigen::Vector3d s = t.states.col(k);
      EXPECT_LT(PushingEnv::ObstaclePenetration(s), 2e-3) << s.transpose();
      EXPECT_TRUE(s.allFinite());
      EXPECT_GT(s.z(), -std::numbers::pi - 1e-12);
      EXPECT_LE(s.z(), std::numbers::pi + 1e-12);
    }
  }
}

TEST(PushingEnv, PushMovesBlockAlongPushAndTipFollowsThePath) {
  PushingConfig config;
  config.obstacle = false;
  PushingEnv env(config);
  env.Reset({0.5, 0.0, 0.0});
  const PushResult r = env.Step({0.0, 0.0, 1.0});  // straight through the centre, 0.1 m
  ASSERT_EQ(r.status, PushStatus::kOk);
  EXPECT_LE(r.max_tracking_error, 2e-3);
  // The tip starts 0.1 m behind the centre and ends 0.035 + 0.1 m further on.
  const auto& path = env.tip_path();
  ASSERT_GE(path.size(), 10u);
  EXPECT_NEAR(path.front().x(), 0.4, 2e-3);
  EXPECT_NEAR(path.back().x(), 0.535, 2e-3);
  EXPECT_NEAR(path.back().z(), config.push_height, 2e-3);
  // The block moves forward by the push beyond first contact, keeps its heading.
  const double contact = 0.5 - 0.05 - config.tip_radius;  // tip centre at first touch
  const double travel = 0.535 - contact;
  EXPECT_GT(r.pose.x() - 0.5, 0.7 * travel);
  EXPECT_LT(r.pose.x() - 0.5, travel + 0.01);
  EXPECT_NEAR(r.pose.y(), 0.0, 2e-3);
  EXPECT_NEAR(r.pose.z(), 0.0, 0.02);
  EXPECT_EQ(env.joint_path().size(), path.size());
}

TEST(PushingEnv, PlanarPathIsTheExecutedToolPath) {
  PushingConfig config;
  config.obstacle = false;
  PushingEnv env(config);
  const Eigen::Vector3d pose(0.55, -0.1, 0.7), action(0.6, -0.9, 0.8);
  env.Reset(pose);
  const PushPath plan = PushingEnv::PlanarPath(pose, action);
  // By hand: a = p - 0.1 e_x + 0.0475 u0 e_y, b = a + 0.035 e_x, c = b + 0.08 at 0.7 - 0.9.
  const Eigen::Vector2d ex(std::cos(0.7), std::sin(0.7)), ey(-std::sin(0.7), std::cos(0.7));
  const Eigen::Vector2d a = pose.head<2>() - 0.1 * ex + 0.0475 * 0.6 * ey;
  EXPECT_LT((plan.approach_start - a).norm(), 1e-15);
  EXPECT_LT((plan.push_start - (a + 0.035 * ex)).norm(), 1e-15);
  EXPECT_LT((plan.push_end - plan.push_start - 0.08 * Eigen::Vector2d(std::cos(-0.2), std::sin(-0.2)))
                .norm(), 1e-15);
  const PushResult r = env.Step(action);
  ASSERT_EQ(r.status, PushStatus::kOk);
  EXPECT_LT((env.tip_path().front().head<2>() - plan.approach_start).norm(), 2e-3);
  EXPECT_LT((env.tip_path().back().head<2>() - plan.push_end).norm(), 2e-3);
}

TEST(PushingEnv, ReachAnnulusSeparatesExecutableFromUnreachablePushes) {
  PushingConfig config;
  config.obstacle = false;
  const PushReach reach = PushingEnv::Reach(config);
  // A Panda's tool point at table height: roughly 0.25-0.3 m to 0.8 m from the base.
  EXPECT_GT(reach.inner, 0.2);
  EXPECT_LT(reach.inner, 0.35);
  EXPECT_GT(reach.outer, 0.7);
  EXPECT_LT(reach.outer, 0.9);
  // Zero-length pushes straight away from the base along azimuth phi: the tool moves
  // out from r - 0.1 to r - 0.065 (the approach). Ending 1.5 cm inside the outer
  // radius Step executes it; starting 1 cm outside it reports it unreachable.
  PushingEnv env(config);
  for (double phi : {-0.5, 0.0, 0.4}) {
    for (double offset : {-0.05, 0.01}) {
      const double r = reach.outer + offset + 0.1;  // the tool starts at reach.outer + offset
      const Eigen::Vector3d pose(r * std::cos(phi), r * std::sin(phi), phi);
      if (!PushingEnv::OnTable(pose.x(), pose.y())) continue;
      env.Reset(pose);
      const PushStatus status = env.Step({0.0, 0.0, 0.0}).status;
      EXPECT_EQ(status == PushStatus::kUnreachable, offset > 0) << "phi " << phi << " offset " << offset;
    }
  }
}

TEST(PushingEnv, InvalidActionsAreRejectedByName) {
  PushingEnv env;
  auto message = [&](const Eigen::Vector3d& u) -> std::string {
    try {
      env.Step(u);
    } catch (const Error& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(message({1.5, 0, 0.5}).find("push_location"), std::string::npos);
  EXPECT_NE(message({0, 2.0, 0.5}).find("push_angle"), std::string::npos);
  EXPECT_NE(message({0, 0, -0.1}).find("push_length"), std::string::npos);
  EXPECT_NE(message({0, 0, std::nan("")}).find("not finite"), std::string::npos);
  EXPECT_NE(message({INFINITY, 0, 0.5}).find("push_location"), std::string::npos);
  EXPECT_THROW(env.Reset({5.0, 0.0, 0.0}), Error);       // off the table
  EXPECT_THROW(env.Reset({0.6, 0.2, 0.0}), Error);       // inside the obstacle
}

TEST(PushingEnv, BlockPushedOffTheTableEndsWithOffTable) {
  PushingConfig config;
  config.obstacle = false;
  PushingEnv env(config);
  env.Reset({0.45, 0.47, std::numbers::pi / 2});  // 3 cm from the table's +y edge, facing it
  const PushResult r = env.Step({0.0, 0.0, 1.0});
  EXPECT_EQ(r.status, PushStatus::kOffTable);
  EXPECT_STREQ(PushStatusName(r.status), "off_table");
  EXPECT_FALSE(PushingEnv::OnTable(r.pose.x(), r.pose.y()));
  EXPECT_EQ(PushStatusName(PushStatus::kUnreachable), std::string("unreachable"));
}

TEST(PushingEnv, SameSeedGivesIdenticalCsvAtOneAndTwoThreads) {
  CollectOptions options;
  options.trajectories = 6;
  options.length = 4;
  options.seed = 99;
  std::ostringstream one, two;
  options.threads = 1;
  WritePushingCsv(one, CollectPushingData(options));
  options.threads = 2;
  WritePushingCsv(two, CollectPushingData(options));
  EXPECT_EQ(one.str(), two.str());
  options.seed = 100;
  std::ostringstream other;
  WritePushingCsv(other, CollectPushingData(options));
  EXPECT_NE(one.str(), other.str());
}

TEST(PushingOracle, MatchesTheEnvironmentAndChecksSizes) {
  PushingConfig config;
  config.obstacle = false;
  const PushingOracle oracle(config);
  EXPECT_EQ(oracle.kind(), "oracle");
  auto ws = oracle.MakeWorkspace(2);
  Eigen::MatrixXd states(3, 2), actions(3, 2), next(3, 2);
  states << 0.45, 0.5, 0.0, 0.1, 0.3, -0.2;
  actions << 0.2, -0.5, 0.1, -0.3, 0.8, 0.6;
  oracle.PredictBatch(states, actions, next, *ws);
  PushingEnv env(config);
  for (int b = 0; b < 2; ++b) {
    env.Reset(states.col(b));
    const Eigen::Vector3d expected = env.Step(actions.col(b)).pose;
    for (int k = 0; k < 3; ++k) EXPECT_EQ(next(k, b), expected[k]);
    EXPECT_GT((next.col(b) - states.col(b)).norm(), 1e-3);  // the pushes move the block
  }
  Eigen::MatrixXd wrong(2, 2);
  EXPECT_THROW(oracle.PredictBatch(wrong, actions, next, *ws), Error);
}

}  // namespace
}  // namespace diffdyn
