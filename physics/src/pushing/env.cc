#include "diffdyn/physics/pushing/env.h"

#include <ode/ode.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>

#include <Eigen/Geometry>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/physics/pushing/ode_engine.h"
#include "diffdyn/physics/pushing/panda_ik.h"

namespace diffdyn {
namespace {

using Vec3 = Eigen::Vector3d;
using Vec7 = Panda::Vector7<double>;
constexpr double kPi = std::numbers::pi;

// The table: collision box 1.5 x 1 x 0.05 m centred at (0.5, 0), top at z = -0.025.
// True when the tip is a box pad rather than the capsule (PushingConfig::tip_pad_x).
bool HasPad(const PushingConfig& config) { return config.tip_pad_x > 0; }

constexpr double kTableCenterX = 0.5;
constexpr double kTableSizeX = 1.5;
constexpr double kTableSizeY = 1.0;
constexpr double kTableThickness = 0.05;
constexpr double kTableTop = -0.025;
// The obstacle box: 0.1 x 0.5 x 0.1 m centred at (0.6, 0.2, 0).
constexpr double kObstacleX = 0.6;
constexpr double kObstacleY = 0.2;
constexpr double kObstacleHalf[3] = {0.05, 0.25, 0.05};
// The seed's action geometry.
constexpr double kStartBehind = 0.1;       // start point behind the block centre
constexpr double kLateralScale = 0.0475;   // 0.1 * 0.5 * 0.95
constexpr double kApproach = 0.035;        // 0.1 - 0.015 - 0.05
constexpr double kPushScale = 0.1;         // push length per unit push_length
constexpr double kWaypoint = 0.005;        // 5 mm waypoints
constexpr int kMaxContacts = 8;
constexpr int kTipPathEvery = 5;           // record the tip every 5 steps
// ODE measures a hinge angle as body 1 relative to body 2, the opposite sense of
// q_i (child relative to parent); its motor drives the same sense except for the
// hinge to the static world (joint 1), whose bodies ODE swaps internally.
constexpr double kHingeSign = -1.0;
double MotorSign(int joint) { return joint == 0 ? -kHingeSign : kHingeSign; }

double WrapAngle(double a) {
  a = std::remainder(a, 2 * kPi);
  return a <= -kPi ? a + 2 * kPi : a;
}

// Rest-to-rest trapezoidal profile s(t) over length `length`.
struct Trapezoid {
  double length = 0, speed = 1, accel = 1, t_accel = 0, duration = 0;
  Trapezoid(double l, double v, double a) : length(l), speed(v), accel(a) {
    if (length <= 0) return;
    if (length < speed * speed / accel) {  // triangular: never reaches `speed`
      t_accel = std::sqrt(length / accel);
      speed = accel * t_accel;
      duration = 2 * t_accel;
    } else {
      t_accel = speed / accel;
      duration = length / speed + t_accel;
    }
  }
  double At(double t) const {
    if (t <= 0) return 0;
    if (t >= duration) return length;
    if (t < t_accel) return 0.5 * accel * t * t;
    if (t > duration - t_accel) {
      const double r = duration - t;
      return length - 0.5 * accel * r * r;
    }
    return 0.5 * accel * t_accel * t_accel + speed * (t - t_accel);
  }
};

// A straight Cartesian segment with IK solutions every 5 mm.
struct Segment {
  Vec3 start, direction;
  double length = 0;
  std::vector<Vec7> q;  // at s = 0, 5 mm, ..., length
  Vec3 PointAt(double s) const { return start + s * direction; }
  Vec7 JointsAt(double s) const {
    if (q.size() == 1) return q[0];
    const double f = std::clamp(s / kWaypoint, 0.0, static_cast<double>(q.size() - 1));
    const int i = std::min(static_cast<int>(f), static_cast<int>(q.size()) - 2);
    // The last interval may be shorter than 5 mm.
    const double s0 = i * kWaypoint, s1 = std::min(length, (i + 1) * kWaypoint);
    const double w = s1 > s0 ? std::clamp((s - s0) / (s1 - s0), 0.0, 1.0) : 1.0;
    return (1 - w) * q[i] + w * q[i + 1];
  }
};

void ToOde(const Eigen::Matrix3d& r, dMatrix3 out) {
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) out[4 * i + j] = r(i, j);
    out[4 * i + 3] = 0;
  }
}

