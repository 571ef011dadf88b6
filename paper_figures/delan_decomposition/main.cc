// Figure 3(a) of the DDN paper on the DeLaN characters (a simulated 2-link arm):
// a deep Lagrangian network trained on torques alone, with the torque split into
// H qdd, c and g on the held-out characters e, q, v, learned against ground truth,
// beside a feed-forward network tau = f(q, qd, qdd) trained on the same data whose
// parts come from the authors' test-time trick (g = f(q, 0, 0), c = f(q, qd, 0) - g,
// H qdd = f(q, 0, qdd) - g). Writes into --out:
//
//   scores.csv       model, seed and the DESIGN.md errors on the test characters
//   timeseries.csv   per test sample: truth, DeLaN and feed-forward tau, m, c, g
//                    (first seed)
//   decomposition.png  with --plot (plot.py)
//
//   build/paper_figures/figure_delan_decomposition --seeds 0,1,2 --plot --out out/
#include <cstdio>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "../figure_main.h"
#include "diffdyn/autodiff_ode/io.h"
#include "diffdyn/models/delan.h"
#include "diffdyn/models/init.h"
#include "diffdyn/solvers/delan_training.h"

namespace fs = std::filesystem;
using namespace diffdyn;

namespace {

// tau = f(q, qd, qdd): one Mlp [3n, 64, 64, n] on the stacked inputs.
struct FeedForward {
  Mlp<double> net;
  Eigen::MatrixXd Inputs(const Eigen::MatrixXd& q, const Eigen::MatrixXd& qd, const Eigen::MatrixXd& qdd) const {
    Eigen::MatrixXd x(3 * q.rows(), q.cols());
    x << q, qd, qdd;
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
FeedForward TrainFeedForward(const JointData& train, const JointData& test, const TrainOptions& options,
                             std::uint64_t seed) {
  const int n = train.dof();
  const MlpArchitecture arch{{3 * n, 64, 64, n}, {Activation::Softplus(), Activation::Softplus()}};
  FeedForward ff{MakeInitializedMlp(arch, Delan::DefaultInit(), seed)};
  const Eigen::MatrixXd x_all = ff.Inputs(train.q, train.qd, train.qdd);
  MlpWorkspace ws;
  Eigen::MatrixXd x, t, y, gy;
  MinibatchProblem problem;
  problem.n_train = train.size();
  problem.n_val = test.size();
  problem.batch_loss = [&](std::span<const int> positions, Eigen::VectorXd* grad) {
    const int b = static_cast<int>(positions.size());
    x.resize(3 * n, b);
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
DelanParts FeedForwardParts(const FeedForward& ff, const JointData& d) {
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
  const DelanSplit split = SplitForDelan(ReadMeasured(data_path), 0.2, 0);
  const JointData& test = split.test;
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

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"DDN Figure 3(a): DeLaN's force decomposition on the 2-link characters"};
  std::string data = "../shared/data/delan_characters", out = "delan_decomposition_out", seeds = "0,1,2";
  TrainOptions options = DelanTrainDefaults();
  bool quick = false, plot = false, quiet = false;
  app.add_option("--data", data, "the DeLaN characters folder")->capture_default_str();
  app.add_option("--out", out, "output folder")->capture_default_str();
  app.add_option("--seeds", seeds, "comma-separated seeds (the first draws the time series)")
      ->capture_default_str();
  app.add_option("--epochs", options.epochs, "training epochs")->check(CLI::Range(1, 1000000))->capture_default_str();
  app.add_option("--threads", options.threads, "threads (0: all cores)")->check(CLI::Range(0, 256));
  app.add_flag("--quick", quick, "100 epochs, seed 0 (seconds)");
  app.add_flag("--plot", plot, "draw decomposition.png with plot.py");
  app.add_flag("--quiet", quiet, "no progress bars");
  CLI11_PARSE(app, argc, argv);
  if (quick) {
    options.epochs = 100;
    seeds = "0";
  }
  options.progress = !quiet;
  try {
    const std::vector<std::uint64_t> seed_list = ParseSeeds(seeds);
    fs::create_directories(out);
    Run(data, out, seed_list, options);
    if (plot) figures::RunPlot(out);
  } catch (const std::exception& e) {
    return figures::ReportError(e);
  }
  return 0;
}
