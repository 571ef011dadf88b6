#include "joint_layout_options.h"

#include <charconv>
#include <string_view>
#include <vector>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn::cli {
namespace {

// "1,3" -> {1, 3}; throws naming `option` for anything but positive integers.
std::vector<int> ParseJointList(const std::string& text, const char* option) {
  std::vector<int> joints;
  std::string_view rest(text);
  while (!rest.empty()) {
    const std::size_t comma = rest.find(',');
    const std::string_view item = rest.substr(0, comma);
    int joint = 0;
    const auto r = std::from_chars(item.data(), item.data() + item.size(), joint);
    DIFFDYN_CHECK(r.ec == std::errc() && r.ptr == item.data() + item.size() && joint >= 1, option,
                  ": '", text.substr(0, 60), "' is not a list of joint numbers (1-based, comma-separated)");
    joints.push_back(joint);
    if (comma == std::string_view::npos) break;
    rest.remove_prefix(comma + 1);
    DIFFDYN_CHECK(!rest.empty(), option, ": '", text.substr(0, 60), "' ends with a comma");
  }
  return joints;
}

}  // namespace

void AddJointLayoutOptions(CLI::App* command, JointLayoutOptions& options) {
  command->add_option("--actuated", options.actuated,
                      "Joint-space data: joints whose torque is an action: auto (those whose torque "
                      "is not zero throughout), all, or a list such as 1,2")
      ->capture_default_str();
  command->add_option("--prismatic", options.prismatic,
                      "Joint-space data: joints that are not angles (not wrapped, no sin/cos), e.g. 1");
  command
      ->add_option(
          "--angle-features", options.angle_features,
          "Joint-space data: learned models see angles as sincos (sin q, cos q) or raw (q); "
          "not given: sincos, but raw for res-node (a field periodic in q cannot carry q "
          "to q_{t+1} - q_t)")
      ->check(CLI::IsMember({"sincos", "raw"}))
      ->capture_default_str();
}

JointLayout ResolveJointLayout(const JointLayoutOptions& options) {
  JointLayout layout;
  if (options.actuated == "all") {
    layout.all_actuated = true;
  } else if (options.actuated != "auto") {
    layout.actuated = ParseJointList(options.actuated, "--actuated");
  }
  layout.angle_features = options.angle_features == "raw" ? AngleFeatures::kRaw : AngleFeatures::kSinCos;
  if (!options.prismatic.empty()) layout.prismatic = ParseJointList(options.prismatic, "--prismatic");
  return layout;
}

}  // namespace diffdyn::cli
