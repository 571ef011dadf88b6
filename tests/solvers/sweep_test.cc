// Sweeps: the spec reader's order and refusals, grid expansion, the gathered CSV,
// and the local scheduler with /bin/sh as the task executable (so the scheduler
// is tested apart from diffdyn's commands).
#include "diffdyn/solvers/sweep.h"

#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {
namespace {
namespace fs = std::filesystem;

std::string ReadText(const fs::path& path) {
  std::ifstream in(path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

fs::path FreshFolder(const std::string& name) {
  const fs::path dir = fs::path(::testing::TempDir()) / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

TEST(SweepSpec, KeepsTheSpecsOrderAndExpandsTheLastAxisFastest) {
  const SweepSpec spec = ParseSweepSpec(
      R"({"command": "train", "options": {"--epochs": 20, "--data": "d.csv", "--free": true, "--off": false},
          "grid": {"--seed": [0, 1, 2], "--model": ["abs-nn", "abs-node"], "--lr": [0.001]}})",
      "spec.json");
  EXPECT_EQ(spec.command, "train");
  ASSERT_EQ(spec.options.size(), 4u);
  EXPECT_EQ(spec.options[0].first, "--epochs");  // not sorted
  ASSERT_EQ(spec.grid.size(), 3u);
  EXPECT_EQ(spec.grid[0].first, "--seed");
  EXPECT_EQ(spec.TaskCount(), 6u);

  const std::vector<SweepTask> tasks = ExpandSweep(spec, "runs", "model.json");
  ASSERT_EQ(tasks.size(), 6u);
  EXPECT_EQ(tasks[1].grid_values, (std::vector<std::string>{"0", "abs-node", "0.001"}));
  EXPECT_EQ(tasks[2].grid_values, (std::vector<std::string>{"1", "abs-nn", "0.001"}));
  const std::vector<std::string> expected = {"train", "--epochs", "20",    "--data", "d.csv",    "--free",
                                             "--seed", "1",        "--model", "abs-nn", "--lr",     "0.001",
                                             "--out",  (fs::path("runs") / "tasks" / "2" / "model.json").string(),
                                             "--json"};
  EXPECT_EQ(tasks[2].args, expected);
}

TEST(SweepSpec, AnOutInTheSpecIsKeptAndNoGridIsOneTask) {
  const SweepSpec spec = ParseSweepSpec(R"({"command": "eval", "options": {"--out": "x"}})", "s");
  const std::vector<SweepTask> tasks = ExpandSweep(spec, "runs", "out");
  ASSERT_EQ(tasks.size(), 1u);
  EXPECT_EQ(tasks[0].args, (std::vector<std::string>{"eval", "--out", "x", "--json"}));
  EXPECT_TRUE(tasks[0].grid_values.empty());
}

TEST(SweepGrid, ExpandsAGridOnItsOwnInTheGivensOrder) {
  // Any program's grid (diffdyn figures runs the figure programs' grids this way).
  const SweepGrid grid = ParseSweepGrid(
      nlohmann::ordered_json::parse(R"({"--seeds": [1, 2], "--fast": [true, false], "--name": ["a b"]})"), "g");
  const std::vector<SweepPoint> points = ExpandSweepGrid(grid);
  ASSERT_EQ(points.size(), 4u);
  EXPECT_EQ(points[0].values, (std::vector<std::string>{"1", "true", "a b"}));
  EXPECT_EQ(points[0].args, (std::vector<std::string>{"--seeds", "1", "--fast", "--name", "a b"}));
  EXPECT_EQ(points[1].args, (std::vector<std::string>{"--seeds", "1", "--name", "a b"}));
  EXPECT_EQ(points[3].values, (std::vector<std::string>{"2", "false", "a b"}));
  ASSERT_EQ(ExpandSweepGrid({}).size(), 1u);
  EXPECT_TRUE(ExpandSweepGrid({})[0].args.empty());
  EXPECT_THROW(ParseSweepGrid(nlohmann::ordered_json::parse(R"({"--seeds": []})"), "g"), Error);
  EXPECT_THROW(ParseSweepGrid(nlohmann::ordered_json::parse(R"([1])"), "g"), Error);
}

TEST(SweepSpec, RefusesWhatACommandLineCannotCarry) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"[1]", "JSON object"},
      {"{\"grid\": {}}", "'command'"},
      {"{\"command\": 3}", "'command'"},
      {"{\"command\": \"sweep\"}", "cannot run sweeps"},
      {"{\"command\": \"-x\"}", "command name"},
      {"{\"command\": \"train\", \"extra\": 1}", "unknown key"},
      {"{\"command\": \"train\", \"options\": []}", "'options'"},
      {"{\"command\": \"train\", \"options\": {\"seed\": 1}}", "not an option name"},
      {"{\"command\": \"train\", \"options\": {\"--a=b\": 1}}", "not an option name"},
      {"{\"command\": \"train\", \"options\": {\"--json\": true}}", "added by the sweep"},
      {"{\"command\": \"train\", \"options\": {\"--seed\": [1]}}", "must be a string"},
      {"{\"command\": \"train\", \"options\": {\"--seed\": null}}", "must be a string"},
      {"{\"command\": \"train\", \"options\": {\"--data\": \"a\\u0000b\"}}", "NUL"},
      {"{\"command\": \"train\", \"options\": {\"--seed\": 1}, \"grid\": {\"--seed\": [2]}}", "also in options"},
      {"{\"command\": \"train\", \"grid\": {\"--seed\": []}}", "non-empty list"},
      {"{\"command\": \"train\", \"grid\": {\"--seed\": [{}]}}", "must be a string"},
      {"{\"command\": \"train\", \"grid\": {\"--a\": [1,2,3,4,5,6,7,8,9,10], \"--b\": [1,2,3,4,5,6,7,8,9,10],"
       " \"--c\": [1,2,3,4,5,6,7,8,9,10], \"--d\": [1,2,3,4,5,6,7,8,9,10], \"--e\": [1,2,3,4,5,6,7,8,9,10], \"--f\": [1,2]}}",
       "combinations"},
      {"{\"command\": \"train\"", "not valid JSON"},
  };
  for (const auto& [text, fragment] : cases) {
    try {
      (void)ParseSweepSpec(text, "spec.json");
      ADD_FAILURE() << "accepted: " << text;
    } catch (const Error& e) {
      const std::string what = e.what();
      EXPECT_EQ(what.rfind("spec.json", 0), 0u) << what;
      EXPECT_NE(what.find(fragment), std::string::npos) << text << " -> " << what;
    }
  }
}

