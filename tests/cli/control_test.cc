// diffdyn control: the JSON keys and files of DESIGN.md, a learned model whose
// step is its data's interval, and one-line errors (exit 2) with nothing written.
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "run_diffdyn.h"

namespace diffdyn {
namespace {

using testing::CountLines;
using testing::RunDiffdyn;
using testing::TempPath;

TEST(Control, PendulumMppiWritesTheContractsKeysAndFiles) {
  const std::string out = TempPath("control_pendulum");
  std::filesystem::remove_all(out);
  const auto r = RunDiffdyn("control --system pendulum --controller mppi --starts 2 --samples 300 --seed 3 --quiet "
                            "--json --out " + out);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ASSERT_EQ(CountLines(r.out), 1) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  for (const char* key : {"system", "controller", "starts", "successes", "success_rate", "ci95_low", "ci95_high",
                          "mean_cost", "median_cost", "p90_cost", "max_abs_u", "ms_per_command"}) {
    EXPECT_TRUE(j.contains(key)) << key;
  }
  EXPECT_TRUE(j["starts"].is_number_integer());
  EXPECT_TRUE(j["successes"].is_number_integer());
  EXPECT_EQ(j["starts"].get<int>(), 2);
  EXPECT_LE(j["max_abs_u"].get<double>(), 2.5);
  EXPECT_LE(j["ci95_low"].get<double>(), j["success_rate"].get<double>());
  std::ifstream starts(out + "/starts.csv");
  std::string header;
  std::getline(starts, header);
  EXPECT_EQ(header, "start,x0_1,x0_2,success,cost,max_abs_u,seconds");
  EXPECT_EQ(CountLines(std::string(std::istreambuf_iterator<char>(starts), {})), 2);
  EXPECT_TRUE(std::filesystem::is_regular_file(out + "/trajectories/start_1.csv"));
}

TEST(Control, PlansWithALearnedModelAtItsDataInterval) {
  const std::string data = TempPath("control_pendulum_data.csv"), model = TempPath("control_pendulum_model.json");
  ASSERT_EQ(RunDiffdyn("collect --system pendulum --trajectories 4 --seconds 1 --seed 1 --quiet --out " + data).exit_code, 0);
  ASSERT_EQ(RunDiffdyn("train --data " + data + " --model abs-nn --hidden 8 --epochs 1 --quiet --out " + model).exit_code, 0);
  const auto r = RunDiffdyn("control --system pendulum --model " + model + " --starts 1 --samples 50 --quiet --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out)["hold"].get<int>(), 5);  // 40 ms = 5 periods
}

TEST(Control, PushingIsATaskOfTheSameEvaluator) {
  const std::string out = TempPath("control_pushing");
  std::filesystem::remove_all(out);
  const auto r = RunDiffdyn("control --system pushing --starts 1 --samples 4 --seed 3 --quiet --json --out " + out);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["system"], "pushing");
  EXPECT_EQ(j["model_kind"], "oracle");
  EXPECT_EQ(j["starts"].get<int>(), 1);
  EXPECT_GE(j["mean_cost"].get<double>(), 0.0);
  std::ifstream starts(out + "/starts.csv");
  std::string header;
  std::getline(starts, header);
  EXPECT_EQ(header, "start,x0_1,x0_2,x0_3,success,cost,max_abs_u,seconds");
  std::ifstream trajectory(out + "/trajectories/start_0.csv");
  std::getline(trajectory, header);
  EXPECT_EQ(header.substr(0, 9), "t,x,y,the") << header;
}

TEST(Control, BadOptionsAreOneLineErrorsAndWriteNothing) {
  const std::string out = TempPath("control_bad");
  for (const auto& [args, fragment] : std::vector<std::pair<std::string, std::string>>{
           {"--system robot", "--system"},
           {"--system pushing --controller lqr", "--controller"},
           {"--dt 0.01", "--dt"},
           {"--dt -1", "--dt"},
           {"--starts 0", "--starts"},
           {"--samples 0", "--samples"},
           {"--horizon 0", "--horizon"},
           {"--lambda nan", "--lambda"},
           {"--controller pid", "--controller"},
           {"--model cartpole", "--model"},
           {"--model /no/such/model.json", "--model"}}) {
    std::filesystem::remove_all(out);
    const std::string starts = args.find("--starts") == std::string::npos ? " --starts 1" : "";
    const auto r = RunDiffdyn("control " + args + starts + " --quiet --out " + out);
    EXPECT_EQ(r.exit_code, 2) << args << ": " << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(fragment), std::string::npos) << args << ": " << r.err;
    EXPECT_FALSE(std::filesystem::exists(out)) << args;
  }
}

// The clipped LQR: the contract's keys plus the Riccati residual; it takes no --model.
TEST(Control, LqrReportsItsRiccatiResidualAndRefusesAModel) {
  const auto r = RunDiffdyn("control --system pendulum --controller lqr --starts 3 --seed 2 --quiet --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["controller"].get<std::string>(), "lqr");
  EXPECT_EQ(j["starts"].get<int>(), 3);
  EXPECT_LT(j["riccati_residual"].get<double>(), 1e-9);
  EXPECT_LE(j["max_abs_u"].get<double>(), 2.5);
  const auto bad = RunDiffdyn("control --system pendulum --controller lqr --model cartpole --starts 3 --quiet");
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_EQ(CountLines(bad.err), 1) << bad.err;
  EXPECT_NE(bad.err.find("--model"), std::string::npos) << bad.err;
}

// One start with few iterations: the keys, the bound and the refusals (the 300-start
// acceptance run is in README.md).
TEST(Control, ShootingReportsDefectsAndRefusesBadOptions) {
  const auto r = RunDiffdyn(
      "control --system pendulum --controller shooting --starts 1 --seed 2 --iterations 5 --quiet --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["controller"].get<std::string>(), "shooting");
  EXPECT_LE(j["max_abs_u"].get<double>(), 2.5);
  EXPECT_LT(j["max_defect"].get<double>(), 1e-9);
  EXPECT_GE(j["max_shooting_defect"].get<double>(), 0.0);
  EXPECT_GT(j["iterations"].get<int>(), 0);
  EXPECT_GT(j["seconds_per_start"].get<double>(), 0.0);
  for (const char* bad_options : {"--model cartpole", "--iterations 0", "--iterations x"}) {
    const auto bad = RunDiffdyn(std::string("control --system pendulum --controller shooting --starts 1 --quiet ") +
                                bad_options);
    EXPECT_EQ(bad.exit_code, 2) << bad_options;
    EXPECT_EQ(CountLines(bad.err), 1) << bad.err;
  }
}

}  // namespace
}  // namespace diffdyn