Eigen::Matrix3d FromOde(const dReal* r) {
  Eigen::Matrix3d m;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) m(i, j) = r[4 * i + j];
  }
  return m;
}

Vec3 FromOdeVec(const dReal* v) { return Vec3(v[0], v[1], v[2]); }

}  // namespace

const char* PushStatusName(PushStatus status) {
  switch (status) {
    case PushStatus::kOk:
      return "ok";
    case PushStatus::kOffTable:
      return "off_table";
    case PushStatus::kUnreachable:
      return "unreachable";
  }
  return "unknown";
}

// The ODE objects of one world and the arm's controller state.
struct PushingEnv::World {
  PushingConfig config;
  dWorldID world = nullptr;
  dJointGroupID contacts = nullptr;
  dSpaceID static_space = nullptr;
  dThreadingImplementationID threading = nullptr;
  std::array<dBodyID, 7> links{};
  std::array<dJointID, 7> hinges{};
  dBodyID block = nullptr;
  dGeomID block_geom = nullptr, tip_geom = nullptr, table_geom = nullptr, obstacle_geom = nullptr;
  Vec3 tool_in_link7;  // tool point in link 7's body frame (origin at its COM)
  PandaIk ik;
  Vec7 home;
  bool arm_active = false;
  bool tip_hit_obstacle = false;
  bool block_hit_obstacle = false;
  std::vector<Vec3> tip_path;
  std::vector<Vec7> joint_path;

  explicit World(const PushingConfig& c) : config(c), ik(MakeIkOptions(c)), home(Home()) {}
  ~World() {
    if (world != nullptr) {
      dWorldSetStepThreadingImplementation(world, nullptr, nullptr);
      dJointGroupDestroy(contacts);
      for (dGeomID g : {block_geom, tip_geom}) {
        if (g != nullptr) dGeomDestroy(g);
      }
      dSpaceDestroy(static_space);  // destroys table and obstacle
      dWorldDestroy(world);
    }
    if (threading != nullptr) dThreadingFreeImplementation(threading);
  }

  static Vec7 Home() {
    Vec7 q;
    q << 0, 0.2, 0, -2.2, 0, 2.4, kPi / 4;
    return q;
  }
  static PandaIkOptions MakeIkOptions(const PushingConfig& c) {
    PandaIkOptions o;
    o.tool_length = c.tool_length;
    o.nominal = Home();
    return o;
  }

