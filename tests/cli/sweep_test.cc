// diffdyn sweep: a grid of collect runs on local workers, a restart (after lost
// records or a killed sweep) that runs only what is missing, a failing task
// recorded, the same gathered CSV under `mpirun -np 2`, and bad specs refused with
// one line (exit 2) and nothing written.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

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
namespace fs = std::filesystem;

using testing::CountLines;
using testing::ReadAll;
using testing::RunDiffdyn;
using testing::TempPath;

// A spec of four short pendulum collections: seeds 1, 2 and --dt 0.01, 0.02.
std::string WriteSpec(const std::string& name, const std::string& dts = "[0.01, 0.02]") {
  const std::string path = TempPath(name);
  std::ofstream(path) << R"({"command": "collect", "options": {"--system": "pendulum", "--trajectories": 2,
    "--seconds": 0.5, "--quiet": true}, "grid": {"--seed": [1, 2], "--dt": )" << dts << "}}\n";
  return path;
}

// results.csv without the timing columns (seconds, *_per_second) and with the
// sweep folder's name replaced by "OUT".
std::string Comparable(const std::string& csv_path, const std::string& out) {
  std::istringstream in(ReadAll(csv_path));
  std::string line, text;
  std::vector<bool> keep;
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::stringstream row(line);
    for (std::string cell; std::getline(row, cell, ',');) cells.push_back(cell);
    if (keep.empty()) {
      for (const std::string& c : cells) keep.push_back(c != "seconds" && c.find("_per_second") == std::string::npos);
    }
    for (std::size_t c = 0; c < cells.size(); ++c) {
      if (c >= keep.size() || !keep[c]) continue;
      std::string cell = cells[c];
      for (std::size_t at; (at = cell.find(out)) != std::string::npos;) cell.replace(at, out.size(), "OUT");
      text += cell + ";";
    }
    text += "\n";
  }
  return text;
}

TEST(Sweep, WorkersRunTheGridAndGatherOneRowPerTaskInGridOrder) {
  const std::string spec = WriteSpec("sweep_spec.json"), out = TempPath("sweep_workers");
  fs::remove_all(out);
  const auto r = RunDiffdyn("sweep --spec " + spec + " --out " + out + " --workers 2 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ASSERT_EQ(CountLines(r.out), 1) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  for (const char* key : {"tasks", "done", "failed", "ranks", "seconds", "results_path"}) {
    EXPECT_TRUE(j.contains(key)) << key;
  }
  EXPECT_EQ(j["tasks"], 4);
  EXPECT_EQ(j["done"], 4);
  EXPECT_EQ(j["failed"], 0);
  EXPECT_EQ(j["ranks"], 1);
  EXPECT_EQ(CountLines(r.err), 4) << r.err;  // one line per task
  const std::string csv = ReadAll(out + "/results.csv");
  ASSERT_EQ(CountLines(csv), 5) << csv;
  const std::string header = csv.substr(0, csv.find('\n'));
  EXPECT_EQ(header.rfind("seed,dt,", 0), 0u) << header;
  EXPECT_NE(header.find(",path,"), std::string::npos) << header;
  EXPECT_EQ(header.substr(header.rfind(',')), ",exit_code") << header;
  // Grid order: seed 1 with dt 0.01 and 0.02, then seed 2.
  std::istringstream rows(csv.substr(header.size() + 1));
  const std::vector<std::string> expected = {"1,0.01,", "1,0.02,", "2,0.01,", "2,0.02,"};
  for (int i = 0; i < 4; ++i) {
    std::string row;
    std::getline(rows, row);
    EXPECT_EQ(row.rfind(expected[i], 0), 0u) << row;
    EXPECT_NE(row.find("," + out + "/tasks/" + std::to_string(i) + "/data.csv,"), std::string::npos) << row;
    EXPECT_EQ(row.substr(row.rfind(',')), ",0") << row;
  }
  // Each task's own output is the same as the command run by hand.
  const std::string by_hand = TempPath("sweep_by_hand.csv");
  ASSERT_EQ(RunDiffdyn("collect --system pendulum --trajectories 2 --seconds 0.5 --quiet --seed 2 --dt 0.01 --out " +
                       by_hand).exit_code, 0);
  EXPECT_EQ(ReadAll(out + "/tasks/2/data.csv"), ReadAll(by_hand));
}

