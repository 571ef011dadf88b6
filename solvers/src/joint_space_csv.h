// The joint-space schemas of dataset_io.h (the joint-space CSV and the real
// datasets of shared/data/), used by dataset_io.cc; not installed.
#pragma once

#include <string>

#include "diffdyn/solvers/dataset_io.h"

namespace diffdyn {

/// Reads a joint-space CSV or a real-data folder or file (dataset_io.h) into a
/// dataset of the joint-space description under `layout`.
Dataset ReadJointSpace(const std::string& path, const JointLayout& layout);

/// Writes a joint-space dataset (states [q; qd], the torque of every joint in the
/// channel "tau") as the joint-space CSV, atomically.
void WriteJointSpaceCsv(const std::string& path, const Dataset& data);

}  // namespace diffdyn
