// Costs of the block-pushing task for MPPI.
//
// The running cost of a predicted block pose x = (x, y, theta) is
//
//   c(x) = (x - g)^T Q (x - g) + w_c in_collision(x),   Q = diag(1, 1, 0.1),
//
// with g the goal pose and w_c = 100 when the obstacle is present. in_collision
// is an exact separating-axis test between the block (a square of side 0.1 m
// rotated by theta) and the axis-aligned obstacle rectangle (half sizes 0.05 x
// 0.25 m at (0.6, 0.2)): two convex polygons are apart exactly when their
// projections on one of the edge normals of either are disjoint. Touching counts
// as apart, as in the seed.
//
// Two optional safety terms (both off by default, which is the seed's cost):
//
//   margin m     in_collision tests the block inflated by m on each side, a square
//                of side 0.1 + 2 m, so a pose that merely touches the obstacle, or
//                passes within m of it, is penalized too;
//   substeps S   the transition form c(x_t -> x_{t+1}) applies w_c once if the
//                (inflated) block overlaps the obstacle at any of the S + 1 poses
//                x_t + s/(S+1) (x_{t+1} - x_t), s = 1..S+1 (linear in x, y and
//                theta, with the angle difference wrapped to [-pi, pi]), so a
//                step that jumps across the obstacle is caught.
//
//   clearance    (distance c, weight w_l) adds w_l (1 - d / c)^2 while d < c, with d
//                the distance between the true block and the obstacle (0 when they
//                overlap), at the closest of the step's swept poses: a smooth push
//                away from the obstacle that still ranks samples once all of them are
//                within the margin (where the flat w_c term no longer does).
//
//   reach        (annulus inner..outer, weight w_r, steps H_r) adds w_r for each of
//                the first H_r steps t < H_r whose push the arm cannot execute: the
//                tool path of action u_t from pose x_t (PushingEnv::PlanarPath:
//                approach start a, push start b, push end c) leaves the annulus
//                inner <= |p| <= outer around the arm's base (PushingEnv::Reach).
//                H_r = 1 checks only the push executed now, from the measured pose;
//                later steps start from predicted poses. The pose form cannot see it.
//
// With m = 0, S = 0 and no clearance or reach term both forms equal the seed's cost
// exactly.
//
//   diffdyn::PushingCost cost({0.8, -0.1, 0.0}, /*obstacle=*/true);
//   cost.set_collision_margin(0.01);    // optional
//   cost.set_collision_substeps(4);     // optional
//   cost.set_clearance(0.05, 1.0);      // optional
//   cost.set_reach(diffdyn::PushingEnv::Reach(), 100.0, 1);  // optional
//   diffdyn::Mppi mppi(model, cost, options, seed);
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/physics/pushing/env.h"
#include "diffdyn/solvers/mppi.h"

namespace diffdyn {

/// An oriented rectangle: centre (x, y), half sizes (a, b) along its own axes, angle.
struct Rectangle {
  Eigen::Vector2d center;
  Eigen::Vector2d half_size;
  double angle = 0;
};

/// True when the rectangles overlap with positive area (separating-axis test on
/// the four edge normals; touching edges count as apart).
inline bool RectanglesOverlap(const Rectangle& r1, const Rectangle& r2) {
  // Each rectangle's unit axes (one sincos per rectangle).
  const Rectangle* rects[2] = {&r1, &r2};
  Eigen::Vector2d axes[2][2];
  for (int i = 0; i < 2; ++i) {
    const double c = std::cos(rects[i]->angle), s = std::sin(rects[i]->angle);
    axes[i][0] = Eigen::Vector2d(c, s);
    axes[i][1] = Eigen::Vector2d(-s, c);
  }
  const Eigen::Vector2d d = r2.center - r1.center;
  for (int i = 0; i < 2; ++i) {
    for (const Eigen::Vector2d& axis : axes[i]) {
      // Projected radius of each rectangle on `axis`, and the distance of centres.
      double radius = 0;
      for (int j = 0; j < 2; ++j) {
        radius += rects[j]->half_size.x() * std::abs(axis.dot(axes[j][0])) +
                  rects[j]->half_size.y() * std::abs(axis.dot(axes[j][1]));
      }
      if (std::abs(axis.dot(d)) >= radius) return false;
    }
  }
  return true;
}

/// Distance (m) between two oriented rectangles, 0 when they overlap: the smallest
/// distance from a corner of one to an edge of the other.
inline double RectangleDistance(const Rectangle& r1, const Rectangle& r2) {
  if (RectanglesOverlap(r1, r2)) return 0.0;
  auto corners = [](const Rectangle& r) {
    const double c = std::cos(r.angle), s = std::sin(r.angle);
    const Eigen::Vector2d a(c * r.half_size.x(), s * r.half_size.x());
    const Eigen::Vector2d b(-s * r.half_size.y(), c * r.half_size.y());
    return std::array<Eigen::Vector2d, 4>{r.center + a + b, r.center - a + b, r.center - a - b,
                                          r.center + a - b};
  };
  const std::array<Eigen::Vector2d, 4> p1 = corners(r1), p2 = corners(r2);
  double best = std::numeric_limits<double>::infinity();
  // Corners of `p` against the edges (q_i, q_{i+1}) of `q`.
  auto scan = [&best](const std::array<Eigen::Vector2d, 4>& p,
                      const std::array<Eigen::Vector2d, 4>& q) {
    for (int i = 0; i < 4; ++i) {
      const Eigen::Vector2d a = q[i], e = q[(i + 1) % 4] - q[i];
      for (const auto& v : p) {
        const double f = std::clamp((v - a).dot(e) / e.squaredNorm(), 0.0, 1.0);
        best = std::min(best, (v - a - f * e).norm());
      }
    }
  };
  scan(p1, p2);
  scan(p2, p1);
  return best;
}

/// The pushing cost of the file comment on batches of block poses.
class PushingCost : public MppiCost {
 public:
  /// Goal pose g; `obstacle` adds the collision term with weight `collision_weight`.
  /// Margin 0 and no substeps: the seed's cost.
  PushingCost(const Eigen::Vector3d& goal, bool obstacle, double collision_weight = 100.0,
              double block_size = 0.1)
      : goal_(goal), obstacle_(obstacle), collision_weight_(collision_weight),
        block_half_(block_size / 2) {}

