// Extended physics models as model files (kind "extended-physics").
//
// An extended model is a nominal analytic model plus named effects and an
// optional learned residual network (effects.h). Its model file follows the
// one diffdyn-model JSON contract (models/model_file.h):
//
//   "architecture": {
//     "model": "panda",                               // --model name
//     "model_params": {"g": 9.80665, ...},            // nominal parameters
//     "effects": [{"kind": "coulomb", "joint": 2,
//                  "params": ["F_c"], "units": ["N m"], "stderr": [0.01]}, ...],
//     "residual": null | {"inputs": 3n, "hidden": H, "outputs": n}
//   }
//   "parameters": theta = (effect parameters in list order,
//                          then in_mean, in_scale, W1, b1, W2, b2 of the network)
//
// The loader validates names, joints and counts and rebuilds the ExtendedModel.
//
//   SaveExtendedModel("out/extended_model.json", ext, provenance, metrics);
//   ExtendedModel back = LoadExtendedModel("out/extended_model.json");
#pragma once

#include <filesystem>

#include <nlohmann/json.hpp>

#include "diffdyn/physics/effects.h"

namespace diffdyn {

/// Registers the "extended-physics" kind with the model-file loader (idempotent).
void RegisterExtendedPhysicsKind();

/// Writes `model` as an "extended-physics" model file, atomically.
void SaveExtendedModel(const std::filesystem::path& path, const ExtendedModel& model,
                       const nlohmann::json& provenance = nlohmann::json::object(),
                       const nlohmann::json& metrics = nlohmann::json::object());

/// Reads an "extended-physics" model file; throws diffdyn::Error naming the path.
ExtendedModel LoadExtendedModel(const std::filesystem::path& path);

}  // namespace diffdyn