TEST(SweepResults, GridColumnsThenSummaryKeysThenExitCode) {
  const SweepSpec spec = ParseSweepSpec(R"({"command": "eval", "grid": {"--seed": [1, 2], "--name": ["a,b"]}})", "s");
  const std::vector<SweepTask> tasks = ExpandSweep(spec, "runs", "");
  std::vector<SweepResult> results(2);
  results[0].exit_code = 0;
  results[0].summary = {{"loss", 0.5}, {"seed", 99}, {"list", {1, 2}}};
  results[1].exit_code = 2;  // failed: no summary
  const fs::path path = FreshFolder("sweep_results") / "results.csv";
  WriteSweepResults(spec, tasks, results, path);
  EXPECT_EQ(ReadText(path),
            "seed,name,list,loss,exit_code\n"
            "1,\"a,b\",\"[1,2]\",0.5,0\n"
            "2,\"a,b\",,,2\n");
}

// A sweep of shell scripts: task i prints a summary and exits with code i % 3.
std::vector<SweepTask> ShellTasks(int count) {
  std::vector<SweepTask> tasks(static_cast<std::size_t>(count));
  for (int i = 0; i < count; ++i) {
    tasks[i].index = i;
    tasks[i].grid_values = {std::to_string(i)};
    tasks[i].args = {"-c", "echo progress >&2; echo '{\"square\": " + std::to_string(i * i) + "}'; exit " +
                               std::to_string(i % 3)};
  }
  return tasks;
}