  /// The obstacle rectangle of the task.
  static Rectangle Obstacle() { return {{0.6, 0.2}, {0.05, 0.25}, 0.0}; }

  /// Safety margin m (m, >= 0): the collision test inflates the block by m per side.
  void set_collision_margin(double margin) {
    DIFFDYN_CHECK(margin >= 0 && std::isfinite(margin),
                  "collision margin must be finite and >= 0, got ", margin);
    margin_ = margin;
  }
  double collision_margin() const { return margin_; }

  /// Substeps S (>= 0) of the swept test in AccumulateStep; 0: end pose only.
  void set_collision_substeps(int substeps) {
    DIFFDYN_CHECK(substeps >= 0, "collision substeps must be >= 0, got ", substeps);
    substeps_ = substeps;
  }
  int collision_substeps() const { return substeps_; }

  /// Clearance term of the file comment: w_l (1 - d / c)^2 while the block is
  /// closer than c (m, >= 0) to the obstacle; c = 0 or w_l = 0 turns it off.
  void set_clearance(double distance, double weight) {
    DIFFDYN_CHECK(distance >= 0 && std::isfinite(distance),
                  "clearance distance must be finite and >= 0, got ", distance);
    DIFFDYN_CHECK(weight >= 0 && std::isfinite(weight),
                  "clearance weight must be finite and >= 0, got ", weight);
    clearance_ = distance;
    clearance_weight_ = weight;
  }
  double clearance() const { return clearance_; }
  double clearance_weight() const { return clearance_weight_; }

  /// Reach term of the file comment: w_r (>= 0; 0 turns it off) for each of the
  /// first `steps` (H_r >= 1) steps whose push path leaves the annulus `reach`
  /// (0 <= inner < outer).
  void set_reach(const PushReach& reach, double weight, int steps) {
    DIFFDYN_CHECK(steps >= 1, "reach steps must be >= 1, got ", steps);
    DIFFDYN_CHECK(std::isfinite(reach.inner) && std::isfinite(reach.outer) && reach.inner >= 0 &&
                      reach.inner < reach.outer,
                  "reach annulus must satisfy 0 <= inner < outer, got ", reach.inner, " and ",
                  reach.outer);
    DIFFDYN_CHECK(weight >= 0 && std::isfinite(weight), "reach weight must be finite and >= 0, got ",
                  weight);
    reach_ = reach;
    reach_weight_ = weight;
    reach_steps_ = steps;
  }
  const PushReach& reach() const { return reach_; }
  double reach_weight() const { return reach_weight_; }
  int reach_steps() const { return reach_steps_; }

  /// True when the push `action` from `pose` leaves the reach annulus (PushReach::Contains).
  bool Unreachable(const Eigen::Ref<const Eigen::Vector3d>& pose,
                   const Eigen::Ref<const Eigen::Vector3d>& action) const {
    return !reach_.Contains(PushingEnv::PlanarPath(pose, action));
  }

  /// The clearance term at one pose (0 when off or farther than c).
  double ClearanceTerm(double x, double y, double theta) const {
    if (clearance_ <= 0 || clearance_weight_ <= 0) return 0.0;
    const Rectangle o = Obstacle();
    // Cheap reject: the block's circumscribed circle is farther than c.
    const double ox = std::max(std::abs(x - o.center.x()) - o.half_size.x(), 0.0);
    const double oy = std::max(std::abs(y - o.center.y()) - o.half_size.y(), 0.0);
    const double reach = std::sqrt(2.0) * block_half_ + clearance_;
    if (ox * ox + oy * oy >= reach * reach) return 0.0;
    const double d = RectangleDistance({{x, y}, {block_half_, block_half_}, theta}, o);
    if (d >= clearance_) return 0.0;
    const double r = 1.0 - d / clearance_;
    return clearance_weight_ * r * r;
  }

