// The Franka Emika Panda: one description for kinematics and dynamics.
//
// Everything diffdyn knows about the 7-DoF Panda lives here, so the pusher's
// inverse kinematics, the ODE-engine arm and the rigid-body dynamics all read
// the same numbers:
//
//   * modified (Craig) Denavit-Hartenberg rows, Franka's published table; row i
//     is the transform from frame i-1 to frame i,
//       T_{i-1,i} = RotX(alpha_i) * TransX(a_i) * RotZ(q_i) * TransZ(d_i),
//     and a fixed 8th row (d_F = 0.107 m) gives the flange F;
//   * link masses, centres of mass c_i (in frame i) and barycentric inertia
//     tensors I_i (about the COM, axes of frame i) of Gaz et al. 2019 (p-hat);
//   * joint position / velocity / torque limits of the Panda datasheet.
//
// Kinematics is templated on the scalar: `double` gives values and
// `ceres::Jet<double, 7>` gives the derivative with respect to q, from which the
// position and geometric Jacobians are built:
//
//   diffdyn::Panda::Vector7<double> q = diffdyn::Panda::kReady;   // 7 joint angles
//   auto flange = diffdyn::Panda::Flange(q);                      // R (3x3), p (3)
//   Eigen::Matrix<double, 6, 7> J = diffdyn::Panda::GeometricJacobian(q, 0.1034);
//
// A "tool" of length L is a point on the flange's z axis, p_tool = p_F + L R_F e_z
// (the pusher tip of the pushing world sits there).
#pragma once

#include <array>
#include <cmath>
#include <numbers>

#include <Eigen/Core>
#include <ceres/jet.h>

namespace diffdyn {

/// A rigid transform: x_parent = R x_child + p. R: 3x3 rotation, p: 3-vector.
template <typename T>
struct RigidPose {
  Eigen::Matrix<T, 3, 3> R = Eigen::Matrix<T, 3, 3>::Identity();
  Eigen::Matrix<T, 3, 1> p = Eigen::Matrix<T, 3, 1>::Zero();

  /// Composition: (this * child).R = R child.R, (this * child).p = R child.p + p.
  RigidPose operator*(const RigidPose& child) const { return {R * child.R, R * child.p + p}; }
};

/// The Panda's kinematic and dynamic parameters and its templated kinematics.
struct Panda {
  /// Number of joints, n = 7.
  static constexpr int kDof = 7;

  template <typename T>
  using Vector7 = Eigen::Matrix<T, 7, 1>;

  /// One modified-DH row: a (m), d (m), alpha (rad); theta = q_i (0 for the flange).
  struct DhRow {
    double a;
    double d;
    double alpha;
  };

  /// Rows 1..7 (joints) and 8 (flange, theta fixed at 0), Franka's table.
  static constexpr std::array<DhRow, 8> kDh = {{{0.0, 0.333, 0.0},
                                                {0.0, 0.0, -std::numbers::pi / 2},
                                                {0.0, 0.316, std::numbers::pi / 2},
                                                {0.0825, 0.0, std::numbers::pi / 2},
                                                {-0.0825, 0.384, -std::numbers::pi / 2},
                                                {0.0, 0.0, std::numbers::pi / 2},
                                                {0.088, 0.0, std::numbers::pi / 2},
                                                {0.0, 0.107, 0.0}}};

  /// Link masses m_i (kg), Gaz et al. Table VIII; total 16.062 kg.
  static constexpr std::array<double, 7> kMass = {4.970684, 0.646926, 3.228604, 3.587895,
                                                  1.225946, 1.666555, 0.735522};

  /// Centres of mass c_i = (cx, cy, cz) in frame i (m), Table VIII (c1z "don't care" = 0).
  static constexpr std::array<std::array<double, 3>, 7> kCom = {{
      {3.875e-03, 2.081e-03, 0.0},
      {-3.141e-03, -2.872e-02, 3.495e-03},
      {2.7518e-02, 3.9252e-02, -6.6502e-02},
      {-5.317e-02, 1.04419e-01, 2.7454e-02},
      {-1.1953e-02, 4.1065e-02, -3.8437e-02},
      {6.0149e-02, -1.4117e-02, -1.0517e-02},
      {1.0517e-02, -4.252e-03, 6.1597e-02},
  }};

