// The figures page: the manifest of the papers' figures (paper_figures/figures.json),
// the numbers each figure's CSVs give, and DIR/index.html that sets them beside the
// papers' (or an issue's) reference values.
//
//   std::vector<FigureEntry> figures = ReadFigureManifest("paper_figures/figures.json");
//   NumberValue v = EvaluateFigureNumber(figures[0].numbers[0], "out/mppi_obstacle");
//   WriteFiguresPage("out/index.html", runs, page_info);
//
// A number is `reduce` (value, median, mean, min, max, count) over column `column`
// of the rows of `csv` whose cells equal every `where` entry; "value" requires
// exactly one such row. The page's cell carries the same recipe as data attributes
// (data-csv, data-where, data-column, data-reduce), so a reader or a test can redo it.
//
// A number with "bench": true reads a stored benchmark comparison (bench/results/,
// written by the PyTorch references of bench/) that the page copies to DIR/bench/;
// its "pytorch_column" (ours_ms beside torch_ms) is set beside ours with the ratio,
// and the row names the machine and date of that benchmark run.
#pragma once

#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "diffdyn/solvers/sweep.h"

namespace diffdyn::cli {

/// One number of a figure, read from the figure's CSV.
struct FigureNumber {
  std::string label;
  std::string csv;  // relative to the figure's output folder
  std::vector<std::pair<std::string, std::string>> where;
  std::string column;
  std::string reduce = "value";
  bool bench = false;           // csv is under DIR/bench/ (a bench/results/ file), not DIR/<figure>/
  std::string pytorch_column;   // the same rows' PyTorch time (empty: no PyTorch reference)
  std::optional<double> reference;
  std::string reference_source;
  // Acceptance: bounds on the value, on value / reference and on value / PyTorch
  // (unset: none).
  std::optional<double> min, max, min_ratio, max_ratio, max_pytorch_ratio;
};

/// Where a figure's full run is stored in the repository (manifest key "stored").
struct StoredRun {
  std::string folder;  // relative to the manifest's folder; empty: none stored
  // Files the full run writes as one that are stored in parts (same header, rows in turn).
  std::vector<std::pair<std::string, std::vector<std::string>>> parts;
};

/// One figure: how to run its program and what it produces.
struct FigureEntry {
  std::string name, paper, title, caption, program, full_time, readme;
  std::vector<std::string> full_args, quick_args;
  // A figure run as a grid (manifest keys "grid", "quick_grid": lists of sweep
  // grids over the program's options, their combinations in turn): one program run
  // per combination, each into DIR/NAME/parts/<k>/, then `plot` (a script under
  // the manifest's folder, `plot DIR/NAME DIR/NAME/parts/0 ...`) merges the parts
  // into DIR/NAME and draws. Empty: one run into DIR/NAME with --plot.
  std::vector<SweepGrid> full_grid, quick_grid;
  std::string plot;
  std::vector<std::string> images, files;
  std::vector<FigureNumber> numbers;
  StoredRun stored;
};

/// Reads the manifest; throws diffdyn::Error "<path>: ..." for a missing key, a
/// wrong type, an unknown reduction, a path leaving the figure's folder or a
/// repeated figure name.
std::vector<FigureEntry> ReadFigureManifest(const std::filesystem::path& path);

/// The same on the manifest's text, named `name` in errors (the fuzz target's entry).
std::vector<FigureEntry> ParseFigureManifest(std::string_view text, const std::string& name);

/// The folder, relative to the page, that holds `number`'s CSV: "bench" for a
/// benchmark comparison, else the figure's name.
std::string NumberFolder(const FigureEntry& figure, const FigureNumber& number);

/// A number's value, or why there is none.
struct NumberValue {
  std::optional<double> value;
  std::optional<double> pytorch;  // the pytorch_column reduced the same way
  std::string measured;           // "<machine>, <date>" of a bench row (its machine and date cells)
  std::size_t rows = 0;  // rows matching `where`
  std::string problem;   // empty when there is a value
};

/// Evaluates `number` on the CSV under `figure_dir` (never throws for a missing
/// or malformed CSV: the problem is returned).
NumberValue EvaluateFigureNumber(const FigureNumber& number, const std::filesystem::path& figure_dir);

/// "meets", "misses", "not judged" (no acceptance bounds) or "missing" (no value).
std::string Verdict(const FigureNumber& number, const NumberValue& value);

/// How one figure's run went.
struct FigureRun {
  const FigureEntry* entry = nullptr;
  std::vector<std::string> commands;  // the shell commands that redo the run, in turn
  int exit_code = -1;                 // the first failing command's, else 0
  double seconds = 0;                 // summed over the commands
  std::vector<std::string> log_dirs;  // per command, relative to the page: stdout.txt, stderr.txt; none: a stored run
  std::string stored;                 // a stored run's folder as the repository names it, or why there is none
};

/// What the page says about the whole run.
struct PageInfo {
  bool quick = false;
  bool stored = false;  // the figures' stored full runs, copied rather than run
  std::string machine;  // CPU, cores, vector ISA
  std::string date;     // UTC
  std::string invocation;
  double seconds = 0;
};

/// The machine as one line: "<CPU model> (N cores, AVX-512|AVX2|baseline ISA)".
std::string DescribeMachine();

/// Writes `path` (index.html; atomically): per figure its caption, PNGs (a missing
/// one is named, never linked), numbers beside their references with ratio and
/// verdict, the command, wall time and logs; above them the machine, the date and
/// the numbers that miss their acceptance. Relative links are relative to the
/// folder of `path`, where each figure's output folder is its name.
void WriteFiguresPage(const std::filesystem::path& path, const std::vector<FigureRun>& runs, const PageInfo& info);

}  // namespace diffdyn::cli
