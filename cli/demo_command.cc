// diffdyn demo: the main job, end to end, with a Markdown report.
//
// 1. collect   pushing trajectories from the ODE-engine Panda world without the obstacle,
//              starts spread over the obstacle task's region
//              (= diffdyn collect --starts task --obstacle off)
// 2. train     the absolute NeuralODE (rk4, 10 grid points, hidden 100) on them
//              (= diffdyn train --model abs-node)
// 3. push      MPPI (K = 1000, T = 20) over the trained model pushes the block around the
//              obstacle in the ODE world, a few seeded trials (= diffdyn push --obstacle)
// report.md lists the data, the training curve, the success rate with its interval, the
// top view of a push, the timings and the commands that redo each stage.
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>
#include <vector>

#include <fmt/core.h>
#include <fmt/ostream.h>

#include "command.h"
#include "diffdyn/models/io.h"
#include "diffdyn/models/progress.h"
#include "diffdyn/physics/pushing/collect.h"
#include "diffdyn/physics/pushing/csv.h"
#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/model_training.h"
#include "diffdyn/solvers/pushing/trials.h"
#include "plot.h"
#include "push_command.h"

namespace diffdyn::cli {
namespace {

struct DemoOptions {
  CommonOptions common;
  std::string out = "demo-output";
  bool quick = false;
  // 600 x 10 obstacle-free pushes: the acceptance model used 1000 (issue #8); 600
  // keeps the demo to a few minutes.
  int trajectories = 600;
  int length = 10;
  int epochs = 150;
  int trials = 10;
  int samples = 1000;
  int horizon = 20;
  int max_steps = 20;
  int threads = 0;
};

double SecondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

void WriteTrainingCsv(const std::filesystem::path& path, const TrainResult& result) {
  WriteFileAtomically(path, [&](std::ostream& out) {
    out << "epoch,train_loss,val_loss\n";
    for (const EpochReport& e : result.epochs) {
      fmt::print(out, "{},{:.9g},{:.9g}\n", e.epoch, e.train_loss, e.val_loss);
    }
  });
}

// NaN is not JSON: a missing validation loss is written as null.
nlohmann::json Number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); }

