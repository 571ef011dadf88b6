// diffdyn push: the JSON keys of DESIGN.md, the trials CSV and top view, the same
// bytes at any thread count, and one-line exit-2 errors naming the option or file.
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "run_diffdyn.h"

namespace {

using diffdyn::testing::CountLines;
using diffdyn::testing::ReadAll;
using diffdyn::testing::RunDiffdyn;
using diffdyn::testing::TempPath;

// The ODE world itself as the model, tiny MPPI: a few dozen simulated pushes.
const char* kTinyOracle =
    "push --model oracle --trials 2 --samples 6 --horizon 1 --max-steps 2 --seed 3 --quiet ";

TEST(PushCommand, TinyOracleRunWritesJsonKeysCsvAndTopView) {
  const std::string dir = TempPath("push_tiny");
  const auto r = RunDiffdyn(std::string(kTinyOracle) + "--json --out " + dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(CountLines(r.out), 1) << r.out;
  const auto s = nlohmann::json::parse(r.out);
  for (const char* key : {"trials", "successes", "success_rate", "ci95_low", "ci95_high",
                          "mean_pushes", "ms_per_command"}) {
    EXPECT_TRUE(s.contains(key)) << key << " missing from " << r.out;
  }
  EXPECT_EQ(s.at("trials").get<int>(), 2);
  const int successes = s.at("successes").get<int>();
  EXPECT_GE(successes, 0);
  EXPECT_LE(successes, 2);
  EXPECT_DOUBLE_EQ(s.at("success_rate").get<double>(), successes / 2.0);
  EXPECT_LE(s.at("ci95_low").get<double>(), s.at("success_rate").get<double>());
  EXPECT_GE(s.at("ci95_high").get<double>(), s.at("success_rate").get<double>());
  const double pushes = s.at("mean_pushes").get<double>();
  EXPECT_GE(pushes, 1.0);
  EXPECT_LE(pushes, 2.0);
  EXPECT_GT(s.at("ms_per_command").get<double>(), 0.0);

  // One row per pose: 2 trials x (pushes + 1), the header first.
  const std::string csv = ReadAll(dir + "/trials.csv");
  EXPECT_EQ(csv.rfind("trial,step,x,y,theta,push_location,push_angle,push_length,outcome,"
                      "pred_x,pred_y,pred_theta\n",
                      0),
            0u)
      << csv;
  EXPECT_EQ(CountLines(csv), 1 + static_cast<int>(2 * pushes + 2 + 0.5)) << csv;
  EXPECT_TRUE(std::filesystem::exists(dir + "/top_view.png"));
  EXPECT_EQ(s.at("top_view").get<std::string>(), dir + "/top_view.png");
}

TEST(PushCommand, SameBytesAtOneAndTwoThreads) {
  const std::string one = TempPath("push_one"), two = TempPath("push_two");
  ASSERT_EQ(RunDiffdyn(std::string(kTinyOracle) + "--threads 1 --out " + one).exit_code, 0);
  const auto r = RunDiffdyn(std::string(kTinyOracle) + "--threads 2 --out " + two);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("success"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("95 %"), std::string::npos) << r.out;
  const std::string a = ReadAll(one + "/trials.csv");
  EXPECT_FALSE(a.empty());
  EXPECT_EQ(a, ReadAll(two + "/trials.csv"));
}

TEST(PushCommand, BadInputsAreOneLineErrorsWithExitCode2) {
  struct Case {
    std::string args, names;
  };
  const std::string bad_model = TempPath("push_bad_model.json");
  std::ofstream(bad_model) << "{ not json";
  const Case cases[] = {
      {"push --model " + TempPath("no_such_model.json"), "--model"},
      {"push --model " + bad_model, bad_model},
      {"push", "--model"},
      {"push --model oracle --no-such-flag", "--no-such-flag"},
      {"push --model oracle --samples 0", "--samples"},
      {"push --model oracle --trials 0", "--trials"},
      {"push --model oracle --max-steps 0", "--max-steps"},
      {"push --model oracle --fallback-margin -1", "--fallback-margin"},
  };
  for (const Case& c : cases) {
    const auto r = RunDiffdyn(c.args);
    EXPECT_EQ(r.exit_code, 2) << c.args << "\n" << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << c.args << "\n" << r.err;
    EXPECT_EQ(r.err.rfind("error: ", 0), 0u) << r.err;
    EXPECT_NE(r.err.find(c.names), std::string::npos) << c.args << "\n" << r.err;
  }
}

}  // namespace
