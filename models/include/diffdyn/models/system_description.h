// What a state and an action are: the description every dynamics model, dataset
// and controller shares, whatever the robot.
//
// A system has a state x of n components and an action u of m components, each
// with a name. Some state components are angles: they are compared on the circle
// (differences wrapped to (-pi, pi]) and, when `angle_features` is kSinCos, a
// learned model sees them as the pair (sin x_i, cos x_i) instead of x_i, so that
// its prediction is periodic in the angle. Actions may be bounded (empty bounds:
// unbounded). The state metric weighs the squared error of each component
// (loss_weights, default 1) and wraps angle differences unless the system says
// otherwise (state_loss.h). Generic code reads these fields and never the name.
//
//   SystemDescription pendulum{.name = "pendulum", .state_names = {"q1", "qd1"},
//                              .action_names = {"tau1"}, .angles = {0},
//                              .angle_features = AngleFeatures::kSinCos};
//   pendulum.Validate();                         // n = 2, m = 1
//   pendulum.feature_size();                     // 4: sin q, cos q, qd, tau
//   nlohmann::json j = SystemToJson(pendulum);   // the "system" of a model file
#pragma once

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/json_io.h"

namespace diffdyn {

/// a wrapped to (-pi, pi].
inline double WrapAngle(double a) {
  double w = std::remainder(a, 2.0 * std::numbers::pi);
  if (w <= -std::numbers::pi) w += 2.0 * std::numbers::pi;
  return w;
}

/// How a learned model sees the angle components of its input.
enum class AngleFeatures {
  kRaw,     ///< as the number itself (the NeuralODE-Panda paper's pushing models)
  kSinCos,  ///< as (sin x_i, cos x_i): periodic in the angle
};

/// Sizes, names, angle components and action bounds of a system (see the file comment).
struct SystemDescription {
  /// A label for reports ("pushing", "pendulum", ...); never tested by generic code.
  std::string name = "unnamed";
  /// n names of the state components and m of the action components.
  std::vector<std::string> state_names;
  std::vector<std::string> action_names;
  /// Indices (0-based, increasing) of the state components that are angles.
  std::vector<int> angles;
  /// How learned models encode the angles of their input.
  AngleFeatures angle_features = AngleFeatures::kRaw;
  /// Action bounds (m entries each), or empty for unbounded.
  Eigen::VectorXd action_low, action_high;
  /// Weights w_i of the state metric sum_i w_i d_i^2 (n entries, > 0), or empty for all 1.
  Eigen::VectorXd loss_weights;
  /// Whether the metric wraps the differences of angle components to (-pi, pi].
  bool loss_wraps_angles = true;

  /// n, the size of the state.
  int state_size() const { return static_cast<int>(state_names.size()); }
  /// m, the size of the action.
  int action_size() const { return static_cast<int>(action_names.size()); }
  /// Whether state component i is an angle.
  bool is_angle(int i) const { return std::binary_search(angles.begin(), angles.end(), i); }
  /// w_i of the state metric (1 when loss_weights is empty).
  double loss_weight(int i) const { return loss_weights.size() > 0 ? loss_weights[i] : 1.0; }
  /// Whether learned models replace angle components by (sin, cos) pairs.
  bool encodes_angles() const {
    return angle_features == AngleFeatures::kSinCos && !angles.empty();
  }
  /// Size of a learned model's input features for [x; u]: n + m, plus one per
  /// encoded angle (each angle becomes two entries).
  int feature_size() const {
    return state_size() + action_size() + (encodes_angles() ? static_cast<int>(angles.size()) : 0);
  }

  /// A system of n states "x1".."xn" and m actions "u1".."um", no angles, unbounded.
  static SystemDescription Unnamed(int n, int m) {
    SystemDescription s;
    for (int i = 0; i < n; ++i) s.state_names.push_back(StrCat("x", i + 1));
    for (int i = 0; i < m; ++i) s.action_names.push_back(StrCat("u", i + 1));
    return s;
  }

  /// Throws diffdyn::Error for n < 1, m < 0, an angle index out of range or not
  /// increasing, or bounds of the wrong size, non-finite or with low > high.
  void Validate() const {
    DIFFDYN_CHECK(state_size() >= 1, "system '", name, "': the state needs at least one component");
    for (std::size_t k = 0; k < angles.size(); ++k) {
      DIFFDYN_CHECK(angles[k] >= 0 && angles[k] < state_size(), "system '", name,
                    "': angle index ", angles[k], " is not a state component (n = ", state_size(), ")");
      DIFFDYN_CHECK(k == 0 || angles[k] > angles[k - 1], "system '", name,
                    "': angle indices must increase");
    }
    if (loss_weights.size() > 0) {
      DIFFDYN_CHECK(loss_weights.size() == state_size(), "system '", name, "': loss_weights need ",
                    state_size(), " entries, got ", loss_weights.size());
      for (int i = 0; i < state_size(); ++i) {
        DIFFDYN_CHECK(std::isfinite(loss_weights[i]) && loss_weights[i] > 0, "system '", name,
                      "': the loss weight of ", state_names[i], " must be positive and finite");
      }
    }
    const bool bounded = action_low.size() > 0 || action_high.size() > 0;
    if (!bounded) return;
    DIFFDYN_CHECK(action_low.size() == action_size() && action_high.size() == action_size(),
                  "system '", name, "': action bounds need ", action_size(), " entries each");
    for (int i = 0; i < action_size(); ++i) {
      DIFFDYN_CHECK(std::isfinite(action_low[i]) && std::isfinite(action_high[i]) &&
                        action_low[i] <= action_high[i],
                    "system '", name, "': bad bounds for action ", action_names[i]);
    }
  }