void RunDemo(const DemoOptions& options) {
  namespace fs = std::filesystem;
  using Clock = std::chrono::steady_clock;
  DIFFDYN_CHECK(!options.out.empty(), "--out: empty directory name");
  DIFFDYN_CHECK(options.trajectories >= 2, "--trajectories: must be >= 2, got ",
                options.trajectories);
  DIFFDYN_CHECK(options.length >= 1, "--length: must be >= 1, got ", options.length);
  DIFFDYN_CHECK(options.epochs >= 1, "--epochs: must be >= 1, got ", options.epochs);
  DIFFDYN_CHECK(options.trials >= 1, "--trials: must be >= 1, got ", options.trials);
  PushTaskOptions task;
  task.obstacle = true;
  task.samples = options.samples;
  task.horizon = options.horizon;
  task.max_steps = options.max_steps;
  task.threads = options.threads;
  ValidatePushTaskOptions(task);
  std::error_code ec;
  fs::create_directories(options.out, ec);
  DIFFDYN_CHECK(!ec && fs::is_directory(options.out), "--out ", options.out,
                ": cannot create directory: ", ec.message());
  const fs::path out(options.out);
  const std::uint64_t seed = options.common.seed;
  const bool show = !options.common.quiet;
  const int threads = options.threads > 0
                          ? options.threads
                          : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  const auto t_start = Clock::now();

  // Stage 1: ODE-engine data over the task's region (diffdyn collect --starts task).
  auto t0 = Clock::now();
  CollectOptions collect;
  collect.trajectories = options.trajectories;
  collect.length = options.length;
  collect.seed = seed;
  collect.threads = threads;
  collect.starts = StartDistribution::kTask;
  // Without the obstacle: the model learns the block's free motion, so a push into
  // the obstacle is predicted to overlap it and the cost sees it (with the obstacle
  // in the data the model learns that the block stops at it, and the cost cannot).
  collect.world.obstacle = false;
  CollectStats collect_stats;
  {
    ProgressBar bar("1/3 collect", options.trajectories, show);
    collect.progress = [&bar](int done) { bar.Update(done); };
    WritePushingCsvFile(out / "pushes.csv", CollectPushingData(collect, &collect_stats));
  }
  const double collect_seconds = SecondsSince(t0);

  // Stage 2: the absolute NeuralODE, trained as diffdyn train does (read back from the CSV).
  t0 = Clock::now();
  const Dataset pushes = ReadDataset((out / "pushes.csv").string());
  TrainOptions train;
  train.epochs = options.epochs;
  train.seed = seed;
  train.threads = options.threads;
  train.progress = show;
  if (show) fmt::print(stderr, "2/3 train: abs-node on {} transitions\n", MakeWindows(pushes, 1).size());
  const FittedModel fit = FitLearnedModel(
      pushes, {.type = LearnedKind::kAbsNode, .hidden = 100, .method = Method::kRk4, .steps = 10}, train, 1, false);
  const LearnedModel& model = fit.model;
  const TrainResult& trained = fit.result;
  const fs::path model_path = out / "abs-node.json";
  SaveLearnedModel(model_path, model,
                   {{"command", "diffdyn demo"}, {"data", (out / "pushes.csv").string()},
                    {"seed", seed}, {"loss", "single"}, {"epochs", options.epochs},
                    {"lr", train.learning_rate}, {"batch", train.batch_size},
                    {"val_fraction", train.val_fraction}, {"n_train", trained.n_train},
                    {"n_val", trained.n_val}},
                   {{"final_train_loss", Number(trained.final_train_loss)},
                    {"final_val_loss", Number(trained.final_val_loss)}});
  WriteTrainingCsv(out / "training.csv", trained);
  const bool curve_plotted = RunPlotScript(
      "demo_training_curve.py", {(out / "training.csv").string(), (out / "training_curve.png").string()});
  const double train_seconds = SecondsSince(t0);

  // Stage 3: MPPI over the trained model, around the obstacle in the ODE world.
  t0 = Clock::now();
  PushTrialsSummary pushed;
  {
    ProgressBar bar("3/3 push", options.trials, show);
    pushed = RunPushTrials(model, options.trials, task, seed, [&bar](int done, int) { bar.Update(done); });
  }
  const fs::path push_dir = out / "push";
  fs::create_directories(push_dir, ec);
  DIFFDYN_CHECK(!ec, push_dir.string(), ": cannot create directory: ", ec.message());
  WritePushTrialsCsv(push_dir / "trials.csv", pushed);
  const int pictured = PictureTrial(pushed);
  const bool top_plotted = PlotPushTopView(push_dir / "trials.csv", pictured, pushed, true,
                                           task.goal_tolerance, push_dir / "top_view.png");
  const double push_seconds = SecondsSince(t0);

  const double total_seconds = SecondsSince(t_start);

  // The commands that redo each stage.
  const std::string data_path = (out / "pushes.csv").string();
  const std::string redo_collect = fmt::format(
      "diffdyn collect --trajectories {} --length {} --starts task --obstacle off --seed {} "
      "--out {}",
      options.trajectories, options.length, seed, data_path);
  const std::string redo_train = fmt::format(
      "diffdyn train --data {} --model abs-node --solver rk4 --steps 10 --hidden 100 --epochs {} "
      "--seed {} --out {}",
      data_path, options.epochs, seed, model_path.string());
  const std::string redo_push = fmt::format(
      "diffdyn push --model {} --trials {} --obstacle --seed {} --samples {} --horizon {} "
      "--max-steps {} --out {}",
      model_path.string(), options.trials, seed, options.samples, options.horizon,
      options.max_steps, push_dir.string());
  const auto outcomes = OutcomeCounts(pushed);
  std::string outcome_text;
  for (const auto& [name, n] : outcomes) outcome_text += fmt::format("{} {}, ", name, n);
  if (!outcome_text.empty()) outcome_text.resize(outcome_text.size() - 2);

  WriteFileAtomically(out / "report.md", [&](std::ostream& s) {
    fmt::print(s, "# diffdyn demo\n\n");
    fmt::print(s,
               "Data from an Open Dynamics Engine simulation of a Panda arm pushing a block, a "
               "NeuralODE learned from it, and MPPI over the learned model pushing the block "
               "around an obstacle in the simulation. Seed {}; everything below is redone "
               "byte for byte (timings aside) by `diffdyn demo --seed {} --out {}{}`.\n\n",
               seed, seed, out.string(), options.quick ? " --quick" : "");

    fmt::print(s, "## 1. Data from the ODE-engine world\n\n");
    fmt::print(s,
               "{} trajectories of up to {} uniformly random pushes (push location in [-1, 1], "
               "angle in [-pi/2, pi/2], length in [0, 1] x 0.1 m), starting uniformly over the "
               "obstacle task's region (x in [0.35, 0.85], y in [-0.35, 0.15], theta in "
               "[-pi/2, pi/2]), without the obstacle in the world, so that the model learns the "
               "block's free motion and a push into the obstacle is predicted to overlap it "
               "(which the controller's collision cost penalizes): {} pushes in `pushes.csv` "
               "({} trajectories ended off the table, {} on an unreachable push).\n\n",
               options.trajectories, options.length, collect_stats.pushes, collect_stats.off_table,
               collect_stats.unreachable);
    fmt::print(s, "```sh\n{}\n```\n\n", redo_collect);

    fmt::print(s, "## 2. The absolute NeuralODE\n\n");
    fmt::print(s,
               "x_{{t+1}} = x_t + integral_0^1 f(z, u) dt of an MLP f (hidden 2 x 100, {} "
               "parameters), integrated by the 3/8-rule RK4 over 10 grid points and trained "
               "through the solver (discrete adjoint) with Adam (lr {:g}, batch {}) for {} "
               "epochs on {} single-step transitions, validated on {} held out (seeded 80/20 "
               "split). SE(2) pose loss: final training {:.4e}, validation {:.4e}. Model file: "
               "`abs-node.json`.\n\n",
               model.num_parameters(), train.learning_rate, train.batch_size, options.epochs,
               trained.n_train, trained.n_val, trained.final_train_loss, trained.final_val_loss);
    if (curve_plotted) fmt::print(s, "![training curve](training_curve.png)\n\n");
    fmt::print(s, "```sh\n{}\n```\n\n", redo_train);

    fmt::print(s, "## 3. Pushing around the obstacle\n\n");
    fmt::print(s,
               "MPPI (K = {}, T = {}, Sigma = 0.5 I, lambda = 0.01, cost (x - g)^T diag(1, 1, "
               "0.1) (x - g) + 100 in_collision, with the block inflated by {:g} m per side and "
               "tested at {} poses inside each predicted push) plans with the learned model; "
               "each chosen push "
               "is executed in the ODE world. Start (0.4, 0, -0.2 pi) perturbed per trial "
               "(uniform within 2 cm and 0.1 rad), goal (0.8, -0.1, 0). A trial succeeds when "
               "the block centre comes within 0.1 m of the goal within {} pushes, without the "
               "block ever touching the obstacle.\n\n",
               options.samples, options.horizon, task.collision_margin,
               task.collision_substeps + 1, options.max_steps);
    if (task.reach_limited || task.reach_weight > 0) {
      const PushReach reach = PushingEnv::Reach(task.world);
      fmt::print(s,
                 "MPPI knows the arm's reach: the tool path of a push must stay {:.3f}-{:.3f} m "
                 "from the base (PushingEnv::Reach).",
                 reach.inner, reach.outer);
      if (task.reach_limited) fmt::print(s, " In the rollouts a push beyond it leaves the block in place.");
      if (task.reach_weight > 0 && task.reach_steps == 1) {
        fmt::print(s, " The push executed now costs {:g} more if beyond it.", task.reach_weight);
      } else if (task.reach_weight > 0) {
        fmt::print(s, " Each of the first {} planned pushes costs {:g} more if beyond it.",
                   task.reach_steps, task.reach_weight);
      }
      fmt::print(s, "\n\n");
    }
    fmt::print(s,
               "**Success: {} of {} trials = {:.0f} % (95 % Wilson interval {:.0f}-{:.0f} %)**, "
               "mean pushes {:.2f}; outcomes: {}.\n\n",
               pushed.successes, pushed.trials, 100 * pushed.success_rate, 100 * pushed.ci95_low,
               100 * pushed.ci95_high, pushed.mean_pushes, outcome_text);
    fmt::print(s, "| trial | outcome | pushes | final distance to goal (m) |\n|---|---|---|---|\n");
    for (std::size_t i = 0; i < pushed.runs.size(); ++i) {
      const PushTrial& t = pushed.runs[i];
      fmt::print(s, "| {} | {} | {} | {:.3f} |\n", i, t.outcome, t.pushes,
                 (t.poses.back().head<2>() - t.goal.head<2>()).norm());
    }
    fmt::print(s, "\n");
    const PushTrial& shown = pushed.runs[pictured];
    if (top_plotted) {
      fmt::print(s, "{}\n\n![top view of trial {}](push/top_view.png)\n\n",
                 shown.success ? fmt::format("A successful push (trial {}, {} pushes):", pictured,
                                             shown.pushes)
                               : fmt::format("No trial succeeded; trial {} ({}):", pictured,
                                             shown.outcome),
                 pictured);
    }
    fmt::print(s, "```sh\n{}\n```\n\n", redo_push);

    fmt::print(s, "## Timings\n\n");
    fmt::print(s, "Wall time on this machine ({} threads).\n\n", threads);
    fmt::print(s, "| stage | seconds | detail |\n|---|---|---|\n");
    fmt::print(s, "| 1. collect | {:.1f} | {:.0f} pushes/s |\n", collect_seconds,
               collect_stats.pushes / std::max(collect_seconds, 1e-9));
    fmt::print(s, "| 2. train | {:.1f} | {:.3f} s per epoch (median training pass) |\n",
               train_seconds, trained.seconds_per_epoch);
    fmt::print(s, "| 3. push | {:.1f} | {:.1f} ms per MPPI command (median) |\n", push_seconds,
               pushed.ms_per_command);
    fmt::print(s, "| total | {:.1f} | |\n", total_seconds);
  });

  const nlohmann::json summary = {
      {"out", out.string()},
      {"collect", {{"trajectories", options.trajectories}, {"pushes", collect_stats.pushes},
                   {"seconds", collect_seconds}}},
      {"train", {{"model_path", model_path.string()}, {"n_train", trained.n_train},
                 {"n_val", trained.n_val}, {"epochs", options.epochs},
                 {"final_train_loss", Number(trained.final_train_loss)},
                 {"final_val_loss", Number(trained.final_val_loss)},
                 {"seconds_per_epoch", trained.seconds_per_epoch}, {"seconds", train_seconds}}},
      {"push", {{"trials", pushed.trials}, {"successes", pushed.successes},
                {"success_rate", pushed.success_rate}, {"ci95_low", pushed.ci95_low},
                {"ci95_high", pushed.ci95_high}, {"mean_pushes", pushed.mean_pushes},
                {"ms_per_command", pushed.ms_per_command}, {"outcomes", outcomes},
                {"seconds", push_seconds}}},
      {"seconds", total_seconds}};
  if (options.common.json) {
    PrintJson(summary);
    return;
  }
  fmt::print("diffdyn demo ({:.0f} s)\n", total_seconds);
  fmt::print("1. collected {} pushes in {} trajectories ({:.0f} s)\n", collect_stats.pushes,
             options.trajectories, collect_seconds);
  fmt::print("2. trained abs-node: validation loss {:.3e} after {} epochs ({:.0f} s)\n",
             trained.final_val_loss, options.epochs, train_seconds);
  fmt::print("3. pushed around the obstacle: {}/{} successes ({:.0f} %, 95 % interval {:.0f}-{:.0f} "
             "%), mean pushes {:.2f} ({:.0f} s)\n",
             pushed.successes, pushed.trials, 100 * pushed.success_rate, 100 * pushed.ci95_low,
             100 * pushed.ci95_high, pushed.mean_pushes, push_seconds);
  fmt::print("report: {}\n", (out / "report.md").string());
}

}  // namespace

