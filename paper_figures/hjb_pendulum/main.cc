// Figure 4 of the DDN paper: the HJB value function of the torque-limited pendulum,
// learned by residual minimisation with a discount homotopy (solvers/hjb.h), used as
// a feedback policy from seeded starts, beside multiple shooting (solved per start,
// solvers/multiple_shooting.h) and the clipped LQR (solvers/lqr.h), all measured by
// one evaluator (solvers/control.h). Writes into --out:
//
//   stages.csv        stage, rho, learning rate, held-out mean squared residual, seconds
//   grid.csv          stage, rho, theta, theta_dot, V, u* over the domain after each stage
//   starts.csv        controller, start, theta0, theta_dot0, success, cost, max_abs_u
//   trajectories.csv  controller, start, t, theta, theta_dot, u (every 10th start)
//   summary.csv       per controller: successes, cost mean / median / p90, max |u|, and
//                     for hjb the ratios J_hjb / J_shooting
//   hjb_pendulum.png  with --plot (plot.py)
//
//   build/paper_figures/figure_hjb_pendulum --plot --out out/      (about 35 minutes on 2 cores)
//   build/paper_figures/figure_hjb_pendulum --quick --out out/     (seconds)
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "../figure_main.h"
#include "diffdyn/models/io.h"
#include "diffdyn/solvers/hjb.h"
#include "diffdyn/solvers/lqr.h"
#include "diffdyn/solvers/multiple_shooting.h"
#include "diffdyn/solvers/statistics.h"

namespace fs = std::filesystem;
using namespace diffdyn;

