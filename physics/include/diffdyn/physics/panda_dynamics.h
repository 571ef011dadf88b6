// Panda rigid-body dynamics: recursive Newton-Euler on the one Panda description.
//
// The kinematics (modified DH rows) and the link masses m_i, centres of mass c_i
// and barycentric inertias I_i come from physics/panda.h. Inverse dynamics is
// the recursive Newton-Euler algorithm (RNEA), all vectors in the moving frame
// i of link i, with R = R_{i-1,i}, p = p_{i-1,i} from DH row i and z = (0,0,1):
//
//   forward, i = 1..7 (base: w_0 = dw_0 = 0, a_0 = -g_vec = (0, 0, g0)):
//     w_i  = R^T w_{i-1} + qd_i z
//     dw_i = R^T dw_{i-1} + (R^T w_{i-1}) x (qd_i z) + qdd_i z
//     a_i  = R^T (a_{i-1} + dw_{i-1} x p + w_{i-1} x (w_{i-1} x p))   (origin of i)
//     a_ci = a_i + dw_i x c_i + w_i x (w_i x c_i)
//     F_i  = m_i a_ci,    N_i = I_i dw_i + w_i x (I_i w_i)
//   backward, i = 7..1 (f_8 = n_8 = 0; R', p' of row i+1):
//     f_i = R' f_{i+1} + F_i
//     n_i = N_i + R' n_{i+1} + c_i x F_i + p' x (R' f_{i+1})
//     tau_i = n_i . z
//
// Gravity is (0, 0, -g0) in the base frame with g0 = 9.80665 (Gaz et al.). A
// known tool is a point mass `tool_mass` at `tool_com` (flange frame); the
// payload effect's TipLoad is the torque a 1 kg point mass at the flange origin
// needs. Mass matrix and forward dynamics follow from ID (analytic_model.h).
//
// PandaSigmoidFriction gives Gaz et al.'s published friction model (Table I),
//   tau_f,j = phi1 / (1 + exp(-phi2 (qd_j + phi3))) - phi1 / (1 + exp(-phi2 phi3)),
// used as the published baseline on the real trajectory.
#pragma once

#include <array>
#include <cmath>
#include <vector>

#include <Eigen/Geometry>

#include "diffdyn/physics/analytic_model.h"
#include "diffdyn/physics/panda.h"

namespace diffdyn {

/// Panda rigid-body dynamics; q, qd, qdd, tau of size 7; p = (tool_mass,
/// tool_com_x, tool_com_y, tool_com_z, g).
struct PandaModel {
  static constexpr const char* kName = "panda";
  static constexpr int kDof = 7;
  static std::vector<ParamSpec> Specs() {
    return {{"tool_mass", 0.0, "kg", "known tool: point mass"},
            {"tool_com_x", 0.0, "m", "known tool: COM x in the flange frame"},
            {"tool_com_y", 0.0, "m", "known tool: COM y in the flange frame"},
            {"tool_com_z", 0.0, "m", "known tool: COM z in the flange frame"},
            {"g", Panda::kGravity, "m/s^2", "gravity along -z of the base"}};
  }
  static bool Prismatic(int) { return false; }

