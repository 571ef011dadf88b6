#include "diffdyn/physics/pushing/collect.h"

#include <algorithm>
#include <atomic>
#include <numbers>
#include <thread>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/parallel.h"

namespace diffdyn {
namespace {

constexpr int kChunk = 4;  // trajectories per chunk (one PushingEnv each)

}  // namespace

Eigen::Vector3d SampleStartPose(StartDistribution starts, Rng& rng) {
  constexpr double kPi = std::numbers::pi;
  if (starts == StartDistribution::kSeed) return {0.4, 0.0, 0.2 * kPi};
  while (true) {
    const Eigen::Vector3d pose(Uniform(rng, 0.35, 0.85), Uniform(rng, -0.35, 0.15),
                               Uniform(rng, -kPi / 2, kPi / 2));
    // 1 cm clearance from the obstacle (a block 2 cm larger must not touch it), and
    // within 0.72 m of the arm's base, so that pushes from the far side stay reachable.
    if (PushingEnv::ObstaclePenetration(pose, 0.12) == 0 && pose.head<2>().norm() <= 0.72) {
      return pose;
    }
  }
}

std::vector<Trajectory> CollectPushingData(const CollectOptions& options,
                                                  CollectStats* stats) {
  DIFFDYN_CHECK(options.trajectories >= 1, "--trajectories must be at least 1, got ",
                options.trajectories);
  DIFFDYN_CHECK(options.length >= 1, "--length must be at least 1, got ", options.length);
  DIFFDYN_CHECK(options.threads >= 1, "--threads must be at least 1, got ", options.threads);
  const int n = options.trajectories;
  std::vector<Trajectory> data(n);
  std::vector<CollectStats> chunk_stats(NumChunks(n, kChunk));
  std::atomic<int> done{0};
  const auto caller = std::this_thread::get_id();

  ParallelForChunks(n, kChunk, options.threads, [&](int chunk, int begin, int end) {
    PushingEnv env(options.world);
    CollectStats& s = chunk_stats[chunk];
    for (int i = begin; i < end; ++i) {
      Rng rng = TrajectoryRng(options.seed, static_cast<std::uint64_t>(i));
      std::vector<Eigen::Vector3d> poses, actions;
      std::string status = "ok";
      const Eigen::Vector3d start = SampleStartPose(options.starts, rng);
      env.Reset(start);
      poses.push_back(env.pose());
      for (int k = 0; k < options.length; ++k) {
        const Eigen::Vector3d action = SamplePushAction(rng);
        const PushResult r = env.Step(action);
        ++s.pushes;
        const bool touched = r.tip_hit_obstacle || r.block_hit_obstacle;
        double& tracking = touched ? s.max_tracking_error_obstacle : s.max_tracking_error;
        tracking = std::max(tracking, r.max_tracking_error);
        s.max_limit_violation = std::max(s.max_limit_violation, r.max_limit_violation);
        // A block pushed off the table falls: its height and speed say nothing then.
        if (r.status == PushStatus::kOk) {
          s.max_block_speed = std::max(s.max_block_speed, r.max_block_speed);
          s.min_block_z = std::min(s.min_block_z, r.min_block_z);
          s.max_block_z = std::max(s.max_block_z, r.max_block_z);
        }
        s.tip_hit_obstacle += r.tip_hit_obstacle ? 1 : 0;
        s.block_hit_obstacle += r.block_hit_obstacle ? 1 : 0;
        if (r.status == PushStatus::kUnreachable) {
          status = PushStatusName(r.status);
          ++s.unreachable;
          break;
        }
        actions.push_back(action);
        poses.push_back(r.pose);
        if (r.status == PushStatus::kOffTable) {
          status = PushStatusName(r.status);
          ++s.off_table;
          break;
        }
      }
      data[i] = MakePushingTrajectory(poses, actions, std::to_string(i), status);
      const int finished = ++done;
      if (options.progress && std::this_thread::get_id() == caller) options.progress(finished);
    }
  });

  if (stats != nullptr) {
    *stats = CollectStats{};
    for (const CollectStats& s : chunk_stats) {
      stats->pushes += s.pushes;
      stats->off_table += s.off_table;
      stats->unreachable += s.unreachable;
      stats->max_tracking_error = std::max(stats->max_tracking_error, s.max_tracking_error);
      stats->max_tracking_error_obstacle =
          std::max(stats->max_tracking_error_obstacle, s.max_tracking_error_obstacle);
      stats->max_limit_violation = std::max(stats->max_limit_violation, s.max_limit_violation);
      stats->max_block_speed = std::max(stats->max_block_speed, s.max_block_speed);
      stats->min_block_z = std::min(stats->min_block_z, s.min_block_z);
      stats->max_block_z = std::max(stats->max_block_z, s.max_block_z);
      stats->tip_hit_obstacle += s.tip_hit_obstacle;
      stats->block_hit_obstacle += s.block_hit_obstacle;
    }
  }
  if (options.progress) options.progress(n);
  return data;
}

}  // namespace diffdyn
