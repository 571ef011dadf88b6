// Control tasks: what a controller must achieve on a joint-space system, and how
// well it did (DESIGN.md, "Control tasks").
//
// A task is a plant (a JointTask: the analytic model with its parameters, effects,
// actuated joints and torque bounds), a seeded start distribution, a running cost
//
//   c(x, u) = sum_i w_i e_i(x)^2 + g(u),
//   e_i = pi sin((x_i - goal_i) / 2)   for a periodic component,
//   e_i = x_i - goal_i                  otherwise,
//   g(u) = sum_j r_j u_j^2                        (quadratic action cost), or
//   g(u) = -(2 beta u_max / pi) log cos(pi u / (2 u_max))   (log-cosine, one action),
//
// a success test at the end (|e_i| < tol_i for every component with a tolerance,
// the periodic ones wrapped), and state limits whose violation ends a run as a
// failure (the cart-pole's track). Control runs at `period` seconds (zero-order
// hold) for `duration` seconds. States use the model's convention (the pendulum's
// q = 0 hangs, so its goal is q = pi). TaskModel is the plant as a transition model
// over any whole number of control periods: the evaluator's plant and the analytic
// model a controller plans with.
//
// As a Task (task.h): one step per control period on TaskModel(task, period, 4)
// (rk4-classic, 4 substeps), step cost period * c(x_k, u_k), run s starting at the
// s-th draw of Rng(seed) from the start box with controller seed
// SplitMix64Hash(SplitMix64Hash(seed) ^ s); a run whose state leaves the limits fails
// ("left_limits", judged at the end), else "success" or "failed" by the success test.
//
//   name       plant                                 starts                          success
//   pendulum   JointTask "pendulum" (m 0.75, l 2/3)  theta ~ U(-pi, pi), |qd| < 0.01  |theta| < 0.1, |qd| < 0.5
//   cartpole   JointTask "cartpole" (cart pushed)    |x| < 0.1, theta ~ pi +- 0.1     |theta| < 0.1, |thetad| < 0.5,
//                                                                                    |x| < 0.5 (track |x| <= 0.5)
//
//   ControlTask task = ControlTaskByName("pendulum");
//   Eigen::VectorXd x0 = task.SampleStart(rng);
//   double c = task.RunningCost(x0, Eigen::VectorXd::Zero(1));
//   auto plant = TaskModel(task, task.period, 4);   // rk4-classic, 4 substeps
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/continuous_model.h"
#include "diffdyn/models/random.h"
#include "diffdyn/models/transition_model.h"
#include "diffdyn/physics/joint_task.h"
#include "diffdyn/physics/task.h"

namespace diffdyn {

/// The action cost g(u) of a control task (see the file comment).
struct ActionCost {
  enum class Kind { kQuadratic, kLogCosine };
  Kind kind = Kind::kQuadratic;
  /// Quadratic: r_j per action (m entries).
  Eigen::VectorXd r;
  /// Log-cosine (one action): the padded bound u_max and beta.
  double u_max = 0.0, beta = 0.0;

  /// g(u) for one action vector u (m), u within the task's bounds.
  double operator()(const Eigen::Ref<const Eigen::VectorXd>& u) const {
    if (kind == Kind::kQuadratic) return (r.array() * u.array().square()).sum();
    const double scale = 2.0 * beta * u_max / std::numbers::pi;
    return -scale * std::log(std::cos(std::numbers::pi * u[0] / (2.0 * u_max)));
  }

  /// The convex conjugate g~(w) = max_u [w^T u - g(u)] (w: m):
  ///   quadratic:   sum_j w_j^2 / (4 r_j);
  ///   log-cosine:  (u_max / pi) [2 w atan(w / beta) - beta log(1 + w^2 / beta^2)].
  double Conjugate(const Eigen::Ref<const Eigen::VectorXd>& w) const {
    if (kind == Kind::kQuadratic) return (w.array().square() / (4.0 * r.array())).sum();
    const double z = w[0] / beta;
    return (u_max / std::numbers::pi) * (2.0 * w[0] * std::atan(z) - beta * std::log1p(z * z));
  }

