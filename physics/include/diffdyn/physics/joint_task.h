// Joint-space systems as tasks: an analytic model with its own parameters,
// effects, actuation, action bounds and start domain (DESIGN.md, "Systems,
// trajectories and models").
//
//   name             model            parameters, effects           actuated  |tau| <=        starts (uniform)
//   pendulum         pendulum         m 0.75, l 2/3, g 9.81        1         2.5 N m         q any, |qd| <= 8
//   cartpole         cartpole         VI parameters; viscous 0.1   1 (cart)  20 N            |x| <= 0.4, theta any,
//                                     (cart), 1e-3 (pole)                                    |xd| <= 2, |thetad| <= 10
//   double-pendulum  double-pendulum  defaults                     1, 2      10 N m          q any, |qd| <= 2
//   arm2             arm2             defaults                     1, 2      10 N m          |q| <= pi/2, |qd| <= 2
//   panda            panda            defaults                     1..7      Franka tau_max  inside the joint limits,
//                                                                                            |qd| <= 0.5
//
// The cart-pole task adds a centring loop -3 x - 2 xd to the cart force
// (`feedback`); exciting every joint (ActuatingAll) bounds its pole torque by 0.5 N m. A task names no cost yet; collect uses it to excite the system
// (solvers/joint_collect.h). Files keep the model's convention (the pendulum's
// q = 0 hangs), and a joint's torque is 0 when it is not actuated.
//
//   JointTask task = JointTaskByName("cartpole");
//   auto plant = task.Plant();                 // ExtendedModel with the task's effects
//   SystemDescription s = task.System();       // x = (q, qd), u = the actuated torques
#pragma once

#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/system_description.h"
#include "diffdyn/physics/effects.h"
#include "diffdyn/physics/model_registry.h"

namespace diffdyn {

/// A joint-space task (see the file comment). Sizes: n joints, a actuated.
struct JointTask {
  std::string name;
  /// The analytic model (model_registry.h) and its parameter overrides ("name=value").
  std::string model;
  std::vector<std::string> params;
  /// Effects of the simulated system (model_conventions.md).
  std::vector<Effect> effects;
  /// 1-based actuated joints (a entries, increasing).
  std::vector<int> actuated;
  /// |tau_j| bound of each actuated joint (a).
  Eigen::VectorXd bound;
  /// Start domain of (q, qd) (2n entries each).
  Eigen::VectorXd start_low, start_high;
  /// Linear feedback added to the actuated torques, tau_act += -feedback x (a x 2n), or empty.
  Eigen::MatrixXd feedback;
  /// |tau_j| bound of every joint (n), used when every joint is excited (collect --actuated all).
  Eigen::VectorXd bound_all;

  /// The same task with every joint actuated within bound_all (the feedback acts
  /// on the joints it acted on before).
  JointTask ActuatingAll() const {
    JointTask all = *this;
    const int n = static_cast<int>(bound_all.size());
    all.actuated.clear();
    for (int j = 1; j <= n; ++j) all.actuated.push_back(j);
    all.bound = bound_all;
    if (feedback.size() > 0) {
      all.feedback = Eigen::MatrixXd::Zero(n, feedback.cols());
      for (std::size_t k = 0; k < actuated.size(); ++k) {
        all.feedback.row(actuated[k] - 1) = feedback.row(static_cast<Eigen::Index>(k));
      }
    }
    return all;
  }

  /// The analytic model with the task's parameters.
  std::shared_ptr<const AnalyticModel> Model() const { return MakeAnalyticModel(model); }

  /// The simulated system: the model with the task's parameters and effects. Throws
  /// diffdyn::Error for a bad effect.
  std::shared_ptr<const ExtendedModel> Plant() const {
    const auto m = Model();
    return std::make_shared<const ExtendedModel>(m, ParseParams(*m, params), effects);
  }

  /// x = (q1..qn, qd1..qdn), u = tau_j of the actuated joints with the task's bounds;
  /// revolute q are angles (sin/cos features).
  SystemDescription System() const {
    const auto m = Model();
    SystemDescription s = AnalyticSystem(*m);
    s.name = name;
    s.action_names.clear();
    for (int j : actuated) s.action_names.push_back(StrCat("tau", j));
    s.action_low = -bound;
    s.action_high = bound;
    s.Validate();
    return s;
  }