  void Build() {
    OdeEngine::Acquire();
    dAllocateODEDataForThread(dAllocateMaskAll);
    world = dWorldCreate();
    threading = dThreadingAllocateSelfThreadedImplementation();
    dWorldSetStepThreadingImplementation(world, dThreadingImplementationGetFunctions(threading),
                                         threading);
    dWorldSetGravity(world, 0, 0, -Panda::kGravity);
    dWorldSetERP(world, 0.2);
    dWorldSetCFM(world, 1e-9);
    dWorldSetContactSurfaceLayer(world, 1e-4);
    dWorldSetAutoDisableFlag(world, 0);
    contacts = dJointGroupCreate(0);
    static_space = dSimpleSpaceCreate(nullptr);

    // Table and obstacle: static geoms.
    table_geom = dCreateBox(static_space, kTableSizeX, kTableSizeY, kTableThickness);
    dGeomSetPosition(table_geom, kTableCenterX, 0, kTableTop - kTableThickness / 2);
    if (config.obstacle) {
      obstacle_geom = dCreateBox(static_space, 2 * kObstacleHalf[0], 2 * kObstacleHalf[1],
                                 2 * kObstacleHalf[2]);
      dGeomSetPosition(obstacle_geom, kObstacleX, kObstacleY, 0);
    }

    // Block: a box body resting on the table.
    block = dBodyCreate(world);
    dMass mass;
    // A solid box's inertia unless the configuration gives one diagonal value.
    const double a = config.block_size, h = config.block_height, m = config.block_mass;
    const bool solid = config.block_inertia <= 0;
    const double ixx = solid ? m * (a * a + h * h) / 12 : config.block_inertia;
    const double izz = solid ? m * (2 * a * a) / 12 : config.block_inertia;
    dMassSetParameters(&mass, m, 0, 0, 0, ixx, ixx, izz, 0, 0, 0);
    dBodySetMass(block, &mass);
    block_geom = dCreateBox(nullptr, config.block_size, config.block_size, config.block_height);
    dGeomSetBody(block_geom, block);

    // Arm: link bodies at q = 0, origin at the COM, axes of frame i.
    const auto frames = Panda::Frames<double>(Vec7::Zero());
    for (int i = 0; i < 7; ++i) {
      links[i] = dBodyCreate(world);
      const Vec3 com(Panda::kCom[i][0], Panda::kCom[i][1], Panda::kCom[i][2]);
      const Vec3 p = frames[i].R * com + frames[i].p;
      dBodySetPosition(links[i], p.x(), p.y(), p.z());
      dMatrix3 r;
      ToOde(frames[i].R, r);
      dBodySetRotation(links[i], r);
      const auto& in = Panda::kInertia[i];
      dMass m;
      dMassSetParameters(&m, Panda::kMass[i], 0, 0, 0, in[0], in[3], in[5], in[1], in[2], in[4]);
      dBodySetMass(links[i], &m);
      dBodySetGyroscopicMode(links[i], 1);
    }
    // Hinges at frame origins along z_i; the q = 0 pose is each hinge's zero angle.
    for (int i = 0; i < 7; ++i) {
      hinges[i] = dJointCreateHinge(world, nullptr);
      dJointAttach(hinges[i], i == 0 ? nullptr : links[i - 1], links[i]);
      const Vec3& o = frames[i].p;
      const Vec3 axis = frames[i].R.col(2);
      dJointSetHingeAnchor(hinges[i], o.x(), o.y(), o.z());
      dJointSetHingeAxis(hinges[i], axis.x(), axis.y(), axis.z());
      dJointSetHingeParam(hinges[i], dParamFMax, Panda::kTauMax[i]);
      dJointSetHingeParam(hinges[i], dParamVel, 0);
      // Stops act on ODE's wrapped angle in [-pi, pi], in its sense [-q_max, -q_min];
      // joint 6, whose range passes pi, is kept inside its limits by the IK alone.
      if (Panda::kQMax[i] < kPi && Panda::kQMin[i] > -kPi) {
        dJointSetHingeParam(hinges[i], dParamLoStop, -Panda::kQMax[i]);
        dJointSetHingeParam(hinges[i], dParamHiStop, -Panda::kQMin[i]);
      }
    }
    // Tip capsule on link 7, axis along z_7, lowest sphere centre at the tool point;
    // or a box pad over the same height, turned to the world's axes at every step.
    const Vec3 com7(Panda::kCom[6][0], Panda::kCom[6][1], Panda::kCom[6][2]);
    tool_in_link7 = Vec3(0, 0, Panda::kDh[7].d + config.tool_length) - com7;
    tip_geom = HasPad(config) ? dCreateBox(nullptr, 2 * config.tip_pad_x, 2 * config.tip_pad_y,
                                           config.tip_length + 2 * config.tip_radius)
                              : dCreateCapsule(nullptr, config.tip_radius, config.tip_length);
    dGeomSetBody(tip_geom, links[6]);
    const Vec3 centre = tool_in_link7 - Vec3(0, 0, config.tip_length / 2);
    dGeomSetOffsetPosition(tip_geom, centre.x(), centre.y(), centre.z());
  }

  // Joint angles, unwrapped next to `reference` (ODE reports hinge angles in (-pi, pi]).
  Vec7 JointAngles(const Vec7& reference) const {
    Vec7 q;
    for (int i = 0; i < 7; ++i) {
      const double a = kHingeSign * dJointGetHingeAngle(hinges[i]);
      q[i] = reference[i] + WrapAngle(a - reference[i]);
    }
    return q;
  }

  Vec3 ToolPoint() const {
    const Eigen::Matrix3d r = FromOde(dBodyGetRotation(links[6]));
    return FromOdeVec(dBodyGetPosition(links[6])) + r * tool_in_link7;
  }

