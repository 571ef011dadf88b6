// diffdyn train / eval: flags, defaults in --help, --json keys, model files that
// eval reads back, and one-line errors naming the file and line for bad CSVs.
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "run_diffdyn.h"

namespace diffdyn {
namespace {

using testing::CountLines;
using testing::RunDiffdyn;

const std::string kData = std::string(DIFFDYN_SHARED_DATA_DIR) + "/pybullet_pushing/collected_data.csv";

// The header and the first `trajectories` trajectories of the shared data (11 rows each).
std::string Head(int trajectories) {
  std::ifstream in(kData);
  std::string line, out;
  for (int i = 0; i < 1 + 11 * trajectories && std::getline(in, line); ++i) out += line + "\n";
  return out;
}

std::string WriteTemp(const std::string& name, const std::string& contents) {
  const std::string path = ::testing::TempDir() + "/" + name;
  std::ofstream(path) << contents;
  return path;
}

TEST(TrainCommand, HelpPrintsTheIssueDefaults) {
  const auto r = RunDiffdyn("train --help");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* s : {"--data", "--model", "abs-nn", "--solver", "rk4", "--steps", "10", "--hidden",
                        "100", "--loss", "single", "--epochs", "--lr", "0.001", "--batch", "500",
                        "--val-fraction", "0.2", "--seed", "--out", "--json"}) {
    EXPECT_NE(r.out.find(s), std::string::npos) << s;
  }
}

TEST(TrainCommand, TrainsSavesAndEvalReadsBack) {
  const std::string csv = WriteTemp("train_eval_20.csv", Head(20));
  const std::string model = ::testing::TempDir() + "/train_eval_node.json";
  const auto train = RunDiffdyn("train --data " + csv +
                                " --model abs-node --hidden 8 --steps 3 --epochs 3 --seed 4 --quiet"
                                " --json --out " + model);
  ASSERT_EQ(train.exit_code, 0) << train.err;
  ASSERT_EQ(CountLines(train.out), 1) << train.out;
  const auto j = nlohmann::json::parse(train.out);
  EXPECT_EQ(j["model_path"], model);
  EXPECT_EQ(j["n_train"].get<int>() + j["n_val"].get<int>(), 200);
  EXPECT_EQ(j["n_val"], 40);
  EXPECT_EQ(j["epochs"], 3);
  EXPECT_GT(j["seconds_per_epoch"].get<double>(), 0.0);
  EXPECT_GT(j["final_train_loss"].get<double>(), 0.0);
  EXPECT_GT(j["final_val_loss"].get<double>(), 0.0);
  ASSERT_TRUE(std::filesystem::exists(model));

  const auto eval = RunDiffdyn("eval --model " + model + " --data " + csv + " --json");
  ASSERT_EQ(eval.exit_code, 0) << eval.err;
  const auto e = nlohmann::json::parse(eval.out);
  EXPECT_EQ(e["n_samples"], 200);
  const double single = e["single_step_loss"].get<double>();
  const double multi = e["avg_multi_step_loss"].get<double>();
  EXPECT_GT(single, 0.0);
  EXPECT_GT(multi, 0.0);
  // Train and validation losses are means over a split of the same 200 samples.
  const double train_val = (160 * j["final_train_loss"].get<double>() +
                            40 * j["final_val_loss"].get<double>()) / 200;
  EXPECT_LT(std::abs(single - train_val), 0.5 * train_val);

  // Same seed, same model file bytes.
  const std::string again = ::testing::TempDir() + "/train_eval_node_again.json";
  ASSERT_EQ(RunDiffdyn("train --data " + csv + " --model abs-node --hidden 8 --steps 3 --epochs 3"
                       " --seed 4 --quiet --threads 1 --out " + again).exit_code, 0);
  std::ifstream a(model), b(again);
  std::stringstream sa, sb;
  sa << a.rdbuf();
  sb << b.rdbuf();
  nlohmann::json ja = nlohmann::json::parse(sa.str()), jb = nlohmann::json::parse(sb.str());
  EXPECT_EQ(ja["parameters"], jb["parameters"]);
}

// --solver / --steps re-integrate a NeuralODE's weights: the model's own settings give
// the same loss to the bit, two accurate solvers agree, one Euler step does not.
TEST(EvalCommand, SolverAndStepsOverrideTheNeuralOde) {
  const std::string csv = WriteTemp("eval_solver_20.csv", Head(20));
  const std::string node = ::testing::TempDir() + "/eval_solver_node.json";
  ASSERT_EQ(RunDiffdyn("train --data " + csv + " --model abs-node --hidden 8 --steps 3 --epochs 3"
                       " --seed 2 --quiet --out " + node).exit_code, 0);
  auto eval = [&](const std::string& args) {
    const auto r = RunDiffdyn("eval --model " + node + " --data " + csv + " --json " + args);
    EXPECT_EQ(r.exit_code, 0) << args << ": " << r.err;
    return nlohmann::json::parse(r.out);
  };
  const auto own = eval("");
  EXPECT_EQ(own["solver"], "rk4");
  EXPECT_EQ(own["steps"], 3);
  const double loss = own["single_step_loss"].get<double>();
  EXPECT_EQ(eval("--solver rk4 --steps 3")["single_step_loss"].get<double>(), loss);

  const auto fine = eval("--steps 60");
  const auto adaptive = eval("--solver dopri5");
  EXPECT_EQ(fine["steps"], 60);
  EXPECT_EQ(adaptive["solver"], "dopri5");
  const double reference = adaptive["single_step_loss"].get<double>();
  EXPECT_NEAR(fine["single_step_loss"].get<double>(), reference, 1e-6 * reference);

  const auto euler = eval("--solver euler --steps 2");
  EXPECT_EQ(euler["solver"], "euler");
  EXPECT_EQ(euler["steps"], 2);
  EXPECT_GT(std::abs(euler["single_step_loss"].get<double>() - reference), 1e-6 * reference);

  // Bad values, and the options on a model without an ODE: exit 2, one line.
  const std::string nn = ::testing::TempDir() + "/eval_solver_nn.json";
  ASSERT_EQ(RunDiffdyn("train --data " + csv + " --model res-nn --hidden 8 --epochs 1 --quiet --out " +
                       nn).exit_code, 0);
  for (const auto& [model, args, fragment] : std::vector<std::tuple<std::string, std::string,
                                                                    std::string>>{
           {node, "--steps 1", "--steps"},
           {node, "--solver rk5", "--solver"},
           {nn, "--steps 4", "--steps"},
           {nn, "--solver dopri5", "--solver"}}) {
    const auto r = RunDiffdyn("eval --model " + model + " --data " + csv + " " + args);
    EXPECT_EQ(r.exit_code, 2) << args;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(fragment), std::string::npos) << r.err;
  }
}

