// PushingEnv: a Panda arm pushing a block on a table, on the Open Dynamics Engine.
//
// The world mirrors the NeuralODE-Panda seed's PyBullet environment: a table
// (top at z = -0.025), a 0.1 x 0.1 x 0.05 m block resting on it (centre z = 0),
// optionally the obstacle box 0.1 x 0.5 x 0.1 m centred at (0.6, 0.2, 0), a goal
// marker (no collision), and a 7-DoF Panda (panda.h) standing at the world
// origin with a pusher tip on its flange: a capsule of radius r around the last
// `tip_length` of the tool axis, whose lowest point-centre is the tool point.
//
// State x = (x, y, theta) of the block; theta = atan2 of its x axis, in (-pi, pi].
// Action u = (push_location in [-1, 1], push_angle in [-pi/2, pi/2],
// push_length in [0, 1]), executed as in the seed:
//   1. raise, 2. move above the start point s = p + R(theta) (-0.1, 0.0475 u0),
//   3. lower to z = 0.02               -- transit: kinematic (arm teleported),
//   4. approach along the block's x axis by 0.035 m,
//   5. push along theta + u1 by 0.1 u2 m in 5 mm waypoints
//                                      -- simulated with the arm's dynamics;
// then the block settles (arm lifted clear) and the next pose is returned.
// Waypoints come from damped-least-squares IK (panda_ik.h); joint references are
// interpolated between them under a rest-to-rest trapezoidal speed profile and
// tracked by ODE hinge motors (velocity servo, torque limited to tau_max).
// The arm is stepped with dWorldStep; each world owns its ODE threading object
// and passes its context to the collision callback through the void* argument,
// so worlds run in parallel threads and give the same numbers in any thread.
//
//   diffdyn::PushingEnv env;                       // default PushingConfig
//   env.Reset({0.4, 0.0, 0.2 * M_PI});
//   auto result = env.Step({0.3, -0.5, 0.8});      // throws on a bad action
//   result.pose;                                   // next block pose
//   env.tip_path();                                // executed tip path (x, y, z)
#pragma once

#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/physics/panda.h"

namespace diffdyn {

/// Parameters of the pushing world. Defaults resemble the seed's PyBullet world.
struct PushingConfig {
  // Block.
  double block_mass = 10.0;              ///< kg (seed: 10)
  /// kg m^2 on each diagonal entry; 0 = a solid box's m (a^2 + b^2) / 12 (see the README).
  double block_inertia = 0.0;
  double block_size = 0.1;               ///< side length (m)
  double block_height = 0.05;            ///< m
  double block_table_friction = 0.1;     ///< Coulomb mu block-table (seed: 0.1 x 1.0)
  double tip_block_friction = 0.1;       ///< Coulomb mu tip-block
  // Obstacle and goal.
  bool obstacle = true;                  ///< the 0.1 x 0.5 x 0.1 box at (0.6, 0.2)
  Eigen::Vector3d goal{0.8, -0.1, 0.0};  ///< drawn only
  // Pusher tip and tool.
  double tool_length = 0.1034;           ///< flange to tool point along the flange z axis (m)
  double tip_radius = 0.016;             ///< radius of the tip capsule (m), see the README
  double tip_length = 0.04;              ///< length of the capsule's axis segment (m)
  /// Half widths (m) of a box pad in place of the capsule: 0, 0 is the capsule; both
  /// positive make the tip a box of (2 tip_pad_x, 2 tip_pad_y) in the horizontal plane
  /// spanning the capsule's height, its sides held parallel to the world's x and y axes
  /// (as the seed's IK holds the end effector's orientation fixed while pushing).
  double tip_pad_x = 0.0;
  double tip_pad_y = 0.0;
  double push_height = 0.02;             ///< z of the tool point while pushing (m)
  // Motion and integration.
  double time_step = 0.002;              ///< dWorldStep step (s)
  double push_speed = 0.2;               ///< peak tip speed while pushing (m/s)
  double push_acceleration = 1.0;        ///< tip acceleration while pushing (m/s^2)
  double approach_speed = 0.3;           ///< peak tip speed of the approach (m/s)
  double approach_acceleration = 3.0;    ///< m/s^2
  double settle_time = 1.0;              ///< longest block-only settling after a push (s)
  double ik_tolerance = 1e-3;            ///< a waypoint the IK misses by more is unreachable (m)
};

/// How a step ended.
enum class PushStatus { kOk, kOffTable, kUnreachable };

/// "ok", "off_table", "unreachable": the CSV `status` names.
const char* PushStatusName(PushStatus status);

/// Result of PushingEnv::Step.
struct PushResult {
  Eigen::Vector3d pose;                ///< block pose after the push and settling
  PushStatus status = PushStatus::kOk; ///< kOffTable: block left the table top
  double max_tracking_error = 0;       ///< max |tip - reference tip| over approach and push (m)
  double max_limit_violation = 0;      ///< max joint-limit excess during the step (rad), 0 if none
  double max_block_speed = 0;          ///< max block speed (m/s), an explosion detector
  double min_block_z = 0;              ///< lowest block centre z (m), a tunnelling detector
  double max_block_z = 0;              ///< highest block centre z (m)
  int steps = 0;                       ///< dWorldStep calls (arm and settling)
  bool tip_hit_obstacle = false;       ///< the tip touched the obstacle
  bool block_hit_obstacle = false;     ///< the block touched the obstacle while pushed
};

/// The tool point's path of one push in the table plane (steps 2-5 of the file
/// comment), for a block at pose p = (x, y, theta) and action u:
///   approach_start a = p - 0.1 e_x + 0.0475 u0 e_y,   e_x = (cos theta, sin theta),
///   push_start     b = a + 0.035 e_x,                 e_y = (-sin theta, cos theta),
///   push_end       c = b + 0.1 u2 (cos(theta + u1), sin(theta + u1)).
struct PushPath {
  Eigen::Vector2d approach_start, push_start, push_end;
};

/// The annulus around the arm's base (the world origin) where the IK reaches the
/// tool point at push height with the tool pointing down: inner <= |(x, y)| <= outer (m).
struct PushReach {
  double inner = 0, outer = 0;

