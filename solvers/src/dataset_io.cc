#include "diffdyn/solvers/dataset_io.h"

#include <algorithm>
#include <filesystem>
#include <fstream>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/physics/pushing/csv.h"
#include "diffdyn/physics/pushing/system.h"

namespace diffdyn {
namespace {

// Whether the first line of `path` is the pushing CSV's header.
bool IsPushingCsv(const std::string& path) {
  if (!std::filesystem::is_regular_file(path)) return false;
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  return line.rfind("trajectory,step,x,y,theta,", 0) == 0;
}

void CheckJoints(const std::vector<int>& joints, int n, const char* what) {
  for (int j : joints) {
    DIFFDYN_CHECK(j >= 1 && j <= n, what, ": joint ", j, " is not one of the ", n, " joints");
  }
}

}  // namespace

SystemDescription JointSpaceSystem(int n, const JointLayout& layout) {
  CheckJoints(layout.actuated, n, "actuated joints");
  CheckJoints(layout.prismatic, n, "prismatic joints");
  SystemDescription s;
  s.name = layout.name;
  for (int j = 1; j <= n; ++j) s.state_names.push_back(StrCat("q", j));
  for (int j = 1; j <= n; ++j) s.state_names.push_back(StrCat("qd", j));
  for (int j = 1; j <= n; ++j) {
    const bool actuated = layout.all_actuated || layout.actuated.empty() ||
                          std::find(layout.actuated.begin(), layout.actuated.end(), j) !=
                              layout.actuated.end();
    if (actuated) s.action_names.push_back(StrCat("tau", j));
    const bool prismatic =
        std::find(layout.prismatic.begin(), layout.prismatic.end(), j) != layout.prismatic.end();
    if (!prismatic) s.angles.push_back(j - 1);
  }
  s.angle_features = layout.angle_features;
  s.Validate();
  return s;
}

Dataset JointDataset(const JointData& data, const JointLayout& layout) {
  const int n = data.dof();
  JointLayout resolved = layout;
  if (!layout.all_actuated && layout.actuated.empty()) {
    // The joints whose torque is not zero throughout.
    for (int j = 0; j < n; ++j) {
      if (!data.tau.row(j).isZero(0.0)) resolved.actuated.push_back(j + 1);
    }
  }
  Dataset d;
  d.system = JointSpaceSystem(n, resolved);
  d.path = data.path;
  d.format = data.format == "csv" ? "joint-csv" : data.format;
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

Dataset ReadDataset(const std::string& path, const JointLayout& layout) {
  if (IsPushingCsv(path)) {
    Dataset d;
    d.system = PushingSystem();
    d.trajectories = ReadPushingCsv(path);
    d.path = path;
    d.format = "pushing-csv";
    DIFFDYN_CHECK(!d.trajectories.empty(), path, ": no trajectories");
    return d;
  }
  return JointDataset(ReadMeasured(path), layout);
}

Dataset DatasetForModel(const Dataset& data, const SystemDescription& model, const std::string& what) {
  if (model.state_names != data.system.state_names) {
    DIFFDYN_CHECK(model.state_size() == data.system.state_size() &&
                      model.action_size() == data.system.action_size(),
                  what, ": the model takes ", model.state_size(), " states and ", model.action_size(),
                  " actions; the data in ", data.path, " have ", data.system.state_size(), " and ",
                  data.system.action_size());
    return data;
  }
  // The model's names, angles and bounds; the data's metric.
  Dataset out = data;
  out.system = model;
  out.system.loss_weights = data.system.loss_weights;
  out.system.loss_wraps_angles = data.system.loss_wraps_angles;
  if (model.action_names == data.system.action_names) return out;
  for (Trajectory& t : out.trajectories) {
    t.actions.resize(model.action_size(), t.transitions());
    for (int r = 0; r < model.action_size(); ++r) {
      const std::string& name = model.action_names[r];
      const auto have = std::find(data.system.action_names.begin(), data.system.action_names.end(), name);
      if (have != data.system.action_names.end()) {
        const auto row = have - data.system.action_names.begin();
        t.actions.row(r) = data.trajectories[&t - out.trajectories.data()].actions.row(row);
        continue;
      }
      const auto tau = t.channels.find("tau");
      int joint = 0;
      const bool is_tau = name.rfind("tau", 0) == 0 && name.size() > 3 && name.size() <= 6 &&
                          name.find_first_not_of("0123456789", 3) == std::string::npos &&
                          (joint = std::stoi(name.substr(3))) >= 1;
      DIFFDYN_CHECK(is_tau && tau != t.channels.end() && joint <= tau->second.rows(), what,
                    ": the model's action '", name, "' is not in the data of ", data.path);
      t.actions.row(r) = tau->second.row(joint - 1).head(t.transitions());
    }
  }
  return out;
}

void WriteDataset(const std::string& path, const Dataset& data) {
  if (data.format == "pushing-csv") {
    WritePushingCsvFile(path, data.trajectories);
    return;
  }
  const int n = data.system.state_size() / 2;
  DIFFDYN_CHECK(n >= 1 && data.system.state_size() == 2 * n, path,
                ": a joint-space CSV needs states [q; qd], got ", data.system.state_size(), " components");
  JointData j;
  j.path = path;
  int count = 0;
  for (const Trajectory& t : data.trajectories) count += static_cast<int>(t.states.cols());
  j.t.resize(count);
  j.q.resize(n, count);
  j.qd.resize(n, count);
  j.tau.resize(n, count);
  j.segment_starts.clear();
  int k = 0;
  for (const Trajectory& t : data.trajectories) {
    const int samples = static_cast<int>(t.states.cols());
    j.segment_starts.push_back(k);
    j.segment_labels.push_back(t.label);
    j.t.segment(k, samples) = t.t;
    j.q.middleCols(k, samples) = t.states.topRows(n);
    j.qd.middleCols(k, samples) = t.states.bottomRows(n);
    const auto tau = t.channels.find("tau");
    DIFFDYN_CHECK(tau != t.channels.end() && tau->second.rows() == n, path,
                  ": trajectory ", t.label, " has no channel 'tau' of ", n, " rows");
    j.tau.middleCols(k, samples) = tau->second;
    for (const auto& [name, values] : t.channels) {
      if (name == "tau") continue;
      Eigen::MatrixXd& all = name == "qdd" ? j.qdd : j.channels[name];
      if (all.cols() != count) all.resize(values.rows(), count);
      all.middleCols(k, samples) = values;
    }
    k += samples;
  }
  WriteJointCsv(path, j);
}

}  // namespace diffdyn
