// diffdyn push: MPPI over a pushing model, executed in the ODE-engine world.
//
//   diffdyn push --model MODEL.json --trials 20 --obstacle --seed 1 --samples 1000
//                --horizon 20 --max-steps 20 [--collision-margin M] [--collision-substeps S]
//                [--clearance C --clearance-weight W] [--fallback-margin F]
//                [--reach-weight W] [--reach-steps H]
//                [--threads 0] [--out DIR] [--json]
//
// --model is a pushing model file or `oracle` (the ODE world itself as the model).
// Prints the success rate with its 95 % Wilson interval, the mean number of pushes,
// the median milliseconds per MPPI command and the outcomes. With --out, writes
// DIR/trials.csv (one row per pose, with the model's prediction of it) and
// DIR/top_view.png of the first successful trial (else the first trial).
#include "push_command.h"

#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <string>

#include <fmt/core.h>
#include <fmt/ostream.h>

#include "command.h"
#include "diffdyn/models/io.h"
#include "diffdyn/models/progress.h"
#include "diffdyn/solvers/load_model.h"
#include "diffdyn/solvers/pushing/world_file.h"
#include "plot.h"

namespace diffdyn::cli {

std::unique_ptr<TransitionModel> LoadPushModel(const std::string& name, const PushingConfig& world,
                                               std::optional<Precision> precision) {
  LoadModelOptions options;
  options.world = world;
  options.precision = precision;
  auto model = LoadTransitionModel(name, options);
  DIFFDYN_CHECK(model->state_size() == 3 && model->action_size() == 3, "--model ", name,
                ": a pushing model has 3 states and 3 actions, this one has ", model->state_size(),
                " and ", model->action_size());
  return model;
}

void WritePushTrialsCsv(const std::filesystem::path& path, const PushTrialsSummary& summary) {
  WriteFileAtomically(path, [&](std::ostream& out) {
    out << "trial,step,x,y,theta,push_location,push_angle,push_length,outcome,pred_x,pred_y,"
           "pred_theta\n";
    for (std::size_t i = 0; i < summary.runs.size(); ++i) {
      const PushTrial& t = summary.runs[i];
      for (std::size_t k = 0; k < t.poses.size(); ++k) {
        const auto& p = t.poses[k];
        fmt::print(out, "{},{},{:.9g},{:.9g},{:.9g},", i, k, p.x(), p.y(), p.z());
        if (k < t.actions.size()) {
          const auto& a = t.actions[k];
          fmt::print(out, "{:.9g},{:.9g},{:.9g},", a.x(), a.y(), a.z());
        } else {
          out << ",,,";
        }
        out << t.outcome;
        // The model's prediction of this pose from the previous pose and action.
        if (k >= 1 && k - 1 < t.predicted.size()) {
          const auto& q = t.predicted[k - 1];
          fmt::print(out, ",{:.9g},{:.9g},{:.9g}\n", q.x(), q.y(), q.z());
        } else {
          out << ",,,\n";
        }
      }
    }
  });
}

int PictureTrial(const PushTrialsSummary& summary) {
  for (std::size_t i = 0; i < summary.runs.size(); ++i) {
    if (summary.runs[i].success) return static_cast<int>(i);
  }
  return 0;
}

bool PlotPushTopView(const std::filesystem::path& csv, int trial, const PushTrialsSummary& summary,
                     bool obstacle, double tolerance, const std::filesystem::path& png) {
  const auto& t = summary.runs.at(trial);
  return RunPlotScript("push_top_view.py",
                       {csv.string(), png.string(), "--trial", std::to_string(trial), "--goal",
                        fmt::format("{:.9g}", t.goal.x()), fmt::format("{:.9g}", t.goal.y()),
                        "--tolerance", fmt::format("{:.9g}", tolerance), "--obstacle",
                        obstacle ? "1" : "0"});
}

std::map<std::string, int> OutcomeCounts(const PushTrialsSummary& summary) {
  std::map<std::string, int> counts;
  for (const auto& t : summary.runs) ++counts[t.outcome];
  return counts;
}

namespace {

struct PushArgs {
  CommonOptions common;
  std::string model;
  std::string world;
  std::string precision;
  int trials = 20;
  bool obstacle = true;
  int samples = 1000;
  int horizon = 20;
  int max_steps = 20;
  int threads = 0;
  std::string out;
  double collision_margin = PushTaskOptions{}.collision_margin;
  int collision_substeps = PushTaskOptions{}.collision_substeps;
  double fallback_margin = PushTaskOptions{}.fallback_margin;
  double clearance = PushTaskOptions{}.clearance;
  double clearance_weight = PushTaskOptions{}.clearance_weight;
  double reach_weight = PushTaskOptions{}.reach_weight;
  int reach_steps = PushTaskOptions{}.reach_steps;
  bool reach_limited = PushTaskOptions{}.reach_limited;
};

void RunPush(const PushArgs& args) {
  PushTaskOptions options;
  options.obstacle = args.obstacle;
  options.samples = args.samples;
  options.horizon = args.horizon;
  options.max_steps = args.max_steps;
  options.threads = args.threads;
  options.collision_margin = args.collision_margin;
  options.collision_substeps = args.collision_substeps;
  options.fallback_margin = args.fallback_margin;
  options.clearance = args.clearance;
  options.clearance_weight = args.clearance_weight;
  options.reach_weight = args.reach_weight;
  options.reach_steps = args.reach_steps;
  options.reach_limited = args.reach_limited;
  if (!args.world.empty()) options.world = LoadPusherWorld(args.world, options.world, "--world");
  options.world.obstacle = args.obstacle;
  DIFFDYN_CHECK(args.trials >= 1, "--trials: must be >= 1, got ", args.trials);
  ValidatePushTaskOptions(options);
  const std::unique_ptr<TransitionModel> model =
      LoadPushModel(args.model, options.world, PrecisionOption(args.precision));
  namespace fs = std::filesystem;
  if (!args.out.empty()) {
    std::error_code ec;
    fs::create_directories(args.out, ec);
    DIFFDYN_CHECK(!ec && fs::is_directory(args.out), "--out ", args.out,
                  ": cannot create directory: ", ec.message());
  }

  ProgressBar bar("push", args.trials, !args.common.quiet);
  const PushTrialsSummary summary =
      RunPushTrials(*model, args.trials, options, args.common.seed, [&bar, &args](int done, int successes) {
        bar.Update(done, StrCat("trial ", done, "/", args.trials, ", ", successes, " successes"));
      });
  bar.Finish();

  std::string top_view;
  if (!args.out.empty()) {
    const fs::path out(args.out);
    WritePushTrialsCsv(out / "trials.csv", summary);
    if (PlotPushTopView(out / "trials.csv", PictureTrial(summary), summary, args.obstacle,
                        options.goal_tolerance, out / "top_view.png")) {
      top_view = (out / "top_view.png").string();
    }
  }

  const auto counts = OutcomeCounts(summary);
  const int fallbacks = summary.fallbacks;
  if (args.common.json) {
    PrintJson({{"trials", summary.trials},
               {"successes", summary.successes},
               {"success_rate", summary.success_rate},
               {"ci95_low", summary.ci95_low},
               {"ci95_high", summary.ci95_high},
               {"mean_pushes", summary.mean_pushes},
               {"ms_per_command", summary.ms_per_command},
               {"model", args.model},
               {"kind", model->kind()},
               {"task", args.obstacle ? "obstacle" : "free"},
               {"samples", args.samples},
               {"horizon", args.horizon},
               {"max_steps", args.max_steps},
               {"collision_margin", args.collision_margin},
               {"collision_substeps", args.collision_substeps},
               {"fallback_margin",  // null: off (inf)
                std::isfinite(args.fallback_margin) ? nlohmann::json(args.fallback_margin) : nlohmann::json()},
               {"fallbacks", fallbacks},
               {"clearance", args.clearance},
               {"clearance_weight", args.clearance_weight},
               {"reach_weight", args.reach_weight},
               {"reach_steps", args.reach_steps},
               {"reach_limited", args.reach_limited},
               {"seed", args.common.seed},
               {"outcomes", counts},
               {"top_view", top_view}});
    return;
  }
  fmt::print("{} ({}) on the {} task: {} trials, K = {}, T = {}, at most {} pushes\n",
             args.model, model->kind(), args.obstacle ? "obstacle" : "free", summary.trials,
             args.samples, args.horizon, args.max_steps);
  fmt::print("success {}/{} = {:.0f} % (95 % interval {:.0f}-{:.0f} %), mean pushes {:.2f}, "
             "{:.1f} ms per MPPI command (median)\n",
             summary.successes, summary.trials, 100 * summary.success_rate,
             100 * summary.ci95_low, 100 * summary.ci95_high, summary.mean_pushes,
             summary.ms_per_command);
  std::string histogram;
  for (const auto& [outcome, n] : counts) histogram += fmt::format(" {} {},", outcome, n);
  if (!histogram.empty()) histogram.pop_back();
  fmt::print("outcomes:{}\n", histogram);
  if (!args.out.empty()) {
    fmt::print("wrote {}{}\n", (fs::path(args.out) / "trials.csv").string(),
               top_view.empty() ? "" : ", " + top_view);
  }
}

}  // namespace

void RegisterPushCommand(CLI::App& app) {
  auto* command = app.add_subcommand(
      "push", "Push the block to the goal with MPPI over a model, in the ODE-engine world");
  auto args = std::make_shared<PushArgs>();
  AddCommonOptions(command, args->common);
  command->add_option("--model", args->model, "Pushing model file, or 'oracle' (the ODE world)")
      ->required();
  AddPrecisionOption(command, args->precision);
  command
      ->add_option("--world", args->world,
                   "A pusher world file (kind oracle, e.g. diagnose --model pushing's "
                   "calibrated_pusher.json): "
                   "the world the pushes are executed in, and the oracle's")
      ->check(InputPath());
  command->add_option("--trials", args->trials, "Seeded trials (start perturbed per trial)")
      ->check(Bounded(1, 10000));
  command->add_flag("--obstacle,!--free", args->obstacle,
                    "Obstacle task: start (0.4, 0, -0.2 pi), goal (0.8, -0.1, 0); --free: start "
                    "(0.4, 0, 0.2 pi), goal (0.8, 0, 0)");
  command->add_option("--samples", args->samples, "MPPI samples K")
      ->check(Bounded(1, 1e6));
  command->add_option("--horizon", args->horizon, "MPPI horizon T")
      ->check(Bounded(1, 1000));
  command->add_option("--max-steps", args->max_steps, "Pushes per trial")
      ->check(Bounded(1, 10000));
  command->add_option("--threads", args->threads,
                      "MPPI threads (0: all cores; results do not depend on it)")
      ->check(Bounded(0, 256));
  command->add_option("--collision-margin", args->collision_margin,
                      "Cost: inflate the block by this much per side in the collision test (m)")
      ->check(Bounded(0, 1))
      ->capture_default_str();
  command->add_option("--collision-substeps", args->collision_substeps,
                      "Cost: also test this many poses interpolated inside each predicted push "
                      "(0: end pose only, the seed's cost)")
      ->check(Bounded(0, 1000))
      ->capture_default_str();
  command->add_option("--fallback-margin", args->fallback_margin,
                      "MPPI: execute the best sample instead of the weighted average when the "
                      "model predicts the average to cost more than the best plus this (inf: off)")
      ->capture_default_str();
  command->add_option("--clearance", args->clearance,
                      "Cost: smooth clearance term active closer than this to the obstacle (m; 0: off)")
      ->check(Bounded(0, 10))
      ->capture_default_str();
  command->add_option("--clearance-weight", args->clearance_weight,
                      "Cost: weight w of the clearance term w (1 - d / clearance)^2")
      ->check(Bounded(0, 1e9))
      ->capture_default_str();
  command->add_option("--reach-weight", args->reach_weight,
                      "Cost: added once per planned push whose tool path leaves the arm's reach "
                      "(0: off)")
      ->check(Bounded(0, 1e9))
      ->capture_default_str();
  command->add_option("--reach-steps", args->reach_steps,
                      "Cost: the reach term checks the first this many planned pushes "
                      "(1: only the push executed now)")
      ->check(Bounded(1, 1000))
      ->capture_default_str();
  command->add_option("--reach-limited", args->reach_limited,
                      "MPPI: predict that a push the arm cannot reach leaves the block in place")
      ->capture_default_str();
  command->add_option("--out", args->out, "Directory for trials.csv and top_view.png (optional)")
      ->check(OutputPath(true));
  command->callback([args] { RunPush(*args); });
}

}  // namespace diffdyn::cli
