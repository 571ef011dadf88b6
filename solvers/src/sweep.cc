// Sweeps: spec reader, grid expansion, child processes, the shared queue, the
// local scheduler and the gathered CSV (solvers/sweep.h).
#include "diffdyn/solvers/sweep.h"

#include <fcntl.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <map>
#include <stdexcept>
#include <system_error>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/io.h"
#include "diffdyn/models/json_io.h"

extern char** environ;

namespace diffdyn {
namespace fs = std::filesystem;

namespace {

// Throws unless `flag` looks like a long option: "--name", no '=', no space.
void CheckFlag(const std::string& flag, const std::string& where) {
  DIFFDYN_CHECK(flag.size() > 2 && flag.rfind("--", 0) == 0 && flag.find_first_of("= \t\n") == std::string::npos &&
                    flag.find('\0') == std::string::npos,
                where, ": '", flag.substr(0, 60), "' is not an option name (\"--name\")");
  DIFFDYN_CHECK(flag != "--json", where, ": '--json' is added by the sweep to every task");
}

// Throws unless `value` is a scalar a command line can carry.
void CheckValue(const nlohmann::ordered_json& value, const std::string& where) {
  DIFFDYN_CHECK(value.is_string() || value.is_number() || value.is_boolean(), where,
                " must be a string, a number or true/false");
  if (value.is_string()) {
    DIFFDYN_CHECK(value.get<std::string>().find('\0') == std::string::npos, where, " contains a NUL character");
  }
  if (value.is_number_float()) {
    DIFFDYN_CHECK(std::isfinite(value.get<double>()), where, " is not a finite number");
  }
}

// An ordered JSON scalar as the plain JSON type the rest of the library uses.
nlohmann::json Plain(const nlohmann::ordered_json& value) { return nlohmann::json::parse(value.dump()); }

// Appends `flag value` (or the bare flag for true, nothing for false) to `args`.
void AppendOption(const std::string& flag, const nlohmann::json& value, std::vector<std::string>& args) {
  if (value.is_boolean()) {
    if (value.get<bool>()) args.push_back(flag);
    return;
  }
  args.push_back(flag);
  args.push_back(SweepValueText(value));
}

}  // namespace

std::size_t SweepSpec::TaskCount() const {
  std::size_t count = 1;
  for (const auto& [flag, values] : grid) count *= values.size();
  return count;
}

SweepSpec ParseSweepSpec(std::string_view text, const std::string& name) {
  const auto j = ParseJsonText<nlohmann::ordered_json>(text, name);
  DIFFDYN_CHECK(j.is_object(), name, ": a sweep spec is a JSON object {\"command\", \"options\", \"grid\"}");
  for (const auto& [key, value] : j.items()) {
    DIFFDYN_CHECK(key == "command" || key == "options" || key == "grid", name, ": unknown key '",
                  key.substr(0, 60), "' (known: command, options, grid)");
  }
  SweepSpec spec;
  DIFFDYN_CHECK(j.contains("command") && j["command"].is_string(), name, ": 'command' must be a string");
  spec.command = j["command"].get<std::string>();
  DIFFDYN_CHECK(!spec.command.empty() && spec.command[0] != '-' &&
                    spec.command.find_first_of(std::string(" \t\n\0", 4)) == std::string::npos,
                name, ": 'command' must be one diffdyn command name");
  DIFFDYN_CHECK(spec.command != "sweep", name, ": a sweep cannot run sweeps");

  std::map<std::string, bool> seen;
  if (j.contains("options")) {
    DIFFDYN_CHECK(j["options"].is_object(), name, ": 'options' must be an object {\"--flag\": value}");
    for (const auto& [flag, value] : j["options"].items()) {
      const std::string where = StrCat(name, ": options '", flag.substr(0, 60), "'");
      CheckFlag(flag, StrCat(name, ": options"));
      CheckValue(value, where);
      DIFFDYN_CHECK(!seen[flag], where, " is given twice");
      seen[flag] = true;
      spec.options.emplace_back(flag, Plain(value));
    }
  }
  if (j.contains("grid")) {
    spec.grid = ParseSweepGrid(j["grid"], name);
    for (const auto& [flag, values] : spec.grid) {
      DIFFDYN_CHECK(!seen[flag], name, ": grid '", flag.substr(0, 60), "' is also in options");
    }
  }
  return spec;
}

SweepGrid ParseSweepGrid(const nlohmann::ordered_json& grid, const std::string& name) {
  DIFFDYN_CHECK(grid.is_object(), name, ": 'grid' must be an object {\"--flag\": [values]}");
  SweepGrid out;
  std::size_t count = 1;
  for (const auto& [flag, values] : grid.items()) {
    const std::string where = StrCat(name, ": grid '", flag.substr(0, 60), "'");
    CheckFlag(flag, StrCat(name, ": grid"));
    DIFFDYN_CHECK(values.is_array() && !values.empty(), where, " must be a non-empty list of values");
    DIFFDYN_CHECK(values.size() <= kMaxSweepTasks / count, name, ": the grid has more than ", kMaxSweepTasks,
                  " combinations");
    count *= values.size();
    std::vector<nlohmann::json> plain;
    for (std::size_t i = 0; i < values.size(); ++i) {
      CheckValue(values[i], StrCat(where, "[", i, "]"));
      plain.push_back(Plain(values[i]));
    }
    out.emplace_back(flag, std::move(plain));
  }
  return out;
}

std::vector<SweepPoint> ExpandSweepGrid(const SweepGrid& grid) {
  std::size_t count = 1;
  for (const auto& [flag, values] : grid) count *= values.size();
  std::vector<SweepPoint> points(count);
  for (std::size_t i = 0; i < count; ++i) {
    // Digits of i in the grid's mixed radix, the last axis varying fastest.
    std::vector<std::size_t> digit(grid.size());
    std::size_t rest = i;
    for (std::size_t a = grid.size(); a-- > 0;) {
      digit[a] = rest % grid[a].second.size();
      rest /= grid[a].second.size();
    }
    for (std::size_t a = 0; a < grid.size(); ++a) {
      const nlohmann::json& value = grid[a].second[digit[a]];
      points[i].values.push_back(SweepValueText(value));
      AppendOption(grid[a].first, value, points[i].args);
    }
  }
  return points;
}

SweepSpec ReadSweepSpec(const fs::path& path) {
  std::ifstream in = OpenInputFile(path);
  std::error_code ec;
  const std::uintmax_t bytes = fs::file_size(path, ec);
  DIFFDYN_CHECK(!ec && bytes <= (std::uintmax_t{1} << 24), path.string(), ": larger than 16 MiB");
  const std::string text{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  return ParseSweepSpec(text, path.string());
}

std::string SweepValueText(const nlohmann::json& value) {
  if (value.is_string()) return value.get<std::string>();
  return value.dump();
}

std::vector<SweepTask> ExpandSweep(const SweepSpec& spec, const fs::path& out_dir, const std::string& out_name) {
  bool has_out = false;
  for (const auto& [flag, value] : spec.options) has_out = has_out || flag == "--out";
  for (const auto& [flag, values] : spec.grid) has_out = has_out || flag == "--out";
  const std::vector<SweepPoint> points = ExpandSweepGrid(spec.grid);
  const std::size_t count = points.size();
  std::vector<SweepTask> tasks(count);
  for (std::size_t i = 0; i < count; ++i) {
    SweepTask& task = tasks[i];
    task.index = static_cast<int>(i);
    task.args.push_back(spec.command);
    for (const auto& [flag, value] : spec.options) AppendOption(flag, value, task.args);
    task.grid_values = points[i].values;
    task.args.insert(task.args.end(), points[i].args.begin(), points[i].args.end());
    if (!out_name.empty() && !has_out) {
      task.args.push_back("--out");
      task.args.push_back((out_dir / "tasks" / std::to_string(i) / out_name).string());
    }
    task.args.push_back("--json");
  }
  return tasks;
}

// ---------------------------------------------------------------------------
// The sweep's folder.

fs::path SweepFolder::TaskDir(int index) const { return root_ / "tasks" / std::to_string(index); }

std::optional<SweepResult> SweepFolder::Recorded(const SweepTask& task) const {
  const fs::path path = TaskDir(task.index) / "result.json";
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) return std::nullopt;
  try {
    const nlohmann::json j = ReadJsonFile(path);
    if (!j.is_object() || j.value("args", nlohmann::json()) != nlohmann::json(task.args)) return std::nullopt;
    SweepResult result;
    result.exit_code = static_cast<int>(JsonInt(j.at("exit_code"), -1, 255, "exit_code"));
    result.summary = j.value("summary", nlohmann::json());
    result.seconds = j.value("seconds", 0.0);
    return result;
  } catch (const std::exception&) {
    return std::nullopt;  // unreadable: the task runs again and the file is replaced
  }
}

void SweepFolder::Record(const SweepTask& task, const SweepResult& result) const {
  const fs::path dir = TaskDir(task.index);
  fs::create_directories(dir);
  const nlohmann::json j = {{"args", task.args},
                            {"exit_code", result.exit_code},
                            {"summary", result.summary},
                            {"seconds", result.seconds}};
  WriteFileAtomically(dir / "result.json", [&](std::ostream& out) { out << j.dump(1) << '\n'; });
}

// ---------------------------------------------------------------------------
// Child processes.

namespace {

// Opens `path` with `flags` (close-on-exec); throws naming the path.
int OpenOrThrow(const fs::path& path, int flags) {
  const int fd = ::open(path.c_str(), flags | O_CLOEXEC, 0644);
  if (fd < 0) throw std::runtime_error(StrCat(path.string(), ": cannot open: ", std::strerror(errno)));
  return fd;
}

// The environment without the MPI launcher's variables (a task is not an MPI rank).
std::vector<std::string> TaskEnvironment() {
  std::vector<std::string> env;
  for (char** e = environ; e != nullptr && *e != nullptr; ++e) {
    const std::string_view entry(*e);
    if (entry.rfind("OMPI_", 0) == 0 || entry.rfind("PMIX_", 0) == 0) continue;
    env.emplace_back(entry);
  }
  return env;
}

// Null-terminated pointers into `strings` (which must outlive them).
std::vector<char*> Pointers(std::vector<std::string>& strings) {
  std::vector<char*> p;
  for (std::string& s : strings) p.push_back(s.data());
  p.push_back(nullptr);
  return p;
}

// The last non-empty line of the file (reading at most its last MiB).
std::string LastLine(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return "";
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  const std::streamoff from = size > (1 << 20) ? size - (1 << 20) : 0;
  in.seekg(from);
  std::string text{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  while (!text.empty() && (text.back() == '\n' || text.back() == '\r')) text.pop_back();
  const std::size_t newline = text.rfind('\n');
  return newline == std::string::npos ? text : text.substr(newline + 1);
}

}  // namespace

RunningTask StartSweepTask(const fs::path& executable, const SweepTask& task, const fs::path& task_dir) {
  fs::create_directories(task_dir);
  const int in = OpenOrThrow("/dev/null", O_RDONLY);
  const int out = OpenOrThrow(task_dir / "stdout.txt", O_WRONLY | O_CREAT | O_TRUNC);
  const int err = OpenOrThrow(task_dir / "stderr.txt", O_WRONLY | O_CREAT | O_TRUNC);
  // Everything the child needs is prepared before fork: after it, only
  // async-signal-safe calls.
  const fs::path& program = task.program.empty() ? executable : task.program;
  std::vector<std::string> argv_strings = {program.filename().string()};
  argv_strings.insert(argv_strings.end(), task.args.begin(), task.args.end());
  std::vector<std::string> env_strings = TaskEnvironment();
  std::vector<char*> argv = Pointers(argv_strings), envp = Pointers(env_strings);
  const std::string exe = program.string();
  const pid_t parent = ::getpid();

  RunningTask running;
  running.index = task.index;
  running.start = std::chrono::steady_clock::now();
  running.pid = ::fork();
  if (running.pid == 0) {
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (::getppid() != parent) ::_exit(128 + SIGTERM);  // the sweep already ended
    if (::dup2(in, 0) < 0 || ::dup2(out, 1) < 0 || ::dup2(err, 2) < 0) ::_exit(127);
    ::execve(exe.c_str(), argv.data(), envp.data());
    static const char kMessage[] = "error: sweep: cannot execute the task's program\n";
    (void)!::write(2, kMessage, sizeof(kMessage) - 1);
    ::_exit(127);
  }
  const int fork_errno = errno;
  ::close(in);
  ::close(out);
  ::close(err);
  if (running.pid < 0) throw std::runtime_error(StrCat("sweep: cannot start a task: ", std::strerror(fork_errno)));
  return running;
}

SweepResult FinishSweepTask(const RunningTask& running, int wait_status, const fs::path& task_dir) {
  SweepResult result;
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - running.start).count();
  if (WIFEXITED(wait_status)) result.exit_code = WEXITSTATUS(wait_status);
  else if (WIFSIGNALED(wait_status)) result.exit_code = 128 + WTERMSIG(wait_status);
  try {
    nlohmann::json summary = ParseJsonText(LastLine(task_dir / "stdout.txt"), "stdout");
    if (summary.is_object()) result.summary = std::move(summary);
  } catch (const Error&) {
    // No summary (the task failed before printing one): the row's cells stay empty.
  }
  return result;
}

// ---------------------------------------------------------------------------
// The queue and the local scheduler.

SweepQueue::SweepQueue(const std::vector<SweepTask>& tasks, SweepFolder folder, Progress progress)
    : tasks_(tasks), folder_(std::move(folder)), progress_(std::move(progress)), results_(tasks.size()) {
  for (std::size_t i = tasks_.size(); i-- > 0;) {
    if (std::optional<SweepResult> r = folder_.Recorded(tasks_[i])) {
      results_[i] = std::move(*r);
      ++recorded_;
    } else {
      pending_.push_back(static_cast<int>(i));
    }
  }
  finished_ = recorded_;
}

std::optional<int> SweepQueue::Next() {
  if (pending_.empty()) return std::nullopt;
  const int index = pending_.back();
  pending_.pop_back();
  return index;
}

void SweepQueue::Finish(int index, SweepResult result) {
  const SweepTask& task = tasks_.at(static_cast<std::size_t>(index));
  folder_.Record(task, result);
  results_[static_cast<std::size_t>(index)] = std::move(result);
  ++finished_;
  if (progress_) progress_(task, results_[static_cast<std::size_t>(index)], finished_);
}

void RunSweepLocal(const fs::path& executable, SweepQueue& queue, int workers) {
  DIFFDYN_CHECK(workers >= 1, "--workers must be at least 1");
  std::map<pid_t, RunningTask> running;
  for (;;) {
    while (static_cast<int>(running.size()) < workers) {
      const std::optional<int> next = queue.Next();
      if (!next) break;
      RunningTask task = StartSweepTask(executable, queue.Tasks()[static_cast<std::size_t>(*next)],
                                        queue.Folder().TaskDir(*next));
      running.emplace(task.pid, task);
    }
    if (running.empty()) return;
    int status = 0;
    const pid_t pid = ::waitpid(-1, &status, 0);  // blocks until a child ends
    if (pid < 0) {
      if (errno == EINTR) continue;
      throw std::runtime_error(StrCat("sweep: waiting for tasks failed: ", std::strerror(errno)));
    }
    const auto it = running.find(pid);
    if (it == running.end()) continue;  // not one of the tasks
    const RunningTask task = it->second;
    running.erase(it);
    queue.Finish(task.index, FinishSweepTask(task, status, queue.Folder().TaskDir(task.index)));
  }
}

bool LaunchedByMpirun() {
  return std::getenv("OMPI_COMM_WORLD_SIZE") != nullptr || std::getenv("PMIX_RANK") != nullptr;
}

// ---------------------------------------------------------------------------
// The gathered CSV.

namespace {

// One CSV cell: strings quoted when needed, arrays and objects as JSON.
std::string Cell(const nlohmann::json& value) {
  std::string text;
  if (value.is_null()) return "";
  text = value.is_string() ? value.get<std::string>() : value.dump();
  if (text.find_first_of(",\"\n\r") == std::string::npos) return text;
  std::string quoted = "\"";
  for (char c : text) {
    if (c == '"') quoted += '"';
    quoted += c;
  }
  return quoted + "\"";
}

}  // namespace

void WriteSweepResults(const SweepSpec& spec, const std::vector<SweepTask>& tasks,
                       const std::vector<SweepResult>& results, const fs::path& path) {
  DIFFDYN_CHECK(tasks.size() == results.size(), "WriteSweepResults: ", tasks.size(), " tasks but ",
                results.size(), " results");
  std::vector<std::string> header, keys;
  std::map<std::string, bool> taken = {{"exit_code", true}};
  for (const auto& [flag, values] : spec.grid) {
    header.push_back(flag.substr(2));
    taken[header.back()] = true;
  }
  for (const SweepResult& r : results) {
    if (!r.summary.is_object()) continue;
    for (const auto& [key, value] : r.summary.items()) {
      if (taken[key]) continue;
      taken[key] = true;
      keys.push_back(key);
    }
  }
  WriteFileAtomically(path, [&](std::ostream& out) {
    std::vector<std::string> columns = header;
    columns.insert(columns.end(), keys.begin(), keys.end());
    columns.push_back("exit_code");
    for (std::size_t c = 0; c < columns.size(); ++c) out << (c ? "," : "") << Cell(columns[c]);
    out << '\n';
    for (std::size_t t = 0; t < tasks.size(); ++t) {
      for (std::size_t g = 0; g < tasks[t].grid_values.size(); ++g) out << Cell(tasks[t].grid_values[g]) << ',';
      for (const std::string& key : keys) {
        const nlohmann::json& s = results[t].summary;
        out << (s.is_object() && s.contains(key) ? Cell(s[key]) : "") << ',';
      }
      out << results[t].exit_code << '\n';
    }
  });
}

}  // namespace diffdyn