TEST(TrainCommand, MultiStepLossUsesFourStepWindows) {
  const std::string csv = WriteTemp("train_multi_20.csv", Head(20));
  const auto r = RunDiffdyn("train --data " + csv + " --model res-nn --hidden 8 --loss multi --epochs 2"
                            " --quiet --json --out " + ::testing::TempDir() + "/train_multi.json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["n_train"].get<int>() + j["n_val"].get<int>(), 140);  // 7 windows per trajectory
}

TEST(TrainCommand, BadOptionsAreOneLineErrors) {
  const std::string csv = WriteTemp("train_opts.csv", Head(3));
  for (const auto& [args, fragment] :
       std::vector<std::pair<std::string, std::string>>{{"--model node", "--model"},
                                                        {"--solver rk5", "--solver"},
                                                        {"--steps 1", "--steps"},
                                                        {"--loss double", "--loss"}}) {
    const auto r = RunDiffdyn("train --data " + csv + " --epochs 1 --quiet " + args + " --out " +
                              ::testing::TempDir() + "/unused.json");
    EXPECT_EQ(r.exit_code, 2) << args;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(fragment), std::string::npos) << r.err;
  }
}

// Each broken file: exit 2, one line naming the file and the line number.
TEST(TrainAndEval, BadDataFilesNameFileAndLine) {
  const std::string good = Head(2);
  std::vector<std::pair<std::string, std::string>> cases;
  // Missing column (header and rows without push_length).
  {
    std::string s;
    std::istringstream in(good);
    std::string line;
    while (std::getline(in, line)) s += line.substr(0, line.rfind(',')) + "\n";
    cases.push_back({"missing_column.csv", s});
  }
  std::string nan = good;
  nan.replace(nan.find('\n', nan.find('\n') + 1) + 1, 1, "0,1,nan");  // row 2 starts "0,1,..."
  cases.push_back({"nan.csv", nan});
  std::string text = good;
  const size_t row3 = text.find("\n0,2,") + 1;
  text.replace(row3, 5, "0,2,abc");
  cases.push_back({"text.csv", text});
  std::string ragged = good;
  const size_t row4 = ragged.find("\n0,3,") + 1;
  ragged.replace(row4, 4, "0,5,");
  cases.push_back({"ragged.csv", ragged});
  const std::string model = ::testing::TempDir() + "/bad_data_model.json";
  ASSERT_EQ(RunDiffdyn("train --data " + WriteTemp("good.csv", good) +
                       " --hidden 4 --epochs 1 --quiet --out " + model).exit_code, 0);
  for (const auto& [name, contents] : cases) {
    const std::string path = WriteTemp(name, contents);
    for (const std::string& cmd : {"train --epochs 1 --quiet --out " + ::testing::TempDir() +
                                       "/unused.json --data " + path,
                                   "eval --model " + model + " --data " + path}) {
      const auto r = RunDiffdyn(cmd);
      EXPECT_EQ(r.exit_code, 2) << name << ": " << r.err;
      EXPECT_EQ(CountLines(r.err), 1) << r.err;
      EXPECT_NE(r.err.find(path + ":"), std::string::npos) << r.err;
    }
  }
  const auto missing = RunDiffdyn("eval --model " + model + " --data /nonexistent/x.csv");
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_NE(missing.err.find("/nonexistent/x.csv"), std::string::npos);
}

