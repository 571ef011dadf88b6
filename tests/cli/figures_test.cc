// diffdyn figures on a manifest of stand-in figure programs (shell scripts that
// write a CSV and a PNG), so the command is tested apart from the papers' figures:
// the page's numbers, ratios and verdicts, the independent page checker
// (scripts/check_figures_page.py) passing on it and failing on a changed number or
// a missing image, speed rows with PyTorch's time from a stored benchmark
// comparison, the page of stored runs (copied, parts joined, nothing run), a
// failing figure (exit 1, page still written), a figure run as a grid (one task
// per combination, parts merged by its plot script), and bad input,
// a missing {data} file among it (one line, exit 2, nothing written). The real
// figures' quick run is the ctest paper_figures.figures_quick.
#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "run_diffdyn.h"

namespace diffdyn {
namespace {
namespace fs = std::filesystem;

using testing::CountLines;
using testing::ReadAll;
using testing::RunDiffdyn;
using testing::TempPath;

// A folder with programs `fig_ok` (writes out/values.csv with three rows and
// out/plot.png) and `fig_fail` (exit 3), and a manifest naming both.
struct StandIns {
  std::string programs, manifest;
};

void WriteProgram(const fs::path& path, const std::string& body) {
  std::ofstream(path) << "#!/bin/sh\n" << body;
  fs::permissions(path, fs::perms::owner_all);
}

// An empty folder `name` under the tests' temporary folder.
fs::path EmptyDir(const std::string& name) {
  const fs::path dir = TempPath(name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

StandIns MakeStandIns(const std::string& name, bool with_failing) {
  const fs::path dir = EmptyDir(name);
  // Arguments: [--quick] --out DIR --plot.
  WriteProgram(dir / "fig_ok",
               "while [ $# -gt 0 ]; do [ \"$1\" = --out ] && out=$2; shift; done\n"
               "mkdir -p \"$out\"\n"
               "printf 'kind,seed,loss\\na,1,1.0\\na,2,10.0\\na,3,2.0\\nb,1,0.125\\n' > \"$out/values.csv\"\n"
               "printf 'png' > \"$out/plot.png\"\n"
               "echo run >> \"$out/runs.txt\"\n");
  WriteProgram(dir / "fig_fail", "echo broken >&2\nexit 3\n");
  const std::string failing = R"(, {"name": "broken", "paper": "Fig. 9", "title": "t", "caption": "c",
      "program": "fig_fail", "full_args": [], "quick_args": [], "full_time": "none",
      "images": [], "files": [], "numbers": []})";
  std::ofstream(dir / "figures.json") << R"({"figures": [{"name": "ok", "paper": "Fig. 1", "title": "Stand-in",
      "caption": "A <stand-in> figure", "program": "fig_ok", "full_args": [], "quick_args": ["--quick"],
      "full_time": "seconds", "images": ["plot.png"], "files": ["values.csv"], "numbers": [
        {"label": "median loss of a", "csv": "values.csv", "where": {"kind": "a"}, "column": "loss",
         "reduce": "median", "reference": 4, "reference_source": "paper", "accept": {"max_ratio": 1}},
        {"label": "loss of b", "csv": "values.csv", "where": {"kind": "b"}, "column": "loss",
         "reduce": "value", "reference": 0.1, "accept": {"max": 0.1}},
        {"label": "loss of c", "csv": "values.csv", "where": {"kind": "c"}, "column": "loss", "reduce": "value"}]})"
                                  << (with_failing ? failing : "") << "]}\n";
  return {dir.string(), (dir / "figures.json").string()};
}

std::string Options(const StandIns& s, const std::string& out) {
  return "figures --quiet --manifest '" + s.manifest + "' --programs '" + s.programs + "' --out '" + out + "'";
}

int CheckPage(const std::string& page) {
  const std::string cmd = std::string(DIFFDYN_PYTHON) + " '" + DIFFDYN_SOURCE_DIR +
                          "/scripts/check_figures_page.py' '" + page + "' > /dev/null";
  return WEXITSTATUS(std::system(cmd.c_str()));
}

