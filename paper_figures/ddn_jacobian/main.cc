// Figure 2 of the DDN paper: accuracy of the network's closed-form Jacobian
// (and Hessian) for relu / softplus / tanh / cos networks trained with a loss
// on f only or on f and its Jacobian. Writes CSVs (and, with --plot, PNGs via
// plot.py) into --out. See README.md for the command and the numbers.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "ddn_experiment.h"
#include "diffdyn/models/io.h"
#include "diffdyn/models/model_file.h"
#include "diffdyn/models/progress.h"
#include "../figure_main.h"

namespace fs = std::filesystem;
using namespace diffdyn;

namespace {

std::vector<std::string> Split(const std::string& s) {
  std::vector<std::string> parts;
  std::stringstream in(s);
  for (std::string item; std::getline(in, item, ',');) parts.push_back(item);
  return parts;
}

Activation ParseFigureActivation(const std::string& name) {
  // The authors' "cos" is cos(2 pi a).
  if (name == "cos") return Activation::Cos(2.0 * std::numbers::pi);
  return MakeActivation(name);
}

// Trains one network with a progress bar over its epochs.
ddn_figure::Result Train(ddn_figure::Config config, const std::string& label, bool quiet) {
  ProgressBar bar(label, config.epochs, !quiet);
  config.on_epoch = [&](int epoch, double loss) { bar.Update(epoch, StrCat("loss ", loss)); };
  return ddn_figure::RunExperiment(config);
}

// --sweep-seeds: both losses per (dim, activation, seed); writes seed_sweep.csv
// with the test MSEs and, in 1-D, where the Jacobian error sits
// (ddn_figure::SplitJacobianError1d).
void SweepSeeds(const ddn_figure::Config& base, const std::vector<std::string>& dims,
                const std::vector<std::string>& acts, const std::vector<std::string>& seeds,
                const std::string& out, bool quiet) {
  std::ostringstream csv;
  csv.precision(6);
  csv << "dim,activation,seed,loss,mse_f,mse_j,mse_h,mse_j_interior,mse_j_fine,mse_j_own_kink_floor,pieces\n";
  std::printf("%-3s %-9s %5s %10s %10s %7s %12s\n", "dim", "act", "seed", "J f+J", "J f", "gain", "gain interior");
  for (const std::string& dim_name : dims) {
    for (const std::string& act_name : acts) {
      for (const std::string& seed_name : seeds) {
        ddn_figure::Config config = base;
        config.dim = std::stoi(dim_name);
        config.activation = ParseFigureActivation(act_name);
        config.seed = std::stoull(seed_name);
        double mse_j[2] = {0, 0}, interior[2] = {0, 0};
        for (bool jac_loss : {true, false}) {
          config.jacobian_loss = jac_loss;
          const std::string loss = jac_loss ? "f+J" : "f";
          const ddn_figure::Result r =
              Train(config, StrCat(dim_name, "-D ", act_name, " ", loss, " seed ", seed_name), quiet);
          mse_j[jac_loss] = r.mse_j;
          csv << config.dim << ',' << act_name << ',' << config.seed << ',' << loss << ',' << r.mse_f << ','
              << r.mse_j << ',' << r.mse_h;
          if (config.dim == 1) {
            const ddn_figure::JacobianErrorSplit split = ddn_figure::SplitJacobianError1d(r.net);
            interior[jac_loss] = split.grid_interior;
            csv << ',' << split.grid_interior << ',' << split.fine << ',' << split.own_kink_floor << ','
                << split.pieces << '\n';
          } else {
            csv << ",,,,\n";
          }
        }
        std::printf("%-3d %-9s %5s %10.2e %10.2e %7.2f", config.dim, act_name.c_str(), seed_name.c_str(),
                    mse_j[1], mse_j[0], mse_j[0] / mse_j[1]);
        if (config.dim == 1) std::printf(" %12.2f", interior[0] / interior[1]);
        std::printf("\n");
        std::fflush(stdout);
      }
    }
  }
  WriteFileAtomically(fs::path(out) / "seed_sweep.csv", [&](std::ostream& f) { f << csv.str(); });
  std::printf("wrote %s/seed_sweep.csv\n", out.c_str());
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"DDN Figure 2: Jacobian accuracy of relu / softplus / tanh / cos networks"};
  bool quick = false, plot = false, quiet = false;
  std::string out = "ddn_jacobian_out", dims_arg = "1,2", acts_arg = "relu,softplus,tanh,cos", sweep_seeds;
  ddn_figure::Config base;
  app.add_flag("--quick", quick, "tiny run (a few seconds): 2,560 samples, 3 epochs, relu and softplus unless --activations is given");
  app.add_option("--out", out, "output folder for CSVs, model files and PNGs")->capture_default_str();
  app.add_option("--dims", dims_arg, "comma-separated dimensions (1, 2)")->capture_default_str();
  app.add_option("--activations", acts_arg, "comma-separated activations")->capture_default_str();
  app.add_option("--epochs", base.epochs, "training epochs")->capture_default_str();
  app.add_option("--n-train", base.n_train, "training samples")->capture_default_str();
  app.add_option("--width", base.width, "hidden width")->capture_default_str();
  app.add_option("--batch", base.batch, "mini-batch size")->capture_default_str();
  app.add_option("--lr", base.learning_rate, "Adam learning rate")->capture_default_str();
  app.add_option("--seed", base.seed, "seed of data, initialisation and shuffling")->capture_default_str();
  app.add_option("--threads", base.threads, "threads per training step")->capture_default_str();
  app.add_flag("--plot", plot, "draw the PNGs with plot.py (Debian python3-matplotlib)");
  app.add_option("--sweep-seeds", sweep_seeds,
                 "comma-separated seeds: instead of the figure, train both losses per seed and write seed_sweep.csv");
  app.add_flag("--quiet", quiet, "no progress bars");
  CLI11_PARSE(app, argc, argv);
  if (quick) {
    base.n_train = 2560;
    base.epochs = 3;
    if (app.count("--activations") == 0) acts_arg = "relu,softplus";
  }
  try {
    fs::create_directories(out);
    if (!sweep_seeds.empty()) {
      SweepSeeds(base, Split(dims_arg), Split(acts_arg), Split(sweep_seeds), out, quiet);
      return 0;
    }
    std::ostringstream results;
    results << "dim,activation,loss,mse_f,mse_j,mse_h,final_train_loss,seconds\n";
    std::printf("%-3s %-9s %-4s %10s %10s %10s %8s\n", "dim", "act", "loss", "mse_f", "mse_j", "mse_h", "sec");
    for (const std::string& dim_name : Split(dims_arg)) {
      const int dim = std::stoi(dim_name);
      const int points = dim == 1 ? 100 : 50;
      const ddn_figure::Dataset test = ddn_figure::MakeTestGrid(dim, points);
      // Curves: truth then every (activation, loss) network on the test grid.
      std::map<std::string, ddn_figure::Dataset> curves;
      for (const std::string& act_name : Split(acts_arg)) {
        for (bool jac_loss : {true, false}) {
          ddn_figure::Config config = base;
          config.dim = dim;
          config.activation = ParseFigureActivation(act_name);
          config.jacobian_loss = jac_loss;
          const std::string loss = jac_loss ? "f+J" : "f";
          const ddn_figure::Result r = Train(config, StrCat(dim, "-D ", act_name, " ", loss), quiet);
          std::printf("%-3d %-9s %-4s %10.2e %10.2e %10.2e %8.1f\n", dim, act_name.c_str(), loss.c_str(),
                      r.mse_f, r.mse_j, r.mse_h, r.seconds);
          std::fflush(stdout);
          results << dim << ',' << act_name << ',' << loss << ',' << r.mse_f << ',' << r.mse_j << ','
                  << r.mse_h << ',' << r.final_train_loss << ',' << r.seconds << '\n';
          const std::string tag = act_name + "_" + (jac_loss ? "fJ" : "f");
          curves[tag] = ddn_figure::Predict(r.net, test.x);
          SaveMlp(fs::path(out) / ("model_" + std::to_string(dim) + "d_" + tag + ".json"), r.net,
                  {{"experiment", "ddn_jacobian"}, {"dim", dim}, {"activation", act_name},
                   {"loss", loss}, {"seed", config.seed}, {"epochs", config.epochs},
                   {"n_train", config.n_train}},
                  {{"test_mse_f", r.mse_f}, {"test_mse_j", r.mse_j}, {"test_mse_h", r.mse_h}});
        }
      }
      // Columns: inputs, truth (f, J entries, H entries), then each network.
      WriteFileAtomically(fs::path(out) / ("curves_" + std::to_string(dim) + "d.csv"), [&](std::ostream& f) {
        f.precision(10);
        f << (dim == 1 ? "x" : "x,y");
        auto header = [&](const std::string& prefix) {
          f << ',' << prefix << "f";
          for (int a = 0; a < dim; ++a) f << ',' << prefix << "j" << a + 1;
          for (int a = 0; a < dim * dim; ++a) f << ',' << prefix << "h" << a + 1;
        };
        header("true_");
        for (const auto& [tag, d] : curves) header(tag + "_");
        f << '\n';
        auto row = [&](const ddn_figure::Dataset& d, Eigen::Index i) {
          f << ',' << d.f(0, i);
          for (int a = 0; a < dim; ++a) f << ',' << d.jac(0, dim * i + a);
          for (int a = 0; a < dim * dim; ++a) f << ',' << d.hess(0, dim * dim * i + a);
        };
        for (Eigen::Index i = 0; i < test.x.cols(); ++i) {
          f << test.x(0, i);
          if (dim == 2) f << ',' << test.x(1, i);
          row(test, i);
          for (const auto& [tag, d] : curves) row(d, i);
          f << '\n';
        }
      });
      // A subsample of the noisy training data, for the grey dots.
      Rng rng(base.seed);
      const ddn_figure::Dataset train = ddn_figure::MakeTrainingData(dim, 400, base.noise, rng);
      WriteFileAtomically(fs::path(out) / ("samples_" + std::to_string(dim) + "d.csv"), [&](std::ostream& f) {
        f.precision(10);
        f << (dim == 1 ? "x,f,j1\n" : "x,y,f,j1,j2\n");
        for (Eigen::Index i = 0; i < train.x.cols(); ++i) {
          for (int a = 0; a < dim; ++a) f << train.x(a, i) << ',';
          f << train.f(0, i);
          for (int a = 0; a < dim; ++a) f << ',' << train.jac(0, dim * i + a);
          f << '\n';
        }
      });
    }
    WriteFileAtomically(fs::path(out) / "results.csv", [&](std::ostream& f) { f << results.str(); });
    std::printf("wrote %s/results.csv and curves_*d.csv\n", out.c_str());
    if (plot) figures::RunPlot(out);
  } catch (const std::exception& e) {
    return figures::ReportError(e);
  }
  return 0;
}