TEST(SweepLocal, RunsEveryTaskRecordsExitCodesAndSkipsRecordedTasks) {
  const fs::path dir = FreshFolder("sweep_local");
  const std::vector<SweepTask> tasks = ShellTasks(5);
  std::set<int> ran;
  SweepQueue queue(tasks, SweepFolder(dir), [&](const SweepTask& t, const SweepResult&, std::size_t) {
    ran.insert(t.index);
  });
  RunSweepLocal("/bin/sh", queue, 2);
  ASSERT_TRUE(queue.AllFinished());
  EXPECT_EQ(ran.size(), 5u);
  for (int i = 0; i < 5; ++i) {
    const SweepResult& r = queue.Results()[static_cast<std::size_t>(i)];
    EXPECT_EQ(r.exit_code, i % 3);
    EXPECT_EQ(r.summary.value("square", -1), i * i);
    EXPECT_EQ(ReadText(dir / "tasks" / std::to_string(i) / "stderr.txt"), "progress\n");
  }

  // Restart: nothing runs again; a task whose record is gone runs alone.
  fs::remove(dir / "tasks" / "3" / "result.json");
  ran.clear();
  SweepQueue again(tasks, SweepFolder(dir), [&](const SweepTask& t, const SweepResult&, std::size_t) {
    ran.insert(t.index);
  });
  EXPECT_EQ(again.RecordedCount(), 4u);
  RunSweepLocal("/bin/sh", again, 2);
  EXPECT_EQ(ran, std::set<int>{3});
  EXPECT_EQ(again.Results()[3].summary.value("square", -1), 9);

  // Changed arguments are a different task: its record does not count.
  std::vector<SweepTask> changed = tasks;
  changed[0].args[1] += " ";
  EXPECT_EQ(SweepQueue(changed, SweepFolder(dir)).RecordedCount(), 4u);
}

TEST(SweepLocal, ATaskKilledByASignalIsRecordedAs128PlusTheSignal) {
  const fs::path dir = FreshFolder("sweep_signal");
  std::vector<SweepTask> tasks(1);
  tasks[0].args = {"-c", "kill -9 $$"};
  SweepQueue queue(tasks, SweepFolder(dir));
  RunSweepLocal("/bin/sh", queue, 1);
  EXPECT_EQ(queue.Results()[0].exit_code, 128 + 9);
  EXPECT_TRUE(queue.Results()[0].summary.is_null());
}

TEST(SweepLocal, ATaskWithItsOwnProgramRunsThatProgram) {
  const fs::path dir = FreshFolder("sweep_program");
  std::vector<SweepTask> tasks(2);
  tasks[0].args = {"-c", "echo '{\"shell\": 1}'"};
  tasks[1].index = 1;
  tasks[1].program = "/bin/echo";
  tasks[1].args = {"{\"echo\": 2}"};
  SweepQueue queue(tasks, SweepFolder(dir));
  RunSweepLocal("/bin/sh", queue, 2);
  EXPECT_EQ(queue.Results()[0].summary.value("shell", -1), 1);
  EXPECT_EQ(queue.Results()[1].summary.value("echo", -1), 2);

  // A program that cannot be executed ends its task with 127, the others run.
  std::vector<SweepTask> missing(1);
  missing[0].program = dir / "no_such_program";
  SweepQueue failed(missing, SweepFolder(FreshFolder("sweep_missing_program")));
  RunSweepLocal("/bin/sh", failed, 1);
  EXPECT_EQ(failed.Results()[0].exit_code, 127);
}

TEST(SweepLocal, TasksDoNotSeeTheMpiLaunchersVariables) {
  const fs::path dir = FreshFolder("sweep_env");
  ::setenv("OMPI_COMM_WORLD_RANK", "3", 1);
  ::setenv("DIFFDYN_SWEEP_TEST_VARIABLE", "kept", 1);
  std::vector<SweepTask> tasks(1);
  tasks[0].args = {"-c", "echo \"{\\\"ompi\\\": \\\"${OMPI_COMM_WORLD_RANK-unset}\\\", "
                         "\\\"other\\\": \\\"${DIFFDYN_SWEEP_TEST_VARIABLE-unset}\\\"}\""};
  SweepQueue queue(tasks, SweepFolder(dir));
  RunSweepLocal("/bin/sh", queue, 1);
  ::unsetenv("OMPI_COMM_WORLD_RANK");
  ::unsetenv("DIFFDYN_SWEEP_TEST_VARIABLE");
  EXPECT_EQ(queue.Results()[0].summary.value("ompi", ""), "unset");
  EXPECT_EQ(queue.Results()[0].summary.value("other", ""), "kept");
}

}  // namespace
}  // namespace diffdyn