  /// Barycentric inertia tensors (kg m^2), Table IX, as (Ixx, Ixy, Ixz, Iyy, Iyz, Izz)
  /// tensor elements (I_xy = -int xy dm), about c_i with the axes of frame i.
  static constexpr std::array<std::array<double, 6>, 7> kInertia = {{
      {7.0337e-01, -1.3900e-04, 6.7720e-03, 7.0661e-01, 1.9169e-02, 9.1170e-03},
      {7.9620e-03, -3.9250e-03, 1.0254e-02, 2.8110e-02, 7.0400e-04, 2.5995e-02},
      {3.7242e-02, -4.7610e-03, -1.1396e-02, 3.6155e-02, -1.2805e-02, 1.0830e-02},
      {2.5853e-02, 7.7960e-03, -1.3320e-03, 1.9552e-02, 8.6410e-03, 2.8323e-02},
      {3.5549e-02, -2.1170e-03, -4.0370e-03, 2.9474e-02, 2.2900e-04, 8.6270e-03},
      {1.9640e-03, 1.0900e-04, -1.1580e-03, 4.3540e-03, 3.4100e-04, 5.4330e-03},
      {1.2516e-02, -4.2800e-04, -1.1960e-03, 1.0027e-02, -7.4100e-04, 4.8150e-03},
  }};

  /// Joint position limits q_min, q_max (rad), Franka's "Limits for Panda".
  static constexpr std::array<double, 7> kQMin = {-2.8973, -1.7628, -2.8973, -3.0718,
                                                  -2.8973, -0.0175, -2.8973};
  static constexpr std::array<double, 7> kQMax = {2.8973, 1.7628, 2.8973, -0.0698,
                                                  2.8973, 3.7525, 2.8973};
  /// Joint velocity limits (rad/s).
  static constexpr std::array<double, 7> kDqMax = {2.1750, 2.1750, 2.1750, 2.1750,
                                                   2.6100, 2.6100, 2.6100};
  /// Joint torque limits (N m).
  static constexpr std::array<double, 7> kTauMax = {87, 87, 87, 87, 12, 12, 12};
  /// Standard gravity used by Gaz et al. (m/s^2), acting along -z of the base.
  static constexpr double kGravity = 9.80665;

  /// The "ready" posture (0, -pi/4, 0, -3pi/4, 0, pi/2, pi/4).
  static Vector7<double> Ready() {
    Vector7<double> q;
    q << 0, -std::numbers::pi / 4, 0, -3 * std::numbers::pi / 4, 0, std::numbers::pi / 2, std::numbers::pi / 4;
    return q;
  }

  /// Barycentric inertia of link i (0-based) as a symmetric 3x3 matrix in frame i+1.
  static Eigen::Matrix3d InertiaMatrix(int i) {
    const auto& v = kInertia[i];
    Eigen::Matrix3d m;
    m << v[0], v[1], v[2], v[1], v[3], v[4], v[2], v[4], v[5];
    return m;
  }

  /// T_{i-1,i} of DH row `row` (0-based; row 7 is the flange) at joint angle theta.
  template <typename T>
  static RigidPose<T> DhTransform(int row, const T& theta) {
    using std::cos;
    using std::sin;
    const DhRow& dh = kDh[row];
    const double ca = std::cos(dh.alpha), sa = std::sin(dh.alpha);
    // Exact zeros for the +-pi/2 rows keep frames exactly orthogonal.
    const double c_alpha = std::abs(ca) < 1e-12 ? 0.0 : ca;
    const T ct = cos(theta), st = sin(theta);
    RigidPose<T> pose;
    pose.R << ct, -st, T(0.0), st * c_alpha, ct * c_alpha, T(-sa), st * sa, ct * sa, T(c_alpha);
    pose.p << T(dh.a), T(-sa * dh.d), T(c_alpha * dh.d);
    return pose;
  }

