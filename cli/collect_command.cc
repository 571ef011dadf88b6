// diffdyn collect: data from a simulated system.
//
//   diffdyn collect --trajectories 400 --length 10 --seed 1 --threads 2
//                   --starts seed --out pushes.csv [--json]
//   diffdyn collect --system pendulum --trajectories 100 --seconds 5 --dt 0.04
//                   [--effect viscous:1=0.05] [--actuated all] --out pendulum.csv
//
// --system pushing (the default) runs the ODE-engine Panda world and writes a
// pushing CSV; a joint-space system (physics/joint_task.h) writes a joint-space
// CSV with ground-truth components (solvers/joint_collect.h). Trajectories run in
// parallel (one world each); the file is byte-identical for the same seed at any
// thread count.
#include <chrono>
#include <ctime>
#include <filesystem>
#include <map>
#include <string>

#include <fmt/core.h>

#include "command.h"
#include "diffdyn/models/progress.h"
#include "diffdyn/physics/pushing/collect.h"
#include "diffdyn/physics/pushing/csv.h"
#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/joint_collect.h"
#include "diffdyn/solvers/pushing/world_file.h"

namespace diffdyn::cli {
namespace {

struct CollectArgs {
  CommonOptions common;
  std::string system = "pushing";
  int trajectories = 0;  // 0: the system's default (pushing 1000, joint space 100)
  int length = 10;
  int threads = 1;
  std::string starts = "seed";
  std::string obstacle = "off";
  std::string world;  // a pusher world file (calibrated_pusher.json of diagnose --model pushing)
  std::string out;
  // Joint-space systems.
  double seconds = 5.0;
  double dt = 0.04;
  std::vector<std::string> effects;
  std::string actuated = "task";
  bool pushing_option_given = false;
  bool joint_option_given = false;
};

// The output's folder must exist (nothing is written on a bad --out).
void CheckOut(const std::string& out) {
  const std::filesystem::path path(out);
  const std::filesystem::path parent = path.has_parent_path() ? path.parent_path() : ".";
  DIFFDYN_CHECK(std::filesystem::is_directory(parent), "--out ", out, ": directory ", parent.string(),
                " does not exist");
}

void RunJointCollect(const CollectArgs& args) {
  DIFFDYN_CHECK(!args.pushing_option_given,
                "--length, --starts, --obstacle and --world apply to --system pushing only");
  JointTask task = JointTaskByName(args.system);
  for (const std::string& spec : args.effects) task.effects.push_back(ParseEffectSpec(spec, "--effect"));
  if (args.actuated == "all") task = task.ActuatingAll();
  CheckOut(args.out);
  JointCollectOptions options;
  options.trajectories = args.trajectories;
  options.seconds = args.seconds;
  options.dt = args.dt;
  options.seed = args.common.seed;
  options.threads = args.threads;
  ProgressBar bar("collect", args.trajectories, !args.common.quiet);
  options.progress = [&bar](int done) { bar.Update(done); };
  try {
    task.Plant();  // a bad effect is bad input
  } catch (const NumericalError&) {
    throw;
  } catch (const Error& e) {
    throw Error(StrCat("--effect: ", e.what()));
  }
  const auto t0 = std::chrono::steady_clock::now();
  Dataset data = CollectJointSpace(task, options);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  bar.Finish();
  data.path = args.out;
  WriteDataset(args.out, data);
  const int transitions = data.transitions();
  const int samples = transitions + static_cast<int>(data.trajectories.size());
  if (args.common.json) {
    PrintJson({{"path", args.out},
               {"trajectories", static_cast<int>(data.trajectories.size())},
               {"pushes", transitions},
               {"seconds", seconds},
               {"pushes_per_second", transitions / seconds},
               {"samples_per_second", samples / seconds},
               {"system", task.name},
               {"dt", args.dt},
               {"actuated", task.actuated},
               {"effects", static_cast<int>(task.effects.size())},
               {"threads", args.threads}});
  } else {
    fmt::print("wrote {} {} trajectories ({} transitions at dt {} s, {} actuated joint(s)) to {} in "
               "{:.2f} s ({:.0f} samples/s)\n",
               data.trajectories.size(), task.name, transitions, args.dt, task.actuated.size(),
               args.out, seconds, samples / seconds);
  }
}

void RunCollect(const CollectArgs& args) {
  if (args.system != "pushing") {
    RunJointCollect(args);
    return;
  }
  DIFFDYN_CHECK(!args.joint_option_given,
                "--seconds, --dt, --effect and --actuated apply to joint-space systems only (--system)");
  DIFFDYN_CHECK(args.trajectories >= 1, "--trajectories must be at least 1, got ",
                args.trajectories);
  DIFFDYN_CHECK(args.length >= 1, "--length must be at least 1, got ", args.length);
  DIFFDYN_CHECK(args.threads >= 1, "--threads must be at least 1, got ", args.threads);
  const std::filesystem::path out(args.out);
  CheckOut(args.out);

  CollectOptions options;
  options.trajectories = args.trajectories;
  options.length = args.length;
  options.seed = args.common.seed;
  options.threads = args.threads;
  options.starts = args.starts == "task" ? StartDistribution::kTask : StartDistribution::kSeed;
  // Without the obstacle by default: a model of the block's free motion predicts a push
  // into the obstacle to overlap it, so the planner's collision cost sees it; data with
  // the obstacle hold contacts the model has no input to explain (README, defaults).
  if (!args.world.empty()) options.world = LoadPusherWorld(args.world, options.world, "--world");
  options.world.obstacle = args.obstacle == "on";
  ProgressBar bar("collect", args.trajectories, !args.common.quiet);
  options.progress = [&bar](int done) { bar.Update(done); };

  const auto t0 = std::chrono::steady_clock::now();
  const std::clock_t cpu0 = std::clock();
  CollectStats stats;
  const auto data = CollectPushingData(options, &stats);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double cpu_seconds = static_cast<double>(std::clock() - cpu0) / CLOCKS_PER_SEC;
  bar.Finish();
  WritePushingCsvFile(out, data);

  const nlohmann::json summary = {
      {"path", out.string()},
      {"trajectories", static_cast<int>(data.size())},
      {"pushes", stats.pushes},
      {"seconds", seconds},
      {"pushes_per_second", stats.pushes / seconds},
      {"cpu_seconds", cpu_seconds},  // all threads; wall time suffers on a loaded machine
      {"threads", args.threads},
      {"starts", args.starts},
      {"obstacle", options.world.obstacle},
      {"off_table", stats.off_table},
      {"unreachable", stats.unreachable},
      {"max_tracking_error_mm", stats.max_tracking_error * 1e3},
  };
  if (args.common.json) {
    PrintJson(summary);
  } else {
    fmt::print("wrote {} trajectories ({} pushes) to {} in {:.2f} s ({:.1f} pushes/s, {:.1f} s CPU); "
               "off_table {}, unreachable {}, max tip tracking error {:.3f} mm\n",
               data.size(), stats.pushes, out.string(), seconds, stats.pushes / seconds,
               cpu_seconds, stats.off_table, stats.unreachable, stats.max_tracking_error * 1e3);
  }
}

}  // namespace

void RegisterCollectCommand(CLI::App& app) {
  auto* command = app.add_subcommand(
      "collect", "Collect trajectories of a simulated system: block pushing in the ODE-engine Panda "
                 "world, or a joint-space system");
  auto args = std::make_shared<CollectArgs>();
  AddCommonOptions(command, args->common);
  command->add_option("--system", args->system,
                      "pushing, or a joint-space system: pendulum, cartpole, double-pendulum, arm2, panda")
      ->capture_default_str();
  command->add_option("--trajectories", args->trajectories,
                      "Number of trajectories (default: 1000 for pushing, 100 for a joint-space system)")
      ->check(Bounded(1, 100000));
  CLI::Option* length = command->add_option("--length", args->length, "Pushing: pushes per trajectory")
      ->check(Bounded(1, 10000))
                            ->capture_default_str();
  command->add_option("--threads", args->threads, "Worker threads (output does not depend on it)")
      ->check(Bounded(1, 256))
      ->capture_default_str();
  CLI::Option* starts = command->add_option("--starts", args->starts,
                      "Pushing: start poses: seed = the seed's (0.4, 0, 0.2 pi); task = spread over the "
                      "obstacle task's region")
      ->check(CLI::IsMember({"seed", "task"}));
  CLI::Option* obstacle = command->add_option("--obstacle", args->obstacle,
                      "Pushing: obstacle in the world (off: the block's free motion, what the obstacle "
                      "task's models learn best)")
      ->check(CLI::IsMember({"on", "off"}))
      ->capture_default_str();
  CLI::Option* world =
      command
          ->add_option("--world", args->world,
                       "Pushing: a pusher world file (kind oracle, e.g. diagnose --model pushing's "
                       "calibrated_pusher.json) in place of the default world")
          ->check(InputPath());
  CLI::Option* seconds = command->add_option("--seconds", args->seconds, "Joint space: seconds per trajectory")
      ->check(Bounded(1e-3, 3600))
                             ->capture_default_str();
  CLI::Option* dt = command->add_option("--dt", args->dt, "Joint space: sample interval (s)")
      ->check(Bounded(1e-4, 10))->capture_default_str();
  CLI::Option* effect = command->add_option("--effect", args->effects,
                      "Joint space: add an effect KIND:JOINT=VALUE[,VALUE] to the simulated system "
                      "(repeatable; kinds of model_conventions.md, e.g. viscous:1=0.3)");
  CLI::Option* actuated = command->add_option("--actuated", args->actuated,
                      "Joint space: task = the task's actuated joints; all = excite every joint")
      ->check(CLI::IsMember({"task", "all"}))
      ->capture_default_str();
  command->add_option("--out", args->out, "Output CSV (pushing or joint-space)")
      ->check(OutputPath())->required();
  command->callback([args, length, starts, obstacle, world, seconds, dt, effect, actuated] {
    args->pushing_option_given =
        length->count() + starts->count() + obstacle->count() + world->count() > 0;
    if (args->trajectories == 0) args->trajectories = args->system == "pushing" ? 1000 : 100;
    args->joint_option_given = seconds->count() + dt->count() + effect->count() + actuated->count() > 0;
    RunCollect(*args);
  });
}

}  // namespace diffdyn::cli