  // Places the arm at rest in configuration q (kinematic transit).
  void Teleport(const Vec7& q) {
    const auto frames = Panda::Frames<double>(q);
    for (int i = 0; i < 7; ++i) {
      const Vec3 com(Panda::kCom[i][0], Panda::kCom[i][1], Panda::kCom[i][2]);
      const Vec3 p = frames[i].R * com + frames[i].p;
      dBodySetPosition(links[i], p.x(), p.y(), p.z());
      dMatrix3 r;
      ToOde(frames[i].R, r);
      dBodySetRotation(links[i], r);
      dBodySetLinearVel(links[i], 0, 0, 0);
      dBodySetAngularVel(links[i], 0, 0, 0);
    }
  }

  void SetArmActive(bool active) {
    arm_active = active;
    for (dBodyID b : links) {
      if (active) {
        dBodyEnable(b);
      } else {
        dBodyDisable(b);
      }
    }
  }

  static void NearCallback(void* data, dGeomID a, dGeomID b) {
    auto* w = static_cast<World*>(data);
    std::array<dContactGeom, kMaxContacts> geoms;
    const int n = dCollide(a, b, kMaxContacts, geoms.data(), sizeof(dContactGeom));
    if (n == 0) return;
    const bool tip = a == w->tip_geom || b == w->tip_geom;
    const bool block = a == w->block_geom || b == w->block_geom;
    double mu = w->config.block_table_friction;
    if (tip && block) {
      mu = w->config.tip_block_friction;
    } else if (tip) {
      w->tip_hit_obstacle = true;
      mu = 0.5;
    } else if (a == w->obstacle_geom || b == w->obstacle_geom) {
      w->block_hit_obstacle = true;
    }
    for (int i = 0; i < n; ++i) {
      dContact contact{};
      contact.surface.mode = dContactApprox1;
      contact.surface.mu = mu;
      contact.geom = geoms[i];
      const dJointID j = dJointCreateContact(w->world, w->contacts, &contact);
      dJointAttach(j, dGeomGetBody(a), dGeomGetBody(b));
    }
  }

  // Contacts of this step, always in the same order: block-static, tip-block, tip-static.
  void Collide() {
    dSpaceCollide2(block_geom, reinterpret_cast<dGeomID>(static_space), this, &NearCallback);
    if (arm_active) {
      NearCallback(this, tip_geom, block_geom);
      dSpaceCollide2(tip_geom, reinterpret_cast<dGeomID>(static_space), this, &NearCallback);
    }
  }

  void StepWorld(PushResult& result) {
    if (arm_active && HasPad(config)) {
      dMatrix3 axes;
      dRSetIdentity(axes);
      dGeomSetOffsetWorldRotation(tip_geom, axes);
    }
    Collide();
    dWorldStep(world, config.time_step);
    dJointGroupEmpty(contacts);
    ++result.steps;
    const Vec3 p = FromOdeVec(dBodyGetPosition(block));
    result.max_block_speed =
        std::max(result.max_block_speed, FromOdeVec(dBodyGetLinearVel(block)).norm());
    result.min_block_z = std::min(result.min_block_z, p.z());
    result.max_block_z = std::max(result.max_block_z, p.z());
    if (!p.allFinite()) throw NumericalError("pushing world: the block's state became non-finite");
  }

  Vec3 BlockPose() const {
    const dReal* p = dBodyGetPosition(block);
    const dReal* r = dBodyGetRotation(block);
    return Vec3(p[0], p[1], std::atan2(r[4], r[0]));
  }

  // IK for every 5 mm waypoint of a segment, continuing from `seed`; false if one is missed.
  bool Plan(Segment& seg, const Vec7& seed) const {
    const int n = static_cast<int>(std::ceil(seg.length / kWaypoint - 1e-9));
    Vec7 q = seed;
    seg.q.clear();
    for (int i = 0; i <= std::max(n, 0); ++i) {
      const double s = std::min(seg.length, i * kWaypoint);
      const auto sol = ik.Solve(seg.PointAt(s), Vec3(0, 0, -1), q);
      if (sol.position_error > config.ik_tolerance) return false;
      q = sol.q;
      seg.q.push_back(q);
    }
    return true;
  }

