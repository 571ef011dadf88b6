#include "figures_page.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <set>
#include <sstream>
#include <thread>

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/io.h"
#include "diffdyn/models/json_io.h"

namespace diffdyn::cli {
namespace {
namespace fs = std::filesystem;
using json = nlohmann::ordered_json;  // a grid's axes keep the manifest's order

// ---------------------------------------------------------------------------
// The manifest.

std::string Text(const json& object, const char* key, const std::string& where, bool required = true) {
  if (!object.contains(key)) {
    DIFFDYN_CHECK(!required, where, ": missing '", key, "'");
    return "";
  }
  DIFFDYN_CHECK(object[key].is_string(), where, ": '", key, "' must be a string");
  return object[key].get<std::string>();
}

std::vector<std::string> Texts(const json& object, const char* key, const std::string& where) {
  DIFFDYN_CHECK(object.contains(key) && object[key].is_array(), where, ": '", key, "' must be an array of strings");
  std::vector<std::string> out;
  for (const json& v : object[key]) {
    DIFFDYN_CHECK(v.is_string(), where, ": '", key, "' must be an array of strings");
    out.push_back(v.get<std::string>());
  }
  return out;
}

std::optional<double> Number(const json& object, const char* key, const std::string& where) {
  if (!object.contains(key)) return std::nullopt;
  DIFFDYN_CHECK(object[key].is_number() && std::isfinite(object[key].get<double>()), where, ": '", key,
                "' must be a finite number");
  return object[key].get<double>();
}

// A file name inside the figure's folder: relative, no "..".
void CheckInside(const std::string& file, const std::string& where) {
  const fs::path p(file);
  bool up = false;
  for (const fs::path& part : p) up = up || part == "..";
  DIFFDYN_CHECK(!file.empty() && p.is_relative() && !up, where, ": '", file,
                "' must be a relative path inside the figure's folder");
}

FigureNumber ReadNumber(const json& j, const std::string& where) {
  DIFFDYN_CHECK(j.is_object(), where, ": must be an object");
  FigureNumber n;
  n.label = Text(j, "label", where);
  n.csv = Text(j, "csv", where);
  CheckInside(n.csv, where);
  n.column = Text(j, "column", where);
  n.reduce = Text(j, "reduce", where);
  static const std::set<std::string> kReduce = {"value", "median", "mean", "min", "max", "count"};
  DIFFDYN_CHECK(kReduce.count(n.reduce) != 0, where, ": unknown reduce '", n.reduce,
                "' (value, median, mean, min, max, count)");
  if (j.contains("where")) {
    DIFFDYN_CHECK(j["where"].is_object(), where, ": 'where' must be an object of strings");
    for (const auto& [column, value] : j["where"].items()) {
      DIFFDYN_CHECK(value.is_string(), where, ": 'where' must be an object of strings");
      n.where.emplace_back(column, value.get<std::string>());
    }
  }
  if (j.contains("bench")) {
    DIFFDYN_CHECK(j["bench"].is_boolean(), where, ": 'bench' must be true or false");
    n.bench = j["bench"].get<bool>();
  }
  n.pytorch_column = Text(j, "pytorch_column", where, /*required=*/false);
  n.reference = Number(j, "reference", where);
  n.reference_source = Text(j, "reference_source", where, /*required=*/false);
  if (j.contains("accept")) {
    const json& a = j["accept"];
    DIFFDYN_CHECK(a.is_object(), where, ": 'accept' must be an object");
    n.min = Number(a, "min", where);
    n.max = Number(a, "max", where);
    n.min_ratio = Number(a, "min_ratio", where);
    n.max_ratio = Number(a, "max_ratio", where);
    n.max_pytorch_ratio = Number(a, "max_pytorch_ratio", where);
    DIFFDYN_CHECK(n.reference || !(n.min_ratio || n.max_ratio), where, ": a ratio bound needs a 'reference'");
    DIFFDYN_CHECK(!n.pytorch_column.empty() || !n.max_pytorch_ratio, where,
                  ": 'max_pytorch_ratio' needs a 'pytorch_column'");
  }
  return n;
}

// {"folder": F, "parts": {"file": ["part", ...]}}: F and the parts inside the manifest's folder.
StoredRun ReadStored(const json& j, const std::string& where) {
  DIFFDYN_CHECK(j.is_object(), where, ": must be an object");
  StoredRun stored;
  stored.folder = Text(j, "folder", where);
  CheckInside(stored.folder, where);
  if (!j.contains("parts")) return stored;
  DIFFDYN_CHECK(j["parts"].is_object(), where, ": 'parts' must be an object of arrays of strings");
  for (const auto& [file, parts] : j["parts"].items()) {
    CheckInside(file, where);
    DIFFDYN_CHECK(parts.is_array() && !parts.empty(), where, ": '", file, "' needs an array of parts");
    std::vector<std::string> names;
    for (const json& part : parts) {
      DIFFDYN_CHECK(part.is_string(), where, ": the parts of '", file, "' must be strings");
      names.push_back(part.get<std::string>());
      CheckInside(names.back(), where);
    }
    stored.parts.emplace_back(file, std::move(names));
  }
  return stored;
}

// `key`: a list of sweep grids over the program's options (absent: none). The
// figures command sets --out and --plot itself.
std::vector<SweepGrid> Grids(const json& j, const char* key, const std::string& where) {
  if (!j.contains(key)) return {};
  DIFFDYN_CHECK(j[key].is_array() && !j[key].empty(), where, ": '", key, "' must be a non-empty array of grids");
  std::vector<SweepGrid> grids;
  for (std::size_t i = 0; i < j[key].size(); ++i) {
    const std::string name = StrCat(where, ": ", key, "[", i, "]");
    grids.push_back(ParseSweepGrid(j[key][i], name));
    for (const auto& [flag, values] : grids.back()) {
      DIFFDYN_CHECK(flag != "--out" && flag != "--plot", name, ": '", flag, "' is set by diffdyn figures");
    }
  }
  return grids;
}

FigureEntry ReadEntry(const json& j, const std::string& where) {
  DIFFDYN_CHECK(j.is_object(), where, ": must be an object");
  FigureEntry e;
  e.name = Text(j, "name", where);
  DIFFDYN_CHECK(!e.name.empty() && e.name.find_first_not_of("abcdefghijklmnopqrstuvwxyz0123456789_") ==
                                       std::string::npos,
                where, ": 'name' must be lower-case letters, digits and '_'");
  const std::string here = StrCat(where, " (", e.name, ")");
  e.paper = Text(j, "paper", here);
  e.title = Text(j, "title", here);
  e.caption = Text(j, "caption", here);
  e.program = Text(j, "program", here);
  CheckInside(e.program, here);
  e.full_time = Text(j, "full_time", here);
  e.readme = Text(j, "readme", here, /*required=*/false);
  e.full_args = Texts(j, "full_args", here);
  e.quick_args = Texts(j, "quick_args", here);
  e.full_grid = Grids(j, "grid", here);
  e.quick_grid = Grids(j, "quick_grid", here);
  e.plot = Text(j, "plot", here, /*required=*/false);
  if (!e.plot.empty()) CheckInside(e.plot, here);
  DIFFDYN_CHECK(!e.plot.empty() || (e.full_grid.empty() && e.quick_grid.empty()), here,
                ": a figure run as a grid needs a 'plot' script to merge its parts");
  e.images = Texts(j, "images", here);
  e.files = Texts(j, "files", here);
  for (const std::string& f : e.images) CheckInside(f, here);
  for (const std::string& f : e.files) CheckInside(f, here);
  DIFFDYN_CHECK(j.contains("numbers") && j["numbers"].is_array(), here, ": 'numbers' must be an array");
  for (std::size_t i = 0; i < j["numbers"].size(); ++i) {
    e.numbers.push_back(ReadNumber(j["numbers"][i], StrCat(here, ": numbers[", i, "]")));
  }
  if (j.contains("stored")) e.stored = ReadStored(j["stored"], StrCat(here, ": stored"));
  return e;
}

std::vector<FigureEntry> FiguresFromJson(const json& j, const std::string& where) {
  DIFFDYN_CHECK(j.is_object() && j.contains("figures") && j["figures"].is_array(), where,
                ": must be an object with an array 'figures'");
  std::vector<FigureEntry> out;
  std::set<std::string> names;
  for (std::size_t i = 0; i < j["figures"].size(); ++i) {
    out.push_back(ReadEntry(j["figures"][i], StrCat(where, ": figures[", i, "]")));
    DIFFDYN_CHECK(names.insert(out.back().name).second, where, ": figure '", out.back().name, "' given twice");
  }
  return out;
}

// ---------------------------------------------------------------------------
// CSV cells.

// One CSV line split into cells (double quotes group a cell; "" is a quote).
std::vector<std::string> SplitCsvLine(const std::string& line) {
  std::vector<std::string> cells(1);
  bool quoted = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted && c == '"' && i + 1 < line.size() && line[i + 1] == '"') {
      cells.back() += '"';
      ++i;
    } else if (c == '"') {
      quoted = !quoted;
    } else if (c == ',' && !quoted) {
      cells.emplace_back();
    } else if (c != '\r') {
      cells.back() += c;
    }
  }
  return cells;
}

