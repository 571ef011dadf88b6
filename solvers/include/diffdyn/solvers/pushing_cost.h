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
//   diffdyn::PushingCost cost({0.8, -0.1, 0.0}, /*obstacle=*/true);
//   diffdyn::Mppi mppi(model, cost, options, seed);
#pragma once

#include <algorithm>
#include <array>
#include <cmath>

#include <Eigen/Core>

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
  const Rectangle* rects[2] = {&r1, &r2};
  const Eigen::Vector2d d = r2.center - r1.center;
  for (const Rectangle* r : rects) {
    const double c = std::cos(r->angle), s = std::sin(r->angle);
    const std::array<Eigen::Vector2d, 2> axes = {Eigen::Vector2d(c, s), Eigen::Vector2d(-s, c)};
    for (const auto& axis : axes) {
      // Projected radius of each rectangle on `axis`, and the distance of centres.
      double radius = 0;
      for (const Rectangle* q : rects) {
        const double cq = std::cos(q->angle), sq = std::sin(q->angle);
        radius += q->half_size.x() * std::abs(axis.dot(Eigen::Vector2d(cq, sq))) +
                  q->half_size.y() * std::abs(axis.dot(Eigen::Vector2d(-sq, cq)));
      }
      if (std::abs(axis.dot(d)) >= radius) return false;
    }
  }
  return true;
}

/// The seed's pushing cost (see the file comment) on batches of block poses.
class PushingCost : public MppiCost {
 public:
  /// Goal pose g; `obstacle` adds the collision term with weight `collision_weight`.
  PushingCost(const Eigen::Vector3d& goal, bool obstacle, double collision_weight = 100.0,
              double block_size = 0.1)
      : goal_(goal), obstacle_(obstacle), collision_weight_(collision_weight),
        block_half_(block_size / 2) {}

  /// The obstacle rectangle of the task.
  static Rectangle Obstacle() { return {{0.6, 0.2}, {0.05, 0.25}, 0.0}; }

  /// in_collision(pose) of the file comment.
  bool InCollision(const Eigen::Ref<const Eigen::Vector3d>& pose) const {
    return RectanglesOverlap({pose.head<2>(), {block_half_, block_half_}, pose.z()}, Obstacle());
  }

  /// costs(b) += (x_b - g)^T Q (x_b - g) + w_c in_collision(x_b); states: 3 x B.
  void Accumulate(const Eigen::Ref<const Eigen::MatrixXd>& states,
                  Eigen::Ref<Eigen::VectorXd> costs) const override {
    for (Eigen::Index b = 0; b < states.cols(); ++b) {
      const double dx = states(0, b) - goal_.x(), dy = states(1, b) - goal_.y(),
                   dt = states(2, b) - goal_.z();
      costs[b] += dx * dx + dy * dy + 0.1 * dt * dt;
      if (obstacle_ && NearObstacle(states(0, b), states(1, b)) && InCollision(states.col(b))) {
        costs[b] += collision_weight_;
      }
    }
  }

 private:
  // False when the block's circumscribed circle misses the obstacle (then they are
  // apart and the exact test, with its trigonometry, is skipped).
  bool NearObstacle(double x, double y) const {
    const Rectangle o = Obstacle();
    const double ox = std::max(std::abs(x - o.center.x()) - o.half_size.x(), 0.0);
    const double oy = std::max(std::abs(y - o.center.y()) - o.half_size.y(), 0.0);
    return ox * ox + oy * oy < 2 * block_half_ * block_half_;
  }

  Eigen::Vector3d goal_;
  bool obstacle_;
  double collision_weight_;
  double block_half_;
};

}  // namespace diffdyn