TEST(Sweep, ARestartRunsOnlyTheTasksWithoutAResult) {
  const std::string spec = WriteSpec("sweep_restart.json"), out = TempPath("sweep_restart");
  fs::remove_all(out);
  ASSERT_EQ(RunDiffdyn("sweep --spec " + spec + " --out " + out + " --quiet").exit_code, 0);
  const std::string first = Comparable(out + "/results.csv", out);
  const std::string kept = ReadAll(out + "/tasks/0/result.json");
  // An interrupted sweep leaves tasks without result.json (and maybe partial output).
  fs::remove(out + "/tasks/1/result.json");
  fs::remove(out + "/tasks/3/result.json");
  fs::remove(out + "/results.csv");
  const auto r = RunDiffdyn("sweep --spec " + spec + " --out " + out + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["recorded"], 2);
  EXPECT_NE(r.err.find("2 of 4 tasks already recorded"), std::string::npos) << r.err;
  EXPECT_EQ(CountLines(r.err), 3) << r.err;  // the note and two task lines
  EXPECT_EQ(ReadAll(out + "/tasks/0/result.json"), kept);
  EXPECT_EQ(Comparable(out + "/results.csv", out), first);
}

TEST(Sweep, ASweepKilledMidwayResumesWithoutRedoingFinishedTasks) {
  const std::string spec = TempPath("sweep_killed.json"), out = TempPath("sweep_killed");
  std::ofstream(spec) << R"({"command": "collect", "options": {"--system": "pendulum", "--trajectories": 30,
    "--seconds": 5, "--quiet": true}, "grid": {"--seed": [1, 2, 3, 4, 5, 6]}})";
  fs::remove_all(out);
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::execl(DIFFDYN_EXE, "diffdyn", "sweep", "--spec", spec.c_str(), "--out", out.c_str(), "--workers", "1",
            "--quiet", static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ASSERT_GT(pid, 0);
  // Kill the sweep (as a scheduler's time limit would) right after its first task is recorded.
  for (int i = 0; i < 6000 && !fs::exists(out + "/tasks/0/result.json"); ++i) ::usleep(10000);
  ::kill(pid, SIGTERM);
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGTERM);
  int recorded = 0;
  for (int i = 0; i < 6; ++i) recorded += fs::exists(out + "/tasks/" + std::to_string(i) + "/result.json");
  ASSERT_GE(recorded, 1);
  ASSERT_LT(recorded, 6) << "the sweep ended before it was killed";
  EXPECT_FALSE(fs::exists(out + "/results.csv"));

  const auto r = RunDiffdyn("sweep --spec " + spec + " --out " + out + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["recorded"], recorded);
  EXPECT_EQ(j["done"], 6);
  EXPECT_EQ(CountLines(r.err), 1 + 6 - recorded) << r.err;  // the note and one line per task run
  EXPECT_EQ(CountLines(ReadAll(out + "/results.csv")), 7);
}