  /// The full torque (n) of the actuated torques u (a): zeros on the other joints.
  Eigen::VectorXd FullTorque(const Eigen::VectorXd& u, int n) const {
    Eigen::VectorXd tau = Eigen::VectorXd::Zero(n);
    for (std::size_t k = 0; k < actuated.size(); ++k) tau[actuated[k] - 1] = u[static_cast<Eigen::Index>(k)];
    return tau;
  }
};

/// The vector of `values` (copied one by one: g++ 12 warns about Eigen's vector loads
/// from a Map over a short initializer list).
inline Eigen::VectorXd VectorOf(std::initializer_list<double> values) {
  Eigen::VectorXd v(static_cast<Eigen::Index>(values.size()));
  Eigen::Index i = 0;
  for (double x : values) v[i++] = x;
  return v;
}

/// The task names, in the table's order.
inline std::vector<std::string> JointTaskNames() {
  return {"pendulum", "cartpole", "double-pendulum", "arm2", "panda"};
}

/// The task `name` (file comment); throws diffdyn::Error naming --system otherwise.
inline JointTask JointTaskByName(const std::string& name) {
  constexpr double kPi = std::numbers::pi;
  JointTask t;
  t.name = name;
  t.model = name;
  auto domain = [&t](std::initializer_list<double> low, std::initializer_list<double> high) {
    t.start_low = VectorOf(low);
    t.start_high = VectorOf(high);
  };
  if (name == "pendulum") {
    t.params = {"m=0.75", "l=0.6666666666666666", "g=9.81"};
    t.actuated = {1};
    t.bound = Eigen::VectorXd::Constant(1, 2.5);
    t.bound_all = t.bound;
    domain({-kPi, -8.0}, {kPi, 8.0});
  } else if (name == "cartpole") {
    t.effects = {Effect{EffectKind::kViscous, 1, {0.1}, {}}, Effect{EffectKind::kViscous, 2, {1e-3}, {}}};
    t.actuated = {1};
    t.bound = Eigen::VectorXd::Constant(1, 20.0);
    t.bound_all.resize(2);
    t.bound_all << 20.0, 0.5;
    domain({-0.4, -kPi, -2.0, -10.0}, {0.4, kPi, 2.0, 10.0});
    t.feedback = Eigen::MatrixXd::Zero(1, 4);
    t.feedback(0, 0) = 3.0;
    t.feedback(0, 2) = 2.0;
  } else if (name == "double-pendulum") {
    t.actuated = {1, 2};
    t.bound = Eigen::VectorXd::Constant(2, 10.0);
    t.bound_all = t.bound;
    domain({-kPi, -kPi, -2.0, -2.0}, {kPi, kPi, 2.0, 2.0});
  } else if (name == "arm2") {
    t.actuated = {1, 2};
    t.bound = Eigen::VectorXd::Constant(2, 10.0);
    t.bound_all = t.bound;
    domain({-kPi / 2, -kPi / 2, -2.0, -2.0}, {kPi / 2, kPi / 2, 2.0, 2.0});
  } else if (name == "panda") {
    // Franka's limits (panda_parameters.md [F-LIM]).
    t.actuated = {1, 2, 3, 4, 5, 6, 7};
    t.bound.resize(7);
    t.bound << 87, 87, 87, 87, 12, 12, 12;
    t.bound_all = t.bound;
    domain({-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973, -0.5, -0.5, -0.5, -0.5, -0.5,
            -0.5, -0.5},
           {2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5});
  } else {
    throw Error(StrCat("--system ", name.substr(0, 60),
                       ": unknown system (pendulum, cartpole, double-pendulum, arm2, panda or pushing)"));
  }
  return t;
}

/// Parses "KIND:JOINT=VALUE[,VALUE...]" (e.g. "viscous:1=0.3", "gain:0=0.9"), the
/// values being the kind's parameters in model_conventions.md's order. Throws
/// diffdyn::Error naming `option`.
inline Effect ParseEffectSpec(const std::string& text, const std::string& option) {
  const auto colon = text.find(':');
  const auto eq = text.find('=');
  DIFFDYN_CHECK(colon != std::string::npos && eq != std::string::npos && colon < eq, option, " ",
                text.substr(0, 80), ": expected KIND:JOINT=VALUE (e.g. viscous:1=0.3)");
  Effect e;
  try {
    e.kind = ParseEffectKind(text.substr(0, colon));
  } catch (const Error& error) {
    throw Error(StrCat(option, " ", text.substr(0, 80), ": ", error.what()));
  }
  const std::string joint = text.substr(colon + 1, eq - colon - 1);
  DIFFDYN_CHECK(!joint.empty() && joint.size() <= 3 && joint.find_first_not_of("0123456789") == std::string::npos,
                option, " ", text.substr(0, 80), ": the joint must be a number (0 = the whole system)");
  e.joint = std::stoi(joint);
  std::size_t start = eq + 1;
  while (true) {
    const auto comma = text.find(',', start);
    const std::string item = text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    std::size_t used = 0;
    double value = 0.0;
    try {
      value = std::stod(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    DIFFDYN_CHECK(!item.empty() && used == item.size() && std::isfinite(value), option, " ",
                  text.substr(0, 80), ": '", item.substr(0, 40), "' is not a finite number");
    e.params.push_back(value);
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  const EffectKindInfo& info = Info(e.kind);
  DIFFDYN_CHECK(e.params.size() == info.params.size(), option, " ", text.substr(0, 80), ": ", info.name,
                " takes ", info.params.size(), " value(s), got ", e.params.size());
  return e;
}

}  // namespace diffdyn
