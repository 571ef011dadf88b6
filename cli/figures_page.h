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
#pragma once

#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace diffdyn::cli {

/// One number of a figure, read from the figure's CSV.
struct FigureNumber {
  std::string label;
  std::string csv;  // relative to the figure's output folder
  std::vector<std::pair<std::string, std::string>> where;
  std::string column;
  std::string reduce = "value";
  std::optional<double> reference;
  std::string reference_source;
  // Acceptance: bounds on the value and on value / reference (unset: none).
  std::optional<double> min, max, min_ratio, max_ratio;
};

/// One figure: how to run its program and what it produces.
struct FigureEntry {
  std::string name, paper, title, caption, program, full_time, readme;
  std::vector<std::string> full_args, quick_args;
  std::vector<std::string> images, files;
  std::vector<FigureNumber> numbers;
};

/// Reads the manifest; throws diffdyn::Error "<path>: ..." for a missing key, a
/// wrong type, an unknown reduction, a path leaving the figure's folder or a
/// repeated figure name.
std::vector<FigureEntry> ReadFigureManifest(const std::filesystem::path& path);

/// The same on the manifest's text, named `name` in errors (the fuzz target's entry).
std::vector<FigureEntry> ParseFigureManifest(std::string_view text, const std::string& name);

/// A number's value, or why there is none.
struct NumberValue {
  std::optional<double> value;
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
  std::string command;  // the shell command that redoes the run
  int exit_code = -1;
  double seconds = 0;
  std::string log_dir;  // relative to the page: stdout.txt, stderr.txt
};

/// What the page says about the whole run.
struct PageInfo {
  bool quick = false;
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
