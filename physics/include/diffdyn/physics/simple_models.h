// Small analytic robots: pendulum, cart-pole, double pendulum, DeLaN 2-link arm.
//
// Each is a struct of templated static functions (see analytic_model.h) with
// the conventions of shared/reference/model_conventions.md. All follow the
// manipulator equation tau = M(q) qdd + c(q, qd) + g(q):
//
//   pendulum (q = 0 hanging down, point mass m at distance l):
//     tau = m l^2 qdd + m g l sin q
//   cart-pole (x cart position, theta = 0 upright, point-mass pole at l):
//     [tau1]   [m_c + m_p      m_p l cos th] [xdd ]   [-m_p l sin th thd^2]
//     [tau2] = [m_p l cos th   m_p l^2     ] [thdd] + [-m_p g l sin th     ]
//   double pendulum (point masses m1, m2 on massless links l1, l2; q1 from
//   hanging down, q2 relative to link 1; phi1 = q1, phi2 = q1 + q2):
//     M11 = (m1 + m2) l1^2 + m2 l2^2 + 2 m2 l1 l2 cos q2,
//     M12 = m2 l2^2 + m2 l1 l2 cos q2,  M22 = m2 l2^2,
//     c1 = -m2 l1 l2 sin q2 (2 qd1 qd2 + qd2^2),  c2 = m2 l1 l2 sin q2 qd1^2,
//     g1 = (m1 + m2) g l1 sin q1 + m2 g l2 sin(q1 + q2),  g2 = m2 g l2 sin(q1 + q2)
//   arm2, the DeLaN character arm (angles from the horizontal), in its base
//   parameters h1, h2, h12 (kg m^2) and g1, g2 (N m):
//     H11 = h1 + 2 h12 cos q2, H12 = h2 + h12 cos q2, H22 = h2,
//     c1 = -h12 sin q2 (2 qd1 qd2 + qd2^2), c2 = h12 sin q2 qd1^2,
//     g(q) = (g1 cos q1 + g2 cos(q1 + q2), g2 cos(q1 + q2)).
//     Its payload tip is at l1 (cos q1, sin q1) + l2 (cos(q1+q2), sin(q1+q2)).
//
// Payload: a point mass m at the tip needs the torque J_tip^T m (a_tip - g_vec);
// for the three point-mass models this equals ID with the tip mass set to 1
// and every other mass set to 0, because ID is linear in the masses.
#pragma once

#include <cmath>
#include <vector>

#include "diffdyn/physics/analytic_model.h"

namespace diffdyn {

/// Single pendulum: q, qd, qdd, tau of size 1; p = (m, l, g).
struct PendulumModel {
  static constexpr const char* kName = "pendulum";
  static constexpr int kDof = 1;
  static std::vector<ParamSpec> Specs() {
    return {{"m", 1.0, "kg", "point mass"},
            {"l", 0.5, "m", "distance of the mass from the pivot"},
            {"g", 9.81, "m/s^2", "gravity"}};
  }
  static bool Prismatic(int) { return false; }

  /// tau = m l^2 qdd + m g l sin q.
  template <typename T, typename Q, typename Qd, typename Qdd, typename P>
  static JointVector<T, kDof> InverseDynamics(const Q& q, const Qd& /*qd*/, const Qdd& qdd, const P& p) {
    using std::sin;
    const T& m = p[0];
    const T& l = p[1];
    const T& g = p[2];
    JointVector<T, kDof> tau;
    tau[0] = m * l * l * qdd[0] + m * g * l * sin(q[0]);
    return tau;
  }