// A CSV as read: its header and its non-empty rows, split into cells.
struct CsvTable {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
};

// `path` read once; nothing (and `problem` set) when it cannot be read.
std::optional<CsvTable> ReadCsvTable(const fs::path& path, std::string& problem) {
  std::ifstream in(path);
  std::string line;
  if (!in.good() || !std::getline(in, line)) {
    problem = "no CSV";
    return std::nullopt;
  }
  CsvTable table{SplitCsvLine(line), {}};
  while (std::getline(in, line)) {
    if (!line.empty() && line != "\r") table.rows.push_back(SplitCsvLine(line));
  }
  return table;
}

// The `column_name` cells of the table's rows matching n.where; sets `problem` on failure.
std::vector<std::string> MatchingCells(const FigureNumber& n, const std::string& column_name, const CsvTable& table,
                                       std::string& problem) {
  const auto index_of = [&](const std::string& name) -> std::ptrdiff_t {
    const auto it = std::find(table.header.begin(), table.header.end(), name);
    return it == table.header.end() ? -1 : it - table.header.begin();
  };
  const std::ptrdiff_t column = index_of(column_name);
  std::vector<std::pair<std::ptrdiff_t, std::string>> filters;
  for (const auto& [name, value] : n.where) filters.emplace_back(index_of(name), value);
  if (column < 0 || std::any_of(filters.begin(), filters.end(), [](const auto& f) { return f.first < 0; })) {
    problem = "a column is not in the CSV";
    return {};
  }
  std::vector<std::string> cells;
  for (const std::vector<std::string>& row : table.rows) {
    const auto cell = [&](std::ptrdiff_t i) { return static_cast<std::size_t>(i) < row.size() ? row[i] : ""; };
    bool match = true;
    for (const auto& [i, value] : filters) match = match && cell(i) == value;
    if (match) cells.push_back(cell(column));
  }
  return cells;
}

