// DiagnosePusherFiles: `diffdyn diagnose --model pushing` (model_diagnosis.h).
#include <chrono>
#include <cmath>
#include <filesystem>
#include <numbers>
#include <tuple>
#include <sstream>

#include "diffdyn/autodiff_ode/str_printf.h"
#include "diffdyn/models/io.h"
#include "diffdyn/models/json_io.h"
#include "diffdyn/physics/pushing/csv.h"
#include "diffdyn/solvers/model_diagnosis.h"
#include "diffdyn/solvers/pushing/world_file.h"

namespace diffdyn {
namespace {

namespace fs = std::filesystem;

// The nominal world: the pusher's defaults without the obstacle (or a world file),
// then --params FILE (a world file or {name: value}), then --param name=value.
PushingConfig NominalWorld(const DiagnoseRequest& r) {
  PushingConfig base;
  base.obstacle = false;
  PushingConfig world = r.model == "pushing" ? base : LoadPusherWorld(r.model, base, "--model");
  if (!r.params_file.empty()) {
    const nlohmann::json j = ReadJsonFile(r.params_file);
    try {
      world = j.is_object() && j.contains("format") ? LoadPusherWorld(r.params_file, world)
                                                    : PusherWorldFromJson(j, world);
    } catch (const Error& e) {
      throw Error(StrCat("--params ", r.params_file, ": ", e.what()));
    }
  }
  nlohmann::json overrides = nlohmann::json::object();
  for (const std::string& p : r.params) {
    const auto eq = p.find('=');
    DIFFDYN_CHECK(eq != std::string::npos && eq > 0, "--param ", p, ": expected name=value");
    double value = 0;
    std::istringstream in(p.substr(eq + 1));
    DIFFDYN_CHECK(static_cast<bool>(in >> value) && in.eof() && std::isfinite(value), "--param ", p,
                  ": the value is not a finite number");
    overrides[p.substr(0, eq)] = value;
  }
  try {
    return PusherWorldFromJson(overrides, world);
  } catch (const Error& e) {
    throw Error(StrCat("--param: ", e.what()));
  }
}

// The calibrated world predicts the held-out pushes significantly better: the
// gain's t statistic over held-out trajectories above 3.
bool SignificantGain(const PusherCalibration& c) { return c.heldout_gain_t > 3; }

// A parameter is named when it moved by more than three standard errors and the
// gain is significant.
bool Named(const PusherParameterFit& p, const PusherCalibration& c) {
  return std::isfinite(p.standard_error) && std::abs(p.value - p.nominal) > 3 * p.standard_error &&
         SignificantGain(c);
}

nlohmann::json Vec(const Eigen::Vector3d& v) { return {v[0], v[1], v[2]}; }

// Held-out RMSE per channel in bins of one action entry: a Markdown table.
std::string BinnedTable(const PusherCalibration& c, int entry, const char* name, double lo,
                        double hi) {
  constexpr int kBins = 5;
  std::string table = StrPrintf(
      "| %s | n | x (mm) nominal → calibrated | y (mm) | θ (mrad) |\n|---|---|---|---|---|\n",
      name);
  for (int b = 0; b < kBins; ++b) {
    const double a = lo + (hi - lo) * b / kBins, z = lo + (hi - lo) * (b + 1) / kBins;
    Eigen::Vector3d nominal = Eigen::Vector3d::Zero(), calibrated = Eigen::Vector3d::Zero();
    int n = 0;
    for (const PusherReplay& r : c.heldout) {
      const double u = r.action[entry];
      if (u < a || (u >= z && b + 1 < kBins)) continue;
      nominal += (r.nominal - r.measured).cwiseAbs2();
      calibrated += (r.calibrated - r.measured).cwiseAbs2();
      ++n;
    }
    if (n == 0) continue;
    nominal = (nominal / n).cwiseSqrt() * 1000;
    calibrated = (calibrated / n).cwiseSqrt() * 1000;
    table +=
        StrPrintf("| %+.2f to %+.2f | %d | %.2f → %.2f | %.2f → %.2f | %.1f → %.1f |\n", a, z, n,
                  nominal[0], calibrated[0], nominal[1], calibrated[1], nominal[2], calibrated[2]);
  }
  return table;
}

std::string Report(const DiagnoseRequest& r, const PusherCalibration& c,
                   const nlohmann::json& summary) {
  std::string s = "# Pusher diagnosis: the ODE-engine pusher against measured pushes\n\n";
  const bool none = summary["no_significant_discrepancy"].get<bool>();
  s += StrPrintf(
      "Measured: `%s` (%d trajectories fitted, %d held out; the fit replays %d training "
      "transitions, "
      "seed %llu).\n\n",
      r.measured.c_str(), c.train_trajectories, c.heldout_trajectories, c.fit_transitions,
      static_cast<unsigned long long>(r.pipeline.seed));
  s += none ? StrPrintf(
                  "**Verdict: no significant discrepancy: no parameter moved by more than three "
                  "standard "
                  "errors with a significant held-out gain (gain t = %.2f, needs 3).**\n\n",
                  c.heldout_gain_t)
            : StrPrintf(
                  "**Verdict: the calibrated pusher removes %.1f %% of the held-out one-step pose "
                  "loss "
                  "(t = %.1f over held-out trajectories).**\n\n",
                  100 * summary["heldout_sse_removed"].get<double>(), c.heldout_gain_t);
  s += "## One-step error on held-out pushes\n\n| | pose loss | x RMSE (mm) | y RMSE (mm) | θ RMSE "
       "(mrad) |\n"
       "|---|---|---|---|---|\n";
  s += StrPrintf("| no motion (x_t+1 = x_t) | %.4g | | | |\n", c.heldout_loss_identity);
  for (const auto& [label, loss, rmse] :
       {std::tuple{"nominal", c.heldout_loss_nominal, c.heldout_rmse_nominal},
        std::tuple{"calibrated", c.heldout_loss_calibrated, c.heldout_rmse_calibrated}}) {
    s += StrPrintf("| %s | %.4g | %.2f | %.2f | %.1f |\n", label, loss, 1000 * rmse[0],
                   1000 * rmse[1], 1000 * rmse[2]);
  }
  s += StrPrintf(
      "\nPose loss = MSE(x) + MSE(y) + rg MSE(θ), rg = 0.0408 m (the seed's loss). Open-loop "
      "rollouts "
      "of the held-out trajectories from their first pose end %.1f mm (nominal) and %.1f mm "
      "(calibrated) from the measured final position, on average.\n\n",
      1000 * c.rollout_error_nominal, 1000 * c.rollout_error_calibrated);
  s += "### By push angle (rad)\n\n" +
       BinnedTable(c, 1, "push angle", -std::numbers::pi / 2, std::numbers::pi / 2) + "\n";
  s += "### By push location\n\n" + BinnedTable(c, 0, "push location", -1, 1) + "\n";
  s +=
      "## Parameters\n\nFitted by Levenberg-Marquardt over forward differences of the replays; "
      "standard errors "
      "s² (JᵀJ)⁻¹ treat the transitions as independent. *Alone*: the held-out pose loss of the "
      "nominal "
      "pusher with only that parameter calibrated.\n\n"
      "| parameter | meaning | nominal | calibrated ± s.e. | unit | held-out loss alone | named |\n"
      "|---|---|---|---|---|---|---|\n";
  for (const PusherParameterFit& p : c.parameters) {
    std::string meaning;
    for (const PusherParameterInfo& info : PusherParameters()) {
      if (info.name == p.name) meaning = info.meaning;
    }
    s += StrPrintf("| %s | %s | %.4g | %.4g ± %.2g | %s | %.4g | %s |\n", p.name.c_str(),
                   meaning.c_str(), p.nominal, p.value, p.standard_error, p.unit.c_str(),
                   p.heldout_loss_alone, Named(p, c) ? "yes" : "no");
  }
  s += StrPrintf(
      "\nFit subsample: pose loss %.4g at the nominal world, %.4g at the coarse search's best "
      "point "
      "(a pad starts as the square around the round tip), %.4g after %d Levenberg-Marquardt "
      "iterations; "
      "%d pushes simulated in all.\n\n",
      c.fit_loss_nominal, c.fit_loss_coarse, c.fit_loss_calibrated, c.iterations, c.replays);
  s += "## Files\n\n- `calibrated_pusher.json`: the calibrated world (`diffdyn collect --world`, "
       "`diffdyn push --world`, or `--model` wherever a model is taken).\n"
       "- `replays.csv`, `rollouts.csv`: the held-out replays and rollouts the tables and plots "
       "are drawn from.\n"
       "- `error_by_push.png`, `rollouts.png`: the plots.\n";
  return s;
}

void WriteReplays(const fs::path& path, const PusherCalibration& c) {
  WriteFileAtomically(path, [&](std::ostream& out) {
    out << "trajectory,step,x,y,theta,push_location,push_angle,push_length,measured_x,measured_y,"
           "measured_theta,"
           "nominal_x,nominal_y,nominal_theta,calibrated_x,calibrated_y,calibrated_theta\n";
    for (const PusherReplay& r : c.heldout) {
      out << r.trajectory << ',' << r.step;
      for (const Eigen::Vector3d* v :
           {&r.state, &r.action, &r.measured, &r.nominal, &r.calibrated}) {
        out << StrPrintf(",%.9g,%.9g,%.9g", (*v)[0], (*v)[1], (*v)[2]);
      }
      out << '\n';
    }
  });
}

void WriteRollouts(const fs::path& path, const PusherCalibration& c) {
  WriteFileAtomically(path, [&](std::ostream& out) {
    out << "rollout,step,measured_x,measured_y,measured_theta,nominal_x,nominal_y,nominal_theta,"
           "calibrated_x,"
           "calibrated_y,calibrated_theta\n";
    for (std::size_t k = 0; k < c.rollout_measured.size(); ++k) {
      for (Eigen::Index i = 0; i < c.rollout_measured[k].cols(); ++i) {
        out << k << ',' << i;
        for (const Eigen::Matrix3Xd* m :
             {&c.rollout_measured[k], &c.rollout_nominal[k], &c.rollout_calibrated[k]}) {
          out << StrPrintf(",%.9g,%.9g,%.9g", (*m)(0, i), (*m)(1, i), (*m)(2, i));
        }
        out << '\n';
      }
    }
  });
}

nlohmann::json Summary(const PusherCalibration& c, const fs::path& out, double seconds) {
  nlohmann::json named = nlohmann::json::array(), parameters = nlohmann::json::array();
  for (const PusherParameterFit& p : c.parameters) {
    const nlohmann::json error =
        std::isfinite(p.standard_error) ? nlohmann::json(p.standard_error) : nullptr;
    parameters.push_back({{"name", p.name},
                          {"unit", p.unit},
                          {"nominal", p.nominal},
                          {"value", p.value},
                          {"stderr", error},
                          {"heldout_loss_alone", p.heldout_loss_alone}});
    if (Named(p, c)) {
      named.push_back({{"kind", p.name},
                       {"joint", 0},
                       {"value", p.value},
                       {"unit", p.unit},
                       {"stderr", error}});
    }
  }
  const double removed = c.heldout_loss_nominal > 0
                             ? std::max(0.0, 1 - c.heldout_loss_calibrated / c.heldout_loss_nominal)
                             : 0.0;
  return {{"model", "pushing"},
          {"n_samples", c.heldout.size()},
          {"nominal_rmse", Vec(c.heldout_rmse_nominal)},
          {"extended_rmse", Vec(c.heldout_rmse_calibrated)},
          {"heldout_sse_removed", removed},
          {"no_significant_discrepancy", named.empty()},
          {"named_effects", named},
          {"parameters", parameters},
          {"nominal_loss", c.heldout_loss_nominal},
          {"calibrated_loss", c.heldout_loss_calibrated},
          {"identity_loss", c.heldout_loss_identity},
          {"heldout_gain_t", c.heldout_gain_t},
          {"rollout_error_nominal", c.rollout_error_nominal},
          {"rollout_error_calibrated", c.rollout_error_calibrated},
          {"fit_transitions", c.fit_transitions},
          {"train_trajectories", c.train_trajectories},
          {"heldout_trajectories", c.heldout_trajectories},
          {"iterations", c.iterations},
          {"fit_loss_nominal", c.fit_loss_nominal},
          {"fit_loss_coarse", c.fit_loss_coarse},
          {"fit_loss_calibrated", c.fit_loss_calibrated},
          {"replays", c.replays},
          {"report", (out / "report.md").string()},
          {"extended_model", (out / "calibrated_pusher.json").string()},
          {"seconds", seconds}};
}

}  // namespace

bool IsPusherModel(const std::string& model) {
  if (model == "pushing") return true;
  std::error_code ec;
  if (!fs::is_regular_file(model, ec)) return false;
  try {
    const nlohmann::json j = ReadJsonFile(model);
    return j.is_object() && j.contains("kind") && j["kind"] == "oracle";
  } catch (const Error&) {
    return false;
  }
}

nlohmann::json DiagnosePusherFiles(const DiagnoseRequest& request) {
  const auto start = std::chrono::steady_clock::now();
  const PushingConfig nominal = NominalWorld(request);
  std::vector<Trajectory> measured;
  try {
    measured = ReadPushingCsv(request.measured);
  } catch (const Error& e) {
    throw Error(StrCat("--measured ", e.what()));
  }
  DIFFDYN_CHECK(!request.out.empty(), "--out: an output folder is needed");
  PusherCalibrationOptions options = request.pusher;
  if (!request.fit_params.empty()) options.parameters = request.fit_params;
  options.seed = request.pipeline.seed;
  options.holdout_fraction = request.pipeline.holdout_fraction;
  PusherCalibration c;
  try {
    c = CalibratePusher(measured, nominal, options);
  } catch (const NumericalError&) {
    throw;
  } catch (const Error& e) {
    throw Error(StrCat("--model pushing: ", e.what()));
  }

  // Outputs, only once every input has been checked.
  const fs::path out(request.out);
  std::error_code ec;
  fs::create_directories(out, ec);
  DIFFDYN_CHECK(!ec, "--out ", request.out, ": cannot create the folder: ", ec.message());
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const nlohmann::json summary = Summary(c, out, seconds);
  SavePusherWorld((out / "calibrated_pusher.json").string(), c.calibrated,
                  {{"command", "diagnose"}, {"measured", request.measured}, {"seed", options.seed}},
                  {{"heldout_loss_nominal", c.heldout_loss_nominal},
                   {"heldout_loss_calibrated", c.heldout_loss_calibrated}});
  WriteReplays(out / "replays.csv", c);
  WriteRollouts(out / "rollouts.csv", c);
  const std::string report = Report(request, c, summary);
  WriteFileAtomically(out / "report.md", [&](std::ostream& s) { s << report; });
  return summary;
}

}  // namespace diffdyn
