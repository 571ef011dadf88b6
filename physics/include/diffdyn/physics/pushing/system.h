// The block-pushing system as a SystemDescription: what a learned pushing model's
// state and action are.
//
// State (x, y, theta): the block's planar pose in the table frame (m, m, rad);
// theta is an angle. Action (push_location, push_angle, push_length) in the seed's
// action space [-1, 1] x [-pi/2, pi/2] x [0, 1] (pushing_collect.h). Learned models
// see theta as a raw number (angle_features = raw), as the NeuralODE-Panda paper's
// models do. Its state metric (state_loss.h) is the paper's pose loss
// MSE(x) + MSE(y) + r_g MSE(theta), r_g the block's radius of gyration, theta not wrapped.
//
//   LearnedModelConfig config{.type = LearnedKind::kAbsNode, .system = PushingSystem()};
#pragma once

#include <cmath>
#include <numbers>

#include <Eigen/Core>

#include "diffdyn/models/system_description.h"

namespace diffdyn {

/// r_g = sqrt((l^2 + w^2) / 12) of a block of length l and width w (metres).
inline double RadiusOfGyration(double length, double width) {
  return std::sqrt((length * length + width * width) / 12.0);
}

/// r_g of the paper's 0.1 m x 0.1 m block (0.040825 m).
inline const double kBlockRadiusOfGyration = RadiusOfGyration(0.1, 0.1);

/// The pushing system (see the file comment).
inline SystemDescription PushingSystem() {
  SystemDescription s;
  s.name = "pushing";
  s.state_names = {"x", "y", "theta"};
  s.action_names = {"push_location", "push_angle", "push_length"};
  s.angles = {2};
  s.angle_features = AngleFeatures::kRaw;
  s.action_low.resize(3);
  s.action_low << -1.0, -std::numbers::pi / 2, 0.0;
  s.action_high.resize(3);
  s.action_high << 1.0, std::numbers::pi / 2, 1.0;
  s.loss_weights.resize(3);
  s.loss_weights << 1.0, 1.0, kBlockRadiusOfGyration;
  s.loss_wraps_angles = false;
  return s;
}

}  // namespace diffdyn