double Reduce(const std::string& how, std::vector<double> v) {
  if (how == "count") return static_cast<double>(v.size());
  std::sort(v.begin(), v.end());
  if (how == "min" || how == "value") return v.front();
  if (how == "max") return v.back();
  double sum = 0;
  for (double x : v) sum += x;
  if (how == "mean") return sum / static_cast<double>(v.size());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);  // median
}

// `reduce` over `column` of the table's rows matching n.where;
// nothing (and `problem` set) without exactly the rows and finite cells it needs.
std::optional<double> ReducedColumn(const FigureNumber& n, const std::string& column, const CsvTable& table,
                                    std::size_t& rows, std::string& problem) {
  const std::vector<std::string> cells = MatchingCells(n, column, table, problem);
  if (!problem.empty()) return std::nullopt;
  rows = cells.size();
  if (cells.empty() || (n.reduce == "value" && cells.size() != 1)) {
    problem = fmt::format("{} matching rows", cells.size());
    return std::nullopt;
  }
  std::vector<double> values;
  for (const std::string& cell : cells) {
    char* end = nullptr;
    const double v = std::strtod(cell.c_str(), &end);
    if (cell.empty() || *end != '\0' || !std::isfinite(v)) {
      problem = "a cell is not a finite number";
      return std::nullopt;
    }
    values.push_back(v);
  }
  return Reduce(n.reduce, std::move(values));
}

// ---------------------------------------------------------------------------
// HTML.

