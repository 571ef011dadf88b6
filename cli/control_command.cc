// diffdyn control: a controller on a control task, from seeded starts.
//
//   diffdyn control --system pendulum --controller mppi [--model M] --starts 20 --seed 1
//                   [--samples 1000] [--horizon 1.0] [--dt 0.04] [--out DIR] [--json]
//   diffdyn control --system pendulum --controller lqr --starts 300 --seed 1
//   diffdyn control --system pendulum --controller shooting --starts 300 --seed 1 [--iterations 50]
//   diffdyn control --system pendulum --controller hjb --model value.json --starts 300 --seed 1
//   diffdyn control --system pushing --controller mppi [--model M] --starts 50 --seed 1
//
// `lqr` is the regulator of the task's own analytic model linearised at the goal
// (solvers/lqr.h), clipped to the bounds by the evaluator. `shooting` solves the
// task's optimal-control problem from each start by multiple shooting on the task's
// own analytic model (solvers/multiple_shooting.h) and replays the actions open loop.
// Neither takes --model. `hjb` acts by u*(x, dV/dx) of the value function in --model
// (a file of kind value, written by `diffdyn hjb` for the same task; solvers/hjb.h).
// Controllers that can be copied (lqr, shooting, hjb) run their starts on --threads
// threads.
//
// The task (physics/control_task.h) gives the plant, the cost, the success test and
// the start distribution; the evaluator (solvers/control.h) runs the controller on
// the plant and measures every start the same way. M is what the controller plans
// with: by default, or when it names the task's system, the task's own analytic
// model on steps of --dt seconds; otherwise anything LoadTransitionModel opens
// (a learned model file, whose time step is its data's sample interval, or an
// extended-physics or DeLaN file, integrated over --dt; a DeLaN's action is the
// torque of the task's actuated joints). The model's step must be a whole
// multiple of the 8-ms control period (else exit 2).
//
// On `--system pushing` (solvers/pushing/trials.h: the obstacle task of `diffdyn push`,
// one push per step, each costing the seed's cost) the controller is pushing's MPPI
// with `diffdyn push`'s defaults (T = 20 pushes, the safety margin and reach terms;
// --samples and --threads apply) over M, by default the simulation itself (`oracle`).
//
// --out DIR writes DIR/starts.csv (start,x0_1..x0_n,success,cost,max_abs_u,seconds)
// and DIR/trajectories/start_<s>.csv (t, the states, the actions held from t).
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include <fmt/core.h>

#include "command.h"
#include "diffdyn/models/io.h"
#include "diffdyn/models/progress.h"
#include "diffdyn/physics/control_task.h"
#include "diffdyn/physics/pushing/system.h"
#include "diffdyn/solvers/control.h"
#include "diffdyn/solvers/hjb.h"
#include "diffdyn/solvers/load_model.h"
#include "diffdyn/solvers/lqr.h"
#include "diffdyn/solvers/multiple_shooting.h"
#include "diffdyn/solvers/pushing/trials.h"
#include "diffdyn/solvers/statistics.h"

