// The ODE-engine pushing world, checked and pictured.
//
// Runs N random pushes (uniform actions, task start poses, obstacle present) in
// parallel worlds and checks the acceptance invariants of the pusher:
//   no tunnelling (block centre z > -5 mm), no explosion (block speed < 1 m/s),
//   joint limits kept, tip tracking <= 2 mm on pushes clear of the obstacle, and
//   the block never ends inside the obstacle or off the table unnoticed.
// Then it records one episode from the obstacle task's start (0.4, 0, -0.2 pi)
// and draws a top view (table, obstacle, goal, block poses, tip path) and the
// arm's configuration during a push with scripts/plots/plot_pushing.py.
//
// Usage: example_pushing_world [--quick] [--pushes N] [--threads K] [--seed S]
//                              [--out-dir DIR]
//   full check: example_pushing_world --pushes 10000 --threads 2   (exit 1 on a violation)
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <numbers>
#include <string>

#include <fmt/core.h>
#include <fmt/os.h>

#include "diffdyn/models/io.h"
#include "diffdyn/physics/pushing/collect.h"

namespace {

using diffdyn::PushingEnv;

// Writes the episode's block poses, tip paths and one arm configuration as CSV.
void WriteEpisode(const std::filesystem::path& dir, int pushes, std::uint64_t seed) {
  diffdyn::PushingConfig config;
  PushingEnv env(config);
  diffdyn::Rng rng = diffdyn::TrajectoryRng(seed, 12345);
  env.Reset({0.4, 0.0, -0.2 * std::numbers::pi});
  std::string poses = "step,x,y,theta\n", tip = "step,x,y,z\n", arm = "point,x,y,z\n";
  auto add_pose = [&](int step, const Eigen::Vector3d& p) {
    poses += fmt::format("{},{},{},{}\n", step, p.x(), p.y(), p.z());
  };
  add_pose(0, env.pose());
  int arm_step = 0;
  bool arm_drawn = false;
  for (int k = 0; k < pushes; ++k) {
    const Eigen::Vector3d before = env.pose();
    const auto r = env.Step(diffdyn::SamplePushAction(rng));
    for (const auto& p : env.tip_path()) tip += fmt::format("{},{},{},{}\n", k, p.x(), p.y(), p.z());
    // The arm picture: halfway through the first push that moved the block 1 cm.
    if (!arm_drawn && !env.joint_path().empty() && (r.pose - before).head<2>().norm() > 0.01) {
      arm_drawn = true;
      const auto& q = env.joint_path()[env.joint_path().size() / 2];
      const auto frames = diffdyn::Panda::Frames<double>(q);
      int i = 0;
      arm += fmt::format("{},0,0,0\n", i++);
      for (const auto& f : frames) arm += fmt::format("{},{},{},{}\n", i++, f.p.x(), f.p.y(), f.p.z());
      const auto t = diffdyn::Panda::Tool<double>(q, config.tool_length);
      arm += fmt::format("{},{},{},{}\n", i, t.p.x(), t.p.y(), t.p.z());
      arm_step = k;
    }
    add_pose(k + 1, r.pose);
    if (r.status != diffdyn::PushStatus::kOk) break;
  }
  auto write = [&](const char* name, const std::string& text) {
    diffdyn::WriteFileAtomically(dir / name, [&](std::ostream& out) { out << text; });
  };
  write("episode_poses.csv", poses);
  write("episode_tip.csv", tip);
  write("episode_arm.csv", arm);

  const auto script =
      std::filesystem::path(__FILE__).parent_path().parent_path() / "scripts/plots/plot_pushing.py";
  const std::string cmd = fmt::format(
      "/usr/bin/python3 '{}' episode --poses '{}' --tip '{}' --arm '{}' --arm-step {} "
      "--top '{}' --side '{}'",
      script.string(), (dir / "episode_poses.csv").string(), (dir / "episode_tip.csv").string(),
      (dir / "episode_arm.csv").string(), arm_step, (dir / "pushing_top_view.png").string(),
      (dir / "pushing_arm.png").string());
  if (std::system(cmd.c_str()) != 0) {
    fmt::print(stderr, "warning: plot script failed: {}\n", cmd);
  } else {
    fmt::print("pictures: {}/pushing_top_view.png, {}/pushing_arm.png\n", dir.string(), dir.string());
  }
}

}  // namespace