namespace {

constexpr double kPi = std::numbers::pi;

struct FigureOptions {
  std::string out = "hjb_pendulum_out";
  int starts = 300;
  std::uint64_t seed = 1;
  int threads = 0;
  bool quick = false;
  bool quiet = false;
  HjbOptions hjb;
};

// theta = q - pi wrapped to (-pi, pi] (theta = 0 upright).
double Theta(double q) { return std::remainder(q - kPi, 2 * kPi); }

// V and u* over a theta x theta_dot grid of the domain, appended to grid.csv's rows.
void AppendGrid(const ControlTask& task, const ValueFunction& value, const HjbStageReport& r, std::ostream& out) {
  const int nt = 61, nv = 49;
  Eigen::MatrixXd x(2, nt * nv);
  for (int i = 0; i < nt; ++i) {
    for (int j = 0; j < nv; ++j) x.col(i * nv + j) << -kPi + 2 * kPi * i / (nt - 1) + kPi, -8.0 + 16.0 * j / (nv - 1);
  }
  Eigen::VectorXd v;
  Eigen::MatrixXd p;
  value.Evaluate(x, &v, &p);
  TaskHjb hjb(task, r.rho);
  for (Eigen::Index k = 0; k < x.cols(); ++k) {
    out << r.stage + 1 << ',' << r.rho << ',' << x(0, k) - kPi << ',' << x(1, k) << ',' << v[k] << ','
        << hjb.Policy(x.col(k), p.col(k))[0] << '\n';
  }
}

struct Evaluated {
  std::string name;
  std::vector<ControlRun> runs;
  double seconds = 0.0;
};

Evaluated Evaluate(const std::string& name, const ControlTask& task, Controller& controller,
                   const FigureOptions& o) {
  const auto start = std::chrono::steady_clock::now();
  Evaluated e{name, EvaluateController(task, controller, {.starts = o.starts, .seed = o.seed, .threads = o.threads}),
              0.0};
  e.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return e;
}

void WriteRuns(const fs::path& out, const std::vector<Evaluated>& all) {
  WriteFileAtomically(out / "starts.csv", [&](std::ostream& f) {
    f.precision(10);
    f << "controller,start,theta0,theta_dot0,success,cost,max_abs_u\n";
    for (const Evaluated& e : all) {
      for (std::size_t s = 0; s < e.runs.size(); ++s) {
        const ControlRun& r = e.runs[s];
        f << e.name << ',' << s << ',' << Theta(r.x0[0]) << ',' << r.x0[1] << ',' << (r.success ? 1 : 0) << ','
          << r.cost << ',' << r.max_abs_u << '\n';
      }
    }
  });
  WriteFileAtomically(out / "trajectories.csv", [&](std::ostream& f) {
    f.precision(6);
    f << "controller,start,t,theta,theta_dot,u\n";
    for (const Evaluated& e : all) {
      for (std::size_t s = 0; s < e.runs.size(); s += 10) {
        const Trajectory& tr = e.runs[s].trajectory;
        for (Eigen::Index k = 0; k + 1 < tr.t.size(); k += 2) {
          f << e.name << ',' << s << ',' << tr.t[k] << ',' << Theta(tr.states(0, k)) << ',' << tr.states(1, k) << ','
            << tr.actions(0, k) << '\n';
        }
      }
    }
  });
}

// Success, cost statistics and (for hjb) the ratios to shooting, printed and written.
void WriteSummary(const fs::path& out, const std::vector<Evaluated>& all) {
  const Evaluated* shooting = nullptr;
  for (const Evaluated& e : all) shooting = e.name == "shooting" ? &e : shooting;
  std::ostringstream text;
  text.precision(6);
  text << "controller,starts,successes,mean_cost,median_cost,p90_cost,max_abs_u,seconds,mean_ratio,median_ratio,"
          "p90_ratio,ratio_starts\n";
  for (const Evaluated& e : all) {
    std::vector<double> cost, ratio;
    int successes = 0;
    double max_u = 0.0, sum = 0.0, shooting_sum = 0.0;
    for (std::size_t s = 0; s < e.runs.size(); ++s) {
      cost.push_back(e.runs[s].cost);
      successes += e.runs[s].success ? 1 : 0;
      max_u = std::max(max_u, e.runs[s].max_abs_u);
      sum += e.runs[s].cost;
      if (shooting) {
        shooting_sum += shooting->runs[s].cost;
        if (shooting->runs[s].cost >= 1.0) ratio.push_back(e.runs[s].cost / shooting->runs[s].cost);
      }
    }
    const double mean_ratio = shooting ? sum / shooting_sum : NAN;
    const double median_ratio = ratio.empty() ? NAN : Percentile(ratio, 0.5);
    const double p90_ratio = ratio.empty() ? NAN : Percentile(ratio, 0.9);
    text << e.name << ',' << e.runs.size() << ',' << successes << ',' << sum / e.runs.size() << ','
         << Percentile(cost, 0.5) << ',' << Percentile(cost, 0.9) << ',' << max_u << ',' << e.seconds << ','
         << mean_ratio << ',' << median_ratio << ',' << p90_ratio << ',' << ratio.size() << '\n';
    std::printf("%-9s %3d/%zu swung up, cost mean %.2f median %.2f p90 %.2f, max |u| %.3f, %.0f s; "
                "J / J_shooting: mean %.4f, median %.4f, p90 %.4f over %zu starts with J_shooting >= 1\n",
                e.name.c_str(), successes, e.runs.size(), sum / e.runs.size(), Percentile(cost, 0.5),
                Percentile(cost, 0.9), max_u, e.seconds, mean_ratio, median_ratio, p90_ratio, ratio.size());
  }
  WriteFileAtomically(out / "summary.csv", [&](std::ostream& f) { f << text.str(); });
}

void Run(const FigureOptions& o) {
  const ControlTask task = ControlTaskByName("pendulum");
  const fs::path out(o.out);
  fs::create_directories(out);
  // The value function, with a snapshot of V and u* after each stage.
  std::ostringstream grid, stages;
  grid.precision(6);
  stages.precision(6);
  grid << "stage,rho,theta,theta_dot,value,action\n";
  stages << "stage,rho,learning_rate,residual,seconds\n";
  ValueFunction value = MakeTaskValueFunction(task, o.hjb);
  double train_seconds = 0.0;
  SolveHjb(task, o.hjb, &value, [&](const HjbStageReport& r) {
    train_seconds += r.seconds;
    stages << r.stage + 1 << ',' << r.rho << ',' << r.learning_rate << ',' << r.result.final_val_loss << ','
           << r.seconds << '\n';
    AppendGrid(task, value, r, grid);
    if (!o.quiet) {
      std::printf("stage %d/%d: rho %.4g, lr %.2g, residual %.4g (held out), %.1f s\n", r.stage + 1, r.stages,
                  r.rho, r.learning_rate, r.result.final_val_loss, r.seconds);
      std::fflush(stdout);
    }
  });
  std::printf("value function: %d stages, %.0f s of training (wall, --threads %d)\n",
              o.hjb.stages + o.hjb.polish_stages + o.hjb.rollout_stages, train_seconds, o.threads);
  WriteFileAtomically(out / "grid.csv", [&](std::ostream& f) { f << grid.str(); });
  WriteFileAtomically(out / "stages.csv", [&](std::ostream& f) { f << stages.str(); });
  SaveValueFunction(out / "value.json", value, "pendulum", {{"command", "figure_hjb_pendulum"}, {"seed", o.hjb.seed}});

  // The three controllers from the same starts.
  HjbController hjb(task, value);
  LqrController lqr(task, TaskLqr(task));
  MultipleShootingOptions shooting_options;
  if (o.quick) shooting_options.max_iterations = 5;
  MultipleShootingController shooting(task, shooting_options);
  std::vector<Evaluated> all;
  all.push_back(Evaluate("hjb", task, hjb, o));
  all.push_back(Evaluate("lqr", task, lqr, o));
  if (!o.quiet) std::printf("multiple shooting from %d starts...\n", o.starts);
  std::fflush(stdout);
  all.push_back(Evaluate("shooting", task, shooting, o));
  WriteRuns(out, all);
  WriteSummary(out, all);
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"DDN Figure 4: HJB value function and feedback policy of the torque-limited pendulum"};
  FigureOptions o;
  bool plot = false;
  app.add_option("--out", o.out, "output folder")->capture_default_str();
  app.add_option("--starts", o.starts, "seeded start states")->check(CLI::Range(1, 100000))->capture_default_str();
  app.add_option("--seed", o.seed, "seed of the start states")->capture_default_str();
  app.add_option("--hjb-seed", o.hjb.seed, "seed of the value network and its states")->capture_default_str();
  app.add_option("--threads", o.threads, "threads (0: all cores)")->check(CLI::Range(0, 256));
  app.add_flag("--quick", o.quick,
               "a toy value function (3 stages, 1 rollout stage), 2 starts, 5 shooting iterations (seconds)");
  app.add_flag("--plot", plot, "draw hjb_pendulum.png with plot.py");
  app.add_flag("--quiet", o.quiet, "no per-stage lines");
  CLI11_PARSE(app, argc, argv);
  o.hjb.train.threads = o.threads;
  if (o.quick) {
    o.starts = std::min(o.starts, 2);
    o.hjb.hidden = {16, 16};
    o.hjb.stages = 3;
    o.hjb.polish_stages = 0;
    o.hjb.rollout_stages = 1;
    o.hjb.rollout_starts = 2;
    o.hjb.rollout_epochs = 1;
    o.hjb.samples = 1000;
    o.hjb.train.epochs = 2;
  }
  try {
    Run(o);
    if (plot) figures::RunPlot(o.out);
  } catch (const std::exception& e) {
    return figures::ReportError(e);
  }
  return 0;
}
