#include "diffdyn/solvers/pushing/world_file.h"

#include <cmath>
#include <utility>
#include <vector>

#include "diffdyn/models/model_file.h"
#include "diffdyn/physics/pushing/system.h"

namespace diffdyn {
namespace {

// The PushingConfig fields a world file carries, by name.
std::vector<std::pair<const char*, double PushingConfig::*>> Fields() {
  return {{"block_mass", &PushingConfig::block_mass},
          {"block_inertia", &PushingConfig::block_inertia},
          {"block_size", &PushingConfig::block_size},
          {"block_height", &PushingConfig::block_height},
          {"block_table_friction", &PushingConfig::block_table_friction},
          {"tip_block_friction", &PushingConfig::tip_block_friction},
          {"tool_length", &PushingConfig::tool_length},
          {"tip_radius", &PushingConfig::tip_radius},
          {"tip_length", &PushingConfig::tip_length},
          {"tip_pad_x", &PushingConfig::tip_pad_x},
          {"tip_pad_y", &PushingConfig::tip_pad_y},
          {"push_height", &PushingConfig::push_height},
          {"time_step", &PushingConfig::time_step},
          {"push_speed", &PushingConfig::push_speed},
          {"push_acceleration", &PushingConfig::push_acceleration},
          {"approach_speed", &PushingConfig::approach_speed},
          {"approach_acceleration", &PushingConfig::approach_acceleration},
          {"settle_time", &PushingConfig::settle_time},
          {"ik_tolerance", &PushingConfig::ik_tolerance}};
}

}  // namespace

nlohmann::json PusherWorldToJson(const PushingConfig& config) {
  nlohmann::json j = nlohmann::json::object();
  for (const auto& [name, field] : Fields()) j[name] = config.*field;
  return j;
}

PushingConfig PusherWorldFromJson(const nlohmann::json& architecture, const PushingConfig& base) {
  DIFFDYN_CHECK(architecture.is_object(), "the pusher world is not a JSON object");
  PushingConfig config = base;
  const auto fields = Fields();
  for (const auto& [key, value] : architecture.items()) {
    double PushingConfig::*target = nullptr;
    for (const auto& [name, field] : fields) {
      if (key == name) target = field;
    }
    DIFFDYN_CHECK(target != nullptr, "unknown pusher world parameter '", key, "'");
    DIFFDYN_CHECK(value.is_number() && std::isfinite(value.get<double>()),
                  "pusher world parameter '", key, "' is not a finite number (", value.dump(), ")");
    config.*target = value.get<double>();
  }
  PushingEnv check(config);  // throws for a world the engine refuses
  return config;
}

void RegisterPusherWorldKind() {
  RegisterModelKind("oracle", [](const nlohmann::json& architecture) -> Eigen::Index {
    PusherWorldFromJson(architecture, PushingConfig{});
    return 0;
  });
}

void SavePusherWorld(const std::string& path, const PushingConfig& config,
                     const nlohmann::json& provenance, const nlohmann::json& metrics) {
  RegisterPusherWorldKind();
  ModelFile file;
  file.kind = "oracle";
  file.architecture = PusherWorldToJson(config);
  file.provenance = provenance;
  file.metrics = metrics;
  file.system = SystemToJson(PushingSystem());
  SaveModelFile(path, file);
}

PushingConfig LoadPusherWorld(const std::string& path, const PushingConfig& base,
                              const std::string& option) {
  RegisterPusherWorldKind();
  const std::string prefix = option.empty() ? "" : option + " ";
  try {
    const ModelFile file = LoadModelFile(path);
    DIFFDYN_CHECK(file.kind == "oracle", path, ": a model of kind '", file.kind,
                  "' is not a pusher world (kind oracle, as diagnose --model pushing writes)");
    return PusherWorldFromJson(file.architecture, base);
  } catch (const NumericalError&) {
    throw;
  } catch (const Error& e) {
    const std::string what = e.what();
    throw Error(prefix + (what.rfind(path, 0) == 0 ? what : StrCat(path, ": ", what)));
  }
}

}  // namespace diffdyn
