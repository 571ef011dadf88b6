// Pieces of `diffdyn push` shared with `diffdyn demo`: loading the model to push
// with, writing the trials CSV and drawing a trial's top view.
#pragma once

#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include "diffdyn/models/transition_model.h"
#include "diffdyn/physics/pushing/env.h"
#include "diffdyn/solvers/pushing/trials.h"

namespace diffdyn::cli {

/// A pushing model file, or `oracle` (the ODE world `world` as the model).
/// Throws diffdyn::Error naming --model for a missing or bad file.
std::unique_ptr<TransitionModel> LoadPushModel(const std::string& name, const PushingConfig& world,
                                               std::optional<Precision> precision = std::nullopt);

/// trial,step,x,y,theta,push_location,push_angle,push_length,outcome,pred_x,pred_y,
/// pred_theta: one row per pose, the last pose of a trial without an action; pred_*
/// is the model's prediction of this pose from the previous row's pose and action
/// (empty on step 0). Written atomically.
void WritePushTrialsCsv(const std::filesystem::path& path, const PushTrialsSummary& summary);

/// The trial to picture: the first successful one, else the first.
int PictureTrial(const PushTrialsSummary& summary);

/// Draws trial `trial` of `csv` (scripts/plots/push_top_view.py) to `png`; false if drawing failed.
bool PlotPushTopView(const std::filesystem::path& csv, int trial, const PushTrialsSummary& summary,
                     bool obstacle, double tolerance, const std::filesystem::path& png);

/// Number of trials per outcome.
std::map<std::string, int> OutcomeCounts(const PushTrialsSummary& summary);

}  // namespace diffdyn::cli