  /// The maximiser u*(w) = grad g~(w) (m): w_j / (2 r_j), or (2 u_max / pi) atan(w / beta),
  /// which stays inside (-u_max, u_max).
  Eigen::VectorXd ConjugateGradient(const Eigen::Ref<const Eigen::VectorXd>& w) const {
    if (kind == Kind::kQuadratic) return (w.array() / (2.0 * r.array())).matrix();
    return Eigen::VectorXd::Constant(1, (2.0 * u_max / std::numbers::pi) * std::atan(w[0] / beta));
  }
};

/// A control task (see the file comment). Sizes: n states (2 x joints), m actions.
struct ControlTask : public Task {
  /// The plant: model, parameters, effects, actuated joints, torque bounds.
  JointTask plant;
  /// Control period and run length (s).
  double period = 1.0 / 125.0;
  double duration = 5.0;
  /// Uniform start distribution over [start_low, start_high] (n each).
  Eigen::VectorXd start_low, start_high;
  /// Goal state, cost weights w_i and which components are periodic (n each).
  Eigen::VectorXd goal, weights;
  std::vector<bool> periodic;
  ActionCost action_cost;
  /// Success tolerances on |e_i| at the end (n; infinity: not tested).
  Eigen::VectorXd tolerance;
  /// |x_i - goal_i| <= limit_i throughout, else the run fails (n; infinity: none).
  Eigen::VectorXd limit;
  /// The state box [domain_low, domain_high] (n each, finite) a value function is
  /// learned over (solvers/hjb.h).
  Eigen::VectorXd domain_low, domain_high;

  /// n and m.
  int state_size() const override { return static_cast<int>(goal.size()); }
  int action_size() const override { return static_cast<int>(plant.actuated.size()); }
  /// The number of control periods of a run.
  int periods() const { return static_cast<int>(std::lround(duration / period)); }
  /// Task: one step per control period.
  double step_period() const override { return period; }
  int max_steps() const override { return periods(); }
  std::vector<TaskStart> Starts(int count, std::uint64_t seed) const override;
  std::unique_ptr<TaskRun> Begin() const override;

  /// The distance of component i from the goal: wrapped to (-pi, pi] when periodic.
  double Deviation(int i, double value) const {
    double d = value - goal[i];
    if (periodic[static_cast<std::size_t>(i)]) d = std::remainder(d, 2.0 * std::numbers::pi);
    return d;
  }

  /// sum_i w_i e_i(x)^2 (file comment) for one state x (n).
  double StateCost(const Eigen::Ref<const Eigen::VectorXd>& x) const {
    double c = 0.0;
    for (int i = 0; i < state_size(); ++i) {
      const double d = x[i] - goal[i];
      const double e = periodic[static_cast<std::size_t>(i)] ? std::numbers::pi * std::sin(0.5 * d) : d;
      c += weights[i] * e * e;
    }
    return c;
  }

  /// c(x, u) = StateCost(x) + g(u) for u within the bounds.
  double RunningCost(const Eigen::Ref<const Eigen::VectorXd>& x,
                     const Eigen::Ref<const Eigen::VectorXd>& u) const {
    return StateCost(x) + action_cost(u);
  }

  /// u clipped to the task's torque bounds.
  Eigen::VectorXd Clip(const Eigen::Ref<const Eigen::VectorXd>& u) const override {
    return u.cwiseMax(-plant.bound).cwiseMin(plant.bound);
  }

  /// Whether x (n) breaks a state limit (the run then fails).
  bool OutOfLimits(const Eigen::Ref<const Eigen::VectorXd>& x) const {
    for (int i = 0; i < state_size(); ++i) {
      if (!(std::abs(x[i] - goal[i]) <= limit[i])) return true;
    }
    return false;
  }

  /// The success test on the final state (file comment).
  bool Succeeded(const Eigen::Ref<const Eigen::VectorXd>& x) const {
    if (OutOfLimits(x)) return false;
    for (int i = 0; i < state_size(); ++i) {
      if (!(std::abs(Deviation(i, x[i])) < tolerance[i])) return false;
    }
    return true;
  }

