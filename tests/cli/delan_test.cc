// diffdyn train --model delan and eval of the model file: the authors' split, the
// component keys, the rollout keys, and one-line errors for data that does not fit;
// delan-friction on the cart-pole with the pole as (sin, cos), and MPPI planning
// with the learned model through the task's actuated joint.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "run_diffdyn.h"

namespace diffdyn {
namespace {

using testing::CountLines;
using testing::RunDiffdyn;
using testing::SummaryJson;
using testing::TempPath;

const std::string kCharacters = std::string(DIFFDYN_SHARED_DATA_DIR) + "/delan_characters";

TEST(DelanCli, TrainThenEvalOnTheCharacters) {
  const std::string model = TempPath("delan_chars.json");
  const auto t =
      SummaryJson(RunDiffdyn("train --data " + kCharacters +
                             " --model delan --epochs 300 --seed 2 --quiet --json --out " + model));
  EXPECT_EQ(t.at("n_train").get<int>(), 2459);
  EXPECT_EQ(t.at("n_val").get<int>(), 454);
  EXPECT_EQ(t.at("model").get<std::string>(), "delan");
  const auto e =
      SummaryJson(RunDiffdyn("eval --model " + model + " --data " + kCharacters + " --json"));
  EXPECT_EQ(e.at("n_samples").get<int>(), 454);
  EXPECT_EQ(e.at("model").get<std::string>(), "delan");
  // 300 epochs already explain most of the torque's variance with a positive definite H.
  EXPECT_LT(e.at("torque_nmse").get<double>(), 0.05);
  EXPECT_GE(e.at("min_mass_eigenvalue").get<double>(), 0.01);
  for (const char* key : {"torque_mse", "inertial_mse", "coriolis_mse", "gravity_mse", "power_mse",
                          "inertial_nmse", "single_step_loss", "avg_multi_step_loss", "avg_10_step_loss"}) {
    ASSERT_TRUE(e.contains(key)) << key;
    EXPECT_GE(e.at(key).get<double>(), 0.0) << key;
  }
  EXPECT_NEAR(e.at("torque_mse").get<double>(), t.at("final_val_loss").get<double>(),
              1e-9 * t.at("final_val_loss").get<double>());
}

TEST(DelanCli, DataOfAnotherSizeIsOneLineError) {
  const std::string model = TempPath("delan_chars_small.json");
  SummaryJson(RunDiffdyn("train --data " + kCharacters +
                         " --model delan --epochs 1 --hidden 4 --quiet --json --out " + model));
  const std::string pendulum = TempPath("delan_pendulum.csv");
  SummaryJson(RunDiffdyn(
      "collect --system pendulum --trajectories 2 --seconds 1 --quiet --json --out " + pendulum));
  const auto r = RunDiffdyn("eval --model " + model + " --data " + pendulum + " --json");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("joints"), std::string::npos) << r.err;
  EXPECT_TRUE(r.out.empty());
}

// Data that cannot train a DeLaN: one line naming the file, exit 2, nothing written.
TEST(DelanCli, DataWithoutJointsOrTorquesIsRefused) {
  const std::string out = TempPath("delan_refused.json");
  std::filesystem::remove(out);
  for (const std::string& data : {std::string(DIFFDYN_SHARED_DATA_DIR) + "/pybullet_pushing/collected_data.csv",
                                 std::string(DIFFDYN_SHARED_DATA_DIR) + "/ibm_double_pendulum"}) {
    const auto r = RunDiffdyn("train --data " + data + " --model delan --epochs 1 --quiet --out " + out);
    EXPECT_EQ(r.exit_code, 2) << data;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_EQ(r.err.rfind("error: ", 0), 0u) << r.err;
    EXPECT_FALSE(std::filesystem::exists(out));
  }
}

// Without a qdd column the accelerations are estimated (10 Hz smoothing) and training runs.
TEST(DelanCli, EstimatesAccelerationsWhenTheDataHasNone) {
  const std::string with = TempPath("delan_pend_qdd.csv"), without = TempPath("delan_pend_noqdd.csv");
  SummaryJson(RunDiffdyn(
      "collect --system pendulum --trajectories 6 --seconds 5 --seed 5 --quiet --json --out " +
      with));
  // Drop the qdd1 column.
  std::ifstream in(with);
  std::ofstream out(without);
  int drop = -1;
  for (std::string line; std::getline(in, line);) {
    std::vector<std::string> cells;
    std::stringstream ss(line);
    for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
    if (drop < 0) drop = static_cast<int>(std::find(cells.begin(), cells.end(), "qdd1") - cells.begin());
    ASSERT_LT(drop, static_cast<int>(cells.size()));
    for (size_t i = 0, k = 0; i < cells.size(); ++i) {
      if (static_cast<int>(i) == drop) continue;
      out << (k++ ? "," : "") << cells[i];
    }
    out << '\n';
  }
  out.close();
  const std::string model = TempPath("delan_pend_noqdd.json");
  const auto t = SummaryJson(RunDiffdyn("train --data " + without +
                                        " --model delan --epochs 5 --hidden 8 --seed 1 "
                                        "--quiet --json --out " +
                                        model));
  EXPECT_GT(t.at("n_train").get<int>(), 0);
  EXPECT_TRUE(std::isfinite(t.at("final_val_loss").get<double>()));
}

// A friction DeLaN on fully actuated cart-pole data: friction keys, learned
// coefficients >= 0, a periodic pole in the file; MPPI plans with it on the task
// (one actuated joint of two); an unknown --prismatic joint is refused.
TEST(DelanCli, FrictionModelOnTheCartpoleTrainsEvaluatesAndControls) {
  const std::string data = TempPath("delan_cartpole_all.csv"), model = TempPath("delan_cartpole.json");
  SummaryJson(RunDiffdyn(
      "collect --system cartpole --actuated all --trajectories 6 --seconds 2 --seed 3 --quiet "
      "--json --out " +
      data));
  const auto t = SummaryJson(
      RunDiffdyn("train --data " + data +
                 " --model delan-friction --prismatic 1 "
                 "--angle-features sincos --epochs 40 --hidden 16 --seed 1 --quiet --json --out " +
                 model));
  EXPECT_EQ(t.at("model").get<std::string>(), "delan-friction");
  std::ifstream file(model);
  const nlohmann::json j = nlohmann::json::parse(file);
  EXPECT_EQ(j.at("kind").get<std::string>(), "delan-friction");
  EXPECT_EQ(j.at("architecture").at("periodic"), nlohmann::json::array({1}));
  const auto e = SummaryJson(RunDiffdyn("eval --model " + model + " --data " + data + " --json"));
  EXPECT_EQ(e.at("model").get<std::string>(), "delan-friction");
  for (const char* key : {"friction_nmse", "kinetic_nmse", "potential_nmse", "power_nmse", "viscous_1",
                          "viscous_2", "coulomb_1", "coulomb_2", "single_step_loss"}) {
    ASSERT_TRUE(e.contains(key)) << key;
    EXPECT_GE(e.at(key).get<double>(), 0.0) << key;
  }
  const auto c =
      SummaryJson(RunDiffdyn("control --system cartpole --controller mppi --model " + model +
                             " --starts 1 --samples 16 --horizon 0.2 --seed 1 --json"));
  EXPECT_EQ(c.at("starts").get<int>(), 1);
  const auto r = RunDiffdyn("train --data " + data + " --model delan --prismatic 3 --angle-features sincos "
                            "--epochs 1 --quiet --out " + TempPath("delan_bad_prismatic.json"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("--prismatic"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace diffdyn
