// diffdyn train --model delan and eval of the model file: the authors' split, the
// component keys, the rollout keys, and one-line errors for data that does not fit.
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "run_diffdyn.h"

namespace diffdyn {
namespace {

using testing::CountLines;
using testing::RunDiffdyn;
using testing::TempPath;

const std::string kCharacters = std::string(DIFFDYN_SHARED_DATA_DIR) + "/delan_characters";

nlohmann::json Json(const testing::CommandResult& r) {
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(CountLines(r.out), 1) << r.out;
  return nlohmann::json::parse(r.out);
}

TEST(DelanCli, TrainThenEvalOnTheCharacters) {
  const std::string model = TempPath("delan_chars.json");
  const auto t = Json(RunDiffdyn("train --data " + kCharacters +
                                 " --model delan --epochs 300 --seed 2 --quiet --json --out " + model));
  EXPECT_EQ(t.at("n_train").get<int>(), 2459);
  EXPECT_EQ(t.at("n_val").get<int>(), 454);
  EXPECT_EQ(t.at("model").get<std::string>(), "delan");
  const auto e = Json(RunDiffdyn("eval --model " + model + " --data " + kCharacters + " --json"));
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
  Json(RunDiffdyn("train --data " + kCharacters + " --model delan --epochs 1 --hidden 4 --quiet --json --out " +
                  model));
  const std::string pendulum = TempPath("delan_pendulum.csv");
  Json(RunDiffdyn("collect --system pendulum --trajectories 2 --seconds 1 --quiet --json --out " + pendulum));
  const auto r = RunDiffdyn("eval --model " + model + " --data " + pendulum + " --json");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("joints"), std::string::npos) << r.err;
  EXPECT_TRUE(r.out.empty());
}

}  // namespace
}  // namespace diffdyn