TEST(Figures, PageShowsEachNumberBesideItsReferenceAndTheCheckerAgrees) {
  const StandIns s = MakeStandIns("figures_ok", false);
  const std::string out = TempPath("figures_ok_out");
  fs::remove_all(out);
  const auto r = RunDiffdyn(Options(s, out) + " --quick --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string page = ReadAll(out + "/index.html");
  // The median of 1, 10, 2 is 2: half the reference 4, within ratio <= 1.
  EXPECT_NE(page.find("data-reduce=\"median\">2</td><td>4</td><td>paper</td><td>0.5</td>"), std::string::npos);
  EXPECT_NE(page.find(">meets<"), std::string::npos);
  // 0.125 > 0.1: misses, and the summary names it.
  EXPECT_NE(page.find(">0.125</td>"), std::string::npos);
  EXPECT_NE(page.find("<li>Fig. 1: loss of b</li>"), std::string::npos);
  EXPECT_NE(page.find("missing: 0 matching rows"), std::string::npos);
  EXPECT_NE(page.find("A &lt;stand-in&gt; figure"), std::string::npos);
  EXPECT_NE(page.find("fig_ok --quick --out"), std::string::npos);
  EXPECT_NE(page.find("<img src=\"ok/plot.png\""), std::string::npos);
  EXPECT_EQ(CheckPage(out + "/index.html"), 0);

  // The checker recomputes from the CSV: a changed number or a missing image fails it.
  std::string changed = page;
  changed.replace(changed.find(">0.125<"), 7, ">0.126<");
  std::ofstream(out + "/changed.html") << changed;
  EXPECT_EQ(CheckPage(out + "/changed.html"), 1);
  fs::remove(out + "/ok/plot.png");
  EXPECT_EQ(CheckPage(out + "/index.html"), 1);
}

TEST(Figures, BenchRowsSetPyTorchBesideOursFromTheStoredComparison) {
  const StandIns s = MakeStandIns("figures_bench", false);
  const fs::path bench = EmptyDir("figures_bench_results");
  std::ofstream(bench / "speed.csv") << "workload,precision,ours_ms,torch_ms,machine,date\n"
                                        "epoch,f64,3,10,Some CPU (2 cores; AVX2),2026-11-30\n"
                                        "epoch,f32,2,4,Some CPU (2 cores; AVX2),2026-11-30\n";
  std::ofstream(s.manifest) << R"({"figures": [{"name": "ok", "paper": "Fig. 1", "title": "t", "caption": "c",
      "program": "fig_ok", "full_args": [], "quick_args": [], "full_time": "", "images": [], "files": [], "numbers": [
        {"label": "f64 epoch", "bench": true, "csv": "speed.csv", "where": {"precision": "f64"}, "column": "ours_ms",
         "reduce": "value", "pytorch_column": "torch_ms", "accept": {"max_pytorch_ratio": 0.33}},
        {"label": "f32 epoch", "bench": true, "csv": "speed.csv", "where": {"precision": "f32"}, "column": "ours_ms",
         "reduce": "value", "pytorch_column": "torch_ms", "accept": {"max_pytorch_ratio": 0.33}},
        {"label": "not measured", "bench": true, "csv": "absent.csv", "column": "ours_ms", "reduce": "value",
         "pytorch_column": "torch_ms"}]}]})";
  const std::string out = TempPath("figures_bench_out");
  fs::remove_all(out);
  const auto r = RunDiffdyn(Options(s, out) + " --bench-results '" + bench.string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string page = ReadAll(out + "/index.html");
  // 3 ms against 10 ms: 0.3, within 0.33; 2 against 4: 0.5 misses; the CSV is copied beside the page.
  EXPECT_EQ(ReadAll(out + "/bench/speed.csv"), ReadAll((bench / "speed.csv").string()));
  EXPECT_NE(page.find("data-csv=\"bench/speed.csv\" data-where=\"precision=f64\" data-column=\"torch_ms\" "
                      "data-reduce=\"value\">10</td><td>0.3</td>"),
            std::string::npos);
  EXPECT_NE(page.find("<li>Fig. 1: f32 epoch</li>"), std::string::npos);
  EXPECT_EQ(page.find("<li>Fig. 1: f64 epoch</li>"), std::string::npos);
  EXPECT_NE(page.find("ours / PyTorch ≤ 0.33"), std::string::npos);
  EXPECT_NE(page.find("benchmark run on Some CPU (2 cores; AVX2), 2026-11-30"), std::string::npos);
  EXPECT_NE(page.find("missing: no CSV"), std::string::npos);
  EXPECT_EQ(CheckPage(out + "/index.html"), 0);
  // The checker recomputes the PyTorch cells too.
  std::string changed = page;
  changed.replace(changed.find(">10</td>"), 8, ">11</td>");
  std::ofstream(out + "/changed.html") << changed;
  EXPECT_EQ(CheckPage(out + "/changed.html"), 1);
}

