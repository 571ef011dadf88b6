// Measured joint-space data: readers for the CSV schema and the real datasets.
//
// A measurement is N samples of an n-joint robot at times t_k (seconds):
//
//   q_k, qd_k, tau_k in R^n (SI units), optionally qdd_k,
//
// stored column-wise (n x N matrices). The joint-space CSV of shared/DESIGN.md
// has a header naming its columns t, q1..qn, qd1..qn, tau1..taun and optional
// qdd1..qddn, in any order; n is found from the q columns. Optional: a
// `trajectory` column (a number or label; a new value starts a new segment, t may
// restart there) and ground-truth channels m1..mn (H qdd), c1..cn (Coriolis and
// centrifugal), g1..gn (gravity), f1..fn (friction), kinetic, potential. The real datasets of
// shared/data/ are read in their own formats, detected from the path:
//
//   panda_gaz2019_traj1/   exciting_traj_{time,positions,velocity,torques}.txt
//                          (7 lines per sample), tau = link-side sensor torque;
//   ibm_double_pendulum/   headerless runs of pixel markers (pivot, bob 1,
//                          bob 2); angles q1 = atan2(dy1, dx1) from hanging
//                          down (gravity points along image +x: the camera
//                          is turned), q2 relative, unwrapped;
//                          400 Hz, tau = 0, qd estimated (has_qd = false);
//                          a folder reads run 0.csv, a file reads that run;
//   delan_characters/      character_data.csv: one segment per character.
//
// Samples may be split into independent segments (segment_starts); smoothing
// and differentiation never cross a segment boundary. Readers validate: a bad
// file, a missing column, a non-number or time that does not increase is a
// diffdyn::Error naming the file and line.
#pragma once

#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace diffdyn {

/// Joint-space measurements; matrices are n x N, one sample per column.
struct JointData {
  std::string path;    ///< where it was read from
  std::string format;  ///< "csv", "panda-gaz2019", "ibm-double-pendulum", "delan-characters"
  Eigen::VectorXd t;   ///< N sample times (s), increasing within each segment
  Eigen::MatrixXd q;   ///< n x N positions (rad or m)
  Eigen::MatrixXd qd;  ///< n x N velocities; estimated from q when !has_qd
  Eigen::MatrixXd qdd; ///< n x N accelerations, or empty (0 x 0) when absent
  Eigen::MatrixXd tau; ///< n x N measured joint torques (zeros for free motion)
  bool has_qd = true;  ///< false: qd was not measured
  bool has_tau = true; ///< false: free motion, tau = 0
  std::vector<int> segment_starts = {0};  ///< first sample of each segment
  std::vector<std::string> segment_labels; ///< the `trajectory` value of each segment, or empty
  /// Ground-truth channels by name ("m", "c", "g", "f": n x N; "kinetic", "potential": 1 x N).
  std::map<std::string, Eigen::MatrixXd> channels;
  std::vector<double> link_lengths_px;    ///< ibm: mean marker distances (pixels)
  std::string notes;   ///< what the reader did (for the report)

  /// n, the number of joints.
  int dof() const { return static_cast<int>(q.rows()); }
  /// N, the number of samples.
  int size() const { return static_cast<int>(t.size()); }
};

/// Reads a joint-space CSV by header name; throws diffdyn::Error naming path:line.
JointData ReadJointCsv(const std::string& path);

/// Reads `path`: a joint-space CSV or one of the real datasets (header comment).
JointData ReadMeasured(const std::string& path);

/// Writes `data` as a joint-space CSV (atomically); qdd columns only if present, a
/// `trajectory` column when there are several segments, then the channels.
void WriteJointCsv(const std::string& path, const JointData& data);

}  // namespace diffdyn
