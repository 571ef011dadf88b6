// Joint-space data end to end: collect --system, train and eval on it (abs-node and
// res-node), eval of diagnose's extended model on the real Panda log, train on the
// real log, and one-line errors (exit 2) for options that do not fit the system.
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "diffdyn/solvers/dataset_io.h"
#include "run_diffdyn.h"

namespace diffdyn {
namespace {

using testing::CountLines;
using testing::RunDiffdyn;
using testing::SummaryJson;
using testing::TempPath;

const std::string kPanda = std::string(DIFFDYN_SHARED_DATA_DIR) + "/panda_gaz2019_traj1";

// A small pendulum NeuralODE learns the dynamics: its single-step loss on a fresh
// seeded file is a small fraction of the "state stays" baseline.
TEST(JointSpace, CollectTrainEvalPendulum) {
  const std::string train = TempPath("js_pendulum_train.csv"), test = TempPath("js_pendulum_test.csv");
  const auto c = SummaryJson(RunDiffdyn(
      "collect --system pendulum --trajectories 20 --seconds 2 --seed 3 --quiet --json --out " +
      train));
  EXPECT_EQ(c.at("trajectories").get<int>(), 20);
  EXPECT_EQ(c.at("pushes").get<int>(), 1000);
  EXPECT_GT(c.at("samples_per_second").get<double>(), 0.0);
  SummaryJson(RunDiffdyn(
      "collect --system pendulum --trajectories 5 --seconds 2 --seed 4 --quiet --json --out " +
      test));
  const std::string model = TempPath("js_pendulum.json");
  const auto t = SummaryJson(RunDiffdyn("train --data " + train +
                                        " --model abs-node --hidden 16 --steps 3 --epochs 30 "
                                        "--lr 3e-3 --batch 100 --seed 1 --quiet --json --out " +
                                        model));
  EXPECT_EQ(t.at("n_train").get<int>() + t.at("n_val").get<int>(), 1000);
  EXPECT_NEAR(t.at("dt").get<double>(), 0.04, 1e-12);
  const auto e = SummaryJson(RunDiffdyn("eval --model " + model + " --data " + test + " --json"));
  EXPECT_EQ(e.at("n_samples").get<int>(), 250);
  const double loss = e.at("single_step_loss").get<double>();
  const double baseline = e.at("baseline_single_step_loss").get<double>();
  EXPECT_GT(baseline, 0.05);
  EXPECT_LT(loss, 0.03 * baseline);
  // The analytic model of other parameters (the model's own defaults) is worse
  // than the learned one but far better than the baseline.
  const auto analytic = SummaryJson(RunDiffdyn("eval --model pendulum --data " + test + " --json"));
  EXPECT_LT(analytic.at("single_step_loss").get<double>(), baseline);
}

// The residual NeuralODE learns the pendulum from its flow started at the wrapped
// angle (learned_model.h): raw angle features by default, recorded in the model file;
// asking it for (sin, cos) features is a one-line error and writes nothing.
TEST(JointSpace, ResidualNodeOnTheCircle) {
  const std::string train = TempPath("js_res_train.csv"), test = TempPath("js_res_test.csv");
  SummaryJson(RunDiffdyn(
      "collect --system pendulum --trajectories 20 --seconds 2 --seed 5 --quiet --json --out " +
      train));
  SummaryJson(RunDiffdyn(
      "collect --system pendulum --trajectories 5 --seconds 2 --seed 6 --quiet --json --out " +
      test));
  const std::string model = TempPath("js_res_node.json");
  SummaryJson(RunDiffdyn(
      "train --data " + train +
      " --model res-node --hidden 32 --steps 3 --epochs 300 --lr 3e-3 --batch 100 --seed 1 "
      "--quiet --json --out " +
      model));
  std::ifstream file(model);
  const nlohmann::json j = nlohmann::json::parse(file);
  EXPECT_EQ(j.at("system").at("angle_features"), "raw") << j.at("system").dump();
  const auto e = SummaryJson(RunDiffdyn("eval --model " + model + " --data " + test + " --json"));
  EXPECT_LT(e.at("single_step_loss").get<double>(),
            0.1 * e.at("baseline_single_step_loss").get<double>());

  const std::string refused = TempPath("js_res_sincos.json");
  const auto r = RunDiffdyn("train --data " + train +
                            " --model res-node --angle-features sincos --quiet --out " + refused);
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("--angle-features"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(refused));
}

// The extended model diagnose writes for the real Panda log predicts the log's
// transitions (each over its own dt) better than the nominal model.
TEST(JointSpace, EvalTakesDiagnosesExtendedModelOnThePandaLog) {
  const std::string out = TempPath("js_panda_diagnosis");
  ASSERT_EQ(
      RunDiffdyn("diagnose --model panda --measured " + kPanda + " --quiet --out " + out).exit_code,
      0);
  // The first 3000 samples (3 s) keep the test short.
  Dataset log = ReadDataset(kPanda);
  const int keep = 3000;
  Trajectory& run = log.trajectories.at(0);
  run.t.conservativeResize(keep);
  run.states.conservativeResize(Eigen::NoChange, keep);
  run.actions.conservativeResize(Eigen::NoChange, keep - 1);
  run.channels.at("tau").conservativeResize(Eigen::NoChange, keep);
  const std::string head = TempPath("js_panda_head.csv");
  WriteDataset(head, log);
  const auto extended = SummaryJson(
      RunDiffdyn("eval --model " + out + "/extended_model.json --data " + head + " --json"));
  const auto nominal = SummaryJson(RunDiffdyn("eval --model panda --data " + head + " --json"));
  EXPECT_EQ(extended.at("n_samples").get<int>(), keep - 1);
  EXPECT_EQ(extended.at("model").get<std::string>(), "extended-physics");
  EXPECT_GT(extended.at("dt_jitter").get<double>(), 1.0);
  EXPECT_LT(extended.at("single_step_loss").get<double>(), 0.5 * nominal.at("single_step_loss").get<double>());
}

TEST(JointSpace, TrainOnTheRealPandaLogReportsFiniteLosses) {
  const auto t = SummaryJson(RunDiffdyn(
      "train --data " + kPanda + " --model res-nn --hidden 16 --epochs 2 --quiet --json --out " +
      TempPath("js_panda_resnn.json")));
  EXPECT_EQ(t.at("n_train").get<int>() + t.at("n_val").get<int>(), 20543);
  EXPECT_TRUE(t.at("final_val_loss").is_number());
  EXPECT_GT(t.at("dt_jitter").get<double>(), 1.0);
}

TEST(JointSpace, OptionsThatDoNotFitTheSystemAreOneLineErrors) {
  const std::string out = TempPath("js_bad.csv");
  for (const auto& [args, fragment] : std::vector<std::pair<std::string, std::string>>{
           {"--system robot", "--system"},
           {"--system pendulum --length 3", "--length"},
           {"--dt 0.01", "--dt"},
           {"--system pendulum --effect viscous:3=0.1", "--effect"},
           {"--system pendulum --effect viscous:1", "--effect"},
           {"--system pendulum --dt 0", "--dt"},
           {"--system pendulum --seconds 0.01", "--seconds"},
           {"--system pendulum --actuated some", "--actuated"}}) {
    const auto r = RunDiffdyn("collect " + args + " --quiet --out " + out);
    EXPECT_EQ(r.exit_code, 2) << args << ": " << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(fragment), std::string::npos) << args << ": " << r.err;
  }
  const auto r = RunDiffdyn("train --data " + kPanda + " --actuated 9 --quiet --out " + TempPath("js_bad.json"));
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("joint 9"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace diffdyn
