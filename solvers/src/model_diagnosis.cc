// DiagnoseFiles: the diagnosis of `diffdyn diagnose` and `diffdyn.diagnose` (model_diagnosis.h).
#include "diffdyn/solvers/model_diagnosis.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>

#include "diffdyn/models/io.h"
#include "diffdyn/physics/model_registry.h"
#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/diagnosis/candidates.h"
#include "diffdyn/solvers/extended_model_file.h"

namespace diffdyn {
namespace {

namespace fs = std::filesystem;

// Nominal parameters: `p` (the model's defaults or a fed-back file's), then
// --params FILE.json, then --param overrides.
Eigen::VectorXd ResolveParams(const AnalyticModel& model, const DiagnoseRequest& o, Eigen::VectorXd p) {
  if (!o.params_file.empty()) {
    try {
      p = ReadParamsFile(model, o.params_file, p);
    } catch (const Error& e) {
      throw Error(StrCat("--params ", e.what()));
    }
  }
  return ParseParams(model, o.params, p);
}

// v with `digits` significant digits (printf's %g).
std::string Num(double v, int digits = 4) {
  char text[64];
  std::snprintf(text, sizeof text, "%.*g", digits, v);
  return text;
}

std::string JointList(const Eigen::VectorXd& v, int digits = 4) {
  std::string s;
  for (int j = 0; j < v.size(); ++j) s += (j ? " | " : "") + Num(v[j], digits);
  return s;
}

void WriteResidualCsv(const fs::path& path, const DiagnosisResult& r) {
  const int n = static_cast<int>(r.row_q.rows());
  WriteFileAtomically(path, [&](std::ostream& out) {
    out.precision(10);
    out << "t,heldout";
    for (int j = 1; j <= n; ++j) out << ",q" << j << ",qd" << j << ",res_nominal" << j << ",res_extended" << j;
    out << "\n";
    for (int k = 0; k < r.row_t.size(); ++k) {
      out << r.row_t[k] << "," << (r.row_heldout[k] ? 1 : 0);
      for (int j = 0; j < n; ++j) {
        out << "," << r.row_q(j, k) << "," << r.row_qd(j, k) << "," << r.residual_nominal(j, k) << ","
            << r.residual_extended(j, k);
      }
      out << "\n";
    }
  });
}

std::string Report(const DiagnoseRequest& o, const AnalyticModel& model, const Eigen::VectorXd& given,
                    const Dataset& data, const DiagnosisResult& r) {
  const int n = model.dof();
  std::ostringstream md;
  md << "# diffdyn diagnose: " << model.name() << " on " << data.path << "\n\n";
  md << "## Verdict\n\n";
  if (r.no_significant_discrepancy) {
    md << "**No significant discrepancy**: the nominal model plus sensor noise explains the data; "
          "nothing is named.\n\n";
  } else {
    md << "The nominal model misses:\n\n";
    for (const Effect& e : r.named_effects) {
      if (e.kind == EffectKind::kResidual) {
        md << "- **residual**: a learned network explains what no named effect does\n";
        continue;
      }
      const auto& info = Info(e.kind);
      md << "- **" << EffectLabel(e) << "**:";
      for (std::size_t i = 0; i < e.params.size(); ++i) {
        md << " " << info.params[i] << " = " << Num(e.params[i]) << " ± "
           << Num(i < e.stderrs.size() ? e.stderrs[i] : 0.0, 2) << " " << EffectUnit(model, e, static_cast<int>(i))
           << (i + 1 < e.params.size() ? "," : "");
      }
      md << "\n";
    }
    md << "\n";
  }
  md << "Held-out gain (`heldout_sse_removed`, " << r.splits[0].name << "): **" << Num(r.heldout_sse_removed, 3)
     << "**; a purely learned residual on the same split: " << Num(r.heldout_sse_removed_learned, 3) << ".\n\n";

  md << "## Data and nominal model\n\n";
  double seconds = 0;
  for (const Trajectory& t : data.trajectories) seconds += t.t[t.t.size() - 1] - t.t[0];
  md << "- data: `" << data.path << "` (" << data.format << "), " << data.samples() << " samples, " << n
     << " joints, " << Num(seconds) << " s";
  if (!data.notes.empty()) md << "; " << data.notes;
  md << "\n- rows used: " << r.train_rows << " train, " << r.heldout_rows << " held out; independent samples in the "
     << "train part n_eff = " << Num(r.n_eff_train, 3) << "\n";
  md << "- torque-sensor noise σ per joint (robust, from each raw sample's deviation from its neighbours' line): "
     << JointList(r.noise_std, 3) << "; velocity noise σ: " << JointList(r.qd_noise_std, 3) << "\n";
  if (r.static_data) md << "- **static data**: no joint moves; velocity-dependent effects cannot be identified\n";
  for (const auto& note : r.notes) md << "- " << note << "\n";
  md << "\nNominal parameters used:\n\n| parameter | given | used | unit | meaning |\n|---|---|---|---|---|\n";
  for (std::size_t i = 0; i < model.param_specs().size(); ++i) {
    const auto& s = model.param_specs()[i];
    md << "| " << s.name << " | " << Num(given[i], 6) << " | " << Num(r.nominal_params[i], 6) << " | " << s.unit
       << " | " << s.meaning << " |\n";
  }

  md << "\n## Where the simulation is wrong\n\n";
  md << "Held-out torque RMSE per joint (one-step inverse-dynamics error):\n\n| joint | nominal | extended | SSE removed |\n|---|---|---|---|\n";
  for (int j = 0; j < n; ++j) {
    md << "| " << j + 1 << " | " << Num(r.nominal_rmse[j]) << " | " << Num(r.extended_rmse[j]) << " | "
       << Num(r.sse_removed_per_joint[j], 3) << " |\n";
  }
  md << "\nRollout error after " << o.pipeline.rollout_horizon
     << " s from the measured state (RMS over held-out windows):\n\n| joint | q nominal | q extended | qd nominal | qd extended |\n|---|---|---|---|---|\n";
  for (int j = 0; j < n; ++j) {
    md << "| " << j + 1 << " | " << Num(r.rollout_q_nominal[j]) << " | " << Num(r.rollout_q_extended[j]) << " | "
       << Num(r.rollout_qd_nominal[j]) << " | " << Num(r.rollout_qd_extended[j]) << " |\n";
  }
  md << "\nEnergy balance over " << o.pipeline.energy_window
     << " s windows (RMS of ∫ qd·(τ − τ̂) dt, J): nominal " << Num(r.energy_error_nominal) << ", extended "
     << Num(r.energy_error_extended) << "\n\n";
  md << "Correlation of the nominal residual of each joint with each signal (train rows); the largest "
        "|correlation| per joint says where the error concentrates:\n\n| residual | strongest signal | corr |\n|---|---|---|\n";
  const char* names[] = {"q", "qd", "qdd", "tau"};
  for (int j = 0; j < n; ++j) {
    Eigen::Index c = 0;
    r.residual_correlation.row(j).cwiseAbs().maxCoeff(&c);
    md << "| r" << j + 1 << " | " << names[c / n] << (c % n) + 1 << " | " << Num(r.residual_correlation(j, c), 3) << " |\n";
  }
  md << "\n## How the cause was named\n\nForward stepwise selection: the BIC-best candidate, its likelihood-ratio "
        "test against Holm's family-wise threshold (α = "
     << Num(o.pipeline.alpha, 3)
     << "), blocked cross-validation, admissible values, torque size against the sensor noise:\n\n"
        "| candidate | deviance before | deviance after | p | threshold | CV before | CV after | size / noise | decision |\n"
        "|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& s : r.steps) {
    md << "| " << s.candidate << " | " << Num(s.deviance_before, 6) << " | " << Num(s.deviance_after, 6) << " | "
       << Num(s.p_value, 3) << " | " << Num(s.threshold, 3) << " | " << Num(s.cv_before, 4) << " | "
       << Num(s.cv_after, 4) << " | " << Num(s.effect_to_noise, 3) << " | " << s.reason << " |\n";
  }
  md << "\n## What the data cannot identify\n\n";
  if (r.not_identifiable.empty()) md << "Every candidate effect is excited by the data.\n";
  for (const auto& u : r.not_identifiable) {
    md << "- " << EffectLabel(Effect{u.kind, u.joint, {}, {}}) << ": " << u.reason << "\n";
  }
  md << "\n## Gains on held-out data\n\n| split | held-out rows | extended | learned residual only |"
     << (model.name() == "panda" ? " published friction (Gaz et al.) |" : "") << "\n|---|---|---|---|"
     << (model.name() == "panda" ? "---|" : "") << "\n";
  for (const auto& s : r.splits) {
    md << "| " << s.name << " | " << s.heldout_rows << " | " << Num(s.sse_removed, 3) << " | "
       << Num(s.sse_removed_learned, 3) << " |";
    if (model.name() == "panda") md << " " << Num(s.sse_removed_baseline, 3) << " |";
    md << "\n";
  }
  md << "\n## Plots\n\n![residual against velocity](residual_vs_velocity.png)\n\n![residual in time](residual_time.png)\n\n";
  md << "The extended model is saved as `extended_model.json` (kind `extended-physics`). Runtime "
     << Num(r.seconds, 3) << " s.\n";
  return md.str();
}

bool IsAnalyticName(const std::string& name) {
  const auto names = AnalyticModelNames();
  return std::find(names.begin(), names.end(), name) != names.end();
}

// The model under test with its nominal parameters: an analytic model by name,
// or an extended-physics file (a diagnosis fed back).
ExtendedModel ModelUnderTest(const DiagnoseRequest& o) {
  if (IsAnalyticName(o.model)) {
    const auto model = MakeAnalyticModel(o.model);
    return ExtendedModel(model, ResolveParams(*model, o, model->DefaultParams()), {});
  }
  try {
    const ExtendedModel fed = LoadExtendedModel(o.model);
    return fed.WithNominalParams(ResolveParams(fed.model(), o, fed.params()));
  } catch (const Error& e) {
    throw Error(StrCat("--model ", e.what()));
  }
}

// The measured data's conventions (the file comment of model_diagnosis.h): the
// pipeline's settings and the nominal parameters it starts from.
void ApplyDatasetConventions(const Dataset& data, const AnalyticModel& model, DiagnosisOptions& pipeline,
                             Eigen::VectorXd& start) {
  if (data.format == "panda-gaz2019" && pipeline.phase_period <= 0) pipeline.phase_period = 2.0 / 0.15;
  if (data.format == "ibm-double-pendulum" && model.name() == "double-pendulum" && pipeline.fit_params.empty() &&
      pipeline.scale_params.empty()) {
    pipeline.fit_params = {"m2"};
    pipeline.scale_params = {"l1", "l2"};
    start[model.ParamIndex("l1")] = 1.0;
    start[model.ParamIndex("l2")] = data.properties.at("link2_px") / data.properties.at("link1_px");
  }
}

// The command line's bounds on the pipeline's settings, named by their options.
void CheckSettings(const DiagnosisOptions& o) {
  const auto check = [](double v, double low, double high, const char* option) {
    DIFFDYN_CHECK(v >= low && v <= high, option, " must be in [", low, ", ", high, "], got ", v);
  };
  check(o.cutoff_hz, 0, 10, "--cutoff-hz");
  check(o.holdout_fraction, 0, 0.9, "--holdout");
  check(o.phase_period, 0, 1e4, "--phase-period");
  check(o.rollout_horizon, 1e-3, 1e4, "--rollout-horizon");
  check(o.min_effect_to_noise, 0, 1e6, "--min-effect-to-noise");
  check(o.alpha, 1e-12, 0.5, "--alpha");
}

std::vector<double> List(const Eigen::VectorXd& v) { return {v.data(), v.data() + v.size()}; }

// The named effects, what cannot be identified and the splits' gains as JSON.
nlohmann::json EffectsJson(const AnalyticModel& model, const DiagnosisResult& r) {
  nlohmann::json effects = nlohmann::json::array();
  for (const Effect& e : r.named_effects) {
    if (e.kind == EffectKind::kResidual) {
      effects.push_back({{"kind", "residual"}, {"joint", 0}, {"value", nullptr}, {"unit", ""}, {"stderr", nullptr}});
      continue;
    }
    effects.push_back({{"kind", Info(e.kind).name},
                       {"joint", e.joint},
                       {"value", e.params[0]},
                       {"unit", EffectUnit(model, e)},
                       {"stderr", e.stderrs.empty() ? 0.0 : e.stderrs[0]},
                       {"params", e.params}});
  }
  return effects;
}

nlohmann::json Summary(const AnalyticModel& model, const DiagnosisResult& r, const fs::path& out) {
  nlohmann::json unidentifiable = nlohmann::json::array();
  for (const auto& u : r.not_identifiable) {
    unidentifiable.push_back({{"kind", Info(u.kind).name}, {"joint", u.joint}, {"reason", u.reason}});
  }
  nlohmann::json splits = nlohmann::json::array();
  for (const auto& s : r.splits) {
    splits.push_back({{"name", s.name},
                      {"heldout_sse_removed", s.sse_removed},
                      {"learned", s.sse_removed_learned},
                      {"published_friction", std::isnan(s.sse_removed_baseline) ? nlohmann::json(nullptr)
                                                                                 : nlohmann::json(s.sse_removed_baseline)}});
  }
  return {{"model", model.name()},
          {"n_samples", r.n_samples},
          {"nominal_rmse", List(r.nominal_rmse)},
          {"extended_rmse", List(r.extended_rmse)},
          {"heldout_sse_removed", r.heldout_sse_removed},
          {"no_significant_discrepancy", r.no_significant_discrepancy},
          {"named_effects", EffectsJson(model, r)},
          {"noise_std", List(r.noise_std)},
          {"not_identifiable", unidentifiable},
          {"static_data", r.static_data},
          {"cutoff_hz", r.cutoff_hz},
          {"heldout_sse_removed_per_joint", List(r.sse_removed_per_joint)},
          {"heldout_sse_removed_learned", r.heldout_sse_removed_learned},
          {"splits", splits},
          {"energy_error_nominal", r.energy_error_nominal},
          {"energy_error_extended", r.energy_error_extended},
          {"rollout_q_nominal", List(r.rollout_q_nominal)},
          {"rollout_q_extended", List(r.rollout_q_extended)},
          {"report", (out / "report.md").string()},
          {"extended_model", (out / "extended_model.json").string()},
          {"seconds", r.seconds}};
}

}  // namespace