  // Drives the arm along a segment under a trapezoidal profile with the hinge motors.
  void Track(const Segment& seg, double speed, double accel, Vec7& q_ref, PushResult& result) {
    // Near the edge of the workspace dq/ds grows: slow down so that no joint needs
    // more than half its velocity limit (keeps the tip on the path).
    double limit = speed;
    for (size_t i = 1; i < seg.q.size(); ++i) {
      const double ds = std::min(seg.length, i * kWaypoint) - (i - 1) * kWaypoint;
      if (ds <= 0) continue;
      for (int j = 0; j < 7; ++j) {
        const double rate = std::abs(seg.q[i][j] - seg.q[i - 1][j]) / ds;  // rad per m
        if (rate > 0) limit = std::min(limit, 0.5 * Panda::kDqMax[j] / rate);
      }
    }
    const Trapezoid profile(seg.length, limit, accel * limit / speed);
    const int n = static_cast<int>(std::ceil(profile.duration / config.time_step - 1e-9));
    for (int k = 0; k < n; ++k) {
      const double s = profile.At((k + 1) * config.time_step);
      const Vec7 q_next = seg.JointsAt(s);
      const Vec7 q = JointAngles(q_ref);
      for (int i = 0; i < 7; ++i) {
        const double v = std::clamp((q_next[i] - q[i]) / config.time_step, -Panda::kDqMax[i],
                                    Panda::kDqMax[i]);
        dJointSetHingeParam(hinges[i], dParamVel, MotorSign(i) * v);
      }
      q_ref = q_next;
      StepWorld(result);
      const Vec7 q_now = JointAngles(q_ref);
      for (int i = 0; i < 7; ++i) {
        const double excess =
            std::max(Panda::kQMin[i] - q_now[i], q_now[i] - Panda::kQMax[i]);
        result.max_limit_violation = std::max(result.max_limit_violation, excess);
      }
      const Vec3 tool = ToolPoint();
      result.max_tracking_error =
          std::max(result.max_tracking_error, (tool - seg.PointAt(s)).norm());
      if ((k + 1) % kTipPathEvery == 0 || k + 1 == n) {
        tip_path.push_back(tool);
        joint_path.push_back(q_now);
      }
    }
  }
};

PushingEnv::PushingEnv(const PushingConfig& config) : world_(std::make_unique<World>(config)) {
  const PushingConfig& c = config;
  DIFFDYN_CHECK(c.block_mass > 0 && c.block_inertia >= 0 && c.block_size > 0 &&
                    c.block_height > 0 && c.block_table_friction >= 0 &&
                    c.tip_block_friction >= 0 && c.tip_radius > 0 && c.tip_length >= 0 &&
                    c.tip_pad_x >= 0 && c.tip_pad_y >= 0 &&
                    (c.tip_pad_x > 0) == (c.tip_pad_y > 0) && c.time_step > 0 && c.push_speed > 0 &&
                    c.push_acceleration > 0 && c.approach_speed > 0 &&
                    c.approach_acceleration > 0 && c.settle_time >= 0,
                "pushing world: masses, sizes, speeds and the time step must be positive, "
                "frictions non-negative, and the tip's pad half widths both zero or both positive");
  world_->Build();
  Reset({0.4, 0.0, 0.2 * kPi});
}

PushingEnv::~PushingEnv() = default;

const PushingConfig& PushingEnv::config() const { return world_->config; }

PushPath PushingEnv::PlanarPath(const Eigen::Vector3d& pose, const Eigen::Vector3d& action) {
  const double c = std::cos(pose.z()), s = std::sin(pose.z());
  const Eigen::Vector2d p(pose.x(), pose.y()), ex(c, s), ey(-s, c);
  PushPath path;
  path.approach_start = p - kStartBehind * ex + kLateralScale * action[0] * ey;
  path.push_start = path.approach_start + kApproach * ex;
  const double a = pose.z() + action[1];
  path.push_end = path.push_start + kPushScale * action[2] * Eigen::Vector2d(std::cos(a), std::sin(a));
  return path;
}

