// Model files: one JSON format and one loader for every kind of model.
//
// A model file is a JSON object
//
//   {
//     "format": "diffdyn-model",
//     "version": 1,
//     "kind": "mlp",                       // or abs-nn, res-node, extended-physics, ...
//     "architecture": { ... },             // kind-specific, see below for "mlp"
//     "parameters": {"count": P, "values": [theta_0, ..., theta_{P-1}]},
//     "provenance": { ... },               // who made it, from what data, seed, ...
//     "metrics": { ... },                  // losses and errors measured on it
//     "system": { ... },                   // optional: the states and actions
//                                          // (system_description.h)
//     "precision": "f64"                   // or "f32": what the batched paths compute
//   }                                      // in (precision.h); absent reads as "f64"
//
// Parameters are the model's ONE flat vector theta, written with the shortest
// decimal form that reads back to the same double (bit-exact round trip).
//
// Kinds register a validator that checks their architecture object and returns
// the parameter count it implies; LoadModelFile checks everything generic
// (format, version, kind known, count == values, every value a finite number,
// count == what the architecture implies) and throws diffdyn::Error with one
// line "<file>: <what is wrong>". Later kinds add themselves with
// RegisterModelKind and reuse MlpArchitectureToJson / FromJson for their nets.
//
// The "mlp" architecture:
//
//   {"sizes": [n_0, ..., n_L],
//    "activations": [{"name": "softplus", "param": 1.0}, ...]}   // L - 1 entries
//
// Files are written atomically (temporary file + rename, io.h).
//
//   SaveMlp("net.json", net, {{"seed", 42}}, {{"val_loss", 1e-4}});
//   Mlp<double> back = LoadMlp("net.json");
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/io.h"
#include "diffdyn/models/mlp.h"
#include "diffdyn/models/precision.h"
#include "diffdyn/models/system_description.h"

