// Pushing datasets: block-pose trajectories under push actions, as CSV.
//
// One row per state, trajectories one after the other (schema in DESIGN.md):
//
//   trajectory,step,x,y,theta,push_location,push_angle,push_length[,status]
//
// Row `step` holds the state x_step = (x, y, theta) and the action u_step that
// moves it to x_{step+1}; the last row of a trajectory has empty action fields.
// The optional `status` column says why the trajectory ended (`ok`, `off_table`,
// `unreachable`); diffdyn writes it on the last row only. A trajectory may be
// shorter than asked. The reader accepts files with and without `status` and
// rejects "ragged" files (non-contiguous steps, a missing action before the last
// row, an action on the last row), text in numeric fields and non-finite numbers
// (nan, inf) with an error naming the file and line.
//
// A trajectory reads into the one Trajectory type (models/trajectory.h): states
// 3 x (T + 1), actions 3 x T, times t_k = k (pushes), label = the trajectory number.
//
//   auto data = diffdyn::ReadPushingCsv("shared/data/pybullet_pushing/collected_data.csv");
//   for (const auto& traj : data) use(traj.states, traj.actions);   // 3 x (T+1), 3 x T
//   diffdyn::WritePushingCsvFile("out.csv", data);                   // atomic
//
// Numbers are written in the shortest form that reads back to the same double,
// so a written file reads back exactly and equal data give equal bytes.
#pragma once

#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/io.h"
#include "diffdyn/models/trajectory.h"

namespace diffdyn {

namespace pushing_csv_internal {

inline constexpr const char* kColumns[] = {"trajectory", "step",  "x",           "y",
                                           "theta",      "push_location", "push_angle",
                                           "push_length"};

// Splits one line at commas (no quoting in this format).
inline std::vector<std::string_view> SplitCommas(std::string_view line) {
  std::vector<std::string_view> fields;
  size_t start = 0;
  while (true) {
    const size_t comma = line.find(',', start);
    fields.push_back(line.substr(start, comma == std::string_view::npos ? comma : comma - start));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return fields;
}

// Shortest round-trip text of a double.
inline void AppendNumber(std::string& out, double value) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  out.append(buffer, result.ptr);
}

}  // namespace pushing_csv_internal

/// The pushing Trajectory of `poses` (T + 1) and `actions` (T), times 0..T.
inline Trajectory MakePushingTrajectory(const std::vector<Eigen::Vector3d>& poses,
                                        const std::vector<Eigen::Vector3d>& actions,
                                        std::string label = "", std::string status = "ok") {
  Trajectory t;
  t.label = std::move(label);
  t.status = std::move(status);
  const int samples = static_cast<int>(poses.size());
  t.t = Eigen::VectorXd::LinSpaced(samples, 0.0, samples - 1.0);
  t.states.resize(3, samples);
  for (int k = 0; k < samples; ++k) t.states.col(k) = poses[k];
  t.actions.resize(3, static_cast<Eigen::Index>(actions.size()));
  for (std::size_t k = 0; k < actions.size(); ++k) {
    t.actions.col(static_cast<Eigen::Index>(k)) = actions[k];
  }
  return t;
}

/// Reads a pushing CSV (with or without `status`). Throws diffdyn::Error naming
/// `path` and the line for a missing file, a wrong header, a bad or non-finite
/// number or a ragged trajectory.
inline std::vector<Trajectory> ReadPushingCsv(const std::filesystem::path& path) {
  using pushing_csv_internal::kColumns;
  std::ifstream in = OpenInputFile(path);
  std::string line;
  DIFFDYN_CHECK(static_cast<bool>(std::getline(in, line)), path.string(), ": empty file");
  if (!line.empty() && line.back() == '\r') line.pop_back();
  const auto header = pushing_csv_internal::SplitCommas(line);
  const bool has_status = header.size() == 9 && header[8] == "status";
  bool header_ok = header.size() == 8 || has_status;
  for (size_t i = 0; header_ok && i < 8; ++i) header_ok = header[i] == kColumns[i];
  DIFFDYN_CHECK(header_ok, path.string(),
                ":1: header must be trajectory,step,x,y,theta,push_location,push_angle,"
                "push_length[,status], got '",
                line, "'");

  // The trajectory being read: poses, actions, number and status.
  struct Open {
    std::vector<Eigen::Vector3d> poses, actions;
    long id = 0;
    std::string status = "ok";
  };
  std::vector<Trajectory> trajectories;
  Open current;
  long current_id = 0;
  bool open = false;  // the last trajectory has a row without action yet to come
  int line_number = 1;
  auto where = [&] { return StrCat(path.string(), ":", line_number, ": "); };
  while (std::getline(in, line)) {
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) continue;
    const auto fields = pushing_csv_internal::SplitCommas(line);
    DIFFDYN_CHECK(fields.size() == header.size(), where(), "expected ", header.size(),
                  " fields, got ", fields.size());
    auto parse_double = [&](size_t i) {
      double value = 0;
      const auto f = fields[i];
      const auto result = std::from_chars(f.data(), f.data() + f.size(), value);
      DIFFDYN_CHECK(result.ec == std::errc() && result.ptr == f.data() + f.size(), where(),
                    "column ", kColumns[i], ": '", std::string(f), "' is not a number");
      // from_chars accepts "nan" and "inf"; no model can learn from them.
      DIFFDYN_CHECK(std::isfinite(value), where(), "column ", kColumns[i], ": '", std::string(f),
                    "' is not finite");
      DIFFDYN_CHECK(std::abs(value) <= kMaxDataMagnitude, where(), "column ", kColumns[i], ": ", value,
                    " is larger in magnitude than ", kMaxDataMagnitude);
      return value;
    };
    auto parse_long = [&](size_t i) {
      long value = 0;
      const auto f = fields[i];
      const auto result = std::from_chars(f.data(), f.data() + f.size(), value);
      DIFFDYN_CHECK(result.ec == std::errc() && result.ptr == f.data() + f.size(), where(),
                    "column ", kColumns[i], ": '", std::string(f), "' is not an integer");
      return value;
    };
    const long id = parse_long(0);
    const long step = parse_long(1);
    const Eigen::Vector3d state(parse_double(2), parse_double(3), parse_double(4));
    const bool no_action = fields[5].empty() && fields[6].empty() && fields[7].empty();
    DIFFDYN_CHECK(no_action || (!fields[5].empty() && !fields[6].empty() && !fields[7].empty()),
                  where(), "ragged: action fields are partly empty");

    // A new trajectory starts at step 0 after the previous one was closed.
    if (!open || id != current_id) {
      DIFFDYN_CHECK(!open, where(), "ragged: trajectory ", current_id,
                    " ends without a row without action (missing action before the last row)");
      DIFFDYN_CHECK(step == 0, where(), "ragged: trajectory ", id, " starts at step ", step,
                    ", expected 0");
      current = Open{};
      current.id = id;
      current_id = id;
      open = true;
    } else {
      const long expected = static_cast<long>(current.poses.size());
      DIFFDYN_CHECK(step == expected, where(), "ragged: trajectory ", id, " has step ", step,
                    " where step ", expected, " was expected (non-contiguous steps)");
    }
    current.poses.push_back(state);
    if (no_action) {
      open = false;
      if (has_status && !fields[8].empty()) current.status = std::string(fields[8]);
      trajectories.push_back(MakePushingTrajectory(
          current.poses, current.actions, std::to_string(current.id), current.status));
    } else {
      current.actions.emplace_back(parse_double(5), parse_double(6), parse_double(7));
    }
  }
  DIFFDYN_CHECK(!open, path.string(), ":", line_number, ": ragged: trajectory ", current_id,
                " ends with an action and no final state");
  return trajectories;
}

