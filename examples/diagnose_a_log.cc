// What does my simulation get wrong? Diagnosing a measured log against a nominal model.
//
// The "measured" log here is the pendulum task simulated with an effect the nominal
// model lacks: Coulomb friction of 0.15 N m on the joint, tau_f = -0.15 sign(qd)
// (model_conventions.md). DiagnoseFiles, the library call behind `diffdyn diagnose`,
// is given only the log and the nominal model (`pendulum` with the task's
// parameters). It estimates the sensor noise, smooths, forms the torque residual
// tau - tau_nominal(q, qd, qdd), selects effects from the library one at a time by a
// likelihood-ratio test (Holm-corrected), refits them jointly within their admissible
// ranges, and scores the extended model on held-out time. It writes report.md,
// extended_model.json and residuals.csv, and returns the `diagnose --json` summary.
//
// Usage: example_diagnose_a_log [--quick] [--out DIR]
//   (exit 1 unless exactly the hidden effect is named, within 15 % of its value)
#include <cmath>
#include <cstring>
#include <filesystem>
#include <string>

#include <fmt/core.h>

#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/joint_collect.h"
#include "diffdyn/solvers/model_diagnosis.h"

int main(int argc, char** argv) {
  using namespace diffdyn;
  bool quick = false;
  std::filesystem::path out = std::filesystem::temp_directory_path() / "diffdyn_example_diagnose";
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--quick") == 0) quick = true;
    if (std::strcmp(argv[i], "--out") == 0 && i + 1 < argc) out = argv[++i];
  }
  std::filesystem::create_directories(out);

  // The log: the task's pendulum with a hidden Coulomb friction.
  const double hidden = 0.15;
  JointTask plant = JointTaskByName("pendulum");
  const std::vector<std::string> nominal_params = plant.params;
  plant.effects.push_back(ParseEffectSpec(fmt::format("coulomb:1={}", hidden), "example"));
  const std::string log = (out / "pendulum_log.csv").string();
  WriteDataset(log, CollectJointSpace(plant, {.trajectories = quick ? 10 : 40, .seed = 7, .threads = 2}));

  // The diagnosis: the nominal model and the log, nothing else.
  DiagnoseRequest request{.model = plant.model, .measured = log, .out = (out / "diagnosis").string()};
  request.params = nominal_params;
  const nlohmann::json summary = DiagnoseFiles(request);

  fmt::print("nominal RMSE {:.4f} N m -> extended {:.4f} N m; held-out SSE removed {:.3f}\n",
             summary["nominal_rmse"][0].get<double>(), summary["extended_rmse"][0].get<double>(),
             summary["heldout_sse_removed"].get<double>());
  bool found = false;
  int named = 0;
  for (const auto& effect : summary["named_effects"]) {
    ++named;
    const std::string kind = effect["kind"];
    const double value = effect["value"].is_number() ? effect["value"].get<double>() : NAN;
    fmt::print("named: {} on joint {} = {:.4f} +- {:.4f}\n", kind, effect["joint"].get<int>(), value,
               effect["stderr"].is_number() ? effect["stderr"].get<double>() : NAN);
    found = found || (kind == "coulomb" && std::abs(value - hidden) <= 0.15 * hidden);
  }
  fmt::print("hidden: coulomb on joint 1 = {}; report: {}\n", hidden, summary["report"].get<std::string>());
  if (!found || named != 1) {
    fmt::print(stderr, "error: expected exactly the hidden coulomb friction, {} effect(s) named\n", named);
    return 1;
  }
  return 0;
}