  /// Same sizes, names, angles, encoding and bounds (the label is ignored).
  bool SameLayout(const SystemDescription& o) const {
    return state_names == o.state_names && action_names == o.action_names &&
           angles == o.angles && angle_features == o.angle_features &&
           action_low == o.action_low && action_high == o.action_high &&
           loss_weights == o.loss_weights && loss_wraps_angles == o.loss_wraps_angles;
  }
};

/// "raw" or "sincos".
inline std::string AngleFeaturesName(AngleFeatures a) {
  return a == AngleFeatures::kSinCos ? "sincos" : "raw";
}

/// {"name", "state", "action", "angles", "angle_features"[, "action_low", "action_high"]
/// [, "loss_weights"][, "loss_wraps_angles"]} (the last two only when not the defaults).
inline nlohmann::json SystemToJson(const SystemDescription& s) {
  nlohmann::json j = {{"name", s.name},
                      {"state", s.state_names},
                      {"action", s.action_names},
                      {"angles", s.angles},
                      {"angle_features", AngleFeaturesName(s.angle_features)}};
  if (s.action_low.size() > 0) {
    j["action_low"] = std::vector<double>(s.action_low.data(), s.action_low.data() + s.action_low.size());
    j["action_high"] =
        std::vector<double>(s.action_high.data(), s.action_high.data() + s.action_high.size());
  }
  if (s.loss_weights.size() > 0) {
    j["loss_weights"] =
        std::vector<double>(s.loss_weights.data(), s.loss_weights.data() + s.loss_weights.size());
  }
  if (!s.loss_wraps_angles) j["loss_wraps_angles"] = false;
  return j;
}

/// Inverse of SystemToJson; throws diffdyn::Error (prefixed "system: ") for a
/// missing or mistyped field or an invalid description.
inline SystemDescription SystemFromJson(const nlohmann::json& j) {
  DIFFDYN_CHECK(j.is_object(), "system: must be an object");
  const auto strings = [&](const char* key) {
    DIFFDYN_CHECK(j.contains(key) && j[key].is_array(), "system: '", key, "' must be a list of names");
    std::vector<std::string> out;
    for (const auto& v : j[key]) {
      DIFFDYN_CHECK(v.is_string(), "system: '", key, "' must hold strings");
      out.push_back(v.get<std::string>());
    }
    return out;
  };
  const auto numbers = [&](const char* key) {
    DIFFDYN_CHECK(j[key].is_array(), "system: '", key, "' must be a list of numbers");
    Eigen::VectorXd out(static_cast<Eigen::Index>(j[key].size()));
    for (std::size_t i = 0; i < j[key].size(); ++i) {
      DIFFDYN_CHECK(j[key][i].is_number(), "system: '", key, "' must hold numbers");
      out[static_cast<Eigen::Index>(i)] = j[key][i].get<double>();
    }
    return out;
  };
  SystemDescription s;
  if (j.contains("name")) {
    DIFFDYN_CHECK(j["name"].is_string(), "system: 'name' must be a string");
    s.name = j["name"].get<std::string>();
  }
  s.state_names = strings("state");
  s.action_names = strings("action");
  DIFFDYN_CHECK(j.contains("angles") && j["angles"].is_array(), "system: 'angles' must be a list");
  for (const auto& v : j["angles"]) {
    s.angles.push_back(static_cast<int>(JsonInt(v, 0, 1 << 20, "system: each of 'angles'")));
  }
  DIFFDYN_CHECK(j.contains("angle_features") && j["angle_features"].is_string(),
                "system: 'angle_features' must be \"raw\" or \"sincos\"");
  const std::string enc = j["angle_features"].get<std::string>();
  DIFFDYN_CHECK(enc == "raw" || enc == "sincos", "system: 'angle_features' must be \"raw\" or \"sincos\", got '",
                enc.substr(0, 40), "'");
  s.angle_features = enc == "sincos" ? AngleFeatures::kSinCos : AngleFeatures::kRaw;
  if (j.contains("action_low") || j.contains("action_high")) {
    DIFFDYN_CHECK(j.contains("action_low") && j.contains("action_high"),
                  "system: 'action_low' and 'action_high' come together");
    s.action_low = numbers("action_low");
    s.action_high = numbers("action_high");
  }
  if (j.contains("loss_weights")) s.loss_weights = numbers("loss_weights");
  if (j.contains("loss_wraps_angles")) {
    DIFFDYN_CHECK(j["loss_wraps_angles"].is_boolean(), "system: 'loss_wraps_angles' must be true or false");
    s.loss_wraps_angles = j["loss_wraps_angles"].get<bool>();
  }
  s.Validate();
  return s;
}

}  // namespace diffdyn
