// Pusher world files: the physical parameters of a PushingConfig saved as a model
// file (models/model_file.h) of kind "oracle", so that a calibrated pusher is one
// file every command takes:
//
//   diffdyn collect --world calibrated_pusher.json ...        // data from that world
//   diffdyn push --world calibrated_pusher.json --model oracle  // MPPI acting in it
//   diffdyn eval --model calibrated_pusher.json --data d.csv    // the world as a model
//
// The file's `architecture` object holds the parameters by PushingConfig field name
// (block_mass, block_inertia, block_table_friction, tip_block_friction, tip_radius,
// tip_pad_x, tip_pad_y, push_speed, ...). The task's obstacle and goal are not
// part of it: loading lays the file's parameters over a base world.
//
//   SavePusherWorld("w.json", config, {{"source", "diagnose"}}, {});
//   PushingConfig world = LoadPusherWorld("w.json", PushingConfig{});
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "diffdyn/physics/pushing/env.h"

namespace diffdyn {

/// Registers the model kind "oracle" (a pusher world file); idempotent.
void RegisterPusherWorldKind();

/// The parameters of `config` as the file's architecture object.
nlohmann::json PusherWorldToJson(const PushingConfig& config);

/// `base` with the parameters of `architecture` laid over it. Throws diffdyn::Error
/// (message without a file name) for an unknown key, a value that is not a finite
/// number, or a world PushingEnv refuses.
PushingConfig PusherWorldFromJson(const nlohmann::json& architecture, const PushingConfig& base);

/// Writes `config` to `path` (atomically) as a model file of kind "oracle".
void SavePusherWorld(const std::string& path, const PushingConfig& config,
                     const nlohmann::json& provenance, const nlohmann::json& metrics);

/// Reads the pusher world file `path` over `base`; throws diffdyn::Error with one
/// line naming the file (after `option`, e.g. "--world", when given) for a missing
/// or malformed file or one of another kind.
PushingConfig LoadPusherWorld(const std::string& path, const PushingConfig& base,
                              const std::string& option = "");

}  // namespace diffdyn
