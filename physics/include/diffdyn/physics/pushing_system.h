// The block-pushing system as a SystemDescription: what a learned pushing model's
// state and action are.
//
// State (x, y, theta): the block's planar pose in the table frame (m, m, rad);
// theta is an angle. Action (push_location, push_angle, push_length) in the seed's
// action space [-1, 1] x [-pi/2, pi/2] x [0, 1] (pushing_collect.h). Learned models
// see theta as a raw number (angle_features = raw), as the NeuralODE-Panda paper's
// models do.
//
//   LearnedModelConfig config{.type = LearnedKind::kAbsNode, .system = PushingSystem()};
#pragma once

#include <numbers>

#include <Eigen/Core>

#include "diffdyn/models/system_description.h"

namespace diffdyn {

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
  return s;
}

}  // namespace diffdyn