  /// Tip load of 1 kg at the bob: l^2 qdd + g l sin q.
  template <typename T, typename Q, typename Qd, typename Qdd, typename P>
  static JointVector<T, kDof> TipLoad(const Q& q, const Qd& qd, const Qdd& qdd, const P& p) {
    VectorX<T> unit = p;
    unit[0] = T(1.0);
    return InverseDynamics<T>(q, qd, qdd, unit);
  }
};

/// Fully actuated cart-pole: q = (x, theta); p = (m_cart, m_pole, l, g).
struct CartPoleModel {
  static constexpr const char* kName = "cartpole";
  static constexpr int kDof = 2;
  static std::vector<ParamSpec> Specs() {
    return {{"m_cart", 0.57, "kg", "cart mass"},
            {"m_pole", 0.127, "kg", "pole point mass at l"},
            {"l", 0.1683, "m", "pole length to its point mass"},
            {"g", 9.81, "m/s^2", "gravity"}};
  }
  static bool Prismatic(int joint) { return joint == 0; }

  /// tau = H(q) qdd + (-m_p l sin th thd^2, -m_p g l sin th).
  template <typename T, typename Q, typename Qd, typename Qdd, typename P>
  static JointVector<T, kDof> InverseDynamics(const Q& q, const Qd& qd, const Qdd& qdd, const P& p) {
    using std::cos;
    using std::sin;
    const T& mc = p[0];
    const T& mp = p[1];
    const T& l = p[2];
    const T& g = p[3];
    const T c = cos(q[1]), s = sin(q[1]);
    JointVector<T, kDof> tau;
    tau[0] = (mc + mp) * qdd[0] + mp * l * c * qdd[1] - mp * l * s * qd[1] * qd[1];
    tau[1] = mp * l * c * qdd[0] + mp * l * l * qdd[1] - mp * g * l * s;
    return tau;
  }

  /// Tip load of 1 kg at the pole's end: ID with m_cart = 0, m_pole = 1.
  template <typename T, typename Q, typename Qd, typename Qdd, typename P>
  static JointVector<T, kDof> TipLoad(const Q& q, const Qd& qd, const Qdd& qdd, const P& p) {
    VectorX<T> unit = p;
    unit[0] = T(0.0);
    unit[1] = T(1.0);
    return InverseDynamics<T>(q, qd, qdd, unit);
  }
};

/// Double pendulum of point masses: q = (q1, q2) relative angles; p = (m1, m2, l1, l2, g).
struct DoublePendulumModel {
  static constexpr const char* kName = "double-pendulum";
  static constexpr int kDof = 2;
  static std::vector<ParamSpec> Specs() {
    return {{"m1", 1.0, "kg", "point mass at the end of link 1"},
            {"m2", 1.0, "kg", "point mass at the end of link 2"},
            {"l1", 1.0, "m", "length of link 1"},
            {"l2", 1.0, "m", "length of link 2"},
            {"g", 9.81, "m/s^2", "gravity"}};
  }
  static bool Prismatic(int) { return false; }

  /// tau = M(q) qdd + c(q, qd) + g(q), terms in the header comment.
  template <typename T, typename Q, typename Qd, typename Qdd, typename P>
  static JointVector<T, kDof> InverseDynamics(const Q& q, const Qd& qd, const Qdd& qdd, const P& p) {
    using std::cos;
    using std::sin;
    const T& m1 = p[0];
    const T& m2 = p[1];
    const T& l1 = p[2];
    const T& l2 = p[3];
    const T& g = p[4];
    const T c2 = cos(q[1]), s2 = sin(q[1]);
    const T s1 = sin(q[0]), s12 = sin(q[0] + q[1]);
    const T k = m2 * l1 * l2;
    const T m11 = (m1 + m2) * l1 * l1 + m2 * l2 * l2 + T(2.0) * k * c2;
    const T m12 = m2 * l2 * l2 + k * c2;
    const T m22 = m2 * l2 * l2;
    JointVector<T, kDof> tau;
    tau[0] = m11 * qdd[0] + m12 * qdd[1] - k * s2 * (T(2.0) * qd[0] * qd[1] + qd[1] * qd[1]) +
             (m1 + m2) * g * l1 * s1 + m2 * g * l2 * s12;
    tau[1] = m12 * qdd[0] + m22 * qdd[1] + k * s2 * qd[0] * qd[0] + m2 * g * l2 * s12;
    return tau;
  }