void RegisterDemoCommand(CLI::App& app) {
  auto* command = app.add_subcommand(
      "demo", "The main job: collect ODE-engine data, train a NeuralODE, push around the "
              "obstacle with MPPI, write a report");
  auto options = std::make_shared<DemoOptions>();
  AddCommonOptions(command, options->common);
  command->add_option("--out", options->out, "Directory for the report, data, model and PNGs")
      ->check(OutputPath(true));
  command->add_flag("--quick", options->quick,
                    "A small run of every stage (used by the tests): 24 x 5 pushes, 3 epochs, "
                    "1 trial with K = 64, T = 5, 3 pushes, unless given");
  command->add_option("--trajectories", options->trajectories, "Stage 1: trajectories to collect")
      ->check(Bounded(1, 100000));
  command->add_option("--length", options->length, "Stage 1: pushes per trajectory")
      ->check(Bounded(1, 10000));
  command->add_option("--epochs", options->epochs, "Stage 2: training epochs")
      ->check(Bounded(1, 1e6));
  command->add_option("--trials", options->trials, "Stage 3: pushing trials")
      ->check(Bounded(1, 10000));
  command->add_option("--samples", options->samples, "Stage 3: MPPI samples K")
      ->check(Bounded(1, 1e6));
  command->add_option("--horizon", options->horizon, "Stage 3: MPPI horizon T")
      ->check(Bounded(1, 1000));
  command->add_option("--max-steps", options->max_steps, "Stage 3: pushes per trial")
      ->check(Bounded(1, 10000));
  command->add_option("--threads", options->threads,
                      "Threads (0: all cores; results do not depend on it)")
      ->check(Bounded(0, 256));
  command->callback([options, command] {
    DemoOptions o = *options;
    if (o.quick) {
      // Small values for what the caller did not set.
      const auto unset = [command](const char* name) { return command->count(name) == 0; };
      if (unset("--trajectories")) o.trajectories = 24;
      if (unset("--length")) o.length = 5;
      if (unset("--epochs")) o.epochs = 3;
      if (unset("--trials")) o.trials = 1;
      if (unset("--samples")) o.samples = 64;
      if (unset("--horizon")) o.horizon = 5;
      if (unset("--max-steps")) o.max_steps = 3;
    }
    RunDemo(o);
  });
}

}  // namespace diffdyn::cli