  /// One start state drawn uniformly from the start box.
  Eigen::VectorXd SampleStart(Rng& rng) const {
    Eigen::VectorXd x(state_size());
    for (int i = 0; i < x.size(); ++i) x[i] = start_low[i] + (start_high[i] - start_low[i]) * UniformUnit(rng);
    return x;
  }
};

/// The control task names.
inline std::vector<std::string> ControlTaskNames() { return {"pendulum", "cartpole"}; }

/// The task `name` (file comment); throws diffdyn::Error naming --system otherwise.
inline ControlTask ControlTaskByName(const std::string& name) {
  constexpr double kPi = std::numbers::pi;
  constexpr double kInf = std::numeric_limits<double>::infinity();
  DIFFDYN_CHECK(name == "pendulum" || name == "cartpole", "--system ", name.substr(0, 60),
                ": no control task (pendulum or cartpole; pushing is `diffdyn push`)");
  ControlTask t;
  t.plant = JointTaskByName(name);
  if (name == "pendulum") {
    // The HJB paper's pendulum; q = 0 hangs, so theta = q - pi.
    t.start_low = VectorOf({0.0, -0.01});
    t.start_high = VectorOf({2.0 * kPi, 0.01});
    t.goal = VectorOf({kPi, 0.0});
    t.weights = VectorOf({1.0, 0.1});
    t.periodic = {true, false};
    const double u_max = 2.5 + 1e-3, r = 0.5;
    t.action_cost = {ActionCost::Kind::kLogCosine, {}, u_max, 4.0 * u_max * u_max * r / kPi};
    t.tolerance = VectorOf({0.1, 0.5});
    t.limit = VectorOf({kInf, kInf});
    t.domain_low = VectorOf({0.0, -8.0});  // |theta| <= pi, |theta'| <= 8 (lutter_facts.md (d))
    t.domain_high = VectorOf({2.0 * kPi, 8.0});
  } else {
    // theta = 0 upright; only the cart is pushed; the track is |x| <= 0.5.
    t.start_low = VectorOf({-0.1, kPi - 0.1, 0.0, 0.0});
    t.start_high = VectorOf({0.1, kPi + 0.1, 0.0, 0.0});
    t.goal = VectorOf({0.0, 0.0, 0.0, 0.0});
    t.weights = VectorOf({1.0, 1.0, 0.1, 0.1});
    t.periodic = {false, true, false, false};
    t.action_cost = {ActionCost::Kind::kQuadratic, VectorOf({0.01}), 0.0, 0.0};
    t.tolerance = VectorOf({0.5, 0.1, kInf, 0.5});
    t.limit = VectorOf({0.5, kInf, kInf, kInf});
    t.domain_low = VectorOf({-0.5, -kPi, -3.0, -10.0});
    t.domain_high = VectorOf({0.5, kPi, 3.0, 10.0});
  }
  return t;
}

/// The plant's viscous joint friction (n coefficients, AnalyticDynamics' damping);
/// throws diffdyn::Error for any other effect.
inline Eigen::VectorXd TaskDamping(const ControlTask& task) {
  const JointTask& plant = task.plant;
  const int n = task.state_size() / 2;
  Eigen::VectorXd damping = Eigen::VectorXd::Zero(n);
  for (const Effect& e : plant.effects) {
    DIFFDYN_CHECK(e.kind == EffectKind::kViscous && e.joint >= 1 && e.joint <= n, plant.name,
                  ": a task plant takes viscous joint friction only");
    damping[e.joint - 1] += e.params[0];
  }
  return damping;
}

/// The actuated joints, 0-based (AnalyticDynamics' actuated).
inline std::vector<int> TaskActuatedJoints(const ControlTask& task) {
  std::vector<int> actuated;
  for (int j : task.plant.actuated) actuated.push_back(j - 1);
  return actuated;
}

/// The task's plant as a transition model over `dt` seconds (rk4-classic, `substeps`
/// steps): x = (q, qd) (n), u = the actuated torques (m), the model's parameters and
/// the task's viscous friction (AnalyticModel::MakeTransitionModel). Throws
/// diffdyn::Error for a task effect other than viscous friction.
inline std::unique_ptr<TransitionModel> TaskModel(const ControlTask& task, double dt, int substeps) {
  const JointTask& plant = task.plant;
  const auto model = plant.Model();
  return model->MakeTransitionModel(ParseParams(*model, plant.params), TaskActuatedJoints(task),
                                    TaskDamping(task), plant.System(),
                                    {.method = Method::kRk4Classic, .dt = dt, .substeps = substeps});
}

}  // namespace diffdyn
