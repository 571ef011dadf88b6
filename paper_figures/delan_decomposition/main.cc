// Figure 3 of the DDN paper: a deep Lagrangian network trained on torques alone,
// with the torque split into its physical parts, learned against ground truth,
// beside a feed-forward network tau = f(q, qd, qdd) trained on the same data whose
// parts come from the authors' test-time trick (g = f(q, 0, 0), c = f(q, qd, 0) - g,
// H qdd = f(q, 0, qdd) - g).
//
// (a) The DeLaN characters (a simulated 2-link arm), held-out characters e, q, v.
// Writes into --out:
//
//   scores.csv       model, seed and the DESIGN.md errors on the test characters
//   timeseries.csv   per test sample: truth, DeLaN and feed-forward tau, m, c, g
//                    (first seed)
//   decomposition.png  with --plot (plot.py)
//
// (b) With --cartpole: the cart-pole task (DESIGN.md: viscous friction 0.1 on the
// cart, 1e-3 on the pole), a delan-friction model with the pole angle as (sin, cos),
// trained once on data with both joints excited (`collect --actuated all`) and once
// on the task's own data (only the cart pushed), each 100 trajectories of 5 s (seed
// 1), scored on 20 held-out trajectories of its kind (seed 2) and on a swing-up by
// multiple shooting (start seed 1, 8-ms samples). Writes into --out:
//
//   data/*.csv                 the generated datasets (collect's schema)
//   cartpole_scores.csv        per training set and test set: the DESIGN.md nmse of
//                              tau, H qdd, c, g, f, T, V (offset-matched), power,
//                              and the learned friction coefficients
//   cartpole_timeseries.csv    the swing-up: truth, DeLaN (both sets) and
//                              feed-forward parts per joint, T, V, power
//   cartpole_decomposition.png with --plot
//
//   build/paper_figures/figure_delan_decomposition --seeds 0,1,2 --plot --out out/
//   build/paper_figures/figure_delan_decomposition --cartpole --plot --out out/
#include <cstdio>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "../figure_main.h"
#include "diffdyn/models/delan.h"
#include "diffdyn/models/init.h"
#include "diffdyn/models/io.h"
#include "diffdyn/physics/control_task.h"
#include "diffdyn/solvers/control.h"
#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/delan_training.h"
#include "diffdyn/solvers/joint_collect.h"
#include "diffdyn/solvers/multiple_shooting.h"

namespace fs = std::filesystem;
using namespace diffdyn;

