// NeuralODE-Panda Figures 2-5: grid searches over solver, grid points and hidden
// width for the absolute and residual NeuralODEs (single-step loss), the multi-step
// grid of the absolute NeuralODE (rk4), the comparison of the four models (the
// paper's Fig. 5 protocol), and the acceptance runs (the four models with the
// defaults of `diffdyn train`, several seeds).
//
// Each configuration trains from its seed on the seeded 80/20 split of a pushing CSV
// (exactly what `diffdyn train --seed S` does with the same flags) and keeps the last
// epoch's train and validation loss. Configurations run in parallel, one per core
// (each trains single-threaded), so the sweep keeps both cores busy and every number
// is independent of the thread count.
//
// Resumable: each finished configuration rewrites its grid's CSV atomically, and a
// configuration whose row is already in the CSV is not trained again, so an
// interrupted sweep is finished by running the same command again. Configurations run
// in priority order: accept, compare, single (rk4 first, then dopri5), multi.
//
// Writes grid_accept.csv, grid_compare.csv, grid_single.csv, grid_multi.csv (and PNGs
// with --plot) into --out. See README.md for the commands and the paper-vs-ours tables.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/io.h"
#include "diffdyn/models/learned_model.h"
#include "diffdyn/models/parallel.h"
#include "diffdyn/models/random.h"
#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/training.h"
#include "../figure_main.h"

namespace fs = std::filesystem;
using namespace diffdyn;

