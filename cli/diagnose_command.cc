// diffdyn diagnose: what does the simulation get wrong on measured data, why,
// and how much does the extended model gain on held-out data.
//
//   diffdyn diagnose --model panda --measured shared/data/panda_gaz2019_traj1 --out diag/ --json
//
// Writes DIR/report.md (nominal parameters, errors per channel, named effects
// with standard errors, selection log, gains), DIR/extended_model.json (kind
// extended-physics), DIR/residuals.csv and the PNGs drawn from it
// (residual against velocity per joint, before and after; residual in time).
#include <algorithm>
#include <filesystem>

#include <fmt/core.h>

#include "command.h"
#include "diffdyn/physics/model_registry.h"
#include "diffdyn/solvers/model_diagnosis.h"
#include "plot.h"

namespace diffdyn::cli {
namespace {

namespace fs = std::filesystem;

struct DiagnoseOptions {
  CommonOptions common;
  DiagnoseRequest request;
};

bool IsAnalyticName(const std::string& name) {
  const auto names = AnalyticModelNames();
  return std::find(names.begin(), names.end(), name) != names.end();
}

void RunDiagnose(DiagnoseOptions& o) {
  o.request.pipeline.seed = o.common.seed;
  if (!o.common.quiet) {
    o.request.pusher.progress = [](const std::string& line) {
      fmt::print(stderr, "diagnose: {}\n", line);
    };
  }
  const nlohmann::json summary = DiagnoseFiles(o.request);
  const fs::path out(o.request.out);
  if (summary["model"] == "pushing") {
    RunPlotScript("diagnose_pushing.py",
                  {(out / "replays.csv").string(), (out / "rollouts.csv").string(), o.request.out});
  } else {
    const int joints = static_cast<int>(summary["nominal_rmse"].size());
    RunPlotScript("diagnose_residuals.py",
                  {(out / "residuals.csv").string(), o.request.out, std::to_string(joints)});
  }
  if (o.common.json) {
    PrintJson(summary);
  } else if (!o.common.quiet) {
    fmt::print("diagnose {}: {} | heldout_sse_removed {:.3f} | report {}\n", summary["model"].get<std::string>(),
               summary["no_significant_discrepancy"].get<bool>() ? "no significant discrepancy" : "effects named",
               summary["heldout_sse_removed"].get<double>(), summary["report"].get<std::string>());
  }
}

}  // namespace

void RegisterDiagnoseCommand(CLI::App& app) {
  auto* command = app.add_subcommand(
      "diagnose", "Compare a simulation model with measured data: errors, named causes, extended model, gain");
  auto o = std::make_shared<DiagnoseOptions>();
  AddCommonOptions(command, o->common);
  command
      ->add_option("--model", o->request.model,
                   "Simulation model: pendulum, cartpole, double-pendulum, arm2, panda, or an "
                   "extended-physics file (a diagnosis fed back: its effects stay, only what is "
                   "missing is named); "
                   "pushing (the ODE-engine pusher, calibrated against a pushing CSV) or a pusher "
                   "world file")
      ->required()
      ->check(CLI::Validator(
          [](std::string& m) -> std::string {
            if (IsAnalyticName(m) || m == "pushing") return {};
            try {
              CheckInputPath(m, false);
            } catch (const Error& e) {
              return e.what();
            }
            return {};
          },
          "NAME|FILE"));
  command
      ->add_option(
          "--measured", o->request.measured,
          "Joint-space CSV (t,q1..,qd1..,tau1..[,qdd1..]) or a dataset folder of shared/data; "
          "with --model pushing a pushing CSV")
      ->check(InputPath(true))
      ->required();
  command->add_option("--param", o->request.params, "Nominal parameter override name=value (repeatable)");
  command->add_option("--params", o->request.params_file, "JSON file {name: value} of nominal parameters")
      ->check(InputPath());
  command->add_option("--out", o->request.out, "Output folder (report.md, extended_model.json, plots)")
      ->check(OutputPath(true))->required();
  command->add_option("--cutoff-hz", o->request.pipeline.cutoff_hz,
                      "Zero-phase smoothing cutoff (Hz, at most 10; default 0: min(10 Hz, f_s / 4, max(f_s / 12, 2 f_99)), f_99 the torque's 99 % power bandwidth)")
      ->check(Bounded(0, 10));
  command
      ->add_option("--holdout", o->request.pipeline.holdout_fraction,
                   "Held-out fraction at the end (in time); pushing: of the trajectories (seeded)")
      ->check(Bounded(0, 0.9));
  command->add_option(
      "--fit-param", o->request.fit_params,
      "Nominal parameter fitted on the first quarter first (repeatable); pushing: the pusher "
      "parameters to calibrate (default tip_pad_x, tip_pad_y, tip_block_friction, "
      "block_table_friction, block_inertia)");
  command
      ->add_option(
          "--fit-transitions", o->request.pusher.fit_transitions,
          "Pushing: training transitions the calibration replays (seeded subsample; 0 = all)")
      ->check(Bounded(0, 1e7));
  command
      ->add_option("--max-iterations", o->request.pusher.max_iterations,
                   "Pushing: Levenberg-Marquardt iterations at most")
      ->check(Bounded(0, 1000));
  command
      ->add_option("--threads", o->request.pusher.threads,
                   "Pushing: worker threads (0 = all cores; "
                   "the numbers do not depend on it)")
      ->check(Bounded(0, 256));
  command->add_option("--scale-param", o->request.scale_params,
                      "Nominal parameters scaled by one common fitted factor (repeatable)");
  command->add_option("--phase-period", o->request.pipeline.phase_period,
                      "Period (s) of a repeating motion: also score a held-out phase window (0 = off)")
      ->check(Bounded(0, 1e4));
  command->add_option("--rollout-horizon", o->request.pipeline.rollout_horizon, "Rollout window (s)")
      ->check(Bounded(1e-3, 1e4));
  command->add_option("--min-effect-to-noise", o->request.pipeline.min_effect_to_noise,
                      "Smallest named effect: torque RMS_j / sensor-noise sigma_j (system-wide effects: RMS over the joints)")
      ->check(Bounded(0, 1e6));
  command->add_option("--alpha", o->request.pipeline.alpha,
                      "Family-wise error of the selection: chance of naming any absent effect")
      ->check(Bounded(1e-12, 0.5));
  command->callback([o] { RunDiagnose(*o); });
}

}  // namespace diffdyn::cli