int main(int argc, char** argv) {
  int pushes = 10000, threads = 2;
  std::uint64_t seed = 1;
  std::filesystem::path out_dir = "pushing_world_out";
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--quick") {
      pushes = 100;
    } else if (a == "--pushes" && has_value) {
      pushes = std::atoi(argv[++i]);
    } else if (a == "--threads" && has_value) {
      threads = std::atoi(argv[++i]);
    } else if (a == "--seed" && has_value) {
      seed = std::strtoull(argv[++i], nullptr, 10);
    } else if (a == "--out-dir" && has_value) {
      out_dir = argv[++i];
    } else {
      fmt::print(stderr, "error: unknown or incomplete option '{}'\n", a);
      return 2;
    }
  }
  if (pushes < 10 || threads < 1) {
    fmt::print(stderr, "error: --pushes must be >= 10 and --threads >= 1\n");
    return 2;
  }
  std::filesystem::create_directories(out_dir);

  // The check: N random pushes from task start poses with the obstacle.
  diffdyn::CollectOptions options;
  options.trajectories = pushes / 10;
  options.length = 10;
  options.seed = seed;
  options.threads = threads;
  options.starts = diffdyn::StartDistribution::kTask;
  options.world.obstacle = true;
  diffdyn::CollectStats stats;
  const auto t0 = std::chrono::steady_clock::now();
  const auto data = diffdyn::CollectPushingData(options, &stats);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  int inside_obstacle = 0, off_table_unmarked = 0;
  for (const auto& t : data) {
    for (Eigen::Index k = 0; k < t.states.cols(); ++k) {
      inside_obstacle += PushingEnv::ObstaclePenetration(t.states.col(k)) > 2e-3;
    }
    const Eigen::Vector3d last = t.states.rightCols<1>();
    off_table_unmarked += !PushingEnv::OnTable(last.x(), last.y()) && t.status != "off_table";
  }
  fmt::print("{} pushes in {:.1f} s ({:.1f} pushes/s on {} threads)\n", stats.pushes, seconds,
             stats.pushes / seconds, threads);
  fmt::print("  block centre z in [{:.5f}, {:.5f}] m, max block speed {:.3f} m/s\n",
             stats.min_block_z, stats.max_block_z, stats.max_block_speed);
  fmt::print("  max joint-limit excess {:.2e} rad\n", stats.max_limit_violation);
  fmt::print("  max tip tracking error {:.3f} mm (pushes clear of the obstacle); {:.3f} mm with "
             "the tip ({} pushes) or block ({} pushes) against the obstacle\n",
             stats.max_tracking_error * 1e3, stats.max_tracking_error_obstacle * 1e3,
             stats.tip_hit_obstacle, stats.block_hit_obstacle);
  fmt::print("  trajectories ended off_table {}, unreachable {}; states inside the obstacle {}\n",
             stats.off_table, stats.unreachable, inside_obstacle);
  const bool ok = stats.min_block_z > -5e-3 && stats.max_block_z < 5e-3 &&
                  stats.max_block_speed < 1.0 && stats.max_limit_violation < 1e-3 &&
                  stats.max_tracking_error <= 2e-3 && inside_obstacle == 0 &&
                  off_table_unmarked == 0;
  fmt::print("check: {}\n", ok ? "passed" : "FAILED");

  WriteEpisode(out_dir, 10, seed);
  return ok ? 0 : 1;
}
