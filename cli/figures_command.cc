// diffdyn figures: every figure of both papers, each by its paper_figures program,
// run as the tasks of one sweep (solvers/sweep.h), and one page DIR/index.html with
// every PNG, its CSVs and our numbers beside the papers' (figures_page.h).
//
//   diffdyn figures --quick --out figs            # every figure at small sizes (minutes)
//   diffdyn figures --only hjb_pendulum --out figs
//   diffdyn figures --stored --out figs           # the stored full runs' page, nothing run
//
// Figure NAME writes into DIR/NAME/; its program's stdout and stderr go to
// DIR/tasks/<i>/. A figure made of a grid (manifest "grid", "quick_grid") is one task
// per combination, each into DIR/NAME/parts/<k>/, and its plot script then merges the
// parts into DIR/NAME/ (logs in DIR/plots/tasks/<j>/). Under `mpirun -np N diffdyn
// figures ...` the tasks run on the ranks (as `diffdyn sweep` does) and rank 0 merges
// and writes the page. The figures to run, their arguments and the numbers the page
// shows come from paper_figures/figures.json. With --resume, a task whose run is
// recorded in DIR with the same arguments is not run again. Speed rows (ours beside
// PyTorch) come from the stored benchmark comparisons of bench/results/, copied to
// DIR/bench/.
#include <algorithm>
#include <chrono>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <unistd.h>
#include <vector>

#include <fmt/core.h>

#include "command.h"
#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/io.h"
#include "diffdyn/solvers/sweep.h"
#include "figures_page.h"

