#include "diffdyn/solvers/pushing/world_file.h"

#include <cmath>
#include <vector>

#include "diffdyn/models/model_file.h"
#include "diffdyn/physics/pushing/system.h"

namespace diffdyn {
namespace {

// A PushingConfig field a world file carries: its name, and the range a file may
// give it (a world the engine builds and steps in reasonable time).
struct Field {
  const char* name;
  double PushingConfig::*member;
  double lo, hi;
};

std::vector<Field> Fields() {
  return {{"block_mass", &PushingConfig::block_mass, 1e-3, 1e3},
          {"block_inertia", &PushingConfig::block_inertia, 0, 1e3},
          {"block_size", &PushingConfig::block_size, 0.01, 0.3},
          {"block_height", &PushingConfig::block_height, 0.01, 0.3},
          {"block_table_friction", &PushingConfig::block_table_friction, 0, 10},
          {"tip_block_friction", &PushingConfig::tip_block_friction, 0, 10},
          {"tool_length", &PushingConfig::tool_length, 0, 0.3},
          {"tip_radius", &PushingConfig::tip_radius, 1e-4, 0.05},
          {"tip_length", &PushingConfig::tip_length, 0, 0.2},
          {"tip_pad_x", &PushingConfig::tip_pad_x, 0, 0.05},
          {"tip_pad_y", &PushingConfig::tip_pad_y, 0, 0.05},
          {"push_height", &PushingConfig::push_height, -0.02, 0.1},
          {"time_step", &PushingConfig::time_step, 1e-4, 0.01},
          {"push_speed", &PushingConfig::push_speed, 1e-3, 2},
          {"push_acceleration", &PushingConfig::push_acceleration, 1e-2, 100},
          {"approach_speed", &PushingConfig::approach_speed, 1e-3, 2},
          {"approach_acceleration", &PushingConfig::approach_acceleration, 1e-2, 100},
          {"settle_time", &PushingConfig::settle_time, 0, 10},
          {"ik_tolerance", &PushingConfig::ik_tolerance, 1e-6, 0.05}};
}

}  // namespace

nlohmann::json PusherWorldToJson(const PushingConfig& config) {
  nlohmann::json j = nlohmann::json::object();
  for (const Field& f : Fields()) j[f.name] = config.*f.member;
  return j;
}

PushingConfig PusherWorldFromJson(const nlohmann::json& architecture, const PushingConfig& base) {
  DIFFDYN_CHECK(architecture.is_object(), "the pusher world is not a JSON object");
  PushingConfig config = base;
  const auto fields = Fields();
  for (const auto& [key, value] : architecture.items()) {
    const Field* target = nullptr;
    for (const Field& f : fields) {
      if (key == f.name) target = &f;
    }
    DIFFDYN_CHECK(target != nullptr, "unknown pusher world parameter '", key, "'");
    DIFFDYN_CHECK(value.is_number() && std::isfinite(value.get<double>()),
                  "pusher world parameter '", key, "' is not a finite number (", value.dump(), ")");
    const double v = value.get<double>();
    DIFFDYN_CHECK(v >= target->lo && v <= target->hi, "pusher world parameter '", key, "' = ", v,
                  " is outside [", target->lo, ", ", target->hi, "]");
    config.*target->member = v;
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