TEST(Figures, StoredRunsAreCopiedAndJoinedNotRun) {
  const StandIns s = MakeStandIns("figures_stored", false);
  const fs::path stored = fs::path(s.programs) / "kept";
  fs::create_directories(stored);
  std::ofstream(stored / "values_a.csv") << "kind,seed,loss\na,1,1.0\na,2,10.0\n";
  std::ofstream(stored / "values_b.csv") << "kind,seed,loss\na,3,2.0\nb,1,0.125\n";
  std::ofstream(stored / "plot.png") << "png";
  std::string manifest = ReadAll(s.manifest);
  manifest.replace(manifest.find("\"numbers\""), 0,
                   R"("stored": {"folder": "kept", "parts": {"values.csv": ["values_a.csv", "values_b.csv"]}}, )");
  std::ofstream(s.manifest) << manifest;
  const std::string out = TempPath("figures_stored_out");
  fs::remove_all(out);
  const auto r = RunDiffdyn(Options(s, out) + " --stored");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_FALSE(fs::exists(out + "/ok/runs.txt"));  // the program did not run
  EXPECT_EQ(ReadAll(out + "/ok/values.csv"), "kind,seed,loss\na,1,1.0\na,2,10.0\na,3,2.0\nb,1,0.125\n");
  const std::string page = ReadAll(out + "/index.html");
  EXPECT_NE(page.find("<b>Stored full runs</b>"), std::string::npos);
  EXPECT_NE(page.find("Stored full run: paper_figures/kept"), std::string::npos);
  // The joined rows give the same median as a run: 2 against the reference 4.
  EXPECT_NE(page.find("data-reduce=\"median\">2</td><td>4</td>"), std::string::npos);
  EXPECT_EQ(CheckPage(out + "/index.html"), 0);

  // Parts whose headers differ are refused before anything is written, and --stored excludes --quick.
  std::ofstream(stored / "values_b.csv") << "kind,loss\nb,0.125\n";
  const std::string bad_out = TempPath("figures_stored_bad");
  fs::remove_all(bad_out);
  const auto bad = RunDiffdyn(Options(s, bad_out) + " --stored");
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_EQ(CountLines(bad.err), 1) << bad.err;
  EXPECT_NE(bad.err.find("values_b.csv: its header differs from values_a.csv's"), std::string::npos) << bad.err;
  EXPECT_FALSE(fs::exists(bad_out + "/ok"));
  EXPECT_EQ(RunDiffdyn(Options(s, TempPath("figures_stored_bad")) + " --stored --quick").exit_code, 2);
}

TEST(Figures, AFailingFigureIsARuntimeFailureWithThePageWritten) {
  const StandIns s = MakeStandIns("figures_fail", true);
  const std::string out = TempPath("figures_fail_out");
  fs::remove_all(out);
  const auto r = RunDiffdyn(Options(s, out));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("1 of 2 figures failed (broken)"), std::string::npos) << r.err;
  const std::string page = ReadAll(out + "/index.html");
  EXPECT_NE(page.find("2 figures, 1 failed"), std::string::npos);
  EXPECT_EQ(ReadAll(out + "/tasks/1/stderr.txt"), "broken\n");

  // Only the failing one again, with --resume: the finished figure is not rerun.
  const auto again = RunDiffdyn(Options(s, out) + " --only ok --resume");
  EXPECT_EQ(again.exit_code, 0) << again.err;
  EXPECT_EQ(ReadAll(out + "/ok/runs.txt"), "run\n");
  // Without --resume it runs again.
  EXPECT_EQ(RunDiffdyn(Options(s, out) + " --only ok").exit_code, 0);
  EXPECT_EQ(ReadAll(out + "/ok/runs.txt"), "run\nrun\n");
}