namespace diffdyn::cli {
namespace {

namespace fs = std::filesystem;

struct ControlCommandOptions {
  CommonOptions common;
  std::string system = "pendulum";
  std::string controller = "mppi";
  std::string model;
  std::string precision;
  int starts = 20;
  double dt = 0.04;
  MppiControlOptions mppi;
  MultipleShootingOptions shooting;
  std::string out;
};

// The model the controller plans with (file comment).
std::unique_ptr<TransitionModel> PlanningModel(const ControlCommandOptions& o, const ControlTask& task) {
  DIFFDYN_CHECK(o.dt > 0 && o.dt <= 1.0, "--dt must be in (0, 1] s, got ", o.dt);
  PeriodsPerStep(o.dt, task.period, "--dt");
  if (o.model.empty() || o.model == o.system) {
    DIFFDYN_CHECK(PrecisionOption(o.precision).value_or(Precision::kF64) == Precision::kF64,
                  "--precision ", o.precision,
                  ": the task's own model computes in float64 only (float32: a learned --model)");
    return TaskModel(task, o.dt, 1);
  }
  return LoadTransitionModel(o.model, {.dt = o.dt,
                                       .method = Method::kRk4Classic,
                                       .substeps = 1,
                                       .actuated = TaskActuatedJoints(task),
                                       .precision = PrecisionOption(o.precision)});
}

void WriteStarts(const fs::path& path, const std::vector<ControlRun>& runs) {
  WriteFileAtomically(path, [&](std::ostream& out) {
    out << "start";
    for (Eigen::Index i = 0; i < runs.front().x0.size(); ++i) out << ",x0_" << i + 1;
    out << ",success,cost,max_abs_u,seconds\n";
    for (std::size_t s = 0; s < runs.size(); ++s) {
      out << s;
      for (double v : runs[s].x0) out << ',' << fmt::format("{}", v);
      out << ',' << (runs[s].success ? 1 : 0) << ',' << fmt::format("{},{},{}", runs[s].cost, runs[s].max_abs_u,
                                                                     runs[s].seconds)
          << '\n';
    }
  });
}

void WriteTrajectory(const fs::path& path, const Trajectory& tr, const SystemDescription& system) {
  WriteFileAtomically(path, [&](std::ostream& out) {
    out << 't';
    for (const std::string& name : system.state_names) out << ',' << name;
    for (const std::string& name : system.action_names) out << ',' << name;
    out << '\n';
    for (Eigen::Index k = 0; k < tr.t.size(); ++k) {
      out << fmt::format("{}", tr.t[k]);
      for (Eigen::Index i = 0; i < tr.states.rows(); ++i) out << ',' << fmt::format("{}", tr.states(i, k));
      for (Eigen::Index i = 0; i < tr.actions.rows(); ++i) {
        out << ',';
        if (k < tr.actions.cols()) out << fmt::format("{}", tr.actions(i, k));
      }
      out << '\n';
    }
  });
}

// What the text and JSON summaries add about the controller.
struct ControllerNotes {
  std::string extra{};
  double riccati_residual = -1.0;
  const MultipleShootingController* shooting = nullptr;
};

// Runs `controller` on `task` from the seeded starts, writes --out, prints the summary.
void Report(const ControlCommandOptions& o, const Task& task, const SystemDescription& system,
            Controller& controller, const std::string& model_kind, const ControllerNotes& notes) {
  if (!o.out.empty()) {
    std::error_code ec;
    fs::create_directories(fs::path(o.out) / "trajectories", ec);
    DIFFDYN_CHECK(!ec, "--out ", o.out, ": cannot create the folder: ", ec.message());
  }

  ProgressBar bar("control", o.starts, !o.common.quiet);
  const std::vector<ControlRun> runs = EvaluateController(
      task, controller,
      {.starts = o.starts, .seed = o.common.seed, .threads = o.mppi.threads, .progress = [&](int done, int) { bar.Update(done); }});
  bar.Finish();

  int successes = 0;
  double max_abs_u = 0.0, cost_sum = 0.0, seconds_sum = 0.0;
  std::vector<double> costs, command_ms;
  for (const ControlRun& r : runs) {
    seconds_sum += r.seconds;
    successes += r.success ? 1 : 0;
    max_abs_u = std::max(max_abs_u, r.max_abs_u);
    cost_sum += r.cost;
    costs.push_back(r.cost);
    command_ms.insert(command_ms.end(), r.command_ms.begin(), r.command_ms.end());
  }
  const auto [low, high] = WilsonInterval(successes, o.starts);
  if (!o.out.empty()) {
    WriteStarts(fs::path(o.out) / "starts.csv", runs);
    for (std::size_t s = 0; s < runs.size(); ++s) {
      WriteTrajectory(fs::path(o.out) / "trajectories" / fmt::format("start_{}.csv", s), runs[s].trajectory,
                      system);
    }
  }
  const double rate = static_cast<double>(successes) / o.starts;
  const double ms = Percentile(command_ms, 0.5);
  if (o.common.json) {
    nlohmann::json summary({{"system", o.system},           {"controller", o.controller},
               {"starts", o.starts},           {"successes", successes},
               {"success_rate", rate},         {"ci95_low", low},
               {"ci95_high", high},            {"mean_cost", cost_sum / o.starts},
               {"median_cost", Percentile(costs, 0.5)}, {"p90_cost", Percentile(costs, 0.9)},
               {"max_abs_u", max_abs_u},       {"ms_per_command", ms},
               {"model", o.model.empty() ? o.system : o.model}, {"model_kind", model_kind},
               {"hold", controller.hold()},    {"seed", o.common.seed}});
    if (notes.riccati_residual >= 0) summary["riccati_residual"] = notes.riccati_residual;
    if (notes.shooting) {
      const ShootingTotals t = notes.shooting->totals();
      summary["seconds_per_start"] = seconds_sum / o.starts;
      summary["max_shooting_defect"] = t.largest_shooting_defect;
      summary["max_defect"] = t.largest_defect;
      summary["iterations"] = t.iterations;
    }
    PrintJson(summary);
    return;
  }
  std::string extra = notes.extra;
  if (notes.shooting) {
    const ShootingTotals t = notes.shooting->totals();
    extra = fmt::format("; {:.2f} s per start (mean), largest continuity defect {:.1e} after the polish "
                        "({:.1e} before), {} iterations",
                        seconds_sum / o.starts, t.largest_defect, t.largest_shooting_defect, t.iterations);
  }
  fmt::print("{} on the {} task with {} ({}), {} starts: success {}/{} = {:.0f} % (95 % interval {:.0f}-{:.0f} %)\n",
             o.controller, o.system, o.model.empty() ? o.system : o.model, model_kind, o.starts, successes,
             o.starts, 100 * rate, 100 * low, 100 * high);
  fmt::print("cost mean {:.2f}, median {:.2f}, 90th percentile {:.2f}; max |u| {:.3f}; {:.2f} ms per command "
             "(median), action held {} period(s){}\n",
             cost_sum / o.starts, Percentile(costs, 0.5), Percentile(costs, 0.9), max_abs_u, ms, controller.hold(),
             extra);
}

// What runs on a task: the planning model and the controller (both owned).
struct Planner {
  std::unique_ptr<TransitionModel> model;
  std::unique_ptr<Controller> controller;
};

// Pushing's MPPI over --model (default: the simulation itself) on the pushing task.
Planner PushingPlanner(const ControlCommandOptions& o, const PushingTask& task) {
  DIFFDYN_CHECK(o.controller == "mppi", "--controller ", o.controller, ": the pushing task takes mppi only");
  Planner p;
  p.model = LoadTransitionModel(o.model.empty() || o.model == o.system ? "oracle" : o.model,
                                {.world = task.world(), .precision = PrecisionOption(o.precision)});
  p.controller = std::make_unique<PushingMppiController>(task, *p.model);
  return p;
}

void RunControl(const ControlCommandOptions& o) {
  PrecisionOption(o.precision);  // a bad value is bad input whatever the controller
  DIFFDYN_CHECK(o.precision.empty() || o.controller == "mppi",
                "--precision: applies to --controller mppi ", "(the model it plans with), not ",
                o.controller);
  // Validate everything before anything is written.
  DIFFDYN_CHECK(o.starts >= 1 && o.starts <= 100000, "--starts must be in [1, 100000], got ", o.starts);
  DIFFDYN_CHECK(o.system == "pushing" || o.system == "pendulum" || o.system == "cartpole", "--system ",
                o.system.substr(0, 60), ": no control task (pendulum, cartpole or pushing)");
  if (o.system == "pushing") {
    PushTaskOptions push;
    push.samples = o.mppi.samples;
    push.threads = o.mppi.threads;
    const PushingTask task(push);
    const Planner planner = PushingPlanner(o, task);
    Report(o, task, PushingSystem(), *planner.controller, planner.model->kind(), {});
    return;
  }
  const ControlTask task = ControlTaskByName(o.system);
  std::unique_ptr<TransitionModel> model;
  std::unique_ptr<Controller> owned;
  ControllerNotes notes;
  ValueFunction value;
  std::string model_kind;
  if (o.controller == "hjb") {
    DIFFDYN_CHECK(!o.model.empty() && o.model != o.system,
                  "--controller hjb needs --model, a value-function file written by `diffdyn hjb`");
    std::string value_task;
    value = LoadValueFunction(o.model, &value_task);
    DIFFDYN_CHECK(value_task == o.system && value.state_size() == task.state_size(), o.model.substr(0, 200),
                  ": a value function of the ", value_task.substr(0, 60), " task over ", value.state_size(),
                  " states, not of --system ", o.system);
    owned = std::make_unique<HjbController>(task, value);
    model_kind = "value";
  } else if (o.controller == "lqr" || o.controller == "shooting") {
    DIFFDYN_CHECK(o.model.empty() || o.model == o.system, "--model ", o.model.substr(0, 80), ": ", o.controller,
                  " uses the task's own analytic model (omit --model)");
    model = TaskModel(task, task.period, 1);
  }
  if (o.controller == "shooting") {
    auto owned_shooting = std::make_unique<MultipleShootingController>(task, o.shooting);
    notes.shooting = owned_shooting.get();
    owned = std::move(owned_shooting);
  } else if (o.controller == "lqr") {
    auto lqr = std::make_unique<LqrController>(task, TaskLqr(task));
    notes.riccati_residual = lqr->solution().riccati_residual;
    std::string gains;
    for (Eigen::Index i = 0; i < lqr->solution().K.size(); ++i) {
      gains += fmt::format("{}{:.4g}", i ? ", " : "", lqr->solution().K.data()[i]);
    }
    notes.extra = fmt::format("; K = [{}] (column-major), Riccati residual {:.1e}", gains, notes.riccati_residual);
    owned = std::move(lqr);
  } else if (o.controller == "mppi") {
    model = PlanningModel(o, task);
    owned = std::make_unique<MppiController>(task, *model, o.mppi);
  }
  if (model) model_kind = model->kind();
  Report(o, task, task.plant.System(), *owned, model_kind, notes);
}

}  // namespace

void RegisterControlCommand(CLI::App& app) {
  auto o = std::make_shared<ControlCommandOptions>();
  CLI::App* command = app.add_subcommand("control", "Run a controller on a control task from seeded starts");
  AddCommonOptions(command, o->common);
  command->add_option("--system", o->system, "Control task: pendulum (swing-up), cartpole (swing-up) or pushing (the obstacle task of diffdyn push)")
      ->capture_default_str();
  command->add_option("--controller", o->controller,
                      "Controller: mppi (over --model), lqr (the task's model linearised at the goal, clipped) "
                      "shooting (multiple shooting per start, replayed open loop) or hjb (the feedback policy of the "
                      "value function in --model)")
      ->check(CLI::IsMember({"mppi", "lqr", "shooting", "hjb"}))
      ->capture_default_str();
  command->add_option("--model", o->model,
                      "Model to plan with: a model file, or the task's system name (default: the task's analytic model); "
                      "for hjb the value-function file");
  AddPrecisionOption(command, o->precision);
  command->add_option("--starts", o->starts, "Seeded start states, 1 to 100000")
      ->check(Bounded(1, 100000))->capture_default_str();
  command->add_option("--dt", o->dt, "Planning step (s) of analytic and extended-physics models, a multiple of 8 ms")
      ->check(Bounded(1e-4, 1))
      ->capture_default_str();
  command->add_option("--samples", o->mppi.samples, "MPPI samples K")
      ->check(Bounded(1, 1e6))->capture_default_str();
  command->add_option("--horizon", o->mppi.horizon_seconds, "MPPI horizon (s)")
      ->check(Bounded(1e-3, 60))->capture_default_str();
  command->add_option("--lambda", o->mppi.lambda, "MPPI temperature")
      ->check(Bounded(1e-9, 1e9))->capture_default_str();
  command->add_option("--noise", o->mppi.noise_fraction, "MPPI noise standard deviation / action bound")
      ->check(Bounded(0, 10))
      ->capture_default_str();
  command->add_option("--terminal", o->mppi.terminal_seconds,
                      "MPPI terminal cost: the state cost at the horizon's end held for this long (s)")
      ->check(Bounded(0, 1e3))
      ->capture_default_str();
  command->add_option("--iterations", o->shooting.max_iterations,
                      "shooting: Levenberg-Marquardt iterations per continuity weight and per polish")
      ->check(Bounded(1, 100000))
      ->capture_default_str();
  command->add_option("--threads", o->mppi.threads, "Threads, >= 0 (0: all cores; results do not depend on it)")
      ->check(Bounded(0, 256))
      ->capture_default_str();
  command->add_option("--out", o->out, "Folder for starts.csv and trajectories/")
      ->check(OutputPath(true));
  command->callback([o] { RunControl(*o); });
}

}  // namespace diffdyn::cli
