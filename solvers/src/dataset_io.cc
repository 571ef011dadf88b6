#include "diffdyn/solvers/dataset_io.h"

#include <algorithm>
#include <filesystem>
#include <fstream>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/physics/pushing/csv.h"
#include "diffdyn/physics/pushing/system.h"
#include "joint_space_csv.h"

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
  return ReadJointSpace(path, layout);
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
  WriteJointSpaceCsv(path, data);
}

}  // namespace diffdyn
