// diffdyn hjb: the contract's keys, a value file that control --controller hjb reads,
// per-stage progress, and one-line refusals (exit 2) that write nothing.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "run_diffdyn.h"

namespace diffdyn {
namespace {

using testing::CountLines;
using testing::RunDiffdyn;
using testing::TempPath;

constexpr const char* kSmall = "--stages 2 --polish-stages 0 --samples 500 --epochs 2 --hidden 8 --rho-start 1 "
                               "--rho-final 0.5 --rollout-stages 0 --seed 2 ";

TEST(Hjb, WritesAValueFileThatControlUses) {
  const std::string value = TempPath("hjb_value.json");
  std::filesystem::remove(value);
  const auto r = RunDiffdyn(std::string("hjb --system pendulum --json --out ") + value + " " + kSmall);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ASSERT_EQ(CountLines(r.out), 1) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  for (const char* key : {"model_path", "stages", "rho_final", "seconds", "final_residual"}) {
    EXPECT_TRUE(j.contains(key)) << key;
  }
  EXPECT_EQ(j["stages"].get<int>(), 2);
  EXPECT_DOUBLE_EQ(j["rho_final"].get<double>(), 0.5);
  EXPECT_GT(j["final_residual"].get<double>(), 0.0);
  EXPECT_EQ(CountLines(r.err), 2) << r.err;  // one progress line per stage
  ASSERT_TRUE(std::filesystem::exists(value));

  const auto c = RunDiffdyn("control --system pendulum --controller hjb --starts 3 --seed 1 --quiet --json --model " +
                            value);
  ASSERT_EQ(c.exit_code, 0) << c.err;
  const nlohmann::json cj = nlohmann::json::parse(c.out);
  EXPECT_EQ(cj["controller"].get<std::string>(), "hjb");
  EXPECT_EQ(cj["model_kind"].get<std::string>(), "value");
  EXPECT_EQ(cj["starts"].get<int>(), 3);
  EXPECT_LT(cj["max_abs_u"].get<double>(), 2.5);

  // The value function belongs to the pendulum task; hjb needs --model.
  for (const std::string& bad : {"--system cartpole --model " + value, std::string("--system pendulum"),
                                 std::string("--system pendulum --model pendulum")}) {
    const auto b = RunDiffdyn("control --controller hjb --starts 1 --quiet " + bad);
    EXPECT_EQ(b.exit_code, 2) << bad;
    EXPECT_EQ(CountLines(b.err), 1) << b.err;
  }
}

// Goal anchors change the training (a different residual, a different file) and
// keep its report.
TEST(Hjb, GoalAnchorsEnterTheTraining) {
  const std::string plain = TempPath("hjb_plain.json"), anchored = TempPath("hjb_anchored.json");
  const auto p = RunDiffdyn(std::string("hjb --quiet --json --out ") + plain + " " + kSmall);
  const auto a = RunDiffdyn(std::string("hjb --quiet --json --goal-anchor 5 --out ") + anchored + " " + kSmall);
  ASSERT_EQ(p.exit_code, 0) << p.err;
  ASSERT_EQ(a.exit_code, 0) << a.err;
  const double rp = nlohmann::json::parse(p.out)["final_residual"].get<double>();
  const double ra = nlohmann::json::parse(a.out)["final_residual"].get<double>();
  EXPECT_TRUE(std::isfinite(ra));
  EXPECT_NE(rp, ra);
}

// Rollout stages run after the homotopy (one progress line each, counted in "stages")
// and change the value function.
TEST(Hjb, RolloutStagesEnterTheTraining) {
  const std::string plain = TempPath("hjb_plain2.json"), rolled = TempPath("hjb_rolled.json");
  const auto p = RunDiffdyn(std::string("hjb --quiet --json --out ") + plain + " " + kSmall);
  std::string small = kSmall;
  small.replace(small.find("--rollout-stages 0"), 18, "--rollout-stages 1");
  const auto r = RunDiffdyn(std::string("hjb --json --out ") + rolled + " " + small +
                            "--rollout-starts 2 --rollout-epochs 1 --rollout-lr 1e-3");
  ASSERT_EQ(p.exit_code, 0) << p.err;
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["stages"].get<int>(), 3);
  EXPECT_EQ(CountLines(r.err), 3) << r.err;
  EXPECT_NE(nlohmann::json::parse(p.out)["final_residual"].get<double>(), j["final_residual"].get<double>());
}

TEST(Hjb, RefusesBadOptionsAndWritesNothing) {
  const std::string value = TempPath("hjb_refused.json");
  std::filesystem::remove(value);
  for (const char* bad : {"--system pushing", "--rho-final 2 --rho-start 1", "--stages 0", "--samples 1",
                          "--epochs nan", "--hidden 0", "--layers 17", "--lr -1", "--goal-anchor -1",
                          "--goal-anchor inf", "--rollout-stages -1", "--rollout-starts 0", "--rollout-weight nan",
                          "--rollout-epochs 0", "--rollout-lr 0"}) {
    const auto r = RunDiffdyn(std::string("hjb --quiet --samples 50 --epochs 1 --out ") + value + " " + bad);
    EXPECT_EQ(r.exit_code, 2) << bad << ": " << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_FALSE(std::filesystem::exists(value)) << bad;
  }
  const auto missing = RunDiffdyn("hjb --quiet --system pendulum");
  EXPECT_EQ(missing.exit_code, 2);
}

}  // namespace
}  // namespace diffdyn