namespace {

constexpr const char* kGrids[] = {"accept", "compare", "single", "multi"};
constexpr const char* kHeader =
    "model,solver,steps,hidden,lr,epochs,seed,train_loss,val_loss,eval_single,eval_avg_multi,"
    "seconds,seconds_per_epoch,diverged";
constexpr int kColumns = 14;

// One training run of the sweep and, once done, its results.
struct Run {
  std::string grid;  // accept, compare, single, multi
  LearnedModelConfig config;
  int horizon = 1;
  int epochs = 100;
  double lr = 1e-3;
  std::uint64_t seed = 1;
  bool done = false;
  double train_loss = 0.0, val_loss = 0.0, eval_single = 0.0, eval_multi = 0.0;
  double seconds = 0.0, seconds_per_epoch = 0.0;
  bool diverged = false;
  std::string error;
};

// The identity of a configuration inside its grid's CSV.
std::string Key(const std::string& model, const std::string& solver, int steps, int hidden, double lr,
                int epochs, std::uint64_t seed) {
  char buffer[160];
  std::snprintf(buffer, sizeof buffer, "%s,%s,%d,%d,%.6g,%d,%llu", model.c_str(), solver.c_str(), steps,
                hidden, lr, epochs, static_cast<unsigned long long>(seed));
  return buffer;
}

std::string Key(const Run& r) {
  return Key(LearnedKindName(r.config.type), MethodName(r.config.method), r.config.steps,
             r.config.hidden, r.lr, r.epochs, r.seed);
}

std::string ConfigName(const Run& r) {
  std::ostringstream s;
  s << r.grid << " " << LearnedKindName(r.config.type) << " " << MethodName(r.config.method)
    << " steps " << r.config.steps << " h " << r.config.hidden << " lr " << r.lr << " epochs "
    << r.epochs << " seed " << r.seed;
  return s.str();
}

std::vector<std::string> SplitCommas(const std::string& line) {
  std::vector<std::string> fields;
  std::stringstream s(line);
  std::string field;
  while (std::getline(s, field, ',')) fields.push_back(field);
  if (!line.empty() && line.back() == ',') fields.emplace_back();
  return fields;
}

// The finished rows of an existing grid CSV (none if the file does not exist). A
// malformed file throws diffdyn::Error "<path>:<line>: ..." rather than being overwritten.
std::vector<Run> ReadDoneRows(const fs::path& path, const std::string& grid) {
  std::vector<Run> rows;
  if (!fs::exists(path)) return rows;
  std::ifstream in(path);
  DIFFDYN_CHECK(in.good(), path.string(), ": cannot open");
  std::string line;
  DIFFDYN_CHECK(std::getline(in, line) && line == kHeader, path.string(),
                ":1: unexpected header (not a figure_neuralode_grids CSV of this version; move it away)");
  for (int number = 2; std::getline(in, line); ++number) {
    if (line.empty()) continue;
    const std::vector<std::string> f = SplitCommas(line);
    DIFFDYN_CHECK(static_cast<int>(f.size()) == kColumns, path.string(), ":", number, ": expected ",
                  kColumns, " fields, got ", f.size());
    Run r;
    r.grid = grid;
    r.done = true;
    try {
      r.config.type = ParseLearnedKind(f[0]);
      r.config.method = ParseMethod(f[1]);
      size_t used = 0;
      auto number_of = [&](const std::string& s) {
        const double v = std::stod(s, &used);
        if (used != s.size()) throw std::invalid_argument(s);
        return v;
      };
      r.config.steps = static_cast<int>(number_of(f[2]));
      r.config.hidden = static_cast<int>(number_of(f[3]));
      r.lr = number_of(f[4]);
      r.epochs = static_cast<int>(number_of(f[5]));
      r.seed = static_cast<std::uint64_t>(number_of(f[6]));
      r.train_loss = number_of(f[7]);
      r.val_loss = number_of(f[8]);
      r.eval_single = number_of(f[9]);
      r.eval_multi = number_of(f[10]);
      r.seconds = number_of(f[11]);
      r.seconds_per_epoch = number_of(f[12]);
      r.diverged = number_of(f[13]) != 0;
    } catch (const std::exception& e) {
      throw Error(StrCat(path.string(), ":", number, ": bad field (", e.what(), ")"));
    }
    r.horizon = grid == "multi" ? 4 : 1;
    rows.push_back(r);
  }
  return rows;
}

void WriteGrid(const fs::path& path, const std::vector<Run>& runs, const std::string& grid) {
  WriteFileAtomically(path, [&](std::ostream& f) {
    f.precision(8);
    f << kHeader << '\n';
    for (const Run& r : runs) {
      if (r.grid != grid || !r.done) continue;
      f << LearnedKindName(r.config.type) << ',' << MethodName(r.config.method) << ','
        << r.config.steps << ',' << r.config.hidden << ',' << r.lr << ',' << r.epochs << ',' << r.seed
        << ',' << r.train_loss << ',' << r.val_loss << ',' << r.eval_single << ',' << r.eval_multi << ','
        << r.seconds << ',' << r.seconds_per_epoch << ',' << (r.diverged ? 1 : 0) << '\n';
    }
  });
}

// The held-out windows of the trainer's seeded split.
Windows HeldOut(const Windows& data, std::uint64_t seed, double fraction) {
  std::vector<int> val;
  SplitWindows(data.size(), fraction, seed, nullptr, &val);
  return SelectWindows(data, val);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"NeuralODE-Panda Figs. 2-5: solver / steps / hidden grids and the four-model comparison"};
  std::string data = "../shared/data/pybullet_pushing/collected_data.csv";
  std::string out = "neuralode_grids_out", which = "accept,compare,single,multi";
  int epochs = 100, compare_epochs = 200, threads = 0;
  std::uint64_t seed = 1;
  std::vector<std::uint64_t> seeds{1, 2, 3};
  std::vector<std::string> single_solvers{"rk4", "dopri5"};
  bool quick = false, plot = false;
  app.add_option("--data", data, "pushing CSV")->capture_default_str();
  app.add_option("--out", out, "output folder for the CSVs and PNGs (existing rows are kept)")
      ->capture_default_str();
  app.add_option("--grids", which, "comma-separated: accept, compare, single, multi")->capture_default_str();
  app.add_option("--epochs", epochs, "epochs per grid configuration and of the acceptance runs (paper: 100)")
      ->capture_default_str();
  app.add_option("--compare-epochs", compare_epochs,
                 "epochs of the four-model comparison and of the 200-epoch NN acceptance rows (paper: 200)")
      ->capture_default_str();
  app.add_option("--seed", seed, "seed of the grid configurations (split, initialisation, batches)")
      ->capture_default_str();
  app.add_option("--seeds", seeds, "seeds of the acceptance runs and the four-model comparison")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--single-solvers", single_solvers, "solvers of the single-step grids (rk4, dopri5)")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--threads", threads, "configurations trained at once (0: all cores)")->capture_default_str();
  app.add_flag("--quick", quick, "tiny run for the tests: 40 trajectories, 2 epochs, 2 x 2 grids, seed 1");
  app.add_flag("--plot", plot, "draw the PNGs with plot.py (Debian python3-matplotlib)");
  CLI11_PARSE(app, argc, argv);
  try {
    auto has = [&](const std::string& g) { return ("," + which + ",").find("," + g + ",") != std::string::npos; };
    for (const std::string& g : SplitCommas(which)) {
      DIFFDYN_CHECK(std::find(std::begin(kGrids), std::end(kGrids), g) != std::end(kGrids), "--grids: unknown grid '",
                    g, "' (expected accept, compare, single or multi)");
    }
    DIFFDYN_CHECK(epochs >= 1 && compare_epochs >= 1, "--epochs and --compare-epochs must be >= 1");
    DIFFDYN_CHECK(!seeds.empty(), "--seeds: need at least one seed");
    std::vector<Method> single_methods;
    for (const std::string& name : single_solvers) {
      DIFFDYN_CHECK(name == "rk4" || name == "dopri5", "--single-solvers: unknown solver '", name,
                    "' (expected rk4 or dopri5)");
      single_methods.push_back(name == "rk4" ? Method::kRk4 : Method::kDopri5);
    }
    Dataset dataset = ReadDataset(data);
    auto& trajectories = dataset.trajectories;
    std::vector<int> steps_single{2, 6, 10}, hidden_single{4, 32, 100};
    std::vector<int> steps_multi{2, 4, 6, 8, 10}, hidden_multi{4, 16, 32, 64, 100};
    int big = 100;
    if (quick) {
      trajectories.resize(std::min<size_t>(trajectories.size(), 40));
      epochs = compare_epochs = 2;
      steps_single = steps_multi = {2, 3};
      hidden_single = hidden_multi = {4, 8};
      seeds = {1};
      big = 8;
    }
    const Windows single = MakeWindows(dataset, 1);
    const Windows multi = MakeWindows(dataset, 4);
    const std::vector<LearnedKind> all_types{LearnedKind::kAbsNn, LearnedKind::kResNn,
                                                  LearnedKind::kAbsNode, LearnedKind::kResNode};
    // The residual NeuralODE uses lr 1e-2 as in the paper's notebook (text: 1e-3).
    auto default_lr = [](LearnedKind t) { return t == LearnedKind::kResNode ? 1e-2 : 1e-3; };

    // The configurations, in priority order (which is also the CSV row order).
    std::vector<Run> runs;
    auto add = [&](const std::string& grid, LearnedKind type, Method method, int steps, int hidden,
                   int n_epochs, double lr, std::uint64_t s) {
      Run r;
      r.grid = grid;
      r.config = {.type = type, .hidden = hidden, .method = method, .steps = steps};
      r.horizon = grid == "multi" ? 4 : 1;
      r.epochs = n_epochs;
      r.lr = lr;
      r.seed = s;
      // Equal configurations (e.g. 100 = 200 epochs in quick mode) train once.
      if (std::none_of(runs.begin(), runs.end(), [&](const Run& q) { return q.grid == grid && Key(q) == Key(r); })) {
        runs.push_back(r);
      }
    };
    if (has("accept")) {
      // The acceptance: `diffdyn train` defaults (rk4, 10 points, h 100,
      // 100 epochs), plus the NNs at the paper's 200 epochs.
      for (std::uint64_t s : seeds) {
        for (LearnedKind type : all_types) {
          add("accept", type, Method::kRk4, 10, big, epochs, default_lr(type), s);
        }
        for (LearnedKind type : {LearnedKind::kAbsNn, LearnedKind::kResNn}) {
          add("accept", type, Method::kRk4, 10, big, compare_epochs, 1e-3, s);
        }
      }
    }
    if (has("compare")) {
      // The paper's final models: NNs lr 1e-3; NODEs dopri5, 10 grid points, h 100, 200 epochs.
      for (std::uint64_t s : seeds) {
        for (LearnedKind type : all_types) {
          add("compare", type, Method::kDopri5, 10, big, compare_epochs, default_lr(type), s);
        }
      }
    }
    if (has("single")) {
      for (Method method : single_methods) {
        for (LearnedKind type : {LearnedKind::kAbsNode, LearnedKind::kResNode}) {
          for (int steps : steps_single) {
            for (int hidden : hidden_single) add("single", type, method, steps, hidden, epochs, default_lr(type), seed);
          }
        }
      }
    }
    if (has("multi")) {
      for (int steps : steps_multi) {
        for (int hidden : hidden_multi) {
          add("multi", LearnedKind::kAbsNode, Method::kRk4, steps, hidden, epochs, 1e-3, seed);
        }
      }
    }

    // Resume: mark the configurations whose rows exist; keep unrelated rows too.
    fs::create_directories(out);
    int skipped = 0;
    for (const std::string grid : kGrids) {
      if (!has(grid)) continue;
      for (const Run& row : ReadDoneRows(fs::path(out) / ("grid_" + grid + ".csv"), grid)) {
        auto it = std::find_if(runs.begin(), runs.end(),
                               [&](const Run& r) { return r.grid == grid && Key(r) == Key(row); });
        if (it != runs.end()) {
          *it = row;
          ++skipped;
        } else {
          runs.push_back(row);
        }
      }
    }
    std::vector<int> todo;
    for (int i = 0; i < static_cast<int>(runs.size()); ++i) {
      if (!runs[i].done) todo.push_back(i);
    }
    std::fprintf(stderr, "%zu configurations: %d already in %s, %zu to train\n", todo.size() + skipped, skipped,
                 out.c_str(), todo.size());

    std::mutex mutex;
    std::atomic<int> finished{0};
    ParallelForChunks(static_cast<int>(todo.size()), 1, threads, [&](int c, int, int) {
      Run r = runs[todo[c]];
      const auto start = std::chrono::steady_clock::now();
      try {
        LearnedModel model = LearnedModel::Initialized(r.config, r.seed);
        TrainOptions options;
        options.epochs = r.epochs;
        options.learning_rate = r.lr;
        options.gamma = 0.9;
        options.seed = r.seed;
        options.threads = 1;
        options.progress = false;
        Trainer trainer(&model, options);
        const TrainResult result = trainer.Train(r.horizon == 1 ? single : multi);
        r.train_loss = result.final_train_loss;
        r.val_loss = result.final_val_loss;
        r.seconds_per_epoch = result.seconds_per_epoch;
        if (r.grid == "accept" || r.grid == "compare") {
          // Fig. 5 metrics: single step on the held-out transitions, average 4-step loss
          // on the held-out 4-step windows of the same seeded split of the windows.
          r.eval_single = RolloutLoss(model, HeldOut(single, r.seed, options.val_fraction), 1.0, 1);
          r.eval_multi = RolloutLoss(model, HeldOut(multi, r.seed, options.val_fraction), 1.0, 1) / 4;
        }
      } catch (const NumericalError& e) {
        r.diverged = true;  // a diverged configuration is a result, reported in the CSV
        r.error = e.what();
      }
      r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      r.done = true;
      std::lock_guard<std::mutex> lock(mutex);
      runs[todo[c]] = r;
      WriteGrid(fs::path(out) / ("grid_" + r.grid + ".csv"), runs, r.grid);
      std::fprintf(stderr, "[%d/%zu] %s: train %.4g val %.4g (%.1f s, %.3f s/epoch)%s%s\n", ++finished,
                   todo.size(), ConfigName(r).c_str(), r.train_loss, r.val_loss, r.seconds,
                   r.seconds_per_epoch, r.diverged ? " diverged: " : "", r.error.c_str());
    });
    for (const std::string grid : kGrids) {
      if (!has(grid)) continue;
      WriteGrid(fs::path(out) / ("grid_" + grid + ".csv"), runs, grid);
      std::printf("wrote %s/grid_%s.csv\n", out.c_str(), grid.c_str());
    }
    if (plot) figures::RunPlot(out);
  } catch (const std::exception& e) {
    return figures::ReportError(e);
  }
  return 0;
}