namespace diffdyn {

/// The model-file format version this build writes and reads.
inline constexpr int kModelFileVersion = 1;

/// The contents of a model file (see model_file.h for the JSON layout).
struct ModelFile {
  /// "mlp", "abs-nn", "res-node", ... (must be registered).
  std::string kind;
  /// Kind-specific architecture object.
  nlohmann::json architecture = nlohmann::json::object();
  /// The flat parameter vector theta (all finite).
  Eigen::VectorXd parameters;
  /// Where the model came from (data, seed, command, ...).
  nlohmann::json provenance = nlohmann::json::object();
  /// Measured errors and losses.
  nlohmann::json metrics = nlohmann::json::object();
  /// The system's description (SystemToJson), or null where the kind has none.
  nlohmann::json system = nullptr;
  /// The precision the model computes in (parameters are written in double).
  Precision precision = Precision::kF64;
};

/// Checks a kind's architecture object and returns its parameter count; throws
/// diffdyn::Error (message without the file name) when the architecture is bad.
using ModelKindValidator = std::function<Eigen::Index(const nlohmann::json& architecture)>;

/// {"sizes": [...], "activations": [{"name", "param"}, ...]} of an MLP.
inline nlohmann::json MlpArchitectureToJson(const MlpArchitecture& arch) {
  nlohmann::json acts = nlohmann::json::array();
  for (const Activation& a : arch.activations) {
    acts.push_back({{"name", ActivationName(a.kind)}, {"param", a.param}});
  }
  return {{"sizes", arch.sizes}, {"activations", acts}};
}

/// Inverse of MlpArchitectureToJson; validates types, sizes and names.
inline MlpArchitecture MlpArchitectureFromJson(const nlohmann::json& j) {
  DIFFDYN_CHECK(j.is_object(), "architecture must be an object");
  DIFFDYN_CHECK(j.contains("sizes") && j["sizes"].is_array(), "architecture: 'sizes' must be a list");
  DIFFDYN_CHECK(j.contains("activations") && j["activations"].is_array(),
                "architecture: 'activations' must be a list");
  MlpArchitecture arch;
  for (const auto& s : j["sizes"]) {
    DIFFDYN_CHECK(s.is_number_integer() && s.get<long long>() > 0 && s.get<long long>() < (1 << 24),
                  "architecture: sizes must be positive integers, got ", s.dump());
    arch.sizes.push_back(s.get<int>());
  }
  for (const auto& a : j["activations"]) {
    DIFFDYN_CHECK(a.is_object() && a.contains("name") && a["name"].is_string() &&
                      a.contains("param") && a["param"].is_number(),
                  "architecture: each activation needs a 'name' and a numeric 'param', got ",
                  a.dump());
    arch.activations.push_back(MakeActivation(a["name"].get<std::string>(), a["param"].get<double>()));
  }
  arch.Validate();
  return arch;
}

namespace internal {

// The registry of model kinds; "mlp" is always there.
inline std::map<std::string, ModelKindValidator>& ModelKinds(std::unique_lock<std::mutex>* lock) {
  static std::mutex mutex;
  static std::map<std::string, ModelKindValidator> kinds = {
      {"mlp", [](const nlohmann::json& j) { return MlpArchitectureFromJson(j).num_parameters(); }}};
  *lock = std::unique_lock<std::mutex>(mutex);
  return kinds;
}

// Removes line breaks so that every error is one line.
inline std::string OneLine(std::string s) {
  for (char& c : s) {
    if (c == '\n' || c == '\r') c = ' ';
  }
  return s;
}

}  // namespace internal

/// Registers (or replaces) the validator of model kind `kind`.
inline void RegisterModelKind(const std::string& kind, ModelKindValidator validator) {
  std::unique_lock<std::mutex> lock;
  internal::ModelKinds(&lock)[kind] = std::move(validator);
}

/// Whether `kind` has a registered validator.
inline bool IsModelKindRegistered(const std::string& kind) {
  std::unique_lock<std::mutex> lock;
  return internal::ModelKinds(&lock).count(kind) > 0;
}

/// Validates a parsed model file object and returns its contents; errors are
/// one line prefixed by `name` (the file path).
inline ModelFile ModelFileFromJson(const nlohmann::json& j, const std::string& name) {
  auto fail = [&](const std::string& what) {
    throw Error(internal::OneLine(StrCat(name, ": ", what)));
  };
  if (!j.is_object()) fail("not a diffdyn model file (top level is not a JSON object)");
  if (!j.contains("format") || j["format"] != "diffdyn-model") {
    fail("not a diffdyn model file (missing \"format\": \"diffdyn-model\")");
  }
  if (!j.contains("version") || !j["version"].is_number_integer()) fail("missing integer 'version'");
  if (j["version"].get<long long>() != kModelFileVersion) {
    fail(StrCat("unsupported model-file version ", j["version"].dump(), " (this build reads version ",
                kModelFileVersion, ")"));
  }
  if (!j.contains("kind") || !j["kind"].is_string()) fail("missing string 'kind'");
  ModelFile file;
  file.kind = j["kind"].get<std::string>();
  ModelKindValidator validator;
  {
    std::unique_lock<std::mutex> lock;
    const auto& kinds = internal::ModelKinds(&lock);
    const auto it = kinds.find(file.kind);
    if (it == kinds.end()) fail(StrCat("unknown model kind '", file.kind, "'"));
    validator = it->second;
  }
  for (const char* key : {"architecture", "parameters", "provenance", "metrics"}) {
    if (!j.contains(key) || !j[key].is_object()) fail(StrCat("missing object '", key, "'"));
  }
  file.architecture = j["architecture"];
  file.provenance = j["provenance"];
  file.metrics = j["metrics"];
  if (j.contains("system")) {
    try {
      SystemFromJson(j["system"]);
    } catch (const Error& e) {
      fail(e.what());
    }
    file.system = j["system"];
  }
  if (j.contains("precision")) {
    if (!j["precision"].is_string()) fail("'precision' must be \"f32\" or \"f64\"");
    try {
      file.precision = ParsePrecision(j["precision"].get<std::string>(), "precision");
    } catch (const Error& e) {
      fail(e.what());
    }
  }
  // Parameters: count, then every value a finite number.
  const nlohmann::json& p = j["parameters"];
  if (!p.contains("count") || !p["count"].is_number_integer() || p["count"].get<long long>() < 0) {
    fail("parameters: missing non-negative integer 'count'");
  }
  if (!p.contains("values") || !p["values"].is_array()) fail("parameters: missing list 'values'");
  const long long count = p["count"].get<long long>();
  const nlohmann::json& values = p["values"];
  if (static_cast<long long>(values.size()) != count) {
    fail(StrCat("parameters: 'count' says ", count, " but there are ", values.size(), " values"));
  }
  file.parameters.resize(count);
  for (long long i = 0; i < count; ++i) {
    const nlohmann::json& v = values[i];
    if (!v.is_number() || !std::isfinite(v.get<double>())) {
      fail(StrCat("parameter ", i, " is not a finite number (", v.dump(), ")"));
    }
    file.parameters[i] = v.get<double>();
  }
  // Kind-specific architecture, and the count it implies.
  Eigen::Index expected = 0;
  try {
    expected = validator(file.architecture);
  } catch (const Error& e) {
    fail(StrCat("kind '", file.kind, "': ", e.what()));
  }
  if (expected != count) {
    fail(StrCat("kind '", file.kind, "' with this architecture has ", expected, " parameters, the file has ",
                count));
  }
  return file;
}

/// The JSON object of `file` (validated like LoadModelFile; errors prefixed by `name`).
inline nlohmann::json ModelFileToJson(const ModelFile& file, const std::string& name) {
  nlohmann::json values = nlohmann::json::array();
  for (Eigen::Index i = 0; i < file.parameters.size(); ++i) {
    DIFFDYN_CHECK(std::isfinite(file.parameters[i]), name, ": parameter ", i,
                  " is not finite; refusing to write the model");
    values.push_back(file.parameters[i]);
  }
  nlohmann::json j = {{"format", "diffdyn-model"},
                      {"version", kModelFileVersion},
                      {"kind", file.kind},
                      {"architecture", file.architecture},
                      {"parameters", {{"count", file.parameters.size()}, {"values", values}}},
                      {"provenance", file.provenance.is_null() ? nlohmann::json::object() : file.provenance},
                      {"metrics", file.metrics.is_null() ? nlohmann::json::object() : file.metrics}};
  if (!file.system.is_null()) j["system"] = file.system;
  j["precision"] = PrecisionName(file.precision);
  ModelFileFromJson(j, name);  // the same checks as loading
  return j;
}

/// Writes `file` to `path` atomically; throws diffdyn::Error (one line, naming
/// the path) if the contents are invalid or the file cannot be written.
inline void SaveModelFile(const std::filesystem::path& path, const ModelFile& file) {
  const nlohmann::json j = ModelFileToJson(file, path.string());
  WriteFileAtomically(path, [&](std::ostream& out) { out << j.dump(1) << '\n'; });
}

/// Reads and validates the model file at `path`; throws diffdyn::Error with one
/// line "<path>: <problem>" for a missing, truncated, malformed, wrong-version,
/// wrong-size or non-finite file.
inline ModelFile LoadModelFile(const std::filesystem::path& path) {
  const std::string name = path.string();
  return ModelFileFromJson(ReadJsonFile(path), name);
}

/// Saves an MLP as kind "mlp" with the given provenance and metrics objects.
inline void SaveMlp(const std::filesystem::path& path, const Mlp<double>& net,
                    const nlohmann::json& provenance = nlohmann::json::object(),
                    const nlohmann::json& metrics = nlohmann::json::object()) {
  SaveModelFile(path, ModelFile{"mlp", MlpArchitectureToJson(net.architecture()), net.parameters(),
                                provenance, metrics});
}

/// Loads a model file of kind "mlp" (throws diffdyn::Error naming the path
/// for any other kind or a bad file).
inline Mlp<double> LoadMlp(const std::filesystem::path& path, ModelFile* contents = nullptr) {
  ModelFile file = LoadModelFile(path);
  DIFFDYN_CHECK(file.kind == "mlp", path.string(), ": model kind is '", file.kind, "', expected 'mlp'");
  Mlp<double> net(MlpArchitectureFromJson(file.architecture), file.parameters);
  if (contents) *contents = std::move(file);
  return net;
}

}  // namespace diffdyn