  /// True when `path` stays in the annulus: no corner beyond `outer` and no segment
  /// (approach or push) closer than `inner` to the base.
  bool Contains(const PushPath& path) const {
    const double outer2 = outer * outer;
    for (const Eigen::Vector2d* q : {&path.approach_start, &path.push_start, &path.push_end}) {
      if (q->squaredNorm() > outer2) return false;
    }
    // Squared distance from the base (origin) to the segment (a, b).
    auto distance2 = [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
      const Eigen::Vector2d e = b - a;
      const double l2 = e.squaredNorm();
      const double f = l2 > 0 ? std::clamp(-a.dot(e) / l2, 0.0, 1.0) : 0.0;
      return (a + f * e).squaredNorm();
    };
    const double inner2 = inner * inner;
    return distance2(path.approach_start, path.push_start) >= inner2 &&
           distance2(path.push_start, path.push_end) >= inner2;
  }
};

/// The ODE-engine pushing world; one per thread (see the file comment).
class PushingEnv {
 public:
  explicit PushingEnv(const PushingConfig& config = {});
  ~PushingEnv();
  PushingEnv(const PushingEnv&) = delete;
  PushingEnv& operator=(const PushingEnv&) = delete;

  const PushingConfig& config() const;

  /// Puts the block at rest at `pose` (x, y, theta) and the arm at rest in its
  /// home posture; clears the tip path. Throws diffdyn::Error for a non-finite
  /// pose, a pose off the table or (with the obstacle) overlapping it.
  void Reset(const Eigen::Vector3d& pose);

  /// Executes one action (see the file comment) and returns the next pose.
  /// Throws diffdyn::Error for an action that is non-finite or out of range.
  PushResult Step(const Eigen::Vector3d& action);

  /// The block pose (x, y, theta), theta in (-pi, pi].
  Eigen::Vector3d pose() const;

  /// The tool-point path executed by the last Step (approach and push), one
  /// (x, y, z) per 10 ms of simulated time plus the end points.
  const std::vector<Eigen::Vector3d>& tip_path() const;

  /// The arm's joint angles now (7).
  Panda::Vector7<double> joint_positions() const;

  /// Joint angles recorded with tip_path() (7 per entry).
  const std::vector<Panda::Vector7<double>>& joint_path() const;

  /// Throws diffdyn::Error naming the entry if `action` is non-finite or outside
  /// [-1, 1] x [-pi/2, pi/2] x [0, 1].
  static void ValidateAction(const Eigen::Vector3d& action);

  /// True when (x, y) lies on the table top (the block's centre is supported).
  static bool OnTable(double x, double y);

  /// The planar tool path of `action` from block pose `pose` (PushPath); no checks.
  static PushPath PlanarPath(const Eigen::Vector3d& pose, const Eigen::Vector3d& action);

  /// The reach annulus of `config`'s arm and tool: for azimuths -0.75..0.75 rad (the
  /// table in front of the arm), bisection to 0.1 mm on the radius where a single IK
  /// solve from the home posture meets config.ik_tolerance; the largest inner and the
  /// smallest outer radius. A push whose path leaves the annulus is (nearly always)
  /// one Step reports as unreachable; Step itself plans with the IK, not with this.
  static PushReach Reach(const PushingConfig& config = {});

  /// Penetration depth (m) of the block at `pose` into the obstacle, 0 if apart.
  static double ObstaclePenetration(const Eigen::Vector3d& pose, double block_size = 0.1);

 private:
  struct World;
  std::unique_ptr<World> world_;
};

}  // namespace diffdyn
