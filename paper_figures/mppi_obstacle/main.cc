// NeuralODE-Panda Figure 1: MPPI pushes the block to the goal around the obstacle.
//
// 1. Collects ODE-engine data with the task's start spread (like `diffdyn collect
//    --starts task --obstacle off`: no obstacle in the world, so the models learn the
//    block's free motion and a push into the obstacle is predicted to overlap it, which
//    the collision cost sees; uniform actions, 10 pushes per trajectory).
// 2. Trains the four models with the paper's settings (hidden 100, single-step SE(2)
//    loss, Adam, batch 500, 80/20 split; abs-nn, res-nn, abs-node lr 1e-3; res-node
//    lr 1e-2; NeuralODEs rk4 3/8 rule on 10 grid points).
// 3. Runs seeded obstacle trials of MPPI (K = 1000, T = 20) with each model, executed
//    in the ODE world (solvers/pushing/trials.h), plus an oracle row: the simulation
//    itself as MPPI's model (K = 100, T = 10), which separates model error from
//    controller error. The cost is the seed's plus a safety margin and a swept test
//    over each predicted push (--collision-margin, --collision-substeps; 0 and 0 give
//    the seed's cost exactly).
// 4. Writes results.csv (one row per model, Wilson 95 % intervals), trials.csv (every
//    pose and action of every trial) and, with --plot, the PNGs (plot.py).
//
//   build/paper_figures/figure_mppi_obstacle --out fig1 --plot     (see README.md)
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/core.h>

#include "diffdyn/models/io.h"
#include "diffdyn/models/learned_model.h"
#include "diffdyn/models/progress.h"
#include "diffdyn/physics/pushing/collect.h"
#include "diffdyn/physics/pushing/oracle.h"
#include "diffdyn/physics/pushing/system.h"
#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/pushing/trials.h"
#include "diffdyn/solvers/training.h"
#include "../figure_main.h"