/// Writes `trajectories` as a pushing CSV to `out`; numbering is 0, 1, ... in order.
/// With `with_status` the last row of each trajectory carries its status.
/// Throws diffdyn::Error if a trajectory's states and actions are not 3 x (T + 1) and 3 x T.
inline void WritePushingCsv(std::ostream& out, const std::vector<Trajectory>& trajectories,
                            bool with_status = true) {
  using pushing_csv_internal::AppendNumber;
  std::string text = "trajectory,step,x,y,theta,push_location,push_angle,push_length";
  text += with_status ? ",status\n" : "\n";
  for (size_t t = 0; t < trajectories.size(); ++t) {
    const auto& traj = trajectories[t];
    DIFFDYN_CHECK(traj.states.rows() == 3 && traj.actions.rows() == 3 &&
                      traj.states.cols() == traj.actions.cols() + 1,
                  "pushing trajectory ", t, " has states ", traj.states.rows(), "x",
                  traj.states.cols(), " and actions ", traj.actions.rows(), "x", traj.actions.cols(),
                  "; expected 3 x (T + 1) and 3 x T");
    for (Eigen::Index s = 0; s < traj.states.cols(); ++s) {
      text += StrCat(t, ",", s);
      for (int k = 0; k < 3; ++k) {
        text += ',';
        AppendNumber(text, traj.states(k, s));
      }
      if (s < traj.actions.cols()) {
        for (int k = 0; k < 3; ++k) {
          text += ',';
          AppendNumber(text, traj.actions(k, s));
        }
        if (with_status) text += ',';
      } else {
        text += ",,,";
        if (with_status) text += "," + traj.status;
      }
      text += '\n';
    }
  }
  out << text;
}

/// WritePushingCsv into `path` atomically (temporary file, then rename).
inline void WritePushingCsvFile(const std::filesystem::path& path,
                                const std::vector<Trajectory>& trajectories,
                                bool with_status = true) {
  WriteFileAtomically(path,
                      [&](std::ostream& out) { WritePushingCsv(out, trajectories, with_status); });
}

}  // namespace diffdyn
