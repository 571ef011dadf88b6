// Trajectories and datasets: the one data type of every system.
//
// A trajectory of T transitions holds T + 1 times and states and the T actions
// between them,
//
//   t_0 < t_1 < ... < t_T,   x_0 .. x_T (n x (T + 1)),   u_0 .. u_{T-1} (m x T),
//
// action u_k moving x_k to x_{k+1} over dt_k = t_{k+1} - t_k (dt may vary: real
// logs jitter). Named channels carry what is measured or known besides the state
// and action, one column per sample (rows x (T + 1)): the full measured torque
// "tau", accelerations "qdd", ground-truth force components "m", "c", "g", "f",
// energies "kinetic", "potential". A pushing trajectory counts pushes: t_k = k.
//
// A dataset is trajectories of one SystemDescription (sizes, names, angles and
// the state metric of state_loss.h). The CSV schemas that read and write it are in
// solvers/dataset_io.h.
//
//   Dataset data = ReadDataset("pendulum.csv");      // solvers/dataset_io.h
//   for (const Trajectory& t : data.trajectories) use(t.states, t.actions);
//   SampleIntervals dt = data.Intervals();          // median, min, max of dt_k
#pragma once

#include <algorithm>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/system_description.h"

namespace diffdyn {

/// Largest magnitude of any number a data file may hold (times, states, actions
/// and channels alike): larger values overflow the squared errors and filters.
inline constexpr double kMaxDataMagnitude = 1e12;

/// Times (T + 1), states (n x (T + 1)), actions (m x T) and named channels
/// (rows x (T + 1) each) of one run; T may be 0.
struct Trajectory {
  /// Its label in the file (a number or a name; "" when the file has one run).
  std::string label;
  Eigen::VectorXd t;
  Eigen::MatrixXd states;
  Eigen::MatrixXd actions;
  std::map<std::string, Eigen::MatrixXd> channels;
  /// Why the run ended ("ok", "off_table", "unreachable", ...).
  std::string status = "ok";

  /// T, the number of transitions.
  int transitions() const { return static_cast<int>(actions.cols()); }

  /// Throws diffdyn::Error naming `what` when the sizes do not fit n, m and each
  /// other, a time does not increase or a number is not finite.
  void Validate(int n, int m, const std::string& what) const {
    const Eigen::Index samples = states.cols();
    DIFFDYN_CHECK(samples >= 1 && states.rows() == n && actions.rows() == m &&
                      actions.cols() == samples - 1 && t.size() == samples,
                  what, ": a trajectory needs T + 1 times and states and T actions of sizes ", n,
                  " and ", m, "; got ", t.size(), " times, states ", states.rows(), "x",
                  states.cols(), ", actions ", actions.rows(), "x", actions.cols());
    DIFFDYN_CHECK(states.allFinite() && actions.allFinite() && t.allFinite(), what,
                  ": non-finite state, action or time");
    for (Eigen::Index k = 1; k < samples; ++k) {
      DIFFDYN_CHECK(t[k] > t[k - 1], what, ": time does not increase at sample ", k, " (t = ", t[k],
                    " after ", t[k - 1], ")");
    }
    for (const auto& [name, values] : channels) {
      DIFFDYN_CHECK(values.cols() == samples && values.allFinite(), what, ": channel '", name,
                    "' needs ", samples, " finite columns, got ", values.cols());
    }
  }
};

/// The spread of the sample intervals dt_k of a dataset (seconds; counts for pushes).
struct SampleIntervals {
  double median = 0.0;
  double min = 0.0;
  double max = 0.0;
  /// (max - min) / median: 0 for regular sampling.
  double jitter() const { return median > 0 ? (max - min) / median : 0.0; }
};

/// Trajectories of one system, read from `path` in `format`.
struct Dataset {
  SystemDescription system;
  std::vector<Trajectory> trajectories;
  /// Where it came from and its schema ("pushing-csv", "joint-csv", "panda-gaz2019", ...).
  std::string path;
  std::string format;
  /// What the reader did, for reports ("qd estimated from q", ...).
  std::string notes;
  /// States and channels holding estimates or assumed values rather than
  /// measurements: "qd1".."qdn" differentiated from q, "tau" for free motion
  /// (torque taken as zero).
  std::vector<std::string> unmeasured;
  /// Numbers the reader found about the setup (the IBM double pendulum's marker
  /// distances "link1_px", "link2_px").
  std::map<std::string, double> properties;

  /// Whether `name` (a state or channel) was measured.
  bool IsMeasured(const std::string& name) const {
    return std::find(unmeasured.begin(), unmeasured.end(), name) == unmeasured.end();
  }

  /// Sum of the trajectories' samples (T + 1 each).
  int samples() const {
    int count = 0;
    for (const Trajectory& t : trajectories) count += static_cast<int>(t.states.cols());
    return count;
  }

  /// Sum of the trajectories' transitions.
  int transitions() const {
    int count = 0;
    for (const Trajectory& t : trajectories) count += t.transitions();
    return count;
  }

  /// Median, smallest and largest dt_k over every transition; throws diffdyn::Error
  /// when there is none.
  SampleIntervals Intervals() const {
    std::vector<double> dt;
    for (const Trajectory& t : trajectories) {
      for (int k = 0; k < t.transitions(); ++k) dt.push_back(t.t[k + 1] - t.t[k]);
    }
    DIFFDYN_CHECK(!dt.empty(), path, ": no transitions");
    SampleIntervals s;
    s.min = *std::min_element(dt.begin(), dt.end());
    s.max = *std::max_element(dt.begin(), dt.end());
    std::nth_element(dt.begin(), dt.begin() + dt.size() / 2, dt.end());
    s.median = dt[dt.size() / 2];
    return s;
  }

  /// Validates the system and every trajectory against it (errors name path and
  /// the trajectory).
  void Validate() const {
    system.Validate();
    for (std::size_t i = 0; i < trajectories.size(); ++i) {
      trajectories[i].Validate(system.state_size(), system.action_size(),
                               StrCat(path, ": trajectory ", i));
    }
  }
};

}  // namespace diffdyn