namespace diffdyn {
namespace {

namespace fs = std::filesystem;

struct FigureOptions {
  std::string out = "mppi_obstacle_out";
  std::string data;
  std::string models = "abs-nn,res-nn,abs-node,res-node";
  bool quick = false, plot = false, reuse = false, quiet = false;
  int threads = 0;
  std::uint64_t seed = 1;
  int trajectories = 1000;
  int epochs = 200;
  int trials = 50;
  int samples = 1000;
  int horizon = 20;
  int max_steps = 20;
  int oracle_trials = 10;
  int oracle_samples = 100;
  int oracle_horizon = 10;  // T = 5 plans too few pushes ahead to go around the obstacle
  double collision_margin = PushTaskOptions{}.collision_margin;
  int collision_substeps = PushTaskOptions{}.collision_substeps;
  double reach_weight = PushTaskOptions{}.reach_weight;
  bool reach_limited = PushTaskOptions{}.reach_limited;
};

struct Row {
  std::string model;
  int samples = 0, horizon = 0;
  PushTrialsSummary summary;
};

std::vector<std::string> SplitList(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream in(s);
  for (std::string item; std::getline(in, item, ',');) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

// The paper's learning rate for each model.
double LearningRate(LearnedKind type) {
  return type == LearnedKind::kResNode ? 1e-2 : 1e-3;
}

LearnedModel TrainModel(LearnedKind type, const Windows& data, const FigureOptions& o,
                        const fs::path& path) {
  LearnedModelConfig config;
  config.type = type;
  config.system = PushingSystem();
  config.hidden = 100;
  config.method = Method::kRk4;
  config.steps = 10;
  if (o.reuse && fs::exists(path)) {
    LearnedModel model = LoadLearnedModel(path);
    DIFFDYN_CHECK(model.config().type == type, path.string(), ": holds a ", model.kind(),
                  ", expected ", LearnedKindName(type));
    if (!o.quiet) fmt::print("{}: reusing {}\n", model.kind(), path.string());
    return model;
  }
  LearnedModel model = LearnedModel::Initialized(config, o.seed);
  TrainOptions t;
  t.epochs = o.epochs;
  t.learning_rate = LearningRate(type);
  t.batch_size = 500;
  t.val_fraction = 0.2;
  t.seed = o.seed;
  t.threads = o.threads;
  t.progress = !o.quiet;
  Trainer trainer(&model, t);
  const TrainResult r = trainer.Train(data);
  if (!o.quiet) {
    fmt::print("{}: trained {} epochs on {} samples, train {:.3e}, val {:.3e}, {:.2f} s/epoch\n",
               model.kind(), o.epochs, r.n_train, r.final_train_loss, r.final_val_loss,
               r.seconds_per_epoch);
  }
  const nlohmann::json provenance = {{"program", "figure_mppi_obstacle"}, {"seed", o.seed},
                                     {"epochs", o.epochs}, {"lr", t.learning_rate},
                                     {"n_train", r.n_train}, {"n_val", r.n_val}};
  const nlohmann::json metrics = {{"final_train_loss", r.final_train_loss},
                                  {"final_val_loss", r.final_val_loss},
                                  {"seconds_per_epoch", r.seconds_per_epoch}};
  SaveLearnedModel(path, model, provenance, metrics);
  return model;
}

void WriteResults(const fs::path& dir, const std::vector<Row>& rows) {
  WriteFileAtomically(dir / "results.csv", [&](std::ostream& out) {
    out << "model,samples,horizon,trials,successes,rate,ci95_low,ci95_high,mean_pushes,"
           "ms_per_command\n";
    for (const Row& r : rows) {
      const auto& s = r.summary;
      out << fmt::format("{},{},{},{},{},{:.4f},{:.4f},{:.4f},{:.3f},{:.2f}\n", r.model, r.samples,
                         r.horizon, s.trials, s.successes, s.success_rate, s.ci95_low, s.ci95_high,
                         s.mean_pushes, s.ms_per_command);
    }
  });
  WriteFileAtomically(dir / "trials.csv", [&](std::ostream& out) {
    out << "model,trial,step,x,y,theta,push_location,push_angle,push_length,outcome,goal_x,"
           "goal_y,goal_theta\n";
    for (const Row& r : rows) {
      for (std::size_t i = 0; i < r.summary.runs.size(); ++i) {
        const PushTrial& t = r.summary.runs[i];
        for (std::size_t k = 0; k < t.poses.size(); ++k) {
          const auto& p = t.poses[k];
          out << fmt::format("{},{},{},{:.6f},{:.6f},{:.6f},", r.model, i, k, p.x(), p.y(), p.z());
          if (k < t.actions.size()) {
            const auto& a = t.actions[k];
            out << fmt::format("{:.6f},{:.6f},{:.6f},", a.x(), a.y(), a.z());
          } else {
            out << ",,,";
          }
          out << fmt::format("{},{:.6f},{:.6f},{:.6f}\n", t.outcome, t.goal.x(), t.goal.y(),
                             t.goal.z());
        }
      }
    }
  });
}

Row RunTrials(const std::string& name, const TransitionModel& model, int trials, int samples,
              int horizon, const FigureOptions& o) {
  PushTaskOptions task;
  task.obstacle = true;
  task.samples = samples;
  task.horizon = horizon;
  task.max_steps = o.max_steps;
  task.threads = o.threads;
  task.collision_margin = o.collision_margin;
  task.collision_substeps = o.collision_substeps;
  task.reach_weight = o.reach_weight;
  task.reach_limited = o.reach_limited;
  ProgressBar bar("trials " + name, trials, !o.quiet);
  Row row{name, samples, horizon, RunPushTrials(model, trials, task, o.seed, [&bar](int done, int) { bar.Update(done); })};
  bar.Finish();
  const auto& s = row.summary;
  if (!o.quiet) {
    fmt::print("{}: {}/{} successes = {:.0f} % [{:.0f}, {:.0f}], {:.1f} pushes, {:.1f} ms/command\n",
               name, s.successes, s.trials, 100 * s.success_rate, 100 * s.ci95_low,
               100 * s.ci95_high, s.mean_pushes, s.ms_per_command);
    std::fflush(stdout);
  }
  return row;
}

void Run(FigureOptions o) {
  if (o.quick) {
    o.trajectories = 20;
    o.epochs = 2;
    o.trials = 1;
    o.samples = 32;
    o.horizon = 3;
    o.max_steps = 2;
    o.oracle_trials = 1;
    o.oracle_samples = 4;
    o.oracle_horizon = 2;
  }
  DIFFDYN_CHECK(o.trajectories >= 1, "--trajectories must be >= 1, got ", o.trajectories);
  DIFFDYN_CHECK(o.epochs >= 1, "--epochs must be >= 1, got ", o.epochs);
  DIFFDYN_CHECK(o.trials >= 1, "--trials must be >= 1, got ", o.trials);
  DIFFDYN_CHECK(o.oracle_trials >= 0, "--oracle-trials must be >= 0, got ", o.oracle_trials);
  std::vector<LearnedKind> types;
  for (const std::string& name : SplitList(o.models)) {
    types.push_back(ParseLearnedKind(name, "--models"));
  }
  const fs::path dir(o.out);
  fs::create_directories(dir / "models");

  // 1. Data: the task's start spread, no obstacle in the world.
  fs::path data_path = o.data.empty() ? dir / "data.csv" : fs::path(o.data);
  if (!types.empty() && o.data.empty() && !(o.reuse && fs::exists(data_path))) {
    CollectOptions c;
    c.trajectories = o.trajectories;
    c.length = 10;
    c.seed = o.seed;
    c.threads = std::max(1, o.threads <= 0 ? 2 : o.threads);
    c.starts = StartDistribution::kTask;
    c.world.obstacle = false;
    ProgressBar bar("collect", o.trajectories, !o.quiet);
    c.progress = [&](int done) { bar.Update(done); };
    CollectStats stats;
    const auto data = CollectPushingData(c, &stats);
    bar.Finish();
    WritePushingCsvFile(data_path, data);
    if (!o.quiet) fmt::print("collected {} pushes in {} trajectories\n", stats.pushes, data.size());
  }
  const Windows windows =
      types.empty() ? Windows{} : MakeWindows(ReadDataset(data_path), 1);

  // 2-3. Train each model, then its trials; results are rewritten after each row.
  std::vector<Row> rows;
  for (LearnedKind type : types) {
    const std::string name = LearnedKindName(type);
    const LearnedModel model = TrainModel(type, windows, o, dir / "models" / (name + ".json"));
    rows.push_back(RunTrials(name, model, o.trials, o.samples, o.horizon, o));
    WriteResults(dir, rows);
  }
  // The oracle row: the ODE world itself as the model.
  if (o.oracle_trials > 0) {
    PushingConfig world;
    world.obstacle = true;
    const PushingOracle oracle(world);
    rows.push_back(RunTrials("oracle", oracle, o.oracle_trials, o.oracle_samples,
                             o.oracle_horizon, o));
    WriteResults(dir, rows);
  }
  if (!o.quiet) fmt::print("wrote {}\n", (dir / "results.csv").string());
  if (o.plot) figures::RunPlot(o.out);
}

}  // namespace
}  // namespace diffdyn

int main(int argc, char** argv) {
  diffdyn::FigureOptions o;
  CLI::App app{"NeuralODE-Panda Figure 1: MPPI obstacle-task success of the four models"};
  app.add_option("--out", o.out, "output folder")->capture_default_str();
  app.add_option("--data", o.data, "pushing CSV to train on (default: collect into --out)");
  app.add_option("--models", o.models, "comma-separated models")->capture_default_str();
  app.add_option("--threads", o.threads, "threads (0: all cores)")->capture_default_str();
  app.add_option("--seed", o.seed, "seed of data, training and trials")->capture_default_str();
  app.add_option("--trajectories", o.trajectories, "trajectories of 10 pushes to collect")
      ->capture_default_str();
  app.add_option("--epochs", o.epochs, "training epochs")->capture_default_str();
  app.add_option("--trials", o.trials, "obstacle trials per model")->capture_default_str();
  app.add_option("--samples", o.samples, "MPPI K for the learned models")->capture_default_str();
  app.add_option("--horizon", o.horizon, "MPPI T for the learned models")->capture_default_str();
  app.add_option("--max-steps", o.max_steps, "pushes per trial")->capture_default_str();
  app.add_option("--oracle-trials", o.oracle_trials, "trials of the oracle row (0: none)")
      ->capture_default_str();
  app.add_option("--oracle-samples", o.oracle_samples, "MPPI K of the oracle")->capture_default_str();
  app.add_option("--oracle-horizon", o.oracle_horizon, "MPPI T of the oracle")->capture_default_str();
  app.add_option("--collision-margin", o.collision_margin,
                 "cost: inflate the block by this much per side in the collision test (m)")
      ->capture_default_str();
  app.add_option("--collision-substeps", o.collision_substeps,
                 "cost: poses tested inside each predicted push (0: end pose only, the seed's)")
      ->capture_default_str();
  app.add_option("--reach-weight", o.reach_weight,
                 "cost: added when the push executed now is beyond the arm's reach (0: off)")
      ->capture_default_str();
  app.add_option("--reach-limited", o.reach_limited,
                 "MPPI: predict that a push the arm cannot reach leaves the block in place")
      ->capture_default_str();
  app.add_flag("--reuse", o.reuse, "reuse data.csv and models/<model>.json found in --out");
  app.add_flag("--quick", o.quick,
               "tiny run for the tests: 20 trajectories, 2 epochs, 1 trial, K 32, T 3, 2 pushes");
  app.add_flag("--plot", o.plot, "draw the PNGs with plot.py (Debian python3-matplotlib)");
  app.add_flag("--quiet", o.quiet, "no progress output");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  try {
    diffdyn::Run(o);
  } catch (const std::exception& e) {
    return diffdyn::figures::ReportError(e);
  }
  return 0;
}