// A stand-in figure run as a grid: `fig_row --kind K --seed S --out DIR` writes one
// row of values.csv; plot.py merges the parts' rows into its first argument.
StandIns MakeGridStandIn(const std::string& name, const std::string& grid) {
  const fs::path dir = EmptyDir(name);
  WriteProgram(dir / "fig_row",
               "while [ $# -gt 0 ]; do case $1 in --out) out=$2;; --kind) k=$2;; --seed) s=$2;; --plot) exit 9;; "
               "esac; shift; done\n"
               "[ \"$k\" = x ] && exit 4\n"
               "mkdir -p \"$out\"\n"
               "case $k$s in a1) l=1.0;; a2) l=10.0;; a3) l=2.0;; *) l=0.125;; esac\n"
               "printf 'kind,seed,loss\\n%s,%s,%s\\n' $k $s $l > \"$out/values.csv\"\n");
  std::ofstream(dir / "plot.py") << "import sys\n"
                                    "rows = [open(p + '/values.csv').read().splitlines() for p in sys.argv[2:]]\n"
                                    "open(sys.argv[1] + '/values.csv', 'w').write('\\n'.join([rows[0][0]] + "
                                    "[r[1] for r in rows]) + '\\n')\n"
                                    "open(sys.argv[1] + '/plot.png', 'w').write('png')\n";
  std::ofstream(dir / "figures.json") << R"({"figures": [{"name": "ok", "paper": "Fig. 1", "title": "Grid",
      "caption": "c", "program": "fig_row", "full_args": [], "quick_args": [], "grid": )" << grid << R"(,
      "plot": "plot.py", "full_time": "seconds", "images": ["plot.png"], "files": ["values.csv"], "numbers": [
        {"label": "median loss of a", "csv": "values.csv", "where": {"kind": "a"}, "column": "loss",
         "reduce": "median", "reference": 4}]}]})";
  return {dir.string(), (dir / "figures.json").string()};
}

