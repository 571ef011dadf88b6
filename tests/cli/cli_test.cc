// The command line's conventions: exit codes, one-line errors, --help, --json.
#include <cmath>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "diffdyn/solvers/version.h"
#include "run_diffdyn.h"

namespace {

using diffdyn::testing::CountLines;
using diffdyn::testing::ReadAll;
using diffdyn::testing::RunDiffdyn;
using Result = diffdyn::testing::CommandResult;

TEST(Cli, UnknownCommandIsOneLineErrorWithExitCode2) {
  const Result r = RunDiffdyn("frobnicate");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_EQ(r.err.rfind("error: ", 0), 0u) << r.err;
  EXPECT_NE(r.err.find("frobnicate"), std::string::npos) << r.err;
  EXPECT_TRUE(r.out.empty());
}

TEST(Cli, UnknownFlagIsOneLineErrorWithExitCode2) {
  const Result r = RunDiffdyn("demo --no-such-flag");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_EQ(r.err.rfind("error: ", 0), 0u) << r.err;
  EXPECT_NE(r.err.find("--no-such-flag"), std::string::npos) << r.err;
}

TEST(Cli, BadOptionValueIsExitCode2) {
  const Result r = RunDiffdyn("info --seed notanumber");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("--seed"), std::string::npos) << r.err;
}

TEST(Cli, NoCommandIsExitCode2) {
  const Result r = RunDiffdyn("");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
}

TEST(Cli, HelpListsTheCommandsThatExist) {
  const Result r = RunDiffdyn("--help");
  EXPECT_EQ(r.exit_code, 0);
  for (const char* command : {"demo", "info"}) {
    EXPECT_NE(r.out.find(command), std::string::npos) << command << " missing from\n" << r.out;
  }
}

TEST(Cli, SubcommandHelpPrintsDefaults) {
  const Result r = RunDiffdyn("info --help");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.out.find("--seed"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("--json"), std::string::npos) << r.out;
}

TEST(Cli, VersionMatchesLibrary) {
  const Result r = RunDiffdyn("--version");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.out.find(diffdyn::Version()), std::string::npos) << r.out;
}

TEST(Cli, JsonSummaryIsOneLineObject) {
  const Result r = RunDiffdyn("info --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(CountLines(r.out), 1) << r.out;
  const auto summary = nlohmann::json::parse(r.out);
  ASSERT_TRUE(summary.is_object());
  EXPECT_TRUE(summary.at("ode_double_precision").get<bool>());
  EXPECT_EQ(summary.at("version").get<std::string>(), diffdyn::Version());
}

}  // namespace

namespace {

TEST(Demo, QuickRunExercisesEveryStageAndWritesItsReport) {
  const std::string out = testing::TempDir() + "/demo_quick";
  const Result r = RunDiffdyn("demo --quick --json --seed 4 --out " + out);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(CountLines(r.out), 1) << r.out;
  const auto summary = nlohmann::json::parse(r.out);
  // Stage 1: the quick run's 24 trajectories of up to 5 pushes.
  const auto& collect = summary.at("collect");
  EXPECT_EQ(collect.at("trajectories").get<int>(), 24);
  EXPECT_GE(collect.at("pushes").get<int>(), 24);
  EXPECT_LE(collect.at("pushes").get<int>(), 120);
  // Stage 2: a trained model with finite losses, split 80/20.
  const auto& train = summary.at("train");
  EXPECT_TRUE(std::isfinite(train.at("final_train_loss").get<double>()));
  EXPECT_TRUE(std::isfinite(train.at("final_val_loss").get<double>()));
  // Every transition of the written data is used; `pushes` also counts the pushes
  // found unreachable, which end a trajectory without a row (how many depends on
  // the instruction set's rounding near the arm's reach).
  std::ifstream csv(out + "/pushes.csv");
  std::string line;
  std::getline(csv, line);  // header
  int transitions = 0;
  while (std::getline(csv, line)) {
    std::stringstream row(line);
    std::string field;
    for (int k = 0; k < 6; ++k) std::getline(row, field, ',');  // push_location
    transitions += field.empty() ? 0 : 1;
  }
  EXPECT_EQ(train.at("n_train").get<int>() + train.at("n_val").get<int>(), transitions);
  EXPECT_LE(transitions, collect.at("pushes").get<int>());
  // Stage 3: one trial, the push keys of DESIGN.md.
  const auto& push = summary.at("push");
  EXPECT_EQ(push.at("trials").get<int>(), 1);
  for (const char* key : {"successes", "success_rate", "ci95_low", "ci95_high", "mean_pushes",
                          "ms_per_command"}) {
    EXPECT_TRUE(push.contains(key)) << key;
  }
  EXPECT_GE(push.at("mean_pushes").get<double>(), 1.0);
  // Three stages: the pendulum identification is examples/identify_through_integrator.cc.
  EXPECT_FALSE(summary.contains("pendulum_fit"));
  for (const char* file : {"report.md", "pushes.csv", "abs-node.json", "training.csv",
                           "push/trials.csv"}) {
    FILE* f = fopen((out + "/" + file).c_str(), "r");
    EXPECT_NE(f, nullptr) << file;
    if (f != nullptr) fclose(f);
  }
  // The report names every stage, with a command that redoes it.
  const std::string report = ReadAll(out + "/report.md");
  for (const char* text : {"## 1. Data", "## 2. The absolute NeuralODE", "## 3. Pushing",
                           "## Timings", "diffdyn collect --trajectories 24",
                           "diffdyn train --data", "diffdyn push --model", "95 % Wilson"}) {
    EXPECT_NE(report.find(text), std::string::npos) << text << " missing from\n" << report;
  }
}

void ReplaceAll(std::string& text, const std::string& from, const std::string& to) {
  for (std::size_t p = text.find(from); p != std::string::npos; p = text.find(from, p + to.size())) {
    text.replace(p, from.size(), to);
  }
}

// The report without its timings section.
std::string ReportWithoutTimings(const std::string& report) {
  return report.substr(0, report.find("## Timings"));
}

TEST(Demo, SameSeedSameBytes) {
  const std::string a = testing::TempDir() + "/demo_a", b = testing::TempDir() + "/demo_b";
  ASSERT_EQ(RunDiffdyn("demo --quick --quiet --seed 11 --threads 1 --out " + a).exit_code, 0);
  ASSERT_EQ(RunDiffdyn("demo --quick --quiet --seed 11 --threads 2 --out " + b).exit_code, 0);
  for (const char* file : {"pushes.csv", "abs-node.json", "training.csv", "push/trials.csv"}) {
    // The model's provenance names its data file, inside the output folder.
    std::string first = ReadAll(a + "/" + file), second = ReadAll(b + "/" + file);
    ReplaceAll(first, a, "OUT");
    ReplaceAll(second, b, "OUT");
    EXPECT_FALSE(first.empty()) << file;
    EXPECT_EQ(first, second) << file;
  }
  // Timings aside, the reports agree (the output folder's name appears in the commands).
  std::string ra = ReportWithoutTimings(ReadAll(a + "/report.md"));
  std::string rb = ReportWithoutTimings(ReadAll(b + "/report.md"));
  ReplaceAll(ra, a, "OUT");
  ReplaceAll(rb, b, "OUT");
  EXPECT_FALSE(ra.empty());
  EXPECT_EQ(ra, rb);
}

TEST(Demo, UnwritableOutputIsExitCode2) {
  const Result r = RunDiffdyn("demo --quick --out /proc/no_such_dir");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("--out"), std::string::npos) << r.err;
}

}  // namespace
