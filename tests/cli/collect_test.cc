// diffdyn collect: the JSON summary, byte-identical output at 1 and 2 threads,
// and one-line errors with exit code 2 that name the bad option.
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "diffdyn/physics/pushing/csv.h"
#include "run_diffdyn.h"

namespace {

using diffdyn::testing::CountLines;
using diffdyn::testing::ReadAll;
using diffdyn::testing::RunDiffdyn;
using diffdyn::testing::TempPath;

TEST(CollectCommand, JsonSummaryAndIdenticalBytesAtOneAndTwoThreads) {
  const std::string one = TempPath("collect_one.csv"), two = TempPath("collect_two.csv");
  const std::string common = " --trajectories 3 --length 3 --seed 5 --quiet --json --out ";
  const auto r1 = RunDiffdyn("collect --threads 1" + common + one);
  ASSERT_EQ(r1.exit_code, 0) << r1.err;
  EXPECT_EQ(CountLines(r1.out), 1) << r1.out;
  const auto summary = nlohmann::json::parse(r1.out);
  EXPECT_EQ(summary.at("path").get<std::string>(), one);
  EXPECT_EQ(summary.at("trajectories").get<int>(), 3);
  const int pushes = summary.at("pushes").get<int>();
  EXPECT_GE(pushes, 1);
  EXPECT_LE(pushes, 9);
  EXPECT_GT(summary.at("seconds").get<double>(), 0.0);
  EXPECT_NEAR(summary.at("pushes_per_second").get<double>(),
              pushes / summary.at("seconds").get<double>(), 1e-6);

  const auto data = diffdyn::ReadPushingCsv(one);
  ASSERT_EQ(data.size(), 3u);
  for (const auto& t : data) EXPECT_EQ(t.states.cols(), t.actions.cols() + 1);

  const auto r2 = RunDiffdyn("collect --threads 2" + common + two);
  ASSERT_EQ(r2.exit_code, 0) << r2.err;
  EXPECT_EQ(ReadAll(one), ReadAll(two));
}

TEST(CollectCommand, BadOptionsAreOneLineErrorsWithExitCode2) {
  const std::string out = TempPath("collect_bad.csv");
  std::filesystem::remove(out);
  struct Case {
    std::string args, names;
  };
  for (const Case& c : {Case{"--starts nowhere --out " + out, "--starts"},
                        Case{"--trajectories 0 --out " + out, "--trajectories"},
                        Case{"--length -1 --out " + out, "--length"},
                        Case{"--threads 0 --out " + out, "--threads"},
                        Case{"--out /nonexistent_dir/pushes.csv", "--out"},
                        Case{"--trajectories 2", "--out"}}) {
    const auto r = RunDiffdyn("collect --quiet " + c.args);
    EXPECT_EQ(r.exit_code, 2) << c.args;
    EXPECT_EQ(CountLines(r.err), 1) << c.args << ": " << r.err;
    EXPECT_EQ(r.err.rfind("error: ", 0), 0u) << r.err;
    EXPECT_NE(r.err.find(c.names), std::string::npos) << c.args << ": " << r.err;
  }
  EXPECT_FALSE(std::filesystem::exists(out));  // nothing written half-way
}

}  // namespace
