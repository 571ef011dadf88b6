// Runs the diffdyn executable from CLI tests and captures its exit code, stdout and
// stderr (stderr through a temporary file of its own, since ctest runs tests in
// parallel).
//
//   const diffdyn::testing::CommandResult r = diffdyn::testing::RunDiffdyn("eval --help");
//   EXPECT_EQ(r.exit_code, 0);
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace diffdyn::testing {

/// Exit code (-1 if killed), stdout and stderr of one run.
struct CommandResult {
  int exit_code = -1;
  std::string out;
  std::string err;
};

/// Runs `launcher DIFFDYN_EXE args` through the shell (args are shell-quoted by the
/// caller; `launcher` is e.g. "mpirun -np 2 ", or empty).
inline CommandResult RunDiffdyn(const std::string& args, const std::string& launcher = "") {
  std::string err_file = ::testing::TempDir() + "/diffdyn_cli_XXXXXX";
  const int fd = mkstemp(err_file.data());
  EXPECT_GE(fd, 0);
  if (fd >= 0) close(fd);
  const std::string command = launcher + std::string(DIFFDYN_EXE) + " " + args + " 2>" + err_file;
  CommandResult result;
  FILE* pipe = popen(command.c_str(), "r");
  EXPECT_NE(pipe, nullptr);
  if (pipe == nullptr) return result;
  std::array<char, 4096> buffer{};
  size_t n = 0;
  while ((n = fread(buffer.data(), 1, buffer.size(), pipe)) > 0) result.out.append(buffer.data(), n);
  const int status = pclose(pipe);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  if (FILE* err = fopen(err_file.c_str(), "r")) {
    while ((n = fread(buffer.data(), 1, buffer.size(), err)) > 0) result.err.append(buffer.data(), n);
    fclose(err);
  }
  std::remove(err_file.c_str());
  return result;
}

/// A path named `name` in gtest's temporary folder.
inline std::string TempPath(const std::string& name) {
  return (std::filesystem::path(::testing::TempDir()) / name).string();
}

/// The whole file, bytes as they are ("" if it cannot be read).
inline std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// Number of '\n' in `s`.
inline int CountLines(const std::string& s) {
  int n = 0;
  for (char c : s) n += c == '\n';
  return n;
}

/// The one-line JSON summary of a run that must succeed (exit 0, one line on stdout).
inline nlohmann::json SummaryJson(const CommandResult& r) {
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(CountLines(r.out), 1) << r.out;
  return nlohmann::json::parse(r.out);
}

}  // namespace diffdyn::testing