  /// Frames T_{0,1} .. T_{0,7} (indices 0..6) and the flange T_{0,F} (index 7) at q.
  template <typename T>
  static std::array<RigidPose<T>, 8> Frames(const Vector7<T>& q) {
    std::array<RigidPose<T>, 8> frames;
    RigidPose<T> pose;
    for (int i = 0; i < 8; ++i) {
      pose = pose * DhTransform<T>(i, i < 7 ? q[i] : T(0.0));
      frames[i] = pose;
    }
    return frames;
  }

  /// The flange pose T_{0,F}(q).
  template <typename T>
  static RigidPose<T> Flange(const Vector7<T>& q) {
    return Frames<T>(q)[7];
  }

  /// The tool pose: the flange frame moved by `tool_length` (m) along its z axis.
  template <typename T>
  static RigidPose<T> Tool(const Vector7<T>& q, double tool_length) {
    RigidPose<T> tool = Flange<T>(q);
    tool.p += tool.R.col(2) * T(tool_length);
    return tool;
  }

  /// World positions of the 7 link centres of mass, p_ci = R_0i c_i + p_0i (3 x 7).
  template <typename T>
  static Eigen::Matrix<T, 3, 7> ComPositions(const Vector7<T>& q) {
    const auto frames = Frames<T>(q);
    Eigen::Matrix<T, 3, 7> coms;
    for (int i = 0; i < 7; ++i) {
      const Eigen::Matrix<T, 3, 1> c = Eigen::Vector3d(kCom[i][0], kCom[i][1], kCom[i][2]).cast<T>();
      coms.col(i) = frames[i].R * c + frames[i].p;
    }
    return coms;
  }

  /// Jet<double, 7> seeded with dq_j / dq = e_j: the input of every Jacobian here.
  using Jet7 = ceres::Jet<double, 7>;
  static Vector7<Jet7> SeedJets(const Vector7<double>& q) {
    Vector7<Jet7> qj;
    for (int j = 0; j < 7; ++j) qj[j] = Jet7(q[j], j);
    return qj;
  }

  /// Position Jacobian of the tool point, J_v = d p_tool / dq (3 x 7), from Jets.
  static Eigen::Matrix<double, 3, 7> PositionJacobian(const Vector7<double>& q,
                                                      double tool_length) {
    const RigidPose<Jet7> tool = Tool<Jet7>(SeedJets(q), tool_length);
    Eigen::Matrix<double, 3, 7> jac;
    for (int r = 0; r < 3; ++r) jac.row(r) = tool.p[r].v.transpose();
    return jac;
  }

  /// Geometric Jacobian of the tool, [v; omega] = J qdot (6 x 7): rows 0-2 are
  /// d p_tool / dq, rows 3-5 the angular velocity columns omega_j = vee(dR/dq_j R^T),
  /// both in the base frame, from Jets.
  static Eigen::Matrix<double, 6, 7> GeometricJacobian(const Vector7<double>& q,
                                                       double tool_length) {
    const RigidPose<Jet7> tool = Tool<Jet7>(SeedJets(q), tool_length);
    Eigen::Matrix3d rot;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) rot(r, c) = tool.R(r, c).a;
    }
    Eigen::Matrix<double, 6, 7> jac;
    for (int j = 0; j < 7; ++j) {
      Eigen::Matrix3d d_rot;
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) d_rot(r, c) = tool.R(r, c).v[j];
      }
      const Eigen::Matrix3d skew = d_rot * rot.transpose();
      for (int r = 0; r < 3; ++r) jac(r, j) = tool.p[r].v[j];
      jac(3, j) = skew(2, 1);
      jac(4, j) = skew(0, 2);
      jac(5, j) = skew(1, 0);
    }
    return jac;
  }

  /// True when every q_i lies in [q_min_i, q_max_i] (with `margin` rad inside).
  static bool WithinLimits(const Vector7<double>& q, double margin = 0.0) {
    for (int i = 0; i < 7; ++i) {
      if (q[i] < kQMin[i] + margin || q[i] > kQMax[i] - margin) return false;
    }
    return true;
  }
};

}  // namespace diffdyn