  /// RNEA (header comment) with link masses scaled by `link_scale` (1 = the
  /// published links, 0 = none) and an extra point mass `tip_mass` at `tip_com`
  /// in the flange frame. Returns tau (7).
  template <typename T, typename Q, typename Qd, typename Qdd>
  static JointVector<T, 7> Rnea(const Q& q, const Qd& qd, const Qdd& qdd, const T& gravity, double link_scale, const T& tip_mass,
                         const Eigen::Matrix<T, 3, 1>& tip_com) {
    using Vec3 = Eigen::Matrix<T, 3, 1>;
    using Mat3 = Eigen::Matrix<T, 3, 3>;
    const Vec3 z(T(0.0), T(0.0), T(1.0));
    std::array<RigidPose<T>, 8> rows;
    for (int i = 0; i < 8; ++i) rows[i] = Panda::DhTransform<T>(i, i < 7 ? q[i] : T(0.0));

    // Forward pass: velocities and accelerations of each link frame.
    std::array<Vec3, 7> force, moment, com;
    Vec3 w = Vec3::Zero(), dw = Vec3::Zero();
    Vec3 a(T(0.0), T(0.0), gravity);
    for (int i = 0; i < 7; ++i) {
      const Mat3 rt = rows[i].R.transpose();
      const Vec3& p = rows[i].p;
      const Vec3 a_origin = rt * (a + dw.cross(p) + w.cross(w.cross(p)));
      const Vec3 w_rot = rt * w;
      const Vec3 w_new = w_rot + qd[i] * z;
      const Vec3 dw_new = rt * dw + w_rot.cross(qd[i] * z) + qdd[i] * z;
      w = w_new;
      dw = dw_new;
      a = a_origin;
      const Vec3 c = Eigen::Vector3d(Panda::kCom[i][0], Panda::kCom[i][1], Panda::kCom[i][2]).cast<T>();
      com[i] = c;
      const Mat3 inertia = (link_scale * Panda::InertiaMatrix(i)).template cast<T>();
      const T mass = T(link_scale * Panda::kMass[i]);
      force[i] = mass * (a + dw.cross(c) + w.cross(w.cross(c)));
      moment[i] = inertia * dw + w.cross(inertia * w);
      if (i == 6) {
        // The tip point mass rides on link 7 at p_7F + tip_com (flange axes = frame 7 axes).
        const Vec3 r = rows[7].p + tip_com;
        const Vec3 f_tip = tip_mass * (a + dw.cross(r) + w.cross(w.cross(r)));
        moment[i] += r.cross(f_tip) - c.cross(f_tip);
        force[i] += f_tip;
      }
    }

    // Backward pass: forces and moments transmitted through the joints.
    JointVector<T, 7> tau;
    Vec3 f_next = Vec3::Zero(), n_next = Vec3::Zero();
    for (int i = 6; i >= 0; --i) {
      Vec3 f = force[i], n = moment[i] + com[i].cross(force[i]);
      if (i < 6) {
        const Vec3 rf = rows[i + 1].R * f_next;
        f += rf;
        n += rows[i + 1].R * n_next + rows[i + 1].p.cross(rf);
      }
      tau[i] = n[2];
      f_next = f;
      n_next = n;
    }
    return tau;
  }

  /// tau = M(q) qdd + C(q, qd) qd + g(q) of the published links plus the known tool.
  template <typename T, typename Q, typename Qd, typename Qdd, typename P>
  static JointVector<T, kDof> InverseDynamics(const Q& q, const Qd& qd, const Qdd& qdd, const P& p) {
    const Eigen::Matrix<T, 3, 1> tool_com(p[1], p[2], p[3]);
    return Rnea<T>(q, qd, qdd, p[4], 1.0, p[0], tool_com);
  }

  /// Torque (7) that 1 kg at the flange origin needs.
  template <typename T, typename Q, typename Qd, typename Qdd, typename P>
  static JointVector<T, kDof> TipLoad(const Q& q, const Qd& qd, const Qdd& qdd, const P& p) {
    return Rnea<T>(q, qd, qdd, p[4], 0.0, T(1.0), Eigen::Matrix<T, 3, 1>::Zero());
  }
};

/// Gaz et al. 2019 sigmoid friction (Table I), tau_f (7) at joint velocities qd (7).
inline Eigen::VectorXd PandaSigmoidFriction(const Eigen::VectorXd& qd) {
  static constexpr std::array<double, 7> kPhi1 = {5.4615e-01, 8.7224e-01, 6.4068e-01, 1.2794e+00,
                                                  8.3904e-01, 3.0301e-01, 5.6489e-01};
  static constexpr std::array<double, 7> kPhi2 = {5.1181e+00, 9.0657e+00, 1.0136e+01, 5.5903e+00,
                                                  8.3469e+00, 1.7133e+01, 1.0336e+01};
  static constexpr std::array<double, 7> kPhi3 = {3.9533e-02, 2.5882e-02, -4.6070e-02, 3.6194e-02,
                                                  2.6226e-02, -2.1047e-02, 3.5526e-03};
  DIFFDYN_CHECK(qd.size() == 7, "PandaSigmoidFriction: expected 7 velocities, got ", qd.size());
  Eigen::VectorXd tau(7);
  for (int j = 0; j < 7; ++j) {
    tau[j] = kPhi1[j] / (1.0 + std::exp(-kPhi2[j] * (qd[j] + kPhi3[j]))) -
             kPhi1[j] / (1.0 + std::exp(-kPhi2[j] * kPhi3[j]));
  }
  return tau;
}

}  // namespace diffdyn