TEST(Sweep, AFailingTaskIsRecordedWithItsExitCodeAndTheSweepGoesOn) {
  const std::string spec = WriteSpec("sweep_failing.json", "[0.01, -1]"), out = TempPath("sweep_failing");
  fs::remove_all(out);
  const auto r = RunDiffdyn("sweep --spec " + spec + " --out " + out + " --json --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["done"], 2);
  EXPECT_EQ(j["failed"], 2);
  const std::string csv = ReadAll(out + "/results.csv");
  const std::size_t row = csv.find("\n1,-1,");  // task 1: seed 1, dt -1
  ASSERT_NE(row, std::string::npos) << csv;
  const std::string line = csv.substr(row + 1, csv.find('\n', row + 1) - row - 1);
  EXPECT_EQ(line.substr(line.rfind(',')), ",2") << line;  // exit code 2: bad input
  EXPECT_NE(ReadAll(out + "/tasks/1/stderr.txt").find("error: "), std::string::npos);
}

TEST(Sweep, MpirunWithTwoRanksGathersWhatOneWorkerGathers) {
#if !defined(DIFFDYN_MPIEXEC)
  GTEST_SKIP() << "built without MPI";
#else
  const std::string spec = WriteSpec("sweep_mpi.json");
  const std::string serial = TempPath("sweep_serial"), mpi = TempPath("sweep_mpi");
  fs::remove_all(serial);
  fs::remove_all(mpi);
  ASSERT_EQ(RunDiffdyn("sweep --spec " + spec + " --out " + serial + " --workers 1 --quiet").exit_code, 0);
  // Root in containers needs the two ALLOW variables; the single-copy setting is the
  // container note of the README; leak reports of Open MPI's own start-up are not ours.
  const std::string launcher =
      "OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=none "
      "OMPI_MCA_rmaps_base_oversubscribe=1 ASAN_OPTIONS=detect_leaks=0 " DIFFDYN_MPIEXEC " -np 2 ";
  const auto r = RunDiffdyn("sweep --spec " + spec + " --out " + mpi + " --json --quiet", launcher);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ASSERT_EQ(CountLines(r.out), 1) << r.out;  // only rank 0 reports
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["ranks"], 2);
  EXPECT_EQ(j["done"], 4);
  EXPECT_EQ(Comparable(mpi + "/results.csv", mpi), Comparable(serial + "/results.csv", serial));
  for (int i = 0; i < 4; ++i) {
    const std::string task = "/tasks/" + std::to_string(i) + "/data.csv";
    EXPECT_EQ(ReadAll(mpi + task), ReadAll(serial + task)) << task;
  }
#endif
}

TEST(Sweep, BadSpecsAndOptionsAreOneLineErrorsAndWriteNothing) {
  const std::string out = TempPath("sweep_bad");
  const auto spec_with = [](const std::string& name, const std::string& text) {
    const std::string path = TempPath(name);
    std::ofstream(path) << text;
    return path;
  };
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"--spec " + TempPath("no_such_spec.json"), "no such file"},
      {"--spec " + spec_with("sweep_bad1.json", "{\"command\": \"train\", "), "not valid JSON"},
      {"--spec " + spec_with("sweep_bad2.json", "{\"command\": \"fly\"}"), "unknown command 'fly'"},
      {"--spec " + spec_with("sweep_bad3.json", "{\"command\": \"collect\", \"options\": {\"--speed\": 1}}"),
       "has no option '--speed'"},
      {"--spec " + spec_with("sweep_bad4.json", "{\"command\": \"collect\", \"grid\": {\"--seed\": [[1]]}}"),
       "must be a string"},
      {"--spec " + spec_with("sweep_bad5.json", "{\"command\": \"collect\", \"options\": {\"--json\": true}}"),
       "--json"},
      {"--spec " + WriteSpec("sweep_bad6.json") + " --workers -1", "--workers"},
      {"--spec " + WriteSpec("sweep_bad7.json") + " --workers 1e9", "--workers"},
  };
  for (const auto& [args, fragment] : cases) {
    fs::remove_all(out);
    const auto r = RunDiffdyn("sweep " + args + " --out " + out);
    EXPECT_EQ(r.exit_code, 2) << args;
    EXPECT_EQ(CountLines(r.err), 1) << args << ": " << r.err;
    EXPECT_EQ(r.err.rfind("error: ", 0), 0u) << r.err;
    EXPECT_NE(r.err.find(fragment), std::string::npos) << args << ": " << r.err;
    EXPECT_FALSE(fs::exists(out)) << args;
  }
}

}  // namespace
}  // namespace diffdyn
