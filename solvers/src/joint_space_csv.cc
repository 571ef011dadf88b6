#include "joint_space_csv.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <sstream>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/io.h"
#include "diffdyn/models/trajectory.h"

namespace diffdyn {
namespace {

namespace fs = std::filesystem;

// Ground-truth channels of the joint-space CSV: per joint (m1..mn, ...) and scalar.
constexpr const char* kJointChannels[] = {"m", "c", "g", "f"};
constexpr const char* kScalarChannels[] = {"kinetic", "potential"};

// A file's samples side by side (n x N matrices), as read: the parse buffer that
// ToDataset cuts into trajectories.
struct Columns {
  std::string path;
  std::string format = "joint-csv";
  Eigen::VectorXd t;
  Eigen::MatrixXd q, qd, qdd, tau;  // qdd: 0 x 0 when absent
  std::vector<int> segment_starts = {0};
  std::vector<std::string> segment_labels;
  std::map<std::string, Eigen::MatrixXd> channels;
  Dataset extra;  // notes, unmeasured, properties

  int size() const { return static_cast<int>(t.size()); }
};

// Splits a CSV line at commas, trimming spaces and a trailing carriage return.
std::vector<std::string> SplitCsv(const std::string& line) {
  std::vector<std::string> cells;
  std::string cell;
  std::stringstream in(line);
  while (std::getline(in, cell, ',')) {
    const auto begin = cell.find_first_not_of(" \t\r");
    const auto end = cell.find_last_not_of(" \t\r");
    cells.push_back(begin == std::string::npos ? "" : cell.substr(begin, end - begin + 1));
  }
  if (!line.empty() && line.back() == ',') cells.emplace_back();
  return cells;
}

double ParseNumber(const std::string& text, const std::string& where) {
  std::size_t used = 0;
  double value = 0;
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  DIFFDYN_CHECK(used == text.size() && !text.empty() && std::isfinite(value), where, ": '", text.substr(0, 40),
                "' is not a finite number");
  DIFFDYN_CHECK(std::abs(value) <= kMaxDataMagnitude, where, ": ", value, " is larger in magnitude than ",
                kMaxDataMagnitude);
  return value;
}

// Reads a file of one number per line.
std::vector<double> ReadColumnFile(const fs::path& path) {
  std::ifstream in = OpenInputFile(path);
  std::vector<double> values;
  std::string line;
  for (int line_no = 1; std::getline(in, line); ++line_no) {
    const auto begin = line.find_first_not_of(" \t\r");
    if (begin == std::string::npos) continue;
    const auto end = line.find_last_not_of(" \t\r");
    values.push_back(
        ParseNumber(line.substr(begin, end - begin + 1), StrCat(path.string(), ":", line_no)));
  }
  return values;
}

// Checks that time increases inside each segment.
void CheckTime(const Columns& data) {
  std::vector<int> starts = data.segment_starts;
  starts.push_back(data.size());
  for (std::size_t s = 0; s + 1 < starts.size(); ++s) {
    DIFFDYN_CHECK(starts[s + 1] - starts[s] >= 3, data.path, ": segment ", s, " has fewer than 3 samples");
    for (int k = starts[s] + 1; k < starts[s + 1]; ++k) {
      DIFFDYN_CHECK(data.t[k] > data.t[k - 1], data.path, ": time does not increase at sample ",
                    k + 1, " (t = ", data.t[k], " after ", data.t[k - 1], ")");
    }
  }
}

// Central-difference velocity of q inside each segment (one-sided at the ends).
Eigen::MatrixXd Differentiate(const Columns& data) {
  Eigen::MatrixXd qd(data.q.rows(), data.size());
  std::vector<int> starts = data.segment_starts;
  starts.push_back(data.size());
  for (std::size_t s = 0; s + 1 < starts.size(); ++s) {
    const int a = starts[s], b = starts[s + 1];
    for (int k = a; k < b; ++k) {
      const int lo = std::max(a, k - 1), hi = std::min(b - 1, k + 1);
      qd.col(k) = (data.q.col(hi) - data.q.col(lo)) / (data.t[hi] - data.t[lo]);
    }
  }
  return qd;
}

// The joint-space CSV (dataset_io.h), read by header name.
Columns ReadCsvColumns(const std::string& path) {
  std::ifstream in = OpenInputFile(path);
  std::string line;
  DIFFDYN_CHECK(static_cast<bool>(std::getline(in, line)), path, ":1: empty file");
  const auto header = SplitCsv(line);
  std::map<std::string, int> column;
  for (int c = 0; c < static_cast<int>(header.size()); ++c) {
    DIFFDYN_CHECK(!column.count(header[c]), path, ":1: duplicate column '", header[c], "'");
    column[header[c]] = c;
  }
  DIFFDYN_CHECK(column.count("t"), path, ":1: no column 't'");
  int n = 0;
  while (column.count(StrCat("q", n + 1))) ++n;
  DIFFDYN_CHECK(n > 0, path, ":1: no column 'q1'");
  const bool has_qd = column.count("qd1") > 0;
  const bool has_qdd = column.count("qdd1") > 0;
  for (int j = 1; j <= n; ++j) {
    DIFFDYN_CHECK(column.count(StrCat("tau", j)), path, ":1: no column 'tau", j, "' (", n,
                  " joints from q1..q", n, ")");
    DIFFDYN_CHECK(!has_qd || column.count(StrCat("qd", j)), path, ":1: no column 'qd", j, "'");
    DIFFDYN_CHECK(!has_qdd || column.count(StrCat("qdd", j)), path, ":1: no column 'qdd", j, "'");
  }
  DIFFDYN_CHECK(!column.count(StrCat("q", n + 2)), path, ":1: q columns are not contiguous");
  // Ground-truth channels: per-joint components and scalar energies.
  std::vector<std::pair<std::string, std::vector<int>>> channel_columns;
  for (const char* prefix : kJointChannels) {
    if (!column.count(StrCat(prefix, 1))) continue;
    std::vector<int> cols(n);
    for (int j = 0; j < n; ++j) {
      DIFFDYN_CHECK(column.count(StrCat(prefix, j + 1)), path, ":1: no column '", prefix, j + 1,
                    "' (", prefix, "1 is there)");
      cols[j] = column[StrCat(prefix, j + 1)];
    }
    channel_columns.emplace_back(prefix, cols);
  }
  for (const char* name : kScalarChannels) {
    if (column.count(name)) channel_columns.emplace_back(name, std::vector<int>{column[name]});
  }
  const int trajectory_column = column.count("trajectory") ? column["trajectory"] : -1;
  std::vector<std::string> labels;
  std::vector<std::vector<double>> channel_values(channel_columns.size());
  // Column indices of every field.
  std::vector<int> cq(n), cqd(n), cqdd(n), ctau(n);
  for (int j = 0; j < n; ++j) {
    cq[j] = column[StrCat("q", j + 1)];
    ctau[j] = column[StrCat("tau", j + 1)];
    if (has_qd) cqd[j] = column[StrCat("qd", j + 1)];
    if (has_qdd) cqdd[j] = column[StrCat("qdd", j + 1)];
  }
  std::vector<double> t, q, qd, qdd, tau;
  std::vector<int> starts = {0};
  for (int line_no = 2; std::getline(in, line); ++line_no) {
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    const auto cells = SplitCsv(line);
    DIFFDYN_CHECK(cells.size() == header.size(), path, ":", line_no, ": ", cells.size(),
                  " cells, the header has ", header.size());
    const std::string where = StrCat(path, ":", line_no);
    const double time = ParseNumber(cells[column["t"]], where);
    if (trajectory_column >= 0) {
      // A new label starts a new segment; inside one, time must increase.
      const std::string& label = cells[trajectory_column];
      DIFFDYN_CHECK(!label.empty(), where, ": empty trajectory label");
      if (labels.empty()) {
        labels.push_back(label);
      } else if (label != labels.back()) {
        DIFFDYN_CHECK(std::find(labels.begin(), labels.end(), label) == labels.end(), where,
                      ": trajectory '", label.substr(0, 40), "' continues after another one");
        labels.push_back(label);
        starts.push_back(static_cast<int>(t.size()));
      } else {
        DIFFDYN_CHECK(time > t.back(), where, ": time does not increase (t = ", time, " after ",
                      t.back(), ")");
      }
    } else if (!t.empty() && time <= t.back()) {
      // Without labels, a time that goes back starts a new segment only if t restarts
      // at its first value.
      DIFFDYN_CHECK(std::abs(time - t[starts.back()]) < 1e-12, where,
                    ": time does not increase (t = ", time, " after ", t.back(), ")");
      starts.push_back(static_cast<int>(t.size()));
    }
    t.push_back(time);
    for (int j = 0; j < n; ++j) {
      q.push_back(ParseNumber(cells[cq[j]], where));
      tau.push_back(ParseNumber(cells[ctau[j]], where));
      if (has_qd) qd.push_back(ParseNumber(cells[cqd[j]], where));
      if (has_qdd) qdd.push_back(ParseNumber(cells[cqdd[j]], where));
    }
    for (std::size_t c = 0; c < channel_columns.size(); ++c) {
      for (int col : channel_columns[c].second) {
        channel_values[c].push_back(ParseNumber(cells[col], where));
      }
    }
  }
  const int count = static_cast<int>(t.size());
  DIFFDYN_CHECK(count >= 3, path, ": only ", count, " samples");
  Columns data;
  data.path = path;
  data.t = Eigen::Map<const Eigen::VectorXd>(t.data(), count);
  data.q = Eigen::Map<const Eigen::MatrixXd>(q.data(), n, count);
  data.tau = Eigen::Map<const Eigen::MatrixXd>(tau.data(), n, count);
  if (has_qdd) data.qdd = Eigen::Map<const Eigen::MatrixXd>(qdd.data(), n, count);
  data.segment_starts = starts;
  data.segment_labels = labels;
  for (std::size_t c = 0; c < channel_columns.size(); ++c) {
    const int rows = static_cast<int>(channel_columns[c].second.size());
    data.channels[channel_columns[c].first] =
        Eigen::Map<const Eigen::MatrixXd>(channel_values[c].data(), rows, count);
  }
  CheckTime(data);
  for (int j = 1; j <= n && !has_qd; ++j) data.extra.unmeasured.push_back(StrCat("qd", j));
  if (!has_qd) data.extra.notes = "qd estimated from q (central differences).";
  data.qd = has_qd ? Eigen::MatrixXd(Eigen::Map<const Eigen::MatrixXd>(qd.data(), n, count))
                   : Differentiate(data);
  return data;
}

Columns ReadPandaGaz(const fs::path& dir) {
  Columns data;
  data.path = dir.string();
  data.format = "panda-gaz2019";
  const auto t = ReadColumnFile(dir / "exciting_traj_time.txt");
  const auto q = ReadColumnFile(dir / "exciting_traj_positions.txt");
  const auto qd = ReadColumnFile(dir / "exciting_traj_velocity.txt");
  const auto tau = ReadColumnFile(dir / "exciting_traj_torques.txt");
  const int n = 7, count = static_cast<int>(t.size());
  for (const auto* file : {&q, &qd, &tau}) {
    DIFFDYN_CHECK(static_cast<int>(file->size()) == n * count, dir.string(),
                  ": expected 7 lines per sample (", n * count, " lines for ", count,
                  " times), got ", file->size());
  }
  data.t = Eigen::Map<const Eigen::VectorXd>(t.data(), count);
  data.q = Eigen::Map<const Eigen::MatrixXd>(q.data(), n, count);
  data.qd = Eigen::Map<const Eigen::MatrixXd>(qd.data(), n, count);
  data.tau = Eigen::Map<const Eigen::MatrixXd>(tau.data(), n, count);
  data.extra.notes = "Gaz et al. 2019 exciting trajectory 1 (real Panda): q, robot-reported qd, "
               "link-side torque sensors; qdd estimated.";
  CheckTime(data);
  return data;
}

Columns ReadIbmRun(const fs::path& file) {
  std::ifstream in = OpenInputFile(file);
  std::vector<std::array<double, 6>> rows;
  std::string line;
  for (int line_no = 1; std::getline(in, line); ++line_no) {
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    const auto cells = SplitCsv(line);
    DIFFDYN_CHECK(cells.size() == 6, file.string(), ":", line_no, ": expected 6 pixel columns, got ",
                  cells.size());
    std::array<double, 6> row;
    for (int c = 0; c < 6; ++c) row[c] = ParseNumber(cells[c], StrCat(file.string(), ":", line_no));
    rows.push_back(row);
  }
  const int count = static_cast<int>(rows.size());
  DIFFDYN_CHECK(count >= 10, file.string(), ": only ", count, " samples");
  Columns data;
  data.path = file.string();
  data.format = "ibm-double-pendulum";
  data.t.resize(count);
  data.q.resize(2, count);
  double len1 = 0, len2 = 0;
  double prev1 = 0, prev2 = 0;
  for (int k = 0; k < count; ++k) {
    const auto& r = rows[k];
    // The camera is turned: gravity points along +x in the image (the
    // pendulum comes to rest with the bobs at larger x than the pivot), so an
    // absolute angle measured from +x is the angle from hanging down. Both
    // angles share one handedness, so the free motion obeys the same equations
    // whichever way the image is mirrored.
    const double phi1 = std::atan2(r[3] - r[1], r[2] - r[0]);
    const double phi2 = std::atan2(r[5] - r[3], r[4] - r[2]);
    double a1 = phi1, a2 = phi2 - phi1;
    // Unwrap against the previous sample.
    if (k > 0) {
      a1 = prev1 + std::remainder(a1 - prev1, 2 * std::numbers::pi);
      a2 = prev2 + std::remainder(a2 - prev2, 2 * std::numbers::pi);
    }
    prev1 = a1;
    prev2 = a2;
    data.q(0, k) = a1;
    data.q(1, k) = a2;
    data.t[k] = k / 400.0;
    len1 += std::hypot(r[2] - r[0], r[3] - r[1]);
    len2 += std::hypot(r[4] - r[2], r[5] - r[3]);
  }
  data.extra.properties = {{"link1_px", len1 / count}, {"link2_px", len2 / count}};
  data.tau = Eigen::MatrixXd::Zero(2, count);
  data.extra.unmeasured = {"qd1", "qd2", "tau"};
  data.qd = Differentiate(data);
  data.extra.notes = StrCat("IBM double pendulum (real, 400 Hz camera), free motion; angles from the "
                            "marker pixels; link lengths ", len1 / count, " px and ", len2 / count,
                            " px; qd, qdd estimated from q.");
  return data;
}

Columns ReadDelan(const fs::path& file) {
  Columns data = ReadCsvColumns(file.string());
  // The `character` column names each segment (time restarts at each character).
  std::ifstream in = OpenInputFile(file.string());
  std::string line;
  std::getline(in, line);
  DIFFDYN_CHECK(SplitCsv(line).front() == "character", file.string(),
                ":1: the first column must be 'character'");
  std::vector<std::string> labels;
  for (int row = 0, segment = 0; std::getline(in, line);) {
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    if (segment < static_cast<int>(data.segment_starts.size()) && row == data.segment_starts[segment]) {
      labels.push_back(SplitCsv(line).front());
      ++segment;
    }
    ++row;
  }
  data.segment_labels = std::move(labels);
  data.format = "delan-characters";
  data.extra.notes = "DeLaN character data (simulated 2-link arm), one trajectory per character.";
  return data;
}

// The file or folder at `path` by its kind (dataset_io.h).
Columns ReadColumns(const std::string& path) {
  const fs::path p(path);
  DIFFDYN_CHECK(fs::exists(p), "--measured ", path, ": no such file or directory");
  if (fs::is_directory(p)) {
    if (fs::exists(p / "exciting_traj_positions.txt")) return ReadPandaGaz(p);
    if (fs::exists(p / "character_data.csv")) return ReadDelan(p / "character_data.csv");
    if (fs::exists(p / "0.csv")) return ReadIbmRun(p / "0.csv");
    throw Error(StrCat("--measured ", path,
                       ": folder is not a known dataset (Panda Gaz 2019, IBM double pendulum, "
                       "DeLaN characters)"));
  }
  // A headerless file of 6 integers per line is an IBM run.
  std::ifstream in = OpenInputFile(p);
  std::string first;
  std::getline(in, first);
  const auto cells = SplitCsv(first);
  bool numeric = cells.size() == 6;
  for (const auto& c : cells) numeric = numeric && !c.empty() && c.find_first_not_of("-0123456789") == std::string::npos;
  if (numeric) return ReadIbmRun(p);
  if (p.filename() == "character_data.csv") return ReadDelan(p);
  return ReadCsvColumns(path);
}

// The joint-space description's dataset of `data`: one trajectory per segment.
Dataset ToDataset(const Columns& data, const JointLayout& layout) {
  const int n = static_cast<int>(data.q.rows());
  JointLayout resolved = layout;
  if (!layout.all_actuated && layout.actuated.empty()) {
    // The joints whose torque is not zero throughout.
    for (int j = 0; j < n; ++j) {
      if (!data.tau.row(j).isZero(0.0)) resolved.actuated.push_back(j + 1);
    }
  }
  Dataset d = data.extra;
  d.system = JointSpaceSystem(n, resolved);
  d.path = data.path;
  d.format = data.format;
  // Action row r takes the torque of joint action_joint[r].
  std::vector<int> action_joint;
  for (const std::string& name : d.system.action_names) action_joint.push_back(std::stoi(name.substr(3)) - 1);
  std::vector<int> starts = data.segment_starts;
  starts.push_back(data.size());
  for (std::size_t s = 0; s + 1 < starts.size(); ++s) {
    const int a = starts[s], samples = starts[s + 1] - starts[s];
    Trajectory t;
    t.label = s < data.segment_labels.size() ? data.segment_labels[s] : std::to_string(s);
    t.t = data.t.segment(a, samples);
    t.states.resize(2 * n, samples);
    t.states.topRows(n) = data.q.middleCols(a, samples);
    t.states.bottomRows(n) = data.qd.middleCols(a, samples);
    t.actions.resize(static_cast<Eigen::Index>(action_joint.size()), samples - 1);
    for (std::size_t r = 0; r < action_joint.size(); ++r) {
      t.actions.row(static_cast<Eigen::Index>(r)) = data.tau.row(action_joint[r]).segment(a, samples - 1);
    }
    t.channels["tau"] = data.tau.middleCols(a, samples);
    if (data.qdd.cols() == data.size()) t.channels["qdd"] = data.qdd.middleCols(a, samples);
    for (const auto& [name, values] : data.channels) t.channels[name] = values.middleCols(a, samples);
    d.trajectories.push_back(std::move(t));
  }
  d.Validate();
  return d;
}

}  // namespace

Dataset ReadJointSpace(const std::string& path, const JointLayout& layout) {
  return ToDataset(ReadColumns(path), layout);
}

Dataset JointSpaceDataset(const std::string& path, const Eigen::VectorXd& t, const Eigen::MatrixXd& q,
                          const Eigen::MatrixXd& qd, const Eigen::MatrixXd& tau, const JointLayout& layout) {
  const Eigen::Index n = q.rows(), count = t.size();
  DIFFDYN_CHECK(n >= 1 && q.cols() == count && qd.rows() == n && qd.cols() == count && tau.rows() == n &&
                    tau.cols() == count,
                path, ": q, qd and tau must be n x N with N = ", count, " sample times; got ", q.rows(), "x",
                q.cols(), ", ", qd.rows(), "x", qd.cols(), ", ", tau.rows(), "x", tau.cols());
  Columns data;
  data.path = path;
  data.t = t;
  data.q = q;
  data.qd = qd;
  data.tau = tau;
  CheckTime(data);
  return ToDataset(data, layout);
}

int JointCount(const Dataset& data) {
  const int n = data.system.state_size() / 2;
  DIFFDYN_CHECK(n >= 1 && data.system.state_size() == 2 * n, data.path,
                ": joint-space data need states [q; qd], got ", data.system.state_size(), " components");
  for (const Trajectory& t : data.trajectories) {
    const auto tau = t.channels.find("tau");
    DIFFDYN_CHECK(tau != t.channels.end() && tau->second.rows() == n, data.path, ": trajectory ", t.label,
                  " has no channel 'tau' of ", n, " rows");
  }
  return n;
}

void WriteJointSpaceCsv(const std::string& path, const Dataset& data) {
  const int n = JointCount(data);
  DIFFDYN_CHECK(!data.trajectories.empty(), path, ": no trajectories to write");
  // Columns: those of the first trajectory's channels; every trajectory must have the same.
  const Trajectory& first = data.trajectories.front();
  const bool with_labels = data.trajectories.size() > 1 || !first.label.empty();
  const bool with_qdd = first.channels.count("qdd") > 0;
  std::vector<std::string> extra;  // ground-truth channels after tau, in name order
  for (const auto& [name, values] : first.channels) {
    if (name != "tau" && name != "qdd") extra.push_back(name);
  }
  for (const Trajectory& t : data.trajectories) {
    DIFFDYN_CHECK(t.channels.size() == extra.size() + 1 + with_qdd && t.channels.count("qdd") == with_qdd, path,
                  ": trajectory ", t.label, " has other channels than trajectory ", first.label);
    for (const std::string& name : extra) {
      DIFFDYN_CHECK(t.channels.count(name) && t.channels.at(name).rows() == first.channels.at(name).rows(),
                    path, ": trajectory ", t.label, " lacks channel '", name, "' of trajectory ", first.label);
    }
  }
  WriteFileAtomically(path, [&](std::ostream& out) {
    out.precision(17);
    if (with_labels) out << "trajectory,";
    out << "t";
    for (const char* prefix : {"q", "qd", "qdd", "tau"}) {
      if (prefix == std::string("qdd") && !with_qdd) continue;
      for (int j = 1; j <= n; ++j) out << "," << prefix << j;
    }
    for (const std::string& name : extra) {
      const Eigen::Index rows = first.channels.at(name).rows();
      const bool scalar = std::find(std::begin(kScalarChannels), std::end(kScalarChannels), name) !=
                          std::end(kScalarChannels);
      DIFFDYN_CHECK(!scalar || rows == 1, path, ": channel ", name, " must have one row");
      if (scalar) {
        out << "," << name;
      } else {
        for (int j = 1; j <= rows; ++j) out << "," << name << j;
      }
    }
    out << "\n";
    for (const Trajectory& t : data.trajectories) {
      for (Eigen::Index k = 0; k < t.states.cols(); ++k) {
        if (with_labels) out << t.label << ",";
        out << t.t[k];
        for (int j = 0; j < 2 * n; ++j) out << "," << t.states(j, k);
        if (with_qdd) {
          for (int j = 0; j < n; ++j) out << "," << t.channels.at("qdd")(j, k);
        }
        for (int j = 0; j < n; ++j) out << "," << t.channels.at("tau")(j, k);
        for (const std::string& name : extra) {
          const Eigen::MatrixXd& values = t.channels.at(name);
          for (Eigen::Index r = 0; r < values.rows(); ++r) out << "," << values(r, k);
        }
        out << "\n";
      }
    }
  });
}

}  // namespace diffdyn
