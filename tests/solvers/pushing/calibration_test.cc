// Calibrating the pusher: a world with another block-table friction is found
// again from its pushes, a world measured with sensor noise alone gives no gain,
// and pusher world files round-trip and refuse bad contents.
#include "diffdyn/solvers/pushing/calibration.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <vector>

#include <gtest/gtest.h>

#include "diffdyn/models/random.h"
#include "diffdyn/physics/pushing/collect.h"
#include "diffdyn/solvers/load_model.h"
#include "diffdyn/solvers/pushing/world_file.h"

namespace diffdyn {
namespace {

PushingConfig FreeWorld() {
  PushingConfig world;
  world.obstacle = false;
  return world;
}

// `count` trajectories of `length` seeded random pushes in `world` from the seed's
// start pose, poses measured with Gaussian noise (sigma_xy m, sigma_theta rad).
std::vector<Trajectory> Measure(const PushingConfig& world, int count, int length,
                                std::uint64_t seed, double sigma_xy = 0, double sigma_theta = 0) {
  std::vector<Trajectory> out;
  PushingEnv env(world);
  Rng noise = TrajectoryRng(seed, 1000);
  for (int t = 0; t < count; ++t) {
    Rng rng = TrajectoryRng(seed, t);
    Trajectory traj;
    traj.states.resize(3, length + 1);
    traj.actions.resize(3, length);
    traj.t = Eigen::VectorXd::LinSpaced(length + 1, 0, length);
    Eigen::Vector3d pose(0.4, 0.0, 0.2 * std::numbers::pi);
    traj.states.col(0) = pose;
    for (int k = 0; k < length; ++k) {
      const Eigen::Vector3d action = SamplePushAction(rng);
      env.Reset(pose);
      pose = env.Step(action).pose;
      traj.actions.col(k) = action;
      traj.states.col(k + 1) = pose;
    }
    for (int k = 1; k <= length; ++k) {
      traj.states(0, k) += sigma_xy * StandardNormal(noise);
      traj.states(1, k) += sigma_xy * StandardNormal(noise);
      traj.states(2, k) += sigma_theta * StandardNormal(noise);
    }
    out.push_back(traj);
  }
  return out;
}

TEST(PusherCalibration, FindsTheBlockTableFrictionOfAnotherWorld) {
  PushingConfig truth = FreeWorld();
  truth.block_table_friction = 0.2;
  const std::vector<Trajectory> data = Measure(truth, 4, 4, 3);
  PusherCalibrationOptions options;
  options.parameters = {"block_table_friction"};
  options.holdout_fraction = 0.25;
  options.max_iterations = 6;
  options.coarse_sweeps = 1;
  const PusherCalibration fit = CalibratePusher(data, FreeWorld(), options);
  ASSERT_EQ(fit.parameters.size(), 1u);
  EXPECT_NEAR(fit.parameters[0].nominal, 0.1, 1e-12);
  EXPECT_NEAR(fit.parameters[0].value, 0.2, 0.02);
  EXPECT_TRUE(std::isfinite(fit.parameters[0].standard_error));
  EXPECT_LT(fit.heldout_loss_calibrated, 0.2 * fit.heldout_loss_nominal);
  EXPECT_EQ(fit.heldout_trajectories, 1);
  EXPECT_EQ(fit.heldout.size(), 4u);
  EXPECT_NEAR(fit.calibrated.block_table_friction, fit.parameters[0].value, 0);
  EXPECT_LT(fit.rollout_error_calibrated, fit.rollout_error_nominal);
}

TEST(PusherCalibration, NoiseAloneGivesNoSignificantGain) {
  const std::vector<Trajectory> data = Measure(FreeWorld(), 6, 3, 4, 1e-3, 0.01);
  PusherCalibrationOptions options;
  options.parameters = {"block_table_friction"};
  options.holdout_fraction = 0.5;
  options.max_iterations = 4;
  options.coarse_sweeps = 1;
  const PusherCalibration fit = CalibratePusher(data, FreeWorld(), options);
  EXPECT_NEAR(fit.parameters[0].value, 0.1, 0.02);
  EXPECT_LT(fit.heldout_gain_t, 3.0);
  EXPECT_GT(fit.heldout_loss_calibrated, 0.9 * fit.heldout_loss_nominal);
}

TEST(PusherCalibration, RefusesUnknownParametersAndALonePadWidth) {
  const std::vector<Trajectory> data = Measure(FreeWorld(), 2, 1, 5);
  PusherCalibrationOptions options;
  options.parameters = {"table_colour"};
  EXPECT_THROW(CalibratePusher(data, FreeWorld(), options), Error);
  options.parameters = {"tip_pad_x"};
  EXPECT_THROW(CalibratePusher(data, FreeWorld(), options), Error);
  options.parameters = {"block_mass", "block_mass"};
  EXPECT_THROW(CalibratePusher(data, FreeWorld(), options), Error);
  options.parameters = {"block_mass"};
  EXPECT_THROW(CalibratePusher({data[0]}, FreeWorld(), options), Error);
}

TEST(PusherCalibration, ParametersReadTheWorldsEffectiveValues) {
  PushingConfig world = FreeWorld();
  EXPECT_NEAR(PusherParameter(world, "block_inertia"), 10.0 * 0.02 / 12, 1e-15);
  EXPECT_EQ(PusherParameter(world, "tip_pad_x"), world.tip_radius);
  SetPusherParameter(world, "tip_pad_y", 0.01);
  EXPECT_EQ(world.tip_pad_x, world.tip_radius);
  EXPECT_EQ(world.tip_pad_y, 0.01);
  EXPECT_THROW(PusherParameter(world, "nothing"), Error);
}

TEST(PusherWorldFile, RoundTripsAndLoadsAsTheOracle) {
  PushingConfig world = FreeWorld();
  world.tip_block_friction = 0.35;
  world.tip_pad_x = 0.004;
  world.tip_pad_y = 0.011;
  const std::string path =
      (std::filesystem::path(::testing::TempDir()) / "pusher_world.json").string();
  SavePusherWorld(path, world, {{"source", "test"}}, {});
  PushingConfig base;
  base.obstacle = true;
  const PushingConfig back = LoadPusherWorld(path, base);
  EXPECT_TRUE(back.obstacle);  // the task's, not the file's
  EXPECT_EQ(back.tip_block_friction, 0.35);
  EXPECT_EQ(back.tip_pad_x, 0.004);
  EXPECT_EQ(back.tip_pad_y, 0.011);

  // As a model: the oracle in that world.
  LoadModelOptions options;
  options.world = FreeWorld();
  const auto model = LoadTransitionModel(path, options);
  EXPECT_EQ(model->kind(), "oracle");
  const Eigen::Matrix3Xd state = Eigen::Vector3d(0.45, 0.02, 0.3),
                         action = Eigen::Vector3d(0.4, 0.3, 0.8);
  Eigen::MatrixXd next(3, 1);
  auto ws = model->MakeWorkspace(1);
  model->PredictBatch(state, action, next, *ws);
  PushingConfig expected_world = back;
  expected_world.obstacle = false;
  const Eigen::Matrix3Xd expected = ReplayPushes(expected_world, state, action, 1);
  EXPECT_TRUE(next.isApprox(expected, 1e-12)) << next.transpose() << " vs " << expected.transpose();
}

TEST(PusherWorldFile, RefusesUnknownKeysAndBadValues) {
  EXPECT_THROW(PusherWorldFromJson({{"table_colour", 1.0}}, FreeWorld()), Error);
  EXPECT_THROW(PusherWorldFromJson({{"block_mass", "heavy"}}, FreeWorld()), Error);
  EXPECT_THROW(PusherWorldFromJson({{"block_mass", -1.0}}, FreeWorld()), Error);
  EXPECT_THROW(PusherWorldFromJson({{"block_size", 1e300}}, FreeWorld()), Error);
  EXPECT_THROW(PusherWorldFromJson({{"time_step", 1e-300}}, FreeWorld()), Error);
  EXPECT_THROW(PusherWorldFromJson({{"tip_pad_x", 0.01}}, FreeWorld()), Error);  // pad y is 0
  const std::string path =
      (std::filesystem::path(::testing::TempDir()) / "not_a_world.json").string();
  std::ofstream(path) << "{\"format\": \"diffdyn-model\"}\n";
  try {
    LoadPusherWorld(path, FreeWorld());
    FAIL() << "a file without kind was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace diffdyn