PushReach PushingEnv::Reach(const PushingConfig& config) {
  const PandaIk ik(World::MakeIkOptions(config));
  const Vec7 home = World::Home();
  auto reaches = [&](double r, double azimuth) {
    const Vec3 target(r * std::cos(azimuth), r * std::sin(azimuth), config.push_height);
    return ik.Solve(target, Vec3(0, 0, -1), home).position_error <= config.ik_tolerance;
  };
  // Bisection between a radius that fails and one that succeeds.
  auto boundary = [&](double fail, double ok, double azimuth) {
    while (std::abs(fail - ok) > 1e-4) {
      const double mid = 0.5 * (fail + ok);
      (reaches(mid, azimuth) ? ok : fail) = mid;
    }
    return ok;
  };
  PushReach reach{0.0, std::numeric_limits<double>::infinity()};
  for (double azimuth = -0.75; azimuth <= 0.75 + 1e-9; azimuth += 0.25) {
    // The middle of the workspace, then out to a radius no Panda reaches, and in to the base.
    const double middle = 0.5;
    DIFFDYN_CHECK(reaches(middle, azimuth), "pushing reach: the IK misses the point at radius ",
                  middle, " m, azimuth ", azimuth, " rad");
    reach.outer = std::min(reach.outer, boundary(1.5, middle, azimuth));
    reach.inner = std::max(reach.inner, reaches(0.0, azimuth) ? 0.0 : boundary(0.0, middle, azimuth));
  }
  return reach;
}

bool PushingEnv::OnTable(double x, double y) {
  return std::abs(x - kTableCenterX) <= kTableSizeX / 2 && std::abs(y) <= kTableSizeY / 2;
}

double PushingEnv::ObstaclePenetration(const Eigen::Vector3d& pose, double block_size) {
  // Separating axes of two rectangles: the block's two edge normals and the obstacle's.
  const double h = block_size / 2;
  const double c = std::cos(pose.z()), s = std::sin(pose.z());
  const Eigen::Vector2d d(pose.x() - kObstacleX, pose.y() - kObstacleY);
  const std::array<Eigen::Vector2d, 4> axes = {Eigen::Vector2d(1, 0), Eigen::Vector2d(0, 1),
                                               Eigen::Vector2d(c, s), Eigen::Vector2d(-s, c)};
  double depth = 1e9;
  for (const auto& n : axes) {
    const double block_r = h * (std::abs(n.dot(Eigen::Vector2d(c, s))) +
                                std::abs(n.dot(Eigen::Vector2d(-s, c))));
    const double obstacle_r = kObstacleHalf[0] * std::abs(n.x()) + kObstacleHalf[1] * std::abs(n.y());
    depth = std::min(depth, block_r + obstacle_r - std::abs(n.dot(d)));
  }
  return std::max(depth, 0.0);
}

void PushingEnv::ValidateAction(const Eigen::Vector3d& action) {
  const char* names[3] = {"push_location", "push_angle", "push_length"};
  const double lo[3] = {-1, -kPi / 2, 0};
  const double hi[3] = {1, kPi / 2, 1};
  for (int i = 0; i < 3; ++i) {
    DIFFDYN_CHECK(std::isfinite(action[i]), "action ", names[i], " is not finite (", action[i],
                  ")");
    DIFFDYN_CHECK(action[i] >= lo[i] && action[i] <= hi[i], "action ", names[i], " = ",
                  action[i], " is outside [", lo[i], ", ", hi[i], "]");
  }
}

void PushingEnv::Reset(const Eigen::Vector3d& pose) {
  World& w = *world_;
  DIFFDYN_CHECK(pose.allFinite(), "pushing reset: pose (", pose.x(), ", ", pose.y(), ", ",
                pose.z(), ") is not finite");
  DIFFDYN_CHECK(OnTable(pose.x(), pose.y()), "pushing reset: pose (", pose.x(), ", ", pose.y(),
                ") is off the table");
  DIFFDYN_CHECK(!w.config.obstacle || ObstaclePenetration(pose, w.config.block_size) == 0,
                "pushing reset: pose (", pose.x(), ", ", pose.y(), ", ", pose.z(),
                ") overlaps the obstacle");
  dAllocateODEDataForThread(dAllocateMaskAll);
  dBodySetPosition(w.block, pose.x(), pose.y(), kTableTop + w.config.block_height / 2);
  const Eigen::Matrix3d r = Eigen::AngleAxisd(pose.z(), Vec3::UnitZ()).toRotationMatrix();
  dMatrix3 m;
  ToOde(r, m);
  dBodySetRotation(w.block, m);
  dBodySetLinearVel(w.block, 0, 0, 0);
  dBodySetAngularVel(w.block, 0, 0, 0);
  dBodySetForce(w.block, 0, 0, 0);
  dBodySetTorque(w.block, 0, 0, 0);
  w.Teleport(w.home);
  w.SetArmActive(false);
  w.tip_path.clear();
  w.joint_path.clear();
}