nlohmann::json DiagnoseFiles(const DiagnoseRequest& request) {
  if (IsPusherModel(request.model)) return DiagnosePusherFiles(request);
  CheckSettings(request.pipeline);
  const ExtendedModel under_test = ModelUnderTest(request);
  const auto model = under_test.model_ptr();
  const Eigen::VectorXd params = under_test.params();
  const Dataset data = ReadDataset(request.measured);
  const int dof = JointCount(data);
  DIFFDYN_CHECK(dof == model->dof(), "--measured ", request.measured, " has ", dof,
                " joints but --model ", request.model, " has ", model->dof());
  DIFFDYN_CHECK(!request.out.empty(), "--out: an output folder is needed");
  DiagnosisOptions pipeline = request.pipeline;
  pipeline.fit_params = request.fit_params;
  pipeline.scale_params = request.scale_params;
  Eigen::VectorXd start = params;
  ApplyDatasetConventions(data, *model, pipeline, start);
  const DiagnosisResult r = Diagnose(under_test.WithNominalParams(start), data, pipeline);

  // Outputs, only once every input has been checked: model file, residual CSV, report.
  const fs::path out(request.out);
  std::error_code ec;
  fs::create_directories(out, ec);
  DIFFDYN_CHECK(!ec, "--out ", request.out, ": cannot create the folder: ", ec.message());
  const nlohmann::json metrics = {{"heldout_sse_removed", r.heldout_sse_removed},
                                  {"heldout_sse_removed_learned", r.heldout_sse_removed_learned}};
  SaveExtendedModel(out / "extended_model.json", *r.extended,
                    {{"command", "diagnose"}, {"measured", request.measured}, {"seed", pipeline.seed}}, metrics);
  WriteResidualCsv(out / "residuals.csv", r);
  const std::string report = Report(request, *model, params, data, r);
  WriteFileAtomically(out / "report.md", [&](std::ostream& s) { s << report; });
  return Summary(*model, r, out);
}

}  // namespace diffdyn
