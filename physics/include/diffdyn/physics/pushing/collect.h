// Collecting pushing datasets from the ODE-engine world, in parallel and
// deterministically.
//
// Trajectory i draws its start pose and its actions from its own generator,
// seeded from (seed, i), and runs in a PushingEnv of its own chunk; so the data
// are byte-identical for the same seed whatever the thread count.
//
//   diffdyn::CollectOptions options;
//   options.trajectories = 400;
//   options.seed = 7;
//   options.threads = 2;
//   diffdyn::CollectStats stats;
//   auto data = diffdyn::CollectPushingData(options, &stats);
//   diffdyn::WritePushingCsvFile("pushes.csv", data);
//
// Actions are uniform as in the seed: push_location U[-1, 1], push_angle
// U[-pi/2, pi/2], push_length U[0, 1]. Start poses: `kSeed` is the seed's
// obstacle-free start (0.4, 0, 0.2 pi); `kTask` is uniform over the region the
// obstacle task crosses, x in [0.35, 0.85], y in [-0.35, 0.15], theta in
// [-pi/2, pi/2], clear of the obstacle by 1 cm and within 0.72 m of the arm's
// base (the Panda reaches about 0.79 m at push height).
#pragma once

#include <cstdint>
#include <functional>
#include <numbers>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/models/random.h"
#include "diffdyn/physics/pushing/csv.h"
#include "diffdyn/physics/pushing/env.h"

namespace diffdyn {

/// Where trajectories start.
enum class StartDistribution { kSeed, kTask };

/// Options of CollectPushingData.
struct CollectOptions {
  int trajectories = 100;                        ///< number of trajectories (>= 1)
  int length = 10;                               ///< pushes per trajectory (>= 1)
  std::uint64_t seed = 0;                        ///< seeds start poses and actions
  int threads = 1;                               ///< worker threads (>= 1)
  StartDistribution starts = StartDistribution::kSeed;
  PushingConfig world;                           ///< the world (obstacle on/off, masses, ...)
  /// Called on the calling thread with the number of finished trajectories; may be empty.
  std::function<void(int)> progress;
};

/// Totals of a collection run.
struct CollectStats {
  long pushes = 0;                  ///< simulated actions
  int off_table = 0;                ///< trajectories ended with status off_table
  int unreachable = 0;              ///< trajectories ended with status unreachable
  /// Max tip-tracking error (m) over pushes where neither tip nor block touched the
  /// obstacle; pushes against the obstacle stall the arm and are counted apart.
  double max_tracking_error = 0;
  double max_tracking_error_obstacle = 0;  ///< over pushes touching the obstacle (m)
  double max_limit_violation = 0;   ///< over all pushes (rad)
  double max_block_speed = 0;       ///< m/s, over pushes that kept the block on the table
  double min_block_z = 0, max_block_z = 0;  ///< block centre height extremes (m), same pushes
  int tip_hit_obstacle = 0;         ///< pushes where the tip touched the obstacle
  int block_hit_obstacle = 0;       ///< pushes where the block touched the obstacle
};

/// One uniform action of the seed's action space (u0, u1, u2).
inline Eigen::Vector3d SamplePushAction(Rng& rng) {
  const double u0 = Uniform(rng, -1.0, 1.0);
  const double u1 = Uniform(rng, -std::numbers::pi / 2, std::numbers::pi / 2);
  const double u2 = UniformUnit(rng);
  return {u0, u1, u2};
}

/// A start pose from `starts` (see the file comment).
Eigen::Vector3d SampleStartPose(StartDistribution starts, Rng& rng);

/// Simulates options.trajectories trajectories of up to options.length pushes.
/// A trajectory ends early with status off_table or unreachable. Throws
/// diffdyn::Error for bad options. `stats` may be null.
std::vector<Trajectory> CollectPushingData(const CollectOptions& options,
                                           CollectStats* stats = nullptr);

}  // namespace diffdyn