TEST(Figures, AGridFigureRunsOneTaskPerCombinationAndItsPlotMergesTheParts) {
  const StandIns s = MakeGridStandIn(
      "figures_grid", R"([{"--kind": ["a"], "--seed": [1, 2, 3]}, {"--kind": ["b"], "--seed": [1]}])");
  const std::string out = TempPath("figures_grid_out");
  fs::remove_all(out);
  const auto r = RunDiffdyn(Options(s, out) + " --workers 2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // Four tasks in grid order (no --plot), then the merge.
  EXPECT_EQ(ReadAll(out + "/ok/parts/1/values.csv"), "kind,seed,loss\na,2,10.0\n");
  EXPECT_EQ(ReadAll(out + "/ok/parts/3/values.csv"), "kind,seed,loss\nb,1,0.125\n");
  EXPECT_FALSE(fs::exists(out + "/tasks/4"));
  EXPECT_EQ(ReadAll(out + "/ok/values.csv"), "kind,seed,loss\na,1,1.0\na,2,10.0\na,3,2.0\nb,1,0.125\n");
  const std::string page = ReadAll(out + "/index.html");
  EXPECT_NE(page.find("data-reduce=\"median\">2</td>"), std::string::npos);
  EXPECT_NE(page.find("fig_row --kind a --seed 3 --out"), std::string::npos);
  EXPECT_NE(page.find("plot.py"), std::string::npos);
  EXPECT_NE(page.find("plots/tasks/0/stdout.txt"), std::string::npos);
  EXPECT_EQ(CheckPage(out + "/index.html"), 0);

  // A failing combination fails the figure and nothing is merged.
  const StandIns bad = MakeGridStandIn("figures_grid_bad", R"([{"--kind": ["a", "x"], "--seed": [1]}])");
  const std::string out_bad = TempPath("figures_grid_bad_out");
  fs::remove_all(out_bad);
  const auto failed = RunDiffdyn(Options(bad, out_bad));
  EXPECT_EQ(failed.exit_code, 1);
  EXPECT_NE(failed.err.find("1 of 1 figures failed (ok)"), std::string::npos) << failed.err;
  EXPECT_FALSE(fs::exists(out_bad + "/ok/values.csv"));
  EXPECT_FALSE(fs::exists(out_bad + "/plots/tasks/0"));
}

TEST(Figures, MpirunWithTwoRanksWritesTheSamePage) {
#if !defined(DIFFDYN_MPIEXEC)
  GTEST_SKIP() << "built without MPI";
#else
  const StandIns s = MakeStandIns("figures_mpi", false);
  const std::string out = TempPath("figures_mpi_out");
  fs::remove_all(out);
  const std::string launcher =
      "OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=none "
      "OMPI_MCA_rmaps_base_oversubscribe=1 ASAN_OPTIONS=detect_leaks=0 " DIFFDYN_MPIEXEC " -np 2 ";
  const auto r = RunDiffdyn(Options(s, out) + " --json", launcher);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(CountLines(r.out), 1) << r.out;  // only rank 0 reports
  EXPECT_NE(ReadAll(out + "/index.html").find("data-reduce=\"median\">2</td>"), std::string::npos);
  EXPECT_EQ(CheckPage(out + "/index.html"), 0);
#endif
}

TEST(Figures, BadInputIsOneLineExitTwoAndNothingWritten) {
  const StandIns s = MakeStandIns("figures_bad", false);
  const std::string out = TempPath("figures_bad_out");
  fs::remove_all(out);
  const auto expect_refused = [&](const std::string& args, const std::string& needle) {
    const auto r = RunDiffdyn(args);
    EXPECT_EQ(r.exit_code, 2) << args;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(needle), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(out)) << args;
  };
  expect_refused(Options(s, out) + " --only ok,nope", "--only: unknown figure 'nope' (ok)");
  expect_refused("figures --manifest '" + s.manifest + "' --programs /nonexistent --out '" + out + "'",
                 "--programs: /nonexistent/fig_ok is not an executable");
  const std::string manifest = TempPath("figures_bad_manifest.json");
  std::ofstream(manifest) << R"({"figures": [{"name": "x", "paper": "p", "title": "t", "caption": "c",
      "program": "fig_ok", "full_args": [], "quick_args": [], "full_time": "", "images": [], "files": [],
      "numbers": [{"label": "l", "csv": "../up.csv", "column": "c", "reduce": "value"}]}]})";
  expect_refused("figures --manifest '" + manifest + "' --programs '" + s.programs + "' --out '" + out + "'",
                 "must be a relative path inside the figure's folder");
  std::ofstream(manifest) << R"({"figures": [{"name": "x", "paper": "p", "title": "t", "caption": "c",
      "program": "fig_ok", "full_args": [], "quick_args": [], "full_time": "", "images": [], "files": [],
      "numbers": [{"label": "l", "csv": "a.csv", "column": "c", "reduce": "mode"}]}]})";
  expect_refused("figures --manifest '" + manifest + "' --programs '" + s.programs + "' --out '" + out + "'",
                 "unknown reduce 'mode'");
  std::ofstream(manifest) << R"({"figures": [{"name": "x", "paper": "p", "title": "t", "caption": "c",
      "program": "fig_ok", "full_args": [], "quick_args": [], "full_time": "", "images": [], "files": [],
      "numbers": [{"label": "l", "csv": "a.csv", "column": "c", "reduce": "value", "accept": {"max_pytorch_ratio": 1}}]}]})";
  expect_refused("figures --manifest '" + manifest + "' --programs '" + s.programs + "' --out '" + out + "'",
                 "'max_pytorch_ratio' needs a 'pytorch_column'");
  std::ofstream(manifest) << R"({"figures": [{"name": "x", "paper": "p", "title": "t", "caption": "c",
      "program": "fig_ok", "full_args": [], "quick_args": [], "grid": [{"--seed": [1]}], "full_time": "",
      "images": [], "files": [], "numbers": []}]})";
  expect_refused("figures --manifest '" + manifest + "' --programs '" + s.programs + "' --out '" + out + "'",
                 "a figure run as a grid needs a 'plot' script");
  std::ofstream(manifest) << R"({"figures": [{"name": "x", "paper": "p", "title": "t", "caption": "c",
      "program": "fig_ok", "full_args": [], "quick_args": [], "grid": [{"--out": ["a"]}], "plot": "p.py",
      "full_time": "", "images": [], "files": [], "numbers": []}]})";
  expect_refused("figures --manifest '" + manifest + "' --programs '" + s.programs + "' --out '" + out + "'",
                 "'--out' is set by diffdyn figures");
  expect_refused(Options(s, out) + " --workers 0", "--workers");
  expect_refused(Options(s, out) + " --bench-results /nonexistent", "--bench-results");
  std::ofstream(manifest) << R"({"figures": [{"name": "x", "paper": "p", "title": "t", "caption": "c",
      "program": "fig_ok", "full_args": ["--data", "{data}/missing.csv"], "quick_args": ["--data", "{data}/missing.csv"],
      "full_time": "", "images": [], "files": [], "numbers": []}]})";
  expect_refused("figures --manifest '" + manifest + "' --programs '" + s.programs + "' --data /nonexistent --out '" +
                     out + "'",
                 "--data: /nonexistent/missing.csv does not exist (figure x reads it)");
}

}  // namespace
}  // namespace diffdyn