PushResult PushingEnv::Step(const Eigen::Vector3d& action) {
  ValidateAction(action);
  World& w = *world_;
  const PushingConfig& c = w.config;
  dAllocateODEDataForThread(dAllocateMaskAll);
  w.tip_path.clear();
  w.joint_path.clear();
  w.tip_hit_obstacle = false;
  w.block_hit_obstacle = false;

  PushResult result;
  const Vec3 pose = w.BlockPose();
  result.pose = pose;
  const double z0 = dBodyGetPosition(w.block)[2];
  result.min_block_z = result.max_block_z = z0;

  // Cartesian segments of the approach and the push at push height.
  const double theta = pose.z();
  const PushPath path = PlanarPath(pose, action);
  Segment approach, push;
  approach.start = Vec3(path.approach_start.x(), path.approach_start.y(), c.push_height);
  approach.direction = Vec3(std::cos(theta), std::sin(theta), 0);
  approach.length = kApproach;
  push.start = Vec3(path.push_start.x(), path.push_start.y(), c.push_height);
  push.direction = Vec3(std::cos(theta + action[1]), std::sin(theta + action[1]), 0);
  push.length = kPushScale * action[2];

  // Plan both with IK; transit (raise, move, lower) is kinematic.
  const auto start = w.ik.Solve(approach.start, Vec3(0, 0, -1), w.home);
  if (start.position_error > c.ik_tolerance || !w.Plan(approach, start.q) ||
      !w.Plan(push, approach.q.back())) {
    result.status = PushStatus::kUnreachable;
    return result;
  }
  Vec7 q_ref = approach.q.front();
  w.Teleport(q_ref);
  w.SetArmActive(true);
  w.tip_path.push_back(w.ToolPoint());
  w.joint_path.push_back(q_ref);

  // Approach and push with the arm's dynamics.
  w.Track(approach, c.approach_speed, c.approach_acceleration, q_ref, result);
  if (push.length > 0) w.Track(push, c.push_speed, c.push_acceleration, q_ref, result);
  result.tip_hit_obstacle = w.tip_hit_obstacle;
  result.block_hit_obstacle = w.block_hit_obstacle;

  // Lift the arm clear and let the block come to rest.
  w.SetArmActive(false);
  const int settle_steps = static_cast<int>(std::ceil(c.settle_time / c.time_step));
  for (int k = 0; k < settle_steps; ++k) {
    const Vec3 v = FromOdeVec(dBodyGetLinearVel(w.block));
    const Vec3 omega = FromOdeVec(dBodyGetAngularVel(w.block));
    if (v.norm() < 1e-4 && omega.norm() < 1e-3) break;
    const Vec3 p = FromOdeVec(dBodyGetPosition(w.block));
    if (!OnTable(p.x(), p.y())) break;
    w.StepWorld(result);
  }
  result.pose = w.BlockPose();
  if (!OnTable(result.pose.x(), result.pose.y())) result.status = PushStatus::kOffTable;
  return result;
}

Eigen::Vector3d PushingEnv::pose() const { return world_->BlockPose(); }

const std::vector<Eigen::Vector3d>& PushingEnv::tip_path() const { return world_->tip_path; }

const std::vector<Panda::Vector7<double>>& PushingEnv::joint_path() const {
  return world_->joint_path;
}

Panda::Vector7<double> PushingEnv::joint_positions() const {
  return world_->JointAngles(world_->home);
}

}  // namespace diffdyn
