// Command-line options that say how a joint-space dataset maps to states and
// actions (solvers/dataset_io.h, JointLayout):
//
//   --actuated auto|all|LIST   joints whose torque is an action (auto: the ones
//                              whose torque is not zero throughout the data)
//   --prismatic LIST           joints that are not angles (e.g. a cart)
//   --angle-features sincos|raw  how learned models see the angles
//
// LIST is 1-based joint numbers separated by commas ("1" or "1,3").
#pragma once

#include <string>

#include <CLI/CLI.hpp>

#include "diffdyn/solvers/dataset_io.h"

namespace diffdyn::cli {

/// The text of the two options.
struct JointLayoutOptions {
  std::string actuated = "auto";
  std::string prismatic;
  std::string angle_features = "sincos";
};

/// Adds --actuated, --prismatic and --angle-features to `command`.
void AddJointLayoutOptions(CLI::App* command, JointLayoutOptions& options);

/// The layout the options name; throws diffdyn::Error naming the option for a bad list.
JointLayout ResolveJointLayout(const JointLayoutOptions& options);

}  // namespace diffdyn::cli
