// Damped-least-squares inverse kinematics of the Panda for a pointing tool.
//
// The task is 5-D: put the tool point (the flange moved by `tool_length` along
// its z axis) at p* and point the tool axis z along z* (for pushing, straight
// down); the rotation about the tool axis is free, so the 2 spare degrees of
// freedom pull the arm towards a nominal posture q_nom in the null space:
//
//   e = [p* - p(q); u.(z(q) x z*); v.(z(q) x z*)],   J = [J_v; u^T J_w; v^T J_w]  (5 x 7)
//   dq = J^T (J J^T + lambda^2 I)^-1 e + (I - J^+ J) k_null (q_nom - q)
//
// with (u, v, z*) orthonormal.
//
// iterated from a seed and clamped to the joint limits (minus a margin). J comes
// from Jets (Panda::GeometricJacobian).
//
//   diffdyn::PandaIk ik({.tool_length = 0.1034});
//   auto sol = ik.Solve({0.5, 0.0, 0.02}, {0, 0, -1}, seed);
//   if (sol.converged) use(sol.q);
#pragma once

#include <algorithm>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Geometry>

#include "diffdyn/physics/panda.h"

namespace diffdyn {

/// Options of PandaIk.
struct PandaIkOptions {
  double tool_length = 0.1034;       ///< tool point on the flange z axis (m)
  double damping = 1e-3;             ///< lambda of the damped pseudo-inverse
  double null_gain = 0.2;            ///< k_null, pull towards q_nom per iteration
  double limit_margin = 0.02;        ///< stay this far inside the joint limits (rad)
  double position_tolerance = 1e-6;  ///< converged when |p* - p| below this (m)
  double axis_tolerance = 1e-5;      ///< and |z x z*| below this
  int max_iterations = 100;
  Panda::Vector7<double> nominal = Panda::Ready();  ///< q_nom of the null-space term
};

/// Result of PandaIk::Solve: the joint angles, whether the tolerances were met
/// and the remaining position error (m).
struct PandaIkResult {
  Panda::Vector7<double> q;
  bool converged = false;
  double position_error = 0;
  int iterations = 0;
};

/// Damped-least-squares IK for the tool point and tool axis (see the file comment).
class PandaIk {
 public:
  explicit PandaIk(PandaIkOptions options = {}) : options_(std::move(options)) {}

  const PandaIkOptions& options() const { return options_; }

  /// Solves for the tool point `target` (3) with tool axis `axis` (unit 3-vector)
  /// from `seed` (7). Never throws; check `converged`.
  PandaIkResult Solve(const Eigen::Vector3d& target, const Eigen::Vector3d& axis,
                      const Panda::Vector7<double>& seed) const {
    using Mat5 = Eigen::Matrix<double, 5, 5>;
    // (u, v, axis) is an orthonormal basis: the axis error has components along u, v.
    const Eigen::Vector3d u = axis.unitOrthogonal();
    const Eigen::Vector3d v = axis.cross(u);
    PandaIkResult result;
    result.q = seed;
    Clamp(result.q);
    for (int it = 0; it <= options_.max_iterations; ++it) {
      const auto tool = Panda::Tool<double>(result.q, options_.tool_length);
      const Eigen::Vector3d tilt = tool.R.col(2).cross(axis);
      // Fixed-size blocks: the comma initializer's dynamic block makes g++ 12 at
      // -march=znver3 report a false -Warray-bounds inside Eigen's AVX loads.
      Eigen::Matrix<double, 5, 1> err;
      err.head<3>() = target - tool.p;
      err[3] = u.dot(tilt);
      err[4] = v.dot(tilt);
      result.position_error = err.head<3>().norm();
      result.iterations = it;
      if (result.position_error < options_.position_tolerance &&
          err.tail<2>().norm() < options_.axis_tolerance) {
        result.converged = true;
        return result;
      }
      if (it == options_.max_iterations) break;
      const Eigen::Matrix<double, 6, 7> geometric =
          Panda::GeometricJacobian(result.q, options_.tool_length);
      Eigen::Matrix<double, 5, 7> jac;
      jac.topRows<3>() = geometric.topRows<3>();
      jac.row(3) = u.transpose() * geometric.bottomRows<3>();
      jac.row(4) = v.transpose() * geometric.bottomRows<3>();
      const Mat5 jjt = jac * jac.transpose();
      const Eigen::LDLT<Mat5> task(jjt + options_.damping * options_.damping * Mat5::Identity());
      Panda::Vector7<double> dq = jac.transpose() * task.solve(err);
      // Null-space pull towards the nominal posture, through a nearly exact projector.
      const Eigen::LDLT<Mat5> null(jjt + 1e-12 * Mat5::Identity());
      const Panda::Vector7<double> pull = options_.null_gain * (options_.nominal - result.q);
      dq += pull - jac.transpose() * null.solve(jac * pull);
      result.q += dq;
      Clamp(result.q);
    }
    return result;
  }

 private:
  void Clamp(Panda::Vector7<double>& q) const {
    for (int i = 0; i < 7; ++i) {
      q[i] = std::clamp(q[i], Panda::kQMin[i] + options_.limit_margin,
                        Panda::kQMax[i] - options_.limit_margin);
    }
  }

  PandaIkOptions options_;
};

}  // namespace diffdyn