  /// Tip load of 1 kg at the end of link 2: ID with m1 = 0, m2 = 1.
  template <typename T, typename Q, typename Qd, typename Qdd, typename P>
  static JointVector<T, kDof> TipLoad(const Q& q, const Qd& qd, const Qdd& qdd, const P& p) {
    VectorX<T> unit = p;
    unit[0] = T(0.0);
    unit[1] = T(1.0);
    return InverseDynamics<T>(q, qd, qdd, unit);
  }
};

/// The DeLaN 2-link arm in base parameters; p = (h1, h2, h12, g1, g2, l1, l2, g).
/// Defaults reproduce shared/data/delan_characters exactly; l1, l2, g only place
/// the payload tip.
struct Arm2Model {
  static constexpr const char* kName = "arm2";
  static constexpr int kDof = 2;
  static std::vector<ParamSpec> Specs() {
    return {{"h1", 1.3727291667, "kg m^2", "constant part of H11"},
            {"h2", 0.5176145833, "kg m^2", "H22 (and constant part of H12)"},
            {"h12", 0.5, "kg m^2", "cos(q2) coupling, m2 l1 lc2"},
            {"g1", 2.625, "N m", "gravity moment coefficient of cos(q1)"},
            {"g2", 1.5, "N m", "gravity moment coefficient of cos(q1 + q2)"},
            {"l1", 1.0, "m", "link 1 length (payload tip only)"},
            {"l2", 1.0, "m", "link 2 length (payload tip only)"},
            {"g", 9.81, "m/s^2", "gravity (payload tip only)"}};
  }
  static bool Prismatic(int) { return false; }

  /// tau = H(q) qdd + c(q, qd) + g(q), terms in the header comment.
  template <typename T, typename Q, typename Qd, typename Qdd, typename P>
  static JointVector<T, kDof> InverseDynamics(const Q& q, const Qd& qd, const Qdd& qdd, const P& p) {
    using std::cos;
    using std::sin;
    const T c2 = cos(q[1]), s2 = sin(q[1]);
    const T c12 = cos(q[0] + q[1]);
    const T h11 = p[0] + T(2.0) * p[2] * c2;
    const T h12 = p[1] + p[2] * c2;
    JointVector<T, kDof> tau;
    tau[0] = h11 * qdd[0] + h12 * qdd[1] - p[2] * s2 * (T(2.0) * qd[0] * qd[1] + qd[1] * qd[1]) +
             p[3] * cos(q[0]) + p[4] * c12;
    tau[1] = h12 * qdd[0] + p[1] * qdd[1] + p[2] * s2 * qd[0] * qd[0] + p[4] * c12;
    return tau;
  }

  /// Tip load of 1 kg: J^T (a_tip + (0, g)) for the planar tip of the header comment.
  template <typename T, typename Q, typename Qd, typename Qdd, typename P>
  static JointVector<T, kDof> TipLoad(const Q& q, const Qd& qd, const Qdd& qdd, const P& p) {
    using std::cos;
    using std::sin;
    const T& l1 = p[5];
    const T& l2 = p[6];
    const T& g = p[7];
    const T phi2 = q[0] + q[1], w1 = qd[0], w2 = qd[0] + qd[1];
    const T a1 = qdd[0], a2 = qdd[0] + qdd[1];
    const T s1 = sin(q[0]), c1 = cos(q[0]), s12 = sin(phi2), c12 = cos(phi2);
    // Tip acceleration of the planar chain with absolute link angles.
    const T ax = -l1 * (s1 * a1 + c1 * w1 * w1) - l2 * (s12 * a2 + c12 * w2 * w2);
    const T ay = l1 * (c1 * a1 - s1 * w1 * w1) + l2 * (c12 * a2 - s12 * w2 * w2);
    const T fx = ax, fy = ay + g;
    JointVector<T, kDof> tau;
    tau[0] = (-l1 * s1 - l2 * s12) * fx + (l1 * c1 + l2 * c12) * fy;
    tau[1] = -l2 * s12 * fx + l2 * c12 * fy;
    return tau;
  }
};

}  // namespace diffdyn