std::string Escape(const std::string& s) {
  std::string out;
  for (const char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string Format(double v) { return fmt::format("{:.4g}", v); }

std::string AcceptText(const FigureNumber& n) {
  std::vector<std::string> parts;
  if (n.min) parts.push_back("≥ " + Format(*n.min));
  if (n.max) parts.push_back("≤ " + Format(*n.max));
  if (n.min_ratio) parts.push_back("ratio ≥ " + Format(*n.min_ratio));
  if (n.max_ratio) parts.push_back("ratio ≤ " + Format(*n.max_ratio));
  if (n.max_pytorch_ratio) parts.push_back("ours / PyTorch ≤ " + Format(*n.max_pytorch_ratio));
  std::string out;
  for (std::size_t i = 0; i < parts.size(); ++i) out += (i ? ", " : "") + parts[i];
  return out.empty() ? "none set" : out;
}

std::string WhereText(const FigureNumber& n) {
  std::string out;
  for (std::size_t i = 0; i < n.where.size(); ++i) {
    out += (i ? ";" : "") + n.where[i].first + "=" + n.where[i].second;
  }
  return out;
}

// A number cell with its recipe as data attributes (class "ours" or "pytorch").
std::string RecipeCell(const char* css, const std::string& csv, const FigureNumber& n, const std::string& column,
                       const std::optional<double>& value, const std::string& problem) {
  return fmt::format("<td class=\"{}\" data-csv=\"{}\" data-where=\"{}\" data-column=\"{}\" data-reduce=\"{}\">{}</td>",
                     css, Escape(csv), Escape(WhereText(n)), Escape(column), n.reduce,
                     value ? Format(*value) : "missing: " + Escape(problem));
}

std::string RatioText(const std::optional<double>& a, const std::optional<double>& b) {
  return a && b && *b != 0 ? fmt::format("{:.3g}", *a / *b) : "-";
}

void WriteNumberRow(std::ostream& html, const FigureEntry& e, const FigureNumber& n, const NumberValue& v,
                    const fs::path& root) {
  const std::string csv = NumberFolder(e, n) + "/" + n.csv;
  html << "<tr><td>" << Escape(n.label) << "</td>" << RecipeCell("ours", csv, n, n.column, v.value, v.problem);
  html << "<td>" << (n.reference ? Format(*n.reference) : "-") << "</td><td>" << Escape(n.reference_source)
       << "</td><td>" << RatioText(v.value, n.reference) << "</td>";
  if (n.pytorch_column.empty()) {
    html << "<td>-</td><td>-</td>";
  } else {
    html << RecipeCell("pytorch", csv, n, n.pytorch_column, v.pytorch, "no value") << "<td>"
         << RatioText(v.value, v.pytorch) << "</td>";
  }
  const std::string verdict = Verdict(n, v);
  html << "<td>" << AcceptText(n) << "</td><td class=\"" << (verdict == "meets" ? "ok" : verdict == "misses" ? "bad" : "")
       << "\">" << verdict << "</td>";
  html << "<td>" << (fs::is_regular_file(root / csv) ? "<a href=\"" + Escape(csv) + "\">" + Escape(n.csv) + "</a>"
                                                     : Escape(n.csv))
       << " " << n.reduce << " of " << Escape(n.column) << (n.where.empty() ? "" : " where " + Escape(WhereText(n)))
       << (v.measured.empty() ? "" : "; benchmark run on " + Escape(v.measured)) << "</td></tr>\n";
}

void WriteFigure(std::ostream& html, const FigureRun& run, const std::vector<NumberValue>& values,
                 const fs::path& root) {
  const FigureEntry& e = *run.entry;
  html << "<section id=\"" << e.name << "\">\n<h2>" << Escape(e.paper) << ": " << Escape(e.title) << "</h2>\n";
  html << "<p>" << Escape(e.caption) << "</p>\n";
  html << "<p class=\"run\">" << (run.commands.size() == 1 ? "Command" : "Commands (the grid's runs, then its merge and plot)") << ":";
  for (const std::string& command : run.commands) html << "<br><code>" << Escape(command) << "</code>";
  html << "<br>";
  if (run.log_dirs.empty()) {
    html << "Stored full run: " << Escape(run.stored) << " (not rerun here; its README gives the date and machine).";
  } else {
    html << "Wall time " << fmt::format("{:.1f}", run.seconds) << " s, exit code " << run.exit_code << ". Logs:";
    for (std::size_t i = 0; i < run.log_dirs.size(); ++i) {
      const std::string dir = Escape(run.log_dirs[i]);
      html << (i == 0 ? " " : "; ") << (run.log_dirs.size() == 1 ? "" : fmt::format("{} ", i + 1)) << "<a href=\""
           << dir << "/stdout.txt\">stdout</a>, <a href=\"" << dir << "/stderr.txt\">stderr</a>";
    }
    html << ".";
  }
  html << " Full run: " << Escape(e.full_time) << "."
       << (e.readme.empty() ? "" : " Details: paper_figures/" + Escape(e.readme) + ".") << "</p>\n<div class=\"pngs\">\n";
  for (const std::string& image : e.images) {
    const std::string rel = e.name + "/" + image;
    if (fs::is_regular_file(root / rel)) {
      html << "<figure><a href=\"" << Escape(rel) << "\"><img src=\"" << Escape(rel) << "\" alt=\"" << Escape(image)
           << "\"></a><figcaption>" << Escape(image) << "</figcaption></figure>\n";
    } else {
      html << "<p class=\"bad\">" << Escape(image) << " was not produced.</p>\n";
    }
  }
  html << "</div>\n<p>CSV: ";
  for (const std::string& file : e.files) {
    const std::string rel = e.name + "/" + file;
    html << (fs::is_regular_file(root / rel) ? "<a href=\"" + Escape(rel) + "\">" + Escape(file) + "</a> "
                                             : Escape(file) + " (not produced) ");
  }
  html << "</p>\n<table>\n<tr><th>quantity</th><th>ours</th><th>reference</th><th>source</th>"
          "<th>ours / reference</th><th>PyTorch (bench/, same run)</th><th>ours / PyTorch</th><th>acceptance</th><th>verdict</th><th>from</th></tr>\n";
  for (std::size_t i = 0; i < e.numbers.size(); ++i) WriteNumberRow(html, e, e.numbers[i], values[i], root);
  html << "</table>\n</section>\n";
}

constexpr const char* kStyle =
    "body{font-family:sans-serif;max-width:1200px;margin:auto;padding:1em}"
    "table{border-collapse:collapse;font-size:90%}td,th{border:1px solid #ccc;padding:3px 6px;text-align:left}"
    "figure{display:inline-block;margin:4px}img{max-width:560px}.ok{color:#070}.bad{color:#b00}"
    "code{background:#f4f4f4}";

}  // namespace

std::vector<FigureEntry> ReadFigureManifest(const fs::path& path) {
  return FiguresFromJson(ReadJsonFile<json>(path), path.string());
}

std::vector<FigureEntry> ParseFigureManifest(std::string_view text, const std::string& name) {
  return FiguresFromJson(ParseJsonText<json>(text, name), name);
}

std::string NumberFolder(const FigureEntry& figure, const FigureNumber& number) {
  return number.bench ? "bench" : figure.name;
}

NumberValue EvaluateFigureNumber(const FigureNumber& number, const fs::path& figure_dir) {
  NumberValue out;
  const std::optional<CsvTable> table = ReadCsvTable(figure_dir / number.csv, out.problem);
  if (!table) return out;
  out.value = ReducedColumn(number, number.column, *table, out.rows, out.problem);
  if (!out.value || number.pytorch_column.empty()) return out;
  std::size_t rows = 0;
  std::string problem;
  out.pytorch = ReducedColumn(number, number.pytorch_column, *table, rows, problem);
  // The benchmark run's machine and date, when the CSV has them.
  std::string none;
  const std::vector<std::string> machine = MatchingCells(number, "machine", *table, none);
  const std::vector<std::string> date = MatchingCells(number, "date", *table, none);
  if (none.empty() && !machine.empty() && !date.empty()) out.measured = machine.front() + ", " + date.front();
  return out;
}

std::string Verdict(const FigureNumber& n, const NumberValue& v) {
  if (!v.value) return "missing";
  if (!n.min && !n.max && !n.min_ratio && !n.max_ratio && !n.max_pytorch_ratio) return "not judged";
  const double x = *v.value;
  bool ok = (!n.min || x >= *n.min) && (!n.max || x <= *n.max);
  if (n.reference && *n.reference != 0) {
    const double r = x / *n.reference;
    ok = ok && (!n.min_ratio || r >= *n.min_ratio) && (!n.max_ratio || r <= *n.max_ratio);
  }
  if (n.max_pytorch_ratio) ok = ok && v.pytorch && *v.pytorch > 0 && x / *v.pytorch <= *n.max_pytorch_ratio;
  return ok ? "meets" : "misses";
}

std::string DescribeMachine() {
  std::ifstream in("/proc/cpuinfo");
  std::string line, model = "unknown CPU", isa = "baseline ISA";
  while (std::getline(in, line)) {
    const std::size_t colon = line.find(':');
    if (colon == std::string::npos) continue;
    const std::string key = line.substr(0, line.find_last_not_of(" \t", colon - 1) + 1);
    const std::string value = colon + 2 <= line.size() ? line.substr(colon + 2) : "";
    if (key == "model name" && model == "unknown CPU") model = value;
    if (key == "flags" && isa == "baseline ISA") {
      const std::string flags = " " + value + " ";
      isa = flags.find(" avx512f ") != std::string::npos ? "AVX-512"
            : flags.find(" avx2 ") != std::string::npos ? "AVX2"
                                                         : "baseline ISA";
    }
  }
  return fmt::format("{} ({} cores, {})", model, std::max(1u, std::thread::hardware_concurrency()), isa);
}

void WriteFiguresPage(const fs::path& path, const std::vector<FigureRun>& runs, const PageInfo& info) {
  const fs::path root = path.parent_path().empty() ? fs::path(".") : path.parent_path();
  // Every number is read from its CSV once, for the summary and the tables.
  std::vector<std::vector<NumberValue>> values(runs.size());
  std::vector<std::string> misses;
  std::size_t judged = 0, failed = 0;
  for (std::size_t r = 0; r < runs.size(); ++r) {
    failed += runs[r].exit_code != 0;
    for (const FigureNumber& n : runs[r].entry->numbers) {
      values[r].push_back(EvaluateFigureNumber(n, root / NumberFolder(*runs[r].entry, n)));
      const std::string v = Verdict(n, values[r].back());
      judged += v == "meets" || v == "misses";
      if (v == "misses") misses.push_back(runs[r].entry->paper + ": " + n.label);
    }
  }
  WriteFileAtomically(path, [&](std::ostream& html) {
    html << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<title>diffdyn: the figures of both papers</title><style>"
         << kStyle << "</style></head><body>\n<h1>The figures of both papers, regenerated by diffdyn</h1>\n";
    html << "<p>" << (info.quick    ? "<b>Quick run</b> (small sizes: it shows that every figure is produced; its numbers "
                                      "are not comparable with the papers')."
                      : info.stored ? "<b>Stored full runs</b>: each figure's results as the repository stores them "
                                      "under paper_figures/, copied here and read as a run's would be; the machine and "
                                      "date below are this page's, each figure's README gives its run's."
                                    : "Full run.")
         << "<br>Command: <code>" << Escape(info.invocation) << "</code><br>Machine: " << Escape(info.machine)
         << ". Date: " << Escape(info.date) << ". Wall time " << fmt::format("{:.1f}", info.seconds) << " s.</p>\n";
    html << "<p>" << runs.size() << (runs.size() == 1 ? " figure, " : " figures, ") << failed << " failed. " << judged
         << " numbers have an acceptance bound; " << misses.size() << (misses.size() == 1 ? " misses it" : " miss it")
         << (misses.empty() ? "." : ":") << "</p>\n";
    if (!misses.empty()) {
      html << "<ul class=\"bad\">\n";
      for (const std::string& m : misses) html << "<li>" << Escape(m) << "</li>\n";
      html << "</ul>\n";
    }
    html << "<ul>\n";
    for (const FigureRun& run : runs) {
      html << "<li><a href=\"#" << run.entry->name << "\">" << Escape(run.entry->paper) << ": "
           << Escape(run.entry->title) << "</a></li>\n";
    }
    html << "</ul>\n";
    for (std::size_t r = 0; r < runs.size(); ++r) WriteFigure(html, runs[r], values[r], root);
    html << "</body></html>\n";
  });
}

}  // namespace diffdyn::cli