// `good` with field `field` of line `line` (1-based, the header is line 1) replaced;
// an empty replacement with `erase` drops the field.
std::string EditField(const std::string& good, int line, int field, const std::string& value,
                      bool erase = false) {
  std::istringstream in(good);
  std::string row, out;
  for (int number = 1; std::getline(in, row); ++number) {
    if (number == line) {
      std::vector<std::string> fields;
      std::istringstream cells(row + ",");
      std::string cell;
      while (std::getline(cells, cell, ',')) fields.push_back(cell);
      if (erase) {
        fields.erase(fields.begin() + field);
      } else {
        fields[field] = value;
      }
      row.clear();
      for (size_t i = 0; i < fields.size(); ++i) row += (i ? "," : "") + fields[i];
    }
    out += row + "\n";
  }
  return out;
}

// Every kind of bad data file, through `diffdyn train`: exit 2, one line naming the
// file and the exact line of the fault, and no model file written.
TEST(TrainCommand, BadDataFilesNameTheExactLine) {
  const std::string good = Head(2);
  struct Case {
    std::string name, contents;
    int line;
    std::string fragment;
  };
  std::string no_column;
  {
    std::istringstream in(good);
    std::string row;
    while (std::getline(in, row)) no_column += row.substr(0, row.rfind(',')) + "\n";
  }
  const std::vector<Case> cases{
      {"no_column.csv", no_column, 1, "header"},
      {"short_row.csv", EditField(good, 6, 7, "", /*erase=*/true), 6, "fields"},
      {"nan_state.csv", EditField(good, 3, 2, "nan"), 3, "not finite"},
      {"inf_action.csv", EditField(good, 4, 6, "-inf"), 4, "not finite"},
      {"huge_number.csv", EditField(good, 9, 3, "1e999"), 9, "not a number"},
      {"text_number.csv", EditField(good, 5, 3, "abc"), 5, "not a number"},
      {"text_step.csv", EditField(good, 8, 1, "two"), 8, "not an integer"},
      {"ragged_step.csv", EditField(good, 7, 1, "9"), 7, "ragged"},
      {"ragged_action.csv", EditField(good, 10, 5, ""), 10, "ragged"},
  };
  for (const Case& c : cases) {
    const std::string path = WriteTemp("exact_" + c.name, c.contents);
    const std::string model = ::testing::TempDir() + "/exact_unused_" + c.name + ".json";
    std::filesystem::remove(model);
    const auto r = RunDiffdyn("train --epochs 1 --hidden 4 --quiet --out " + model + " --data " + path);
    EXPECT_EQ(r.exit_code, 2) << c.name << ": " << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << c.name << ": " << r.err;
    EXPECT_EQ(r.err.rfind("error: ", 0), 0u) << r.err;
    EXPECT_NE(r.err.find(path + ":" + std::to_string(c.line) + ":"), std::string::npos)
        << c.name << ": " << r.err;
    EXPECT_NE(r.err.find(c.fragment), std::string::npos) << c.name << ": " << r.err;
    EXPECT_FALSE(std::filesystem::exists(model)) << c.name;
  }
}

}  // namespace
}  // namespace diffdyn