namespace diffdyn::cli {
namespace {
namespace fs = std::filesystem;

struct FiguresOptions {
  std::string out;
  std::string only;
  std::string manifest = DIFFDYN_FIGURE_MANIFEST;
  std::string programs = DIFFDYN_FIGURE_PROGRAMS;
  std::string data = DIFFDYN_SHARED_DATA;
  std::string bench_results = DIFFDYN_BENCH_RESULTS;
  int workers = 1;
  bool quick = false;
  bool resume = false;
  bool stored = false;
  bool json = false;
  bool quiet = false;
};

// The figures `only` names (comma-separated; empty: all), in the manifest's order.
std::vector<const FigureEntry*> Select(const std::vector<FigureEntry>& all, const std::string& only) {
  std::set<std::string> wanted;
  for (std::size_t start = 0; !only.empty() && start <= only.size();) {
    const std::size_t comma = std::min(only.find(',', start), only.size());
    wanted.insert(only.substr(start, comma - start));
    start = comma + 1;
  }
  std::string known;
  for (const FigureEntry& e : all) known += (known.empty() ? "" : ", ") + e.name;
  for (const std::string& name : wanted) {
    DIFFDYN_CHECK(std::any_of(all.begin(), all.end(), [&](const FigureEntry& e) { return e.name == name; }),
                  "--only: unknown figure '", name.substr(0, 60), "' (", known, ")");
  }
  std::vector<const FigureEntry*> out;
  for (const FigureEntry& e : all) {
    if (wanted.empty() || wanted.count(e.name)) out.push_back(&e);
  }
  return out;
}

// `arg` with "{data}" replaced by the data folder.
std::string Substitute(std::string arg, const std::string& data) {
  for (std::size_t at = arg.find("{data}"); at != std::string::npos; at = arg.find("{data}", at + data.size())) {
    arg.replace(at, 6, data);
  }
  return arg;
}

std::string ShellQuote(const std::string& s) {
  if (!s.empty() && s.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-+=.,/:@") ==
                        std::string::npos) {
    return s;
  }
  std::string out = "'";
  for (const char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

// The tasks of one figure in the sweep: [first, first + count).
struct FigureTasks {
  const FigureEntry* entry = nullptr;
  std::size_t first = 0, count = 0;
  bool grid = false;  // run as a grid: parts to merge with the figure's plot script
};

// The figure's program and its arguments for this run ({data} substituted; a path
// under the data folder is checked now, not when the figure fails).
SweepTask FigureTask(const FigureEntry& e, const FiguresOptions& o) {
  SweepTask task;
  task.program = fs::path(o.programs) / e.program;
  DIFFDYN_CHECK(::access(task.program.c_str(), X_OK) == 0, "--programs: ", task.program.string(),
                " is not an executable (build the figure_* targets, or point --programs at them)");
  for (const std::string& arg : o.quick ? e.quick_args : e.full_args) {
    task.args.push_back(Substitute(arg, o.data));
    DIFFDYN_CHECK(arg.find("{data}") == std::string::npos || fs::exists(task.args.back()), "--data: ",
                  task.args.back(), " does not exist (figure ", e.name, " reads it)");
  }
  return task;
}

// The output folder of part k of a figure run as a grid: DIR/NAME/parts/<k>.
fs::path PartDir(const FiguresOptions& o, const FigureEntry& e, std::size_t k) {
  return fs::path(o.out) / e.name / "parts" / std::to_string(k);
}

// The sweep's tasks: per figure one run with "--out DIR/NAME --plot", or for a
// figure run as a grid one run per combination with "--out DIR/NAME/parts/<k>".
std::vector<SweepTask> MakeTasks(const std::vector<const FigureEntry*>& figures, const FiguresOptions& o,
                                 std::vector<FigureTasks>& spans) {
  std::vector<SweepTask> tasks;
  for (const FigureEntry* e : figures) {
    const SweepTask base = FigureTask(*e, o);
    const std::vector<SweepGrid>& grids = o.quick ? e->quick_grid : e->full_grid;
    FigureTasks span{e, tasks.size(), 0, !grids.empty()};
    const fs::path folder = fs::path(o.out) / e->name;
    if (grids.empty()) {
      SweepTask task = base;
      task.grid_values = {e->name};
      task.args.insert(task.args.end(), {"--out", folder.string(), "--plot"});
      tasks.push_back(std::move(task));
    }
    for (const SweepGrid& grid : grids) {
      for (const SweepPoint& point : ExpandSweepGrid(grid)) {
        SweepTask task = base;
        std::string values;
        for (const std::string& v : point.values) values += " " + v;
        task.grid_values = {e->name + values};
        task.args.insert(task.args.end(), point.args.begin(), point.args.end());
        task.args.insert(task.args.end(), {"--out", PartDir(o, *e, tasks.size() - span.first).string()});
        tasks.push_back(std::move(task));
      }
    }
    span.count = tasks.size() - span.first;
    spans.push_back(span);
  }
  for (std::size_t i = 0; i < tasks.size(); ++i) tasks[i].index = static_cast<int>(i);
  return tasks;
}

// Per figure run as a grid whose parts all succeeded: `python plot DIR/NAME
// DIR/NAME/parts/0 ...`, which merges the parts and draws.
std::vector<SweepTask> MakePlotTasks(const std::vector<FigureTasks>& spans, const std::vector<SweepResult>& results,
                                     const FiguresOptions& o) {
  std::vector<SweepTask> plots;
  for (const FigureTasks& span : spans) {
    bool ok = span.grid;
    for (std::size_t i = span.first; i < span.first + span.count; ++i) ok = ok && results[i].exit_code == 0;
    if (!ok) continue;
    SweepTask plot;
    plot.index = static_cast<int>(plots.size());
    plot.grid_values = {span.entry->name + " plot"};
    plot.program = DIFFDYN_PYTHON;
    plot.args = {(fs::path(o.manifest).parent_path() / span.entry->plot).string(),
                 (fs::path(o.out) / span.entry->name).string()};
    for (std::size_t k = 0; k < span.count; ++k) plot.args.push_back(PartDir(o, *span.entry, k).string());
    plots.push_back(std::move(plot));
  }
  return plots;
}

std::string CommandText(const SweepTask& task) {
  std::string text = ShellQuote(task.program.string());
  for (const std::string& arg : task.args) text += " " + ShellQuote(arg);
  return text;
}

// How each figure went: its tasks' (and plot's) commands, logs, time and exit code.
std::vector<FigureRun> FigureRuns(const std::vector<FigureTasks>& spans, const std::vector<SweepTask>& tasks,
                                  const std::vector<SweepResult>& results, const std::vector<SweepTask>& plots,
                                  const std::vector<SweepResult>& plot_results) {
  std::vector<FigureRun> runs;
  auto add = [](FigureRun& run, const SweepTask& task, const SweepResult& r, const std::string& log_dir) {
    run.commands.push_back(CommandText(task));
    run.log_dirs.push_back(log_dir);
    run.seconds += r.seconds;
    if (run.exit_code == 0) run.exit_code = r.exit_code;
  };
  std::size_t plot = 0;
  for (const FigureTasks& span : spans) {
    FigureRun run{span.entry, {}, 0, 0, {}, ""};
    for (std::size_t i = span.first; i < span.first + span.count; ++i) {
      add(run, tasks[i], results[i], fmt::format("tasks/{}", i));
    }
    if (span.grid && run.exit_code == 0) {
      add(run, plots[plot], plot_results[plot], fmt::format("plots/tasks/{}", plot));
      ++plot;
    }
    runs.push_back(std::move(run));
  }
  return runs;
}

std::string UtcNow() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  ::gmtime_r(&now, &tm);
  char buffer[32];
  std::strftime(buffer, sizeof buffer, "%Y-%m-%d %H:%M UTC", &tm);
  return buffer;
}

// The command line that redoes this run (options at their defaults left out).
std::string Invocation(const FiguresOptions& o) {
  const FiguresOptions defaults;
  std::string text = "diffdyn figures";
  if (o.quick) text += " --quick";
  if (!o.only.empty()) text += " --only " + ShellQuote(o.only);
  if (o.workers != defaults.workers) text += fmt::format(" --workers {}", o.workers);
  if (o.resume) text += " --resume";
  if (o.stored) text += " --stored";
  if (o.manifest != defaults.manifest) text += " --manifest " + ShellQuote(o.manifest);
  if (o.programs != defaults.programs) text += " --programs " + ShellQuote(o.programs);
  if (o.data != defaults.data) text += " --data " + ShellQuote(o.data);
  if (o.bench_results != defaults.bench_results) text += " --bench-results " + ShellQuote(o.bench_results);
  return text + " --out " + ShellQuote(o.out);
}

// Copies the stored benchmark comparisons the figures cite into DIR/bench/ (a
// missing one is left for the page to name).
void CopyBenchResults(const std::vector<const FigureEntry*>& figures, const FiguresOptions& o) {
  for (const FigureEntry* e : figures) {
    for (const FigureNumber& n : e->numbers) {
      const fs::path from = fs::path(o.bench_results) / n.csv, to = fs::path(o.out) / "bench" / n.csv;
      if (!n.bench || !fs::is_regular_file(from)) continue;
      fs::create_directories(to.parent_path());
      fs::copy_file(from, to, fs::copy_options::overwrite_existing);
    }
  }
}

// The first line of `path` (a stored CSV part).
std::string HeaderOf(const fs::path& path) {
  std::ifstream in(path);
  std::string line;
  DIFFDYN_CHECK(in.good() && std::getline(in, line), path.string(), ": cannot read its header");
  return line;
}

// Every part of a stored CSV has the first part's header (checked before anything is written).
void CheckStoredParts(const std::vector<const FigureEntry*>& figures, const fs::path& root) {
  for (const FigureEntry* e : figures) {
    for (const auto& [file, parts] : e->stored.parts) {
      const fs::path folder = root / e->stored.folder;
      const std::string header = HeaderOf(folder / parts[0]);
      for (const std::string& part : parts) {
        DIFFDYN_CHECK(HeaderOf(folder / part) == header, (folder / part).string(), ": its header differs from ",
                      parts[0], "'s (", file, " is stored in parts)");
      }
    }
  }
}

// Writes `to` from the stored `parts`: the first part whole, the others without their header.
void JoinParts(const fs::path& folder, const std::vector<std::string>& parts, const fs::path& to) {
  WriteFileAtomically(to, [&](std::ostream& out) {
    for (std::size_t i = 0; i < parts.size(); ++i) {
      std::ifstream in(folder / parts[i]);
      std::string line;
      for (bool header = true; std::getline(in, line); header = false) {
        if (!header || i == 0) out << line << '\n';
      }
    }
  });
}

// The figures' stored full runs (manifest key "stored") copied into DIR/NAME/:
// the listed PNGs and CSVs, a CSV stored in parts joined. A figure without a
// stored run, or missing files, is left for the page to name.
std::vector<FigureRun> CopyStoredRuns(const std::vector<const FigureEntry*>& figures, const FiguresOptions& o) {
  const fs::path root = fs::path(o.manifest).parent_path();
  std::vector<FigureRun> runs;
  for (const FigureEntry* e : figures) {
    FigureRun run{e, {}, 0, 0, {}, "none stored"};
    std::string command = ShellQuote((fs::path(o.programs) / e->program).string());
    for (const std::string& arg : e->full_args) command += " " + ShellQuote(Substitute(arg, o.data));
    if (!e->stored.folder.empty()) {
      const fs::path from = root / e->stored.folder, to = fs::path(o.out) / e->name;
      run.stored = "paper_figures/" + e->stored.folder;
      command += " --out " + ShellQuote(run.stored) + " --plot";
      fs::create_directories(to);
      for (const std::vector<std::string>* list : {&e->images, &e->files}) {
        for (const std::string& file : *list) {
          const auto parts = std::find_if(e->stored.parts.begin(), e->stored.parts.end(),
                                          [&](const auto& p) { return p.first == file; });
          if (parts != e->stored.parts.end()) {
            JoinParts(from, parts->second, to / file);
          } else if (fs::is_regular_file(from / file)) {
            fs::create_directories((to / file).parent_path());
            fs::copy_file(from / file, to / file, fs::copy_options::overwrite_existing);
          }
        }
      }
    }
    run.commands = {command};
    runs.push_back(std::move(run));
  }
  return runs;
}

// --stored: the page from the stored full runs, nothing run.
void WriteStoredPage(const FiguresOptions& o, const std::string& invocation) {
  const auto start = std::chrono::steady_clock::now();
  const std::vector<FigureEntry> manifest = ReadFigureManifest(o.manifest);
  const std::vector<const FigureEntry*> figures = Select(manifest, o.only);
  const fs::path page = fs::path(o.out) / "index.html";
  CheckOutputPath(page);
  CheckStoredParts(figures, fs::path(o.manifest).parent_path());
  const std::vector<FigureRun> runs = CopyStoredRuns(figures, o);
  CopyBenchResults(figures, o);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  PageInfo info{false, true, DescribeMachine(), UtcNow(), invocation, seconds};
  WriteFiguresPage(page, runs, info);
  if (o.json) {
    PrintJson({{"figures", figures.size()}, {"done", figures.size()}, {"failed", 0}, {"seconds", seconds},
               {"index_path", page.string()}});
  } else {
    fmt::print("{} stored figure{}; page: {}\n", figures.size(), figures.size() == 1 ? "" : "s", page.string());
  }
}

// Runs the figures' sweep (on mpirun's ranks or local workers; without --resume
// every task anew) and returns the results in task order; nothing on the ranks
// other than 0, which stop here.
std::optional<std::vector<SweepResult>> RunFigureTasks(const std::vector<SweepTask>& tasks, const FiguresOptions& o,
                                                       SweepQueue::Progress progress) {
  const SweepFolder folder(o.out);
  std::error_code ec;
  if (!o.resume && MpiRankFromEnvironment() == 0) {  // under mpirun only rank 0 clears
    for (const SweepTask& t : tasks) fs::remove(folder.TaskDir(t.index) / "result.json", ec);
  }
  SweepQueue queue(tasks, folder, std::move(progress));
  if (!RunSweepTasks(fs::read_symlink("/proc/self/exe"), queue, o.workers).coordinator) return std::nullopt;
  return queue.Results();
}

// The progress line of one finished task (nothing with --quiet).
SweepQueue::Progress ProgressPrinter(const FiguresOptions& o, std::size_t total) {
  return [&o, total](const SweepTask& t, const SweepResult& r, std::size_t finished) {
    if (!o.quiet) {
      fmt::print(stderr, "figures: [{}/{}] {}: exit {}, {:.1f} s\n", finished, total, t.grid_values[0], r.exit_code,
                 r.seconds);
    }
  };
}

void RunFigures(const FiguresOptions& o, const std::string& invocation) {
  if (o.stored) return WriteStoredPage(o, invocation);
  const auto start = std::chrono::steady_clock::now();
  const std::vector<FigureEntry> manifest = ReadFigureManifest(o.manifest);
  const std::vector<const FigureEntry*> figures = Select(manifest, o.only);
  const fs::path out(o.out), page = fs::path(o.out) / "index.html";
  CheckOutputPath(page);
  std::vector<FigureTasks> spans;
  const std::vector<SweepTask> tasks = MakeTasks(figures, o, spans);
  std::error_code ec;
  fs::create_directories(out / "tasks", ec);
  if (ec) throw std::runtime_error(StrCat(o.out, ": cannot create the folder: ", ec.message()));
  if (!o.quiet && MpiRankFromEnvironment() == 0) {
    for (const FigureEntry* e : figures) {
      fmt::print(stderr, "figures: {} ({}){}\n", e->name, e->paper, o.quick ? "" : "; full run: " + e->full_time);
    }
  }
  const std::optional<std::vector<SweepResult>> results = RunFigureTasks(tasks, o, ProgressPrinter(o, tasks.size()));
  if (!results) return;

  // The grids' parts merged and drawn by each figure's plot script, always anew.
  const std::vector<SweepTask> plots = MakePlotTasks(spans, *results, o);
  const SweepFolder plot_folder(out / "plots");
  for (const SweepTask& t : plots) fs::remove(plot_folder.TaskDir(t.index) / "result.json", ec);
  SweepQueue plot_queue(plots, plot_folder, ProgressPrinter(o, plots.size()));
  RunSweepLocal(DIFFDYN_PYTHON, plot_queue, o.workers);

  const std::vector<FigureRun> runs = FigureRuns(spans, tasks, *results, plots, plot_queue.Results());
  std::vector<std::string> failed;
  for (const FigureRun& run : runs) {
    if (run.exit_code != 0) failed.push_back(run.entry->name);
  }
  CopyBenchResults(figures, o);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  WriteFiguresPage(page, runs, {o.quick, false, DescribeMachine(), UtcNow(), invocation, seconds});
  if (!failed.empty()) {
    std::string names;
    for (const std::string& n : failed) names += (names.empty() ? "" : ", ") + n;
    throw std::runtime_error(StrCat("figures: ", failed.size(), " of ", figures.size(), " figures failed (", names,
                                    "); their logs are linked from ", page.string()));
  }
  if (o.json) {
    PrintJson({{"figures", figures.size()}, {"done", figures.size()}, {"failed", 0}, {"seconds", seconds},
               {"index_path", page.string()}});
  } else {
    fmt::print("{} figure{} in {:.1f} s; page: {}\n", figures.size(), figures.size() == 1 ? "" : "s", seconds,
               page.string());
  }
}

}  // namespace

void RegisterFiguresCommand(CLI::App& app) {
  auto* command = app.add_subcommand(
      "figures", "Regenerate every figure of both papers and one page DIR/index.html with ours beside the papers'");
  auto o = std::make_shared<FiguresOptions>();
  command->add_option("--out", o->out, "Output folder: one folder per figure, tasks/ with logs, index.html")
      ->required()
      ->check(OutputPath(/*folder=*/true));
  command->add_option("--only", o->only, "Comma-separated figure names (default: all; see paper_figures/figures.json)");
  command->add_flag("--quick", o->quick, "Small sizes (minutes): every figure is produced, numbers not comparable");
  command->add_option("--workers", o->workers, "Figures run at once without mpirun (each uses both cores itself)")
      ->check(Bounded(1, 64))
      ->capture_default_str();
  command->add_flag("--resume", o->resume, "Keep the figures already recorded in --out with the same arguments");
  command->add_flag("--stored", o->stored,
                    "Run nothing: the page from the full runs stored under paper_figures/ (manifest key 'stored')")
      ->excludes("--quick")
      ->excludes("--resume");
  command->add_option("--manifest", o->manifest, "The figures and their numbers")->check(InputPath())->capture_default_str();
  command->add_option("--programs", o->programs, "Folder of the figure_* programs")->capture_default_str();
  command->add_option("--data", o->data, "The shared data folder ({data} in the manifest)")->capture_default_str();
  command->add_option("--bench-results", o->bench_results,
                      "Folder of the stored benchmark comparisons the page cites (copied to DIR/bench/)")
      ->check(InputPath(/*allow_folder=*/true))
      ->capture_default_str();
  command->add_flag("--json", o->json, "Print a one-line JSON summary on stdout");
  command->add_flag("--quiet", o->quiet, "No progress lines");
  command->callback([o] {
    RunFigures(*o, Invocation(*o));
  });
}

}  // namespace diffdyn::cli
