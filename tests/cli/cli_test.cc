// The command line's conventions: exit codes, one-line errors, --help, --json.
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "diffdyn/solvers/version.h"

namespace {

struct Result {
  int exit_code;
  std::string out;  // stdout
  std::string err;  // stderr
};

// Runs the diffdyn executable with `args` (a shell-quoted string).
Result RunDiffdyn(const std::string& args) {
  // A file of its own per call: ctest runs tests in parallel.
  std::string err_file = testing::TempDir() + "/diffdyn_stderr_XXXXXX";
  const int fd = mkstemp(err_file.data());
  EXPECT_GE(fd, 0);
  close(fd);
  const std::string command = std::string(DIFFDYN_EXE) + " " + args + " 2>" + err_file;
  Result result{};
  FILE* pipe = popen(command.c_str(), "r");
  EXPECT_NE(pipe, nullptr);
  std::array<char, 4096> buffer{};
  size_t n = 0;
  while ((n = fread(buffer.data(), 1, buffer.size(), pipe)) > 0) result.out.append(buffer.data(), n);
  const int status = pclose(pipe);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  FILE* err = fopen(err_file.c_str(), "r");
  if (err != nullptr) {
    while ((n = fread(buffer.data(), 1, buffer.size(), err)) > 0) result.err.append(buffer.data(), n);
    fclose(err);
  }
  std::remove(err_file.c_str());
  return result;
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

int CountLines(const std::string& s) {
  int lines = 0;
  for (char c : s) lines += (c == '\n');
  return lines;
}

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

TEST(Demo, QuickRunIdentifiesThePendulumAndWritesItsReport) {
  const std::string out = testing::TempDir() + "/demo_quick";
  const Result r = RunDiffdyn("demo --quick --json --seed 4 --out " + out);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto summary = nlohmann::json::parse(r.out);
  const auto& fit = summary.at("pendulum_fit");
  EXPECT_TRUE(fit.at("converged").get<bool>());
  EXPECT_LT(fit.at("final_rms").get<double>(), fit.at("initial_rms").get<double>());
  for (const auto& p : fit.at("params")) {
    EXPECT_LT(p.at("z").get<double>(), 4.0) << p.dump();
    EXPECT_LT(std::abs(p.at("fitted").get<double>() - p.at("truth").get<double>()),
              0.05 * p.at("truth").get<double>())
        << p.dump();
  }
  for (const char* file : {"report.md", "pendulum_fit.csv"}) {
    FILE* f = fopen((out + "/" + file).c_str(), "r");
    EXPECT_NE(f, nullptr) << file;
    if (f != nullptr) fclose(f);
  }
}

TEST(Demo, SameSeedSameBytes) {
  const std::string a = testing::TempDir() + "/demo_a", b = testing::TempDir() + "/demo_b";
  ASSERT_EQ(RunDiffdyn("demo --quick --quiet --seed 11 --out " + a).exit_code, 0);
  ASSERT_EQ(RunDiffdyn("demo --quick --quiet --seed 11 --out " + b).exit_code, 0);
  const std::string first = ReadFile(a + "/pendulum_fit.csv");
  EXPECT_FALSE(first.empty());
  EXPECT_EQ(first, ReadFile(b + "/pendulum_fit.csv"));
  EXPECT_EQ(ReadFile(a + "/report.md"), ReadFile(b + "/report.md"));
}

TEST(Demo, UnwritableOutputIsExitCode2) {
  const Result r = RunDiffdyn("demo --quick --out /proc/no_such_dir");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("--out"), std::string::npos) << r.err;
}

}  // namespace