  /// in_collision(pose) of the file comment (block inflated by the margin).
  bool InCollision(const Eigen::Ref<const Eigen::Vector3d>& pose) const {
    const double h = block_half_ + margin_;
    return RectanglesOverlap({pose.head<2>(), {h, h}, pose.z()}, Obstacle());
  }

  /// costs(b) += (x_b - g)^T Q (x_b - g) + w_c in_collision(x_b) (+ the clearance
  /// term at x_b); states: 3 x B.
  void Accumulate(const Eigen::Ref<const Eigen::MatrixXd>& states,
                  Eigen::Ref<Eigen::VectorXd> costs) const override {
    for (Eigen::Index b = 0; b < states.cols(); ++b) {
      costs[b] += GoalTerm(states(0, b), states(1, b), states(2, b));
      if (obstacle_ && Collides(states(0, b), states(1, b), states(2, b))) {
        costs[b] += collision_weight_;
      }
      if (obstacle_) costs[b] += ClearanceTerm(states(0, b), states(1, b), states(2, b));
    }
  }

  /// costs(b) += (x'_b - g)^T Q (x'_b - g) + w_c swept_collision(x_b -> x'_b) (+ the
  /// largest clearance term over the swept poses) (+ w_r when t < H_r and the push
  /// u_b from x_b is unreachable), with x = prev_states(:, b), u = actions(:, b),
  /// x' = states(:, b) (3 x B each) and the swept test of the file comment; equals
  /// Accumulate(states, costs) when substeps = 0 and the reach term is off.
  void AccumulateStep(int t, const Eigen::Ref<const Eigen::MatrixXd>& prev_states,
                      const Eigen::Ref<const Eigen::MatrixXd>& actions,
                      const Eigen::Ref<const Eigen::MatrixXd>& states,
                      Eigen::Ref<Eigen::VectorXd> costs) const override {
    if (substeps_ == 0 || !obstacle_) {
      Accumulate(states, costs);
    } else {
      AccumulateSwept(prev_states, states, costs);
    }
    if (reach_weight_ > 0 && t < reach_steps_) {
      for (Eigen::Index b = 0; b < states.cols(); ++b) {
        if (Unreachable(prev_states.col(b), actions.col(b))) costs[b] += reach_weight_;
      }
    }
  }

 private:
  // The goal, swept-collision and clearance terms of AccumulateStep (obstacle on).
  void AccumulateSwept(const Eigen::Ref<const Eigen::MatrixXd>& prev_states,
                       const Eigen::Ref<const Eigen::MatrixXd>& states,
                       Eigen::Ref<Eigen::VectorXd> costs) const {
    const bool clearance = clearance_ > 0 && clearance_weight_ > 0;
    const int poses = substeps_ + 1;
    for (Eigen::Index b = 0; b < states.cols(); ++b) {
      const double x1 = states(0, b), y1 = states(1, b), t1 = states(2, b);
      costs[b] += GoalTerm(x1, y1, t1);
      const double x0 = prev_states(0, b), y0 = prev_states(1, b), t0 = prev_states(2, b);
      const double dx = x1 - x0, dy = y1 - y0;
      const double dt = std::remainder(t1 - t0, 2 * std::numbers::pi);
      bool hit = false;
      double closest = 0;  // the largest clearance term over the swept poses
      for (int s = 1; s <= poses; ++s) {
        const double f = double(s) / poses;
        const double x = x0 + f * dx, y = y0 + f * dy, t = t0 + f * dt;
        if (!hit && Collides(x, y, t)) {
          costs[b] += collision_weight_;
          hit = true;
          if (!clearance) break;
        }
        if (clearance) closest = std::max(closest, ClearanceTerm(x, y, t));
      }
      costs[b] += closest;
    }
  }

  double GoalTerm(double x, double y, double theta) const {
    const double dx = x - goal_.x(), dy = y - goal_.y(), dt = theta - goal_.z();
    return dx * dx + dy * dy + 0.1 * dt * dt;
  }

  // The inflated block at (x, y, theta) overlaps the obstacle. The exact test, with
  // its trigonometry, is skipped when the block's circumscribed circle misses the
  // obstacle (then they are apart).
  bool Collides(double x, double y, double theta) const {
    const Rectangle o = Obstacle();
    const double h = block_half_ + margin_;
    const double ox = std::max(std::abs(x - o.center.x()) - o.half_size.x(), 0.0);
    const double oy = std::max(std::abs(y - o.center.y()) - o.half_size.y(), 0.0);
    if (ox * ox + oy * oy >= 2 * h * h) return false;
    return RectanglesOverlap({{x, y}, {h, h}, theta}, o);
  }

  Eigen::Vector3d goal_;
  bool obstacle_;
  double collision_weight_;
  double block_half_;
  double margin_ = 0;
  int substeps_ = 0;
  double clearance_ = 0;
  double clearance_weight_ = 0;
  PushReach reach_{0.0, std::numeric_limits<double>::infinity()};
  double reach_weight_ = 0;
  int reach_steps_ = 1;
};

}  // namespace diffdyn
