#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/physics/panda_dynamics.h"
#include "diffdyn/solvers/diagnosis.h"
#include "diffdyn/solvers/diagnosis/dissipation.h"
#include "diffdyn/solvers/diagnosis/refit.h"

namespace diffdyn {
namespace {

bool Wanted(const DiagnosisOptions& options, EffectKind kind) {
  return options.kinds.empty() ||
         std::find(options.kinds.begin(), options.kinds.end(), kind) != options.kinds.end();
}

// corr(r_j, s) over the train rows for s in [q, qd, qdd, tau] (n x 4n).
Eigen::MatrixXd ResidualCorrelation(const PreparedData& prep) {
  const int n = prep.n, count = static_cast<int>(prep.train.size());
  const SmoothedData& sd = prep.sd;
  const Eigen::MatrixXd* signals[] = {&sd.q, &sd.qd, &sd.qdd, &sd.tau};
  Eigen::MatrixXd out(n, 4 * n);
  for (int j = 0; j < n; ++j) {
    for (int c = 0; c < 4 * n; ++c) {
      Eigen::VectorXd a(count), b(count);
      for (int i = 0; i < count; ++i) {
        a[i] = prep.residual(j, prep.train[i]);
        b[i] = (*signals[c / n])(c % n, prep.Sample(prep.train[i]));
      }
      a.array() -= a.mean();
      b.array() -= b.mean();
      const double den = a.norm() * b.norm();
      out(j, c) = den > 0 ? a.dot(b) / den : 0.0;
    }
  }
  return out;
}

// The published friction of Gaz et al. on the Panda, smoothed like the data,
// added to the nominal prediction (a baseline for the real Panda log).
Eigen::MatrixXd PandaFrictionBaseline(const PreparedData& prep) {
  Eigen::MatrixXd out = prep.id_nominal;
  for (int r = 0; r < prep.rows; ++r) {
    for (int j = 0; j < prep.n; ++j) {
      out(j, r) += prep.sd.KernelAverage<double>(r, j, [j](double v) {
        Eigen::VectorXd qd = Eigen::VectorXd::Zero(7);
        qd[j] = v;
        return PandaSigmoidFriction(qd)[j];
      });
    }
  }
  return out;
}

// True when every parameter of `e` (but a stribeck's v_s) is within 3 standard
// errors of its neutral value: the joint refit returned the effect to "absent".
bool BackToAbsent(const Effect& e) {
  const EffectKindInfo& info = Info(e.kind);
  const std::size_t count = e.kind == EffectKind::kStribeck ? 2 : e.params.size();
  for (std::size_t i = 0; i < count; ++i) {
    const double se = i < e.stderrs.size() ? e.stderrs[i] : 0.0;
    if (std::abs(e.params[i] - info.neutral[i]) > 3 * se) return false;
  }
  return true;
}

// n_eff sum_j log(SSE_j / rows) of `ext` on the train rows.
double TrainDeviance(const PreparedData& prep, const ExtendedModel& ext) {
  const Eigen::VectorXd sse = RowSse(prep, PredictAll(prep, ext), prep.train);
  double d = 0;
  for (int j = 0; j < prep.n; ++j) d += prep.n_eff * std::log(sse[j] / prep.train.size() + 1e-300);
  return d;
}

// Backward check after the joint refit (the selection saw linearised effects, e.g.
// a long delay's first-order term): while some added effect is not significant
// at `alpha` against the refit without it (likelihood ratio), the least
// significant one is dropped and the rest refitted.
ExtendedModel DropInsignificant(const PreparedData& prep, ExtendedModel ext, const Eigen::VectorXd& inv_sigma,
                                double alpha, DiagnosisResult* result) {
  const double inflation = prep.train.size() / prep.n_eff;
  const std::size_t known = prep.nominal->effects().size();
  while (ext.effects().size() > known + 1) {
    const double full = TrainDeviance(prep, ext);
    double worst_p = -1;
    std::size_t worst = 0;
    std::optional<ExtendedModel> without_worst;
    for (std::size_t i = known; i < ext.effects().size(); ++i) {
      std::vector<Effect> rest(ext.effects().begin() + static_cast<std::ptrdiff_t>(known), ext.effects().end());
      rest.erase(rest.begin() + static_cast<std::ptrdiff_t>(i - known));
      const ExtendedModel without =
          RefitEffects(prep, prep.nominal->WithMoreEffects(rest), prep.train, inv_sigma, inflation);
      const double p = ChiSquareSurvival(TrainDeviance(prep, without) - full,
                                         static_cast<int>(ext.effects()[i].params.size()));
      if (p > worst_p) {
        worst_p = p;
        worst = i;
        without_worst = without;
      }
    }
    if (worst_p < alpha) break;
    SelectionStep step;
    step.candidate = EffectLabel(ext.effects()[worst]);
    step.p_value = worst_p;
    step.threshold = alpha;
    step.reason = StrCat("dropped: after the joint refit it is not significant (p = ", worst_p, ")");
    result->steps.push_back(step);
    ext = *without_worst;
  }
  return ext;
}

// The refit of the selected effects; an effect the joint refit returns to
// absent is dropped (logged) and the rest refitted once more.
ExtendedModel RefitSelected(const PreparedData& prep, const ExtendedModel& extended, const Eigen::VectorXd& inv_sigma,
                            DiagnosisResult* result) {
  const double inflation = prep.train.size() / prep.n_eff;
  const ExtendedModel refitted = RefitEffects(prep, extended, prep.train, inv_sigma, inflation);
  const std::size_t known = prep.nominal->effects().size();
  std::vector<Effect> kept;
  for (std::size_t i = known; i < refitted.effects().size(); ++i) {
    const Effect& e = refitted.effects()[i];
    if (!BackToAbsent(e)) {
      kept.push_back(e);
      continue;
    }
    SelectionStep step;
    step.candidate = EffectLabel(e);
    step.reason = StrCat("dropped: the joint refit puts it within 3 standard errors of absent (",
                         Info(e.kind).params[0], " = ", e.params[0], " +- ", e.stderrs[0], ")");
    result->steps.push_back(step);
  }
  if (kept.size() + known == refitted.effects().size()) return refitted;
  const ExtendedModel rest = prep.nominal->WithMoreEffects(kept);
  return kept.empty() ? rest : RefitEffects(prep, rest, prep.train, inv_sigma, inflation);
}

// Named effects: the torque-regressor selection, its refit, and for free
// motion the energy balance.
ExtendedModel NameEffects(const PreparedData& prep, const Dataset& data, const DiagnosisOptions& options,
                          DiagnosisResult* result, Eigen::VectorXd* inv_sigma) {
  const CandidateLibrary lib = BuildCandidates(prep, options.kinds, data.IsMeasured("tau"));
  result->not_identifiable = lib.not_identifiable;
  result->static_data = lib.static_data;
  if (lib.static_data) {
    result->notes.push_back("static data: no joint moves, so velocity- and acceleration-dependent "
                            "effects cannot be identified (listed under not identifiable)");
  }
  const LinearSelection selection(prep, lib, options.folds, options.min_effect_to_noise);
  SelectionOptions select;
  select.alpha = options.alpha;
  select.family = std::max(1, lib.distinct);
  select.max_selected = options.max_effects;
  const std::vector<int> chosen = ForwardSelect(selection, select, &result->steps);
  ExtendedModel extended = prep.nominal->WithMoreEffects(selection.Effects(chosen));
  *inv_sigma = (selection.Variance(chosen).array() + 1e-300).rsqrt().matrix();
  if (options.refit && !chosen.empty()) {
    extended = DropInsignificant(prep, RefitSelected(prep, extended, *inv_sigma, result), *inv_sigma, options.alpha,
                                 result);
  }
  if (!data.IsMeasured("tau") && Wanted(options, EffectKind::kViscous)) {
    std::vector<int> joints;
    for (int j = 0; j < prep.n; ++j) {
      const bool has = std::any_of(extended.effects().begin(), extended.effects().end(), [&](const Effect& e) {
        return e.joint == j + 1 && (e.kind == EffectKind::kViscous || IsFrictionKind(e.kind));
      });
      if (!has) joints.push_back(j);
    }
    extended = extended.WithMoreEffects(SelectDissipation(prep, PredictAll(prep, extended), joints,
                                                          options.energy_window, options.folds, options.alpha,
                                                          &result->steps));
  }
  return extended;
}

// A learned residual on top of the named effects, kept when it clearly helps
// (a fed-back model's own residual network stays as it is).
ExtendedModel AddLearnedResidual(const PreparedData& prep, const DiagnosisOptions& options,
                                 const ExtendedModel& extended, DiagnosisResult* result) {
  if (extended.residual() != nullptr) return extended;
  const double k = extended.Gain<double>(extended.EffectParams());
  const Eigen::MatrixXd remaining = (prep.tau - PredictAll(prep, extended)) * k;
  double gain = 0;
  auto net = FitResidualNetwork(prep, remaining, prep.train, options.residual_hidden, options.seed, &gain);
  // Its torque size against the sensor noise, the largest over the joints.
  const Eigen::MatrixXd pred = PredictResidual(prep, *net);
  double size = 0;
  for (int j = 0; j < prep.n; ++j) {
    double sq = 0;
    for (int r : prep.train) sq += pred(j, r) * pred(j, r);
    const double rms = std::sqrt(sq / prep.train.size());
    size = std::max(size, prep.noise_std[j] > 0 ? rms / prep.noise_std[j] : 0.0);
  }
  const bool named = gain > options.residual_min_gain && size >= options.residual_min_to_noise;
  result->notes.push_back(StrCat("learned residual on top of the named effects: validation SSE drop ", 100 * gain,
                                 "%, torque RMS ", size, " x the sensor noise (named when above ",
                                 100 * options.residual_min_gain, "% and ", options.residual_min_to_noise, " x)"));
  return named ? extended.WithResidual(net) : extended;
}

// The held-out phase window of a periodic motion: the same effects refitted on the rest.
void ScorePhaseWindow(const PreparedData& prep, const DiagnosisOptions& options, const ExtendedModel& extended,
                      const Eigen::VectorXd& inv_sigma, const Eigen::MatrixXd& baseline,
                      DiagnosisResult* result) {
  std::vector<int> train, held;
  const double lo = 1.0 - options.phase_window_fraction;
  const SmoothedData& sd = prep.sd;
  for (int r = 0; r < prep.rows; ++r) {
    const double phase = std::fmod(sd.t[prep.Sample(r)] - sd.t[0], options.phase_period) / options.phase_period;
    (phase >= lo ? held : train).push_back(r);
  }
  if (held.size() < 5 || train.size() < 10) return;
  ExtendedModel refit = extended.WithResidual(nullptr);
  if (!refit.effects().empty()) {
    refit = RefitEffects(prep, refit, train, inv_sigma, train.size() / prep.n_eff);
  }
  if (extended.residual()) {
    const Eigen::MatrixXd remaining = (prep.tau - PredictAll(prep, refit)) * refit.Gain<double>(refit.EffectParams());
    refit = refit.WithResidual(FitResidualNetwork(prep, remaining, train, options.residual_hidden, options.seed, nullptr));
  }
  const Eigen::MatrixXd learned =
      prep.id_nominal +
      PredictResidual(prep, *FitResidualNetwork(prep, prep.residual, train, options.residual_hidden, options.seed, nullptr));
  result->splits.push_back(ScoreSplit(prep,
                                      StrCat("phase window [", lo * options.phase_period, ", ", options.phase_period,
                                             ") s of the ", options.phase_period, " s period"),
                                      held, PredictAll(prep, refit), learned, baseline));
}

// Held-out scores, rollouts and energy balance of `extended`.
void ScoreGains(const PreparedData& prep, const DiagnosisOptions& options, const ExtendedModel& extended,
                const Eigen::VectorXd& inv_sigma, DiagnosisResult* result) {
  const Eigen::MatrixXd pred = PredictAll(prep, extended);
  const Eigen::MatrixXd learned =
      prep.id_nominal + PredictResidual(prep, *FitResidualNetwork(prep, prep.residual, prep.train,
                                                                  options.residual_hidden, options.seed, nullptr));
  const Eigen::MatrixXd baseline = prep.model->name() == "panda" ? PandaFrictionBaseline(prep) : Eigen::MatrixXd();
  result->splits.push_back(ScoreSplit(prep, StrCat("last ", std::lround(100 * options.holdout_fraction), "% in time"),
                                      prep.heldout, pred, learned, baseline));
  const SplitScore& main = result->splits[0];
  result->heldout_sse_removed = main.sse_removed;
  result->heldout_sse_removed_learned = main.sse_removed_learned;
  result->sse_removed_per_joint =
      (1.0 - main.sse_extended.array() / main.sse_nominal.array().max(1e-300)).matrix();
  result->nominal_rmse = (main.sse_nominal / std::max(1, main.heldout_rows)).cwiseSqrt();
  result->extended_rmse = (main.sse_extended / std::max(1, main.heldout_rows)).cwiseSqrt();
  if (options.phase_period > 0) ScorePhaseWindow(prep, options, extended, inv_sigma, baseline, result);

  const RolloutErrors rollouts = ScoreRollouts(prep, extended, options.rollout_horizon);
  result->rollout_q_nominal = rollouts.q_nominal;
  result->rollout_q_extended = rollouts.q_extended;
  result->rollout_qd_nominal = rollouts.qd_nominal;
  result->rollout_qd_extended = rollouts.qd_extended;
  result->notes.push_back(StrCat("rollouts: ", rollouts.windows, " held-out windows of ", options.rollout_horizon,
                                 " s from the measured state, RK4, measured torque as input",
                                 rollouts.failed > 0 ? StrCat("; a mass matrix was not positive definite in ",
                                                              rollouts.failed, " rollouts (NaN)")
                                                     : std::string()));
  result->energy_error_nominal = EnergyBalanceError(prep, prep.id_nominal, options.energy_window);
  result->energy_error_extended = EnergyBalanceError(prep, pred, options.energy_window);
  result->residual_extended = prep.tau - pred;
}

// Rows, states and residuals for the plots.
void FillPlotArrays(const PreparedData& prep, DiagnosisResult* result) {
  result->row_t.resize(prep.rows);
  result->row_q.resize(prep.n, prep.rows);
  result->row_qd.resize(prep.n, prep.rows);
  result->row_heldout.assign(prep.rows, false);
  for (int r = 0; r < prep.rows; ++r) {
    const int k = prep.Sample(r);
    result->row_t[r] = prep.sd.t[k];
    result->row_q.col(r) = prep.sd.q.col(k);
    result->row_qd.col(r) = prep.sd.qd.col(k);
  }
  for (int r : prep.heldout) result->row_heldout[r] = true;
  result->residual_nominal = prep.residual;
}

}  // namespace

std::string EffectUnit(const AnalyticModel& model, const Effect& effect, int param) {
  const EffectKindInfo& info = Info(effect.kind);
  if (param >= static_cast<int>(info.units.size())) return "";
  const bool prismatic = effect.joint > 0 && model.prismatic(effect.joint - 1);
  return prismatic ? info.prismatic_units[param] : info.units[param];
}

DiagnosisResult Diagnose(std::shared_ptr<const AnalyticModel> model, const Eigen::VectorXd& params,
                         const Dataset& data, const DiagnosisOptions& options) {
  DIFFDYN_CHECK(model != nullptr, "diagnose: no model");
  DIFFDYN_CHECK(params.size() == static_cast<int>(model->param_specs().size()), "diagnose: model ",
                model->name(), " needs ", model->param_specs().size(), " parameters, got ", params.size());
  return Diagnose(ExtendedModel(model, params, {}), data, options);
}

DiagnosisResult Diagnose(const ExtendedModel& nominal, const Dataset& data, const DiagnosisOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  DIFFDYN_CHECK(options.alpha > 0 && options.alpha < 1, "diagnose: alpha ", options.alpha, " must be in (0, 1)");
  PrepareOptions prepare;
  prepare.cutoff_hz = options.cutoff_hz;
  prepare.holdout_fraction = options.holdout_fraction;
  prepare.fit_params = options.fit_params;
  prepare.scale_params = options.scale_params;
  prepare.calibration_fraction = options.calibration_fraction;
  const PreparedData prep = PrepareData(nominal, data, prepare);
  const std::shared_ptr<const AnalyticModel> model = nominal.model_ptr();

  DiagnosisResult result;
  result.model_name = model->name();
  result.cutoff_hz = prep.sd.cutoff_hz;
  result.n_samples = data.samples();
  result.notes = prep.notes;
  result.nominal_params = prep.params;
  result.train_rows = static_cast<int>(prep.train.size());
  result.heldout_rows = static_cast<int>(prep.heldout.size());
  result.n_eff_train = prep.n_eff;
  result.noise_std = prep.noise_std;
  result.qd_noise_std = prep.qd_noise_std;
  result.residual_correlation = ResidualCorrelation(prep);

  Eigen::VectorXd inv_sigma;
  ExtendedModel extended = NameEffects(prep, data, options, &result, &inv_sigma);
  extended = AddLearnedResidual(prep, options, extended, &result);
  const auto& all = extended.effects();
  result.named_effects.assign(all.begin() + static_cast<std::ptrdiff_t>(nominal.effects().size()), all.end());
  if (extended.residual() && !nominal.residual()) result.named_effects.push_back({EffectKind::kResidual, 0, {}, {}});
  result.no_significant_discrepancy = result.named_effects.empty();
  ScoreGains(prep, options, extended, inv_sigma, &result);
  FillPlotArrays(prep, &result);
  result.extended = extended;
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace diffdyn