namespace {

// tau = f(q, qd, qdd): one Mlp [3n (+ periodic), 64, 64, n] on the stacked inputs
// (periodic joints' q as sin, cos, as DeLaN's).
struct FeedForward {
  Mlp<double> net;
  InputFeatures features;
  Eigen::MatrixXd Inputs(const Eigen::MatrixXd& q, const Eigen::MatrixXd& qd, const Eigen::MatrixXd& qdd) const {
    const Eigen::MatrixXd z = features.Encode(q);
    Eigen::MatrixXd x(z.rows() + 2 * q.rows(), q.cols());
    x << z, qd, qdd;
    return x;
  }
  Eigen::MatrixXd Predict(const Eigen::MatrixXd& q, const Eigen::MatrixXd& qd, const Eigen::MatrixXd& qdd) const {
    const Eigen::MatrixXd x = Inputs(q, qd, qdd);
    Eigen::MatrixXd y(net.num_outputs(), x.cols());
    MlpWorkspace ws;
    net.Evaluate(x, y, &ws);
    return y;
  }
};

// The feed-forward baseline with DeLaN's optimiser settings and loss.
FeedForward TrainFeedForward(const DelanSamples& train, const DelanSamples& test, const TrainOptions& options,
                             std::uint64_t seed, const InputFeatures& features = {}) {
  const int n = train.dof();
  const MlpArchitecture arch{{features.size(n) + 2 * n, 64, 64, n},
                             {Activation::Softplus(), Activation::Softplus()}};
  FeedForward ff{MakeInitializedMlp(arch, Delan::DefaultInit(), seed), features};
  const Eigen::MatrixXd x_all = ff.Inputs(train.q, train.qd, train.qdd);
  MlpWorkspace ws;
  Eigen::MatrixXd x, t, y, gy;
  MinibatchProblem problem;
  problem.n_train = train.size();
  problem.n_val = test.size();
  problem.batch_loss = [&](std::span<const int> positions, Eigen::VectorXd* grad) {
    const int b = static_cast<int>(positions.size());
    x.resize(x_all.rows(), b);
    t.resize(n, b);
    for (int i = 0; i < b; ++i) x.col(i) = x_all.col(positions[i]), t.col(i) = train.tau.col(positions[i]);
    ff.net.Forward(x, &y, nullptr, &ws, options.threads);
    gy = (2.0 / b) * (y - t);
    ff.net.Backward(gy, Eigen::MatrixXd(), grad, nullptr, &ws, options.threads);
    return (y - t).squaredNorm() / b;
  };
  problem.validation_loss = [&] {
    return (ff.Predict(test.q, test.qd, test.qdd) - test.tau).squaredNorm() / test.size();
  };
  FitMinibatches(problem, options, &ff.net.mutable_parameters());
  return ff;
}

// The feed-forward network's parts by the authors' trick.
DelanParts FeedForwardParts(const FeedForward& ff, const DelanSamples& d) {
  const Eigen::MatrixXd zero = Eigen::MatrixXd::Zero(d.dof(), d.size());
  DelanParts p;
  p.torque = ff.Predict(d.q, d.qd, d.qdd);
  p.gravity = ff.Predict(d.q, zero, zero);
  p.coriolis = ff.Predict(d.q, d.qd, zero) - p.gravity;
  p.inertial = ff.Predict(d.q, zero, d.qdd) - p.gravity;
  return p;
}

double Mse(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) { return (a - b).squaredNorm() / a.cols(); }

std::vector<std::uint64_t> ParseSeeds(const std::string& text) {
  std::vector<std::uint64_t> seeds;
  std::stringstream in(text);
  for (std::string item; std::getline(in, item, ',');) {
    DIFFDYN_CHECK(!item.empty() && item.find_first_not_of("0123456789") == std::string::npos,
                  "--seeds: '", item, "' is not a non-negative integer");
    seeds.push_back(std::stoull(item));
  }
  DIFFDYN_CHECK(!seeds.empty(), "--seeds: no seed given");
  return seeds;
}

void Run(const std::string& data_path, const std::string& out, const std::vector<std::uint64_t>& seeds,
         TrainOptions options) {
  const DelanSplit split = SplitForDelan(ReadDataset(data_path), 0.2, 0);
  const DelanSamples& test = split.test;
  std::ostringstream scores;
  scores.precision(6);
  scores << "model,seed,torque_mse,inertial_mse,coriolis_mse,gravity_mse,power_mse,min_mass_eigenvalue,"
            "seconds_per_epoch\n";
  std::printf("%-12s %4s %10s %10s %10s %10s %10s %8s\n", "model", "seed", "tau", "H qdd", "c", "g", "power",
              "min eig");
  DelanParts first, ff_parts;
  for (std::size_t s = 0; s < seeds.size(); ++s) {
    options.seed = seeds[s];
    Delan model = Delan::Initialized({.dof = test.dof()}, seeds[s]);
    const TrainResult r = TrainDelan(&model, split.train, test, options);
    std::map<std::string, double> e = ScoreDelan(model, test);
    scores << "delan," << seeds[s] << ',' << e["torque_mse"] << ',' << e["inertial_mse"] << ','
           << e["coriolis_mse"] << ',' << e["gravity_mse"] << ',' << e["power_mse"] << ','
           << e["min_mass_eigenvalue"] << ',' << r.seconds_per_epoch << '\n';
    std::printf("%-12s %4llu %10.3e %10.3e %10.3e %10.3e %10.3e %8.3f\n", "delan",
                static_cast<unsigned long long>(seeds[s]), e["torque_mse"], e["inertial_mse"], e["coriolis_mse"],
                e["gravity_mse"], e["power_mse"], e["min_mass_eigenvalue"]);
    if (s == 0) {
      DelanWorkspace ws;
      first = model.Decompose(test.q, test.qd, test.qdd, &ws);
    }
  }
  // The feed-forward baseline, first seed.
  options.seed = seeds[0];
  const FeedForward ff = TrainFeedForward(split.train, test, options, seeds[0]);
  ff_parts = FeedForwardParts(ff, test);
  const Eigen::MatrixXd& m = test.channels.at("m");
  const Eigen::MatrixXd& c = test.channels.at("c");
  const Eigen::MatrixXd& g = test.channels.at("g");
  scores << "feed-forward," << seeds[0] << ',' << Mse(ff_parts.torque, test.tau) << ','
         << Mse(ff_parts.inertial, m) << ',' << Mse(ff_parts.coriolis, c) << ',' << Mse(ff_parts.gravity, g)
         << ",,,\n";
  std::printf("%-12s %4llu %10.3e %10.3e %10.3e %10.3e\n", "feed-forward",
              static_cast<unsigned long long>(seeds[0]), Mse(ff_parts.torque, test.tau),
              Mse(ff_parts.inertial, m), Mse(ff_parts.coriolis, c), Mse(ff_parts.gravity, g));
  WriteFileAtomically(fs::path(out) / "scores.csv", [&](std::ostream& f) { f << scores.str(); });
  // Time series of the first seed, test characters in file order.
  WriteFileAtomically(fs::path(out) / "timeseries.csv", [&](std::ostream& f) {
    f.precision(8);
    f << "sample";
    for (const char* q : {"tau", "m", "c", "g"})
      for (const char* who : {"true", "delan", "ff"})
        for (int j = 1; j <= test.dof(); ++j) f << ',' << q << j << '_' << who;
    f << '\n';
    for (int i = 0; i < test.size(); ++i) {
      f << i;
      const Eigen::MatrixXd* rows[4][3] = {{&test.tau, &first.torque, &ff_parts.torque},
                                           {&m, &first.inertial, &ff_parts.inertial},
                                           {&c, &first.coriolis, &ff_parts.coriolis},
                                           {&g, &first.gravity, &ff_parts.gravity}};
      for (auto& quantity : rows)
        for (const Eigen::MatrixXd* who : quantity)
          for (int j = 0; j < test.dof(); ++j) f << ',' << (*who)(j, i);
      f << '\n';
    }
  });
  std::printf("wrote %s/scores.csv and %s/timeseries.csv\n", out.c_str(), out.c_str());
}

// ---- (b) the cart-pole ----

// Writes `data` to dir/NAME.csv and reads it back as `diffdyn train` would.
Dataset ThroughFile(const fs::path& dir, const std::string& name, const Dataset& data) {
  const std::string path = (dir / (name + ".csv")).string();
  WriteDataset(path, data);
  return ReadDataset(path);
}

// The cart-pole task's samples: both joints excited (`all`) or only the cart.
DelanSamples CollectCartpole(const fs::path& dir, const std::string& name, bool all, int trajectories,
                             std::uint64_t seed, int threads) {
  JointTask task = ControlTaskByName("cartpole").plant;
  if (all) task = task.ActuatingAll();
  JointCollectOptions o;
  o.trajectories = trajectories;
  o.seed = seed;
  o.threads = threads > 0 ? threads : 2;
  return SamplesOf(ThroughFile(dir, name, CollectJointSpace(task, o)));
}

// A swing-up by multiple shooting from the task's start of `seed`, with ground truth.
Dataset SwingUp(const fs::path& dir, std::uint64_t seed, bool* success) {
  const ControlTask task = ControlTaskByName("cartpole");
  MultipleShootingController controller(task, MultipleShootingOptions{});
  EvaluationOptions eval;
  eval.starts = 1;
  eval.seed = seed;
  const std::vector<ControlRun> runs = EvaluateController(task, controller, eval);
  *success = runs[0].success;
  Dataset d;
  d.system = task.plant.System();
  d.format = "joint-csv";
  d.trajectories.push_back(runs[0].trajectory);
  AddGroundTruth(task.plant, &d.trajectories[0]);
  d.trajectories[0].label = "swing-up";
  return ThroughFile(dir, "swing_up", d);
}

// Friction: viscous and Coulomb per joint; the pole angle (joint 2) as (sin, cos);
// H's lower bounds eps + floor^2 = 1e-4 + 1e-6 below the pole's m_p l^2 = 0.0036
// (the characters' defaults, 0.01 + 0.0025, would exceed it).
DelanOptions CartpoleDelanOptions() {
  return {.dof = 2, .epsilon = 1e-4, .diagonal_floor = 1e-3, .periodic = {1}, .friction = true};
}

const char* const kCartpoleKeys[] = {"torque", "inertial", "coriolis", "gravity", "friction",
                                     "kinetic", "potential", "power"};

void WriteScoreRow(std::ostream& out, const std::string& train, const std::string& test, const std::string& model,
                   std::map<std::string, double> e) {
  out << train << ',' << test << ',' << model;
  for (const char* key : kCartpoleKeys) {
    out << ',';
    if (e.count(StrCat(key, "_nmse"))) out << e[StrCat(key, "_nmse")];
  }
  for (const char* key : {"min_mass_eigenvalue", "viscous_1", "viscous_2", "coulomb_1", "coulomb_2"}) {
    out << ',';
    if (e.count(key)) out << e[key];
  }
  out << '\n';
  std::printf("%-6s %-9s %-6s nmse", train.c_str(), test.c_str(), model.c_str());
  for (const char* key : kCartpoleKeys) {
    if (e.count(StrCat(key, "_nmse"))) std::printf("  %s %.2e", key, e[StrCat(key, "_nmse")]);
  }
  std::printf("\n");
}

// DESIGN.md's scores of `model` on `test` plus its friction coefficients.
std::map<std::string, double> CartpoleScores(const Delan& model, const DelanSamples& test) {
  std::map<std::string, double> e = ScoreDelan(model, test);
  for (int j = 0; j < model.dof(); ++j) {
    e[StrCat("viscous_", j + 1)] = model.viscous()[j];
    e[StrCat("coulomb_", j + 1)] = model.coulomb()[j];
  }
  return e;
}

// The feed-forward network's nmse; its c (by the trick) holds friction too, so it
// is scored against c + f.
std::map<std::string, double> FeedForwardScores(const FeedForward& ff, const DelanSamples& test) {
  const DelanParts p = FeedForwardParts(ff, test);
  return {{"torque_nmse", NormalizedMse(p.torque, test.tau)},
          {"inertial_nmse", NormalizedMse(p.inertial, test.channels.at("m"))},
          {"coriolis_nmse", NormalizedMse(p.coriolis, test.channels.at("c") + test.channels.at("f"))},
          {"gravity_nmse", NormalizedMse(p.gravity, test.channels.at("g"))}};
}

// The swing-up time series: truth, DeLaN on both sets and the feed-forward parts.
void WriteCartpoleSeries(const fs::path& path, const Dataset& run, const Delan& full, const Delan& under,
                         const FeedForward& ff) {
  const DelanSamples d = SamplesOf(run);
  const Eigen::RowVectorXd times = StackTrajectories(run, [](const Trajectory& t) { return t.t.transpose(); });
  DelanWorkspace ws;
  const DelanParts pf = full.Decompose(d.q, d.qd, d.qdd, &ws), pu = under.Decompose(d.q, d.qd, d.qdd, &ws);
  const DelanParts pff = FeedForwardParts(ff, d);
  const Eigen::MatrixXd none;
  const std::vector<std::pair<const char*, std::vector<const Eigen::MatrixXd*>>> parts = {
      {"tau", {&d.tau, &pf.torque, &pu.torque, &pff.torque}},
      {"m", {&d.channels.at("m"), &pf.inertial, &pu.inertial, &pff.inertial}},
      {"c", {&d.channels.at("c"), &pf.coriolis, &pu.coriolis, &pff.coriolis}},
      {"g", {&d.channels.at("g"), &pf.gravity, &pu.gravity, &pff.gravity}},
      {"f", {&d.channels.at("f"), &pf.friction, &pu.friction, &none}}};
  const Eigen::RowVectorXd& v_true = d.channels.at("potential");
  const auto matched = [&](const Eigen::RowVectorXd& v) {
    return Eigen::RowVectorXd((v.array() + (v_true.mean() - v.mean())).matrix());
  };
  const auto delivered = [&](const DelanParts& p) {
    return Eigen::RowVectorXd(p.power + (d.qd.array() * p.friction.array()).colwise().sum().matrix());
  };
  const Eigen::RowVectorXd energies[] = {
      d.channels.at("kinetic"), pf.kinetic, pu.kinetic, v_true, matched(pf.potential), matched(pu.potential),
      (d.qd.array() * d.tau.array()).colwise().sum().matrix(), delivered(pf), delivered(pu)};
  WriteFileAtomically(path, [&](std::ostream& f) {
    f.precision(8);
    f << 't';
    for (const auto& [name, who] : parts)
      for (const char* w : {"true", "full", "under", "ff"})
        for (int j = 1; j <= d.dof(); ++j) f << ',' << name << j << '_' << w;
    for (const char* e : {"T", "V", "P"})
      for (const char* w : {"true", "full", "under"}) f << ',' << e << '_' << w;
    f << '\n';
    for (int i = 0; i < d.size(); ++i) {
      f << times[i];
      for (const auto& [name, who] : parts)
        for (const Eigen::MatrixXd* m : who)
          for (int j = 0; j < d.dof(); ++j) {
            f << ',';
            if (m->size() > 0) f << (*m)(j, i);
          }
      for (const Eigen::RowVectorXd& e : energies) f << ',' << e[i];
      f << '\n';
    }
  });
}

struct CartpoleOptions {
  int train_trajectories = 100, test_trajectories = 20;
  bool swing_up = true;
};

void RunCartpole(const std::string& out, const CartpoleOptions& c, TrainOptions options) {
  const fs::path dir = fs::path(out) / "data";
  fs::create_directories(dir);
  const int threads = options.threads;
  const DelanSamples full_train = CollectCartpole(dir, "full_train", true, c.train_trajectories, 1, threads);
  const DelanSamples full_test = CollectCartpole(dir, "full_test", true, c.test_trajectories, 2, threads);
  const DelanSamples under_train = CollectCartpole(dir, "under_train", false, c.train_trajectories, 1, threads);
  const DelanSamples under_test = CollectCartpole(dir, "under_test", false, c.test_trajectories, 2, threads);
  bool swung = false;
  const Dataset swing_run = c.swing_up ? SwingUp(dir, 1, &swung) : ReadDataset((dir / "full_test.csv").string());
  const DelanSamples swing = SamplesOf(swing_run);
  std::printf("swing-up by multiple shooting (start seed 1): %s, %d samples\n",
              c.swing_up ? (swung ? "success" : "not swung up") : "skipped (--quick)", swing.size());
  Delan full = Delan::Initialized(CartpoleDelanOptions(), options.seed);
  TrainDelan(&full, full_train, full_test, options);
  Delan under = Delan::Initialized(CartpoleDelanOptions(), options.seed);
  TrainDelan(&under, under_train, under_test, options);
  const FeedForward ff = TrainFeedForward(full_train, full_test, options, options.seed, InputFeatures{{1}});
  std::ostringstream scores;
  scores.precision(6);
  scores << "train_set,test_set,model";
  for (const char* key : kCartpoleKeys) scores << ',' << key << "_nmse";
  scores << ",min_mass_eigenvalue,viscous_1,viscous_2,coulomb_1,coulomb_2\n";
  WriteScoreRow(scores, "full", "held-out", "delan", CartpoleScores(full, full_test));
  WriteScoreRow(scores, "full", "swing-up", "delan", CartpoleScores(full, swing));
  WriteScoreRow(scores, "full", "held-out", "ff", FeedForwardScores(ff, full_test));
  WriteScoreRow(scores, "full", "swing-up", "ff", FeedForwardScores(ff, swing));
  WriteScoreRow(scores, "under", "held-out", "delan", CartpoleScores(under, under_test));
  WriteScoreRow(scores, "under", "swing-up", "delan", CartpoleScores(under, swing));
  WriteFileAtomically(fs::path(out) / "cartpole_scores.csv", [&](std::ostream& f) { f << scores.str(); });
  SaveDelan(fs::path(out) / "data" / "cartpole_delan_full.json", full);
  SaveDelan(fs::path(out) / "data" / "cartpole_delan_under.json", under);
  WriteCartpoleSeries(fs::path(out) / "cartpole_timeseries.csv", swing_run, full, under, ff);
  std::printf("wrote %s/cartpole_scores.csv and %s/cartpole_timeseries.csv\n", out.c_str(), out.c_str());
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"DDN Figure 3: DeLaN's force decomposition, (a) the 2-link characters, (b) --cartpole"};
  std::string data = "../shared/data/delan_characters", out = "delan_decomposition_out", seeds = "0,1,2";
  TrainOptions options = DelanTrainDefaults();
  bool quick = false, plot = false, quiet = false, cartpole = false;
  app.add_option("--data", data, "the DeLaN characters folder")->capture_default_str();
  app.add_option("--out", out, "output folder")->capture_default_str();
  app.add_option("--seeds", seeds, "comma-separated seeds (the first draws the time series)")
      ->capture_default_str();
  app.add_option("--epochs", options.epochs, "training epochs")->check(CLI::Range(1, 1000000))->capture_default_str();
  app.add_option("--threads", options.threads, "threads (0: all cores)")->check(CLI::Range(0, 256));
  app.add_flag("--cartpole", cartpole, "Figure 3(b): the cart-pole with friction (one seed: the first)");
  app.add_flag("--quick", quick, "100 epochs, seed 0 (seconds); cart-pole: 10 + 4 trajectories, 30 epochs, no swing-up");
  app.add_flag("--plot", plot, "draw decomposition.png with plot.py");
  app.add_flag("--quiet", quiet, "no progress bars");
  CLI11_PARSE(app, argc, argv);
  if (quick) {
    options.epochs = cartpole ? 30 : 100;
    seeds = "0";
  }
  options.progress = !quiet;
  try {
    const std::vector<std::uint64_t> seed_list = ParseSeeds(seeds);
    fs::create_directories(out);
    if (cartpole) {
      options.seed = seed_list.front();
      CartpoleOptions c;
      if (quick) c = {10, 4, false};
      RunCartpole(out, c, options);
    } else {
      Run(data, out, seed_list, options);
    }
    if (plot) figures::RunPlot(out);
  } catch (const std::exception& e) {
    return figures::ReportError(e);
  }
  return 0;
}
