// The command line's conventions: exit codes, one-line errors, --help, --json.
#include <sys/wait.h>

#include <array>
#include <cstdio>
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
  const std::string err_file = testing::TempDir() + "/diffdyn_stderr.txt";
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
  return result;
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
