#include "diffdyn/solvers/diagnosis.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <numeric>
#include <tuple>

#include <ceres/ceres.h>
#include <Eigen/Cholesky>
#include <Eigen/LU>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/autodiff_ode/random.h"
#include "diffdyn/physics/panda_dynamics.h"

namespace diffdyn {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Stribeck velocity grid of the linear stage (rad/s or m/s); the refit frees v_s.
constexpr double kStribeckGrid[] = {0.015, 0.03, 0.06, 0.12, 0.25, 0.5};
constexpr int kStribeckGridSize = 6;

bool IsFriction(EffectKind kind) {
  return kind == EffectKind::kCoulomb || kind == EffectKind::kStribeck;
}

// The smoothed value sum_i alpha_i f(q_raw_i, qd_raw_i) of a per-joint friction
// feature around row `r` (index into sd.rows), with an optional time shift.
template <typename T, typename F>
T SmoothedFeature(const SmoothedData& sd, int r, int joint, F&& f) {
  const Eigen::VectorXd& alpha = sd.kernel_alpha[r];
  const int begin = sd.kernel_begin[r];
  T acc = T(0.0);
  for (int i = 0; i < alpha.size(); ++i) acc += alpha[i] * f(sd.qd_raw(joint, begin + i));
  return acc;
}

// Everything the pipeline shares: smoothed data, nominal model, row sets.
struct Context {
  std::shared_ptr<const AnalyticModel> model;
  Eigen::VectorXd params;
  SmoothedData sd;
  int n = 0;
  int rows = 0;                    // R, all decimated rows
  Eigen::MatrixXd id_nominal;      // n x R
  Eigen::MatrixXd tau;             // n x R, smoothed measured torque
  std::vector<int> train, heldout; // indices into 0..R-1
};

// Predicted measured torque (n) at row r of the extended model with parameters
// theta (no learned residual unless the model holds one):
//   tau_hat = JointTorque(x(t_r + d)) / k, friction smoothed like the data.
template <typename T>
VectorX<T> PredictRow(const Context& ctx, const ExtendedModel& ext, const VectorX<T>& theta,
                      int r) {
  const int k = ctx.sd.rows[r];
  const T d = ext.Delay<T>(theta);
  VectorX<T> q, qd, qdd;
  bool shifted = false;
  for (const Effect& e : ext.effects()) shifted = shifted || e.kind == EffectKind::kDelay;
  if (shifted) {
    ctx.sd.StateAt<T>(T(ctx.sd.t[k]) + d, ctx.sd.segment_of[k], q, qd, qdd);
  } else {
    q = ctx.sd.q.col(k).template cast<T>();
    qd = ctx.sd.qd.col(k).template cast<T>();
    qdd = ctx.sd.qdd.col(k).template cast<T>();
  }
  VectorX<T> tau = ext.JointTorque<T>(q, qd, qdd, theta);
  // Replace sharp friction at the smoothed velocity by the smoothed friction.
  for (int i = 0; i < static_cast<int>(ext.effects().size()); ++i) {
    const Effect& e = ext.effects()[i];
    if (!IsFriction(e.kind)) continue;
    const int j = e.joint - 1;
    const T* th = theta.data() + ext.ParamOffset(i);
    const T zero(0.0);
    tau[j] -= JointEffectTorque<T>(e.kind, th, q[j], qd[j], zero);
    tau[j] += SmoothedFeature<T>(ctx.sd, r, j, [&](double v) {
      return JointEffectTorque<T>(e.kind, th, zero, T(v), zero);
    });
  }
  return tau / ext.Gain<T>(theta);
}

// Predicted torque (n x R) at every row, double, including a learned residual.
Eigen::MatrixXd PredictAll(const Context& ctx, const ExtendedModel& ext) {
  Eigen::MatrixXd out(ctx.n, ctx.rows);
  const Eigen::VectorXd theta = ext.EffectParams();
  for (int r = 0; r < ctx.rows; ++r) out.col(r) = PredictRow<double>(ctx, ext, theta, r);
  return out;
}

// Per-joint SSE of (tau - prediction) over the rows `idx`.
Eigen::VectorXd Sse(const Context& ctx, const Eigen::MatrixXd& prediction,
                    const std::vector<int>& idx) {
  Eigen::VectorXd sse = Eigen::VectorXd::Zero(ctx.n);
  for (int r : idx) sse += (ctx.tau.col(r) - prediction.col(r)).array().square().matrix();
  return sse;
}

// Ceres cost: weighted torque residuals of the extended model at the given
// rows, with the effect parameters `free` (indices into theta, at most
// kDiagJetSize) as the one parameter block and the others fixed at `base`.
class RefitCost : public ceres::CostFunction {
 public:
  RefitCost(const Context& ctx, const ExtendedModel& ext, const std::vector<int>& rows,
            const Eigen::VectorXd& inv_sigma, std::vector<int> free, Eigen::VectorXd base)
      : ctx_(ctx), ext_(ext), rows_(rows), inv_sigma_(inv_sigma), free_(std::move(free)),
        base_(std::move(base)) {
    set_num_residuals(ctx.n * static_cast<int>(rows.size()));
    mutable_parameter_block_sizes()->push_back(static_cast<int>(free_.size()));
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const int p = static_cast<int>(free_.size());
    const int n = ctx_.n;
    VectorX<DiagJet> theta = base_.cast<DiagJet>();
    for (int i = 0; i < p; ++i) theta[free_[i]] = DiagJet(parameters[0][i], i);
    for (std::size_t i = 0; i < rows_.size(); ++i) {
      const VectorX<DiagJet> pred = PredictRow<DiagJet>(ctx_, ext_, theta, rows_[i]);
      for (int j = 0; j < n; ++j) {
        const int row = static_cast<int>(i) * n + j;
        residuals[row] = (pred[j].a - ctx_.tau(j, rows_[i])) * inv_sigma_[j];
        if (!std::isfinite(residuals[row])) return false;
        if (jacobians != nullptr && jacobians[0] != nullptr) {
          for (int c = 0; c < p; ++c) jacobians[0][row * p + c] = pred[j].v[c] * inv_sigma_[j];
        }
      }
    }
    return true;
  }

 private:
  const Context& ctx_;
  const ExtendedModel& ext_;
  const std::vector<int>& rows_;
  Eigen::VectorXd inv_sigma_;
  std::vector<int> free_;
  Eigen::VectorXd base_;
};

// Refits every effect parameter of `ext` on `rows` (Ceres, Jets); returns the
// model with fitted values and standard errors (covariance inflated by
// `inflation` for correlated noise). More than kDiagJetSize parameters are
// refitted by blocks of whole effects (two sweeps, the others held fixed).
ExtendedModel RefitEffects(const Context& ctx, const ExtendedModel& ext,
                           const std::vector<int>& rows, const Eigen::VectorXd& inv_sigma,
                           double inflation) {
  Eigen::VectorXd theta = ext.EffectParams();
  const int p = static_cast<int>(theta.size());
  if (p == 0) return ext;
  // Blocks of whole effects with at most kDiagJetSize parameters each.
  std::vector<std::vector<int>> blocks(1);
  for (int i = 0; i < static_cast<int>(ext.effects().size()); ++i) {
    const int o = ext.ParamOffset(i), count = static_cast<int>(ext.effects()[i].params.size());
    if (static_cast<int>(blocks.back().size()) + count > kDiagJetSize) blocks.emplace_back();
    for (int k = 0; k < count; ++k) blocks.back().push_back(o + k);
  }
  Eigen::VectorXd stderrs = Eigen::VectorXd::Zero(p);
  const int sweeps = blocks.size() > 1 ? 2 : 1;
  for (int sweep = 0; sweep < sweeps; ++sweep) {
    for (const std::vector<int>& free : blocks) {
      Eigen::VectorXd x(free.size());
      for (std::size_t i = 0; i < free.size(); ++i) x[i] = theta[free[i]];
      auto* cost = new RefitCost(ctx, ext, rows, inv_sigma, free, theta);
      ceres::Problem problem;
      problem.AddResidualBlock(cost, nullptr, x.data());
      // Physical bounds: a positive gain and Stribeck velocity.
      for (int e = 0; e < static_cast<int>(ext.effects().size()); ++e) {
        const Effect& effect = ext.effects()[e];
        int bounded = -1;
        if (effect.kind == EffectKind::kGain) bounded = ext.ParamOffset(e);
        if (effect.kind == EffectKind::kStribeck) bounded = ext.ParamOffset(e) + 2;
        const auto it = std::find(free.begin(), free.end(), bounded);
        if (bounded >= 0 && it != free.end()) {
          problem.SetParameterLowerBound(x.data(), static_cast<int>(it - free.begin()), 1e-3);
        }
      }
      ceres::Solver::Options options;
      options.max_num_iterations = 50;
      options.linear_solver_type = ceres::DENSE_QR;
      options.logging_type = ceres::SILENT;
      ceres::Solver::Summary summary;
      ceres::Solve(options, &problem, &summary);
      if (!x.allFinite()) throw NumericalError("diagnose: refit produced non-finite parameters");
      for (std::size_t i = 0; i < free.size(); ++i) theta[free[i]] = x[i];
      // Covariance from the Jacobian at the solution: s^2 (J^T J)^{-1} * inflation.
      RefitCost at(ctx, ext, rows, inv_sigma, free, theta);
      const int m = at.num_residuals(), k = static_cast<int>(free.size());
      Eigen::VectorXd residuals(m);
      Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> jac(m, k);
      const double* params[] = {x.data()};
      double* jacs[] = {jac.data()};
      at.Evaluate(params, residuals.data(), jacs);
      const double s2 = residuals.squaredNorm() / std::max(1, m - k);
      const Eigen::MatrixXd cov =
          Eigen::MatrixXd(jac.transpose() * jac).completeOrthogonalDecomposition().pseudoInverse() *
          s2 * inflation;
      for (int i = 0; i < k; ++i) stderrs[free[i]] = std::sqrt(std::max(0.0, cov(i, i)));
    }
  }
  return ext.WithEffectParams(theta, stderrs);
}

// ---------- the linear stage: candidates, Gram matrices, stepwise EBIC ----------

struct Candidate {
  EffectKind kind;
  int joint;                // 1-based, 0 = system
  double v_s = 0;           // stribeck grid value
  std::vector<int> columns; // global column ids
  int n_params = 1;         // parameters counted by the criterion
  std::string label;
};

struct LinearStage {
  int n = 0, folds = 0, cols = 0;
  std::vector<Eigen::MatrixXd> column_data;  // cols x (n x R)
  std::vector<Candidate> candidates;
  // Gram blocks per fold and joint over train rows.
  std::vector<std::vector<Eigen::MatrixXd>> gram;  // [fold][joint] cols x cols
  std::vector<std::vector<Eigen::VectorXd>> cross; // [fold][joint] cols
  std::vector<std::vector<double>> energy;         // [fold][joint]
  std::vector<int> fold_rows;                      // rows per fold
};

// Weighted least squares of the columns `s` on folds where use[f] is true.
Eigen::VectorXd FitColumns(const LinearStage& ls, const std::vector<int>& s,
                           const std::vector<bool>& use, const Eigen::VectorXd& w,
                           Eigen::MatrixXd* gram_out = nullptr) {
  const int k = static_cast<int>(s.size());
  Eigen::MatrixXd g = Eigen::MatrixXd::Zero(k, k);
  Eigen::VectorXd h = Eigen::VectorXd::Zero(k);
  for (int f = 0; f < ls.folds; ++f) {
    if (!use[f]) continue;
    for (int j = 0; j < ls.n; ++j) {
      for (int a = 0; a < k; ++a) {
        h[a] += w[j] * ls.cross[f][j][s[a]];
        for (int b = 0; b < k; ++b) g(a, b) += w[j] * ls.gram[f][j](s[a], s[b]);
      }
    }
  }
  if (gram_out) *gram_out = g;
  if (k == 0) return h;
  // A tiny ridge keeps exactly collinear candidates (e.g. payload and gain on a
  // pendulum) solvable; such a candidate then adds nothing and is not selected.
  const double ridge = 1e-10 * (g.diagonal().maxCoeff() + 1e-300);
  g.diagonal().array() += ridge;
  return g.ldlt().solve(h);
}

// SSE of joint j on fold f for coefficients beta of columns s.
double FoldSse(const LinearStage& ls, const std::vector<int>& s, const Eigen::VectorXd& beta,
               int f, int j) {
  double sse = ls.energy[f][j];
  for (std::size_t a = 0; a < s.size(); ++a) {
    sse -= 2 * beta[a] * ls.cross[f][j][s[a]];
    for (std::size_t b = 0; b < s.size(); ++b) sse += beta[a] * beta[b] * ls.gram[f][j](s[a], s[b]);
  }
  return std::max(sse, 0.0);
}

// log of the binomial coefficient C(p, k).
double LogBinomial(int p, int k) {
  return std::lgamma(p + 1.0) - std::lgamma(k + 1.0) - std::lgamma(p - k + 1.0);
}

}  // namespace

std::string EffectLabel(const Effect& effect) {
  const std::string name = Info(effect.kind).name;
  return effect.joint > 0 ? StrCat(name, " j", effect.joint) : name;
}

std::string EffectUnit(const AnalyticModel& model, const Effect& effect, int param) {
  const EffectKindInfo& info = Info(effect.kind);
  if (param >= static_cast<int>(info.units.size())) return "";
  const bool prismatic = effect.joint > 0 && model.prismatic(effect.joint - 1);
  return prismatic ? info.prismatic_units[param] : info.units[param];
}

namespace {

// The pipeline at one smoothing cutoff (options.cutoff_hz > 0). `tau_noise`
// (n) is the torque-noise estimate to use (from the 10 Hz smoothing, which
// signal does not leak into). With `cv_gain` set, stops after the selection
// and returns there the blocked cross-validated fraction of the nominal
// residual's SSE that the selected effects remove (unweighted, all joints).
DiagnosisResult DiagnoseAtCutoff(std::shared_ptr<const AnalyticModel> model,
                                 const Eigen::VectorXd& params, const JointData& data,
                                 const DiagnosisOptions& options,
                                 const Eigen::VectorXd& tau_noise, double* cv_gain) {
  const auto start = std::chrono::steady_clock::now();
  DIFFDYN_CHECK(model != nullptr, "diagnose: no model");
  DIFFDYN_CHECK(data.dof() == model->dof(), "--measured ", data.path, " has ", data.dof(),
                " joints, --model ", model->name(), " has ", model->dof());
  DIFFDYN_CHECK(params.size() == static_cast<int>(model->param_specs().size()),
                "diagnose: model ", model->name(), " needs ", model->param_specs().size(),
                " parameters, got ", params.size());
  DIFFDYN_CHECK(options.holdout_fraction > 0 && options.holdout_fraction < 1,
                "--holdout ", options.holdout_fraction, ": must be in (0, 1)");
  DIFFDYN_CHECK(options.folds >= 2, "diagnose: need at least 2 folds, got ", options.folds);

  DiagnosisResult result;
  result.model_name = model->name();
  result.cutoff_hz = options.cutoff_hz;
  result.n_samples = data.size();
  Context ctx;
  ctx.model = model;
  ctx.params = params;
  ctx.sd = SmoothJointData(data, options.cutoff_hz);
  if (tau_noise.size() == ctx.sd.tau_noise.size()) ctx.sd.tau_noise = tau_noise;
  ctx.n = model->dof();
  ctx.rows = static_cast<int>(ctx.sd.rows.size());
  const int n = ctx.n, rows = ctx.rows;
  const SmoothedData& sd = ctx.sd;
  result.tau_noise = sd.tau_noise;
  ctx.tau.resize(n, rows);
  for (int r = 0; r < rows; ++r) ctx.tau.col(r) = sd.tau.col(sd.rows[r]);
  result.notes.push_back(StrCat("smoothing: local-linear Gaussian kernel, cutoff ",
                                options.cutoff_hz, " Hz (s = ", sd.sigma_t * 1e3,
                                " ms), same weights for q, qd, tau; qdd = d/dt of smoothed qd"));

  // Calibration of named nominal parameters on the first rows.
  if (!options.fit_params.empty() || !options.scale_params.empty()) {
    std::vector<int> fit_index, scale_index;
    for (const auto& name : options.fit_params) {
      const int i = model->ParamIndex(name);
      DIFFDYN_CHECK(i >= 0, "--fit-param ", name, ": model ", model->name(), " has no such parameter");
      fit_index.push_back(i);
    }
    for (const auto& name : options.scale_params) {
      const int i = model->ParamIndex(name);
      DIFFDYN_CHECK(i >= 0, "--scale-param ", name, ": model ", model->name(), " has no such parameter");
      scale_index.push_back(i);
    }
    const int free = static_cast<int>(fit_index.size()) + (scale_index.empty() ? 0 : 1);
    DIFFDYN_CHECK(free <= kDiagJetSize, "at most ", kDiagJetSize, " calibrated parameters");
    const int calib_rows = std::max(10, static_cast<int>(options.calibration_fraction * rows));
    Eigen::VectorXd x(free);
    for (std::size_t i = 0; i < fit_index.size(); ++i) x[i] = params[fit_index[i]];
    if (!scale_index.empty()) x[free - 1] = 1.0;
    auto assemble = [&](const auto& xv, auto tag) {
      using T = decltype(tag);
      VectorX<T> p = params.template cast<T>();
      for (std::size_t i = 0; i < fit_index.size(); ++i) p[fit_index[i]] = xv[i];
      for (int i : scale_index) p[i] = T(params[i]) * xv[free - 1];
      return p;
    };
    // A small dynamic cost: residual tau - ID(p(x)) on the first calib_rows rows.
    class CalibrationCost : public ceres::CostFunction {
     public:
      CalibrationCost(const Context& c, int count, int free,
                      std::function<VectorX<DiagJet>(const VectorX<DiagJet>&)> params_of)
          : ctx_(c), count_(count), free_(free), params_of_(std::move(params_of)) {
        set_num_residuals(c.n * count);
        mutable_parameter_block_sizes()->push_back(free);
      }
      bool Evaluate(double const* const* parameters, double* residuals,
                    double** jacobians) const override {
        VectorX<DiagJet> xj(free_);
        for (int i = 0; i < free_; ++i) xj[i] = DiagJet(parameters[0][i], i);
        const VectorX<DiagJet> p = params_of_(xj);
        for (int r = 0; r < count_; ++r) {
          const int k = ctx_.sd.rows[r];
          const VectorX<DiagJet> q = ctx_.sd.q.col(k).cast<DiagJet>();
          const VectorX<DiagJet> qd = ctx_.sd.qd.col(k).cast<DiagJet>();
          const VectorX<DiagJet> qdd = ctx_.sd.qdd.col(k).cast<DiagJet>();
          const VectorX<DiagJet> tau = ctx_.model->InverseDynamics(q, qd, qdd, p);
          // Residuals divided by the diagonal of M(q; p): acceleration units,
          // so shrinking the whole model (free motion, tau = 0) cannot fit.
          const VectorX<DiagJet> zero = VectorX<DiagJet>::Zero(ctx_.n);
          const VectorX<DiagJet> bias = ctx_.model->InverseDynamics(q, zero, zero, p);
          for (int j = 0; j < ctx_.n; ++j) {
            VectorX<DiagJet> unit = zero;
            unit[j] = DiagJet(1.0);
            const DiagJet mjj = ctx_.model->InverseDynamics(q, zero, unit, p)[j] - bias[j];
            const DiagJet res = (DiagJet(ctx_.tau(j, r)) - tau[j]) / mjj;
            const int row = r * ctx_.n + j;
            residuals[row] = res.a;
            if (!std::isfinite(residuals[row])) return false;
            if (jacobians && jacobians[0]) {
              for (int c = 0; c < free_; ++c) jacobians[0][row * free_ + c] = res.v[c];
            }
          }
        }
        return true;
      }

     private:
      const Context& ctx_;
      int count_, free_;
      std::function<VectorX<DiagJet>(const VectorX<DiagJet>&)> params_of_;
    };
    ceres::Problem problem;
    problem.AddResidualBlock(
        new CalibrationCost(ctx, calib_rows, free,
                            [&](const VectorX<DiagJet>& xv) { return assemble(xv, DiagJet()); }),
        nullptr, x.data());
    for (int i = 0; i < free; ++i) problem.SetParameterLowerBound(x.data(), i, 1e-6);
    ceres::Solver::Options solver_options;
    solver_options.max_num_iterations = 100;
    solver_options.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(solver_options, &problem, &summary);
    DIFFDYN_CHECK(x.allFinite(), "calibration of the nominal parameters failed");
    VectorX<double> fitted = assemble(x, 0.0);
    ctx.params = fitted;
    std::string text = StrCat("nominal parameters fitted on the first ",
                              static_cast<int>(100 * options.calibration_fraction), "% of the rows:");
    for (int i : fit_index) text += StrCat(" ", model->param_specs()[i].name, "=", fitted[i]);
    for (int i : scale_index) text += StrCat(" ", model->param_specs()[i].name, "=", fitted[i]);
    if (!scale_index.empty()) text += " (common scale of the scaled parameters)";
    result.notes.push_back(text);
  }
  result.nominal_params = ctx.params;

  // Nominal inverse dynamics and residual at every row.
  ctx.id_nominal.resize(n, rows);
  Eigen::MatrixXd tip(n, rows);
  for (int r = 0; r < rows; ++r) {
    const int k = sd.rows[r];
    ctx.id_nominal.col(r) = model->InverseDynamics(Eigen::VectorXd(sd.q.col(k)), Eigen::VectorXd(sd.qd.col(k)),
                                                   Eigen::VectorXd(sd.qdd.col(k)), ctx.params);
    tip.col(r) = model->TipLoad(Eigen::VectorXd(sd.q.col(k)), Eigen::VectorXd(sd.qd.col(k)),
                                Eigen::VectorXd(sd.qdd.col(k)), ctx.params);
  }
  const Eigen::MatrixXd residual = ctx.tau - ctx.id_nominal;
  if (!residual.allFinite()) throw NumericalError("diagnose: non-finite nominal residual");

  // Split: the last holdout_fraction of the rows (in time) is held out.
  const int train_count = static_cast<int>(std::lround((1.0 - options.holdout_fraction) * rows));
  DIFFDYN_CHECK(train_count >= 10 && rows - train_count >= 5, "--measured ", data.path,
                ": too few rows (", rows, ") to hold out ", options.holdout_fraction);
  for (int r = 0; r < rows; ++r) (r < train_count ? ctx.train : ctx.heldout).push_back(r);
  result.train_rows = train_count;
  result.heldout_rows = rows - train_count;
  double train_seconds = 0;
  for (std::size_t i = 1; i < ctx.train.size(); ++i) {
    const int a = sd.rows[ctx.train[i - 1]], b = sd.rows[ctx.train[i]];
    if (sd.segment_of[a] == sd.segment_of[b]) train_seconds += sd.t[b] - sd.t[a];
  }
  const double n_eff = std::clamp(train_seconds * sd.IndependentRate(), 2.0,
                                  static_cast<double>(train_count));
  result.n_eff_train = n_eff;
  const double inflation = train_count / n_eff;

  // Where the error concentrates: correlation of the residual with each signal.
  result.residual_correlation.resize(n, 4 * n);
  for (int j = 0; j < n; ++j) {
    for (int c = 0; c < 4 * n; ++c) {
      Eigen::VectorXd a(train_count), b(train_count);
      for (int i = 0; i < train_count; ++i) {
        const int k = sd.rows[i];
        a[i] = residual(j, i);
        const int which = c / n, jj = c % n;
        b[i] = which == 0 ? sd.q(jj, k) : which == 1 ? sd.qd(jj, k) : which == 2 ? sd.qdd(jj, k) : sd.tau(jj, k);
      }
      a.array() -= a.mean();
      b.array() -= b.mean();
      const double den = a.norm() * b.norm();
      result.residual_correlation(j, c) = den > 0 ? a.dot(b) / den : 0.0;
    }
  }

  // ---- candidate columns ----
  std::vector<EffectKind> kinds = options.kinds;
  if (kinds.empty()) {
    for (const auto& info : AllEffectKinds()) {
      if (info.kind != EffectKind::kResidual) kinds.push_back(info.kind);
    }
  }
  auto wanted = [&](EffectKind k) { return std::find(kinds.begin(), kinds.end(), k) != kinds.end(); };
  LinearStage ls;
  ls.n = n;
  auto add_column = [&](Eigen::MatrixXd column) {
    ls.column_data.push_back(std::move(column));
    return static_cast<int>(ls.column_data.size()) - 1;
  };
  for (int j = 0; j < n; ++j) {
    const int joint = j + 1;
    auto joint_column = [&](auto&& value) {
      Eigen::MatrixXd c = Eigen::MatrixXd::Zero(n, rows);
      for (int r = 0; r < rows; ++r) c(j, r) = value(r, sd.rows[r]);
      return c;
    };
    if (wanted(EffectKind::kViscous)) {
      const int c = add_column(joint_column([&](int, int k) { return sd.qd(j, k); }));
      ls.candidates.push_back({EffectKind::kViscous, joint, 0, {c}, 1, StrCat("viscous j", joint)});
    }
    int tanh_col = -1;
    if (wanted(EffectKind::kCoulomb) || wanted(EffectKind::kStribeck)) {
      tanh_col = add_column(joint_column([&](int r, int) {
        return SmoothedFeature<double>(sd, r, j, [](double v) { return std::tanh(v / kCoulombVelocityScale); });
      }));
    }
    if (wanted(EffectKind::kCoulomb)) {
      ls.candidates.push_back({EffectKind::kCoulomb, joint, 0, {tanh_col}, 1, StrCat("coulomb j", joint)});
    }
    if (wanted(EffectKind::kStribeck)) {
      for (int g = 0; g < kStribeckGridSize; ++g) {
        const double vs = kStribeckGrid[g];
        const int c = add_column(joint_column([&](int r, int) {
          return SmoothedFeature<double>(sd, r, j, [vs](double v) {
            return std::exp(-(v / vs) * (v / vs)) * std::tanh(v / kCoulombVelocityScale);
          });
        }));
        ls.candidates.push_back({EffectKind::kStribeck, joint, vs, {tanh_col, c}, 3,
                                 StrCat("stribeck j", joint)});
      }
    }
    if (wanted(EffectKind::kOffset)) {
      const int c = add_column(joint_column([](int, int) { return -1.0; }));
      ls.candidates.push_back({EffectKind::kOffset, joint, 0, {c}, 1, StrCat("offset j", joint)});
    }
    if (wanted(EffectKind::kSpring)) {
      const int c = add_column(joint_column([&](int, int k) { return sd.q(j, k); }));
      ls.candidates.push_back({EffectKind::kSpring, joint, 0, {c}, 1, StrCat("spring j", joint)});
    }
    if (wanted(EffectKind::kArmature)) {
      const int c = add_column(joint_column([&](int, int k) { return sd.qdd(j, k); }));
      ls.candidates.push_back({EffectKind::kArmature, joint, 0, {c}, 1, StrCat("armature j", joint)});
    }
  }
  if (wanted(EffectKind::kPayload)) {
    const int c = add_column(tip);
    ls.candidates.push_back({EffectKind::kPayload, 0, 0, {c}, 1, "payload"});
  }
  if (wanted(EffectKind::kGain) && data.has_tau) {
    const int c = add_column(ctx.id_nominal);
    ls.candidates.push_back({EffectKind::kGain, 0, 0, {c}, 1, "gain"});
  }
  if (wanted(EffectKind::kDelay) && data.has_tau) {
    Eigen::MatrixXd c(n, rows);
    for (int r = 0; r < rows; ++r) c.col(r) = sd.dtau.col(sd.rows[r]);
    ls.candidates.push_back({EffectKind::kDelay, 0, 0, {add_column(c)}, 1, "delay"});
  }
  ls.cols = static_cast<int>(ls.column_data.size());
  // Distinct effects tested (a stribeck grid counts once per joint).
  int distinct = 0;
  for (std::size_t i = 0; i < ls.candidates.size(); ++i) {
    if (i == 0 || ls.candidates[i].label != ls.candidates[i - 1].label) ++distinct;
  }

  // Gram blocks per fold and joint over the train rows (contiguous folds).
  ls.folds = options.folds;
  ls.gram.assign(ls.folds, std::vector<Eigen::MatrixXd>(n, Eigen::MatrixXd::Zero(ls.cols, ls.cols)));
  ls.cross.assign(ls.folds, std::vector<Eigen::VectorXd>(n, Eigen::VectorXd::Zero(ls.cols)));
  ls.energy.assign(ls.folds, std::vector<double>(n, 0.0));
  ls.fold_rows.assign(ls.folds, 0);
  for (int f = 0; f < ls.folds; ++f) {
    const int a = f * train_count / ls.folds, b = (f + 1) * train_count / ls.folds;
    ls.fold_rows[f] = b - a;
    for (int j = 0; j < n; ++j) {
      Eigen::MatrixXd x(b - a, ls.cols);
      for (int c = 0; c < ls.cols; ++c) x.col(c) = ls.column_data[c].row(j).segment(a, b - a).transpose();
      const Eigen::VectorXd y = residual.row(j).segment(a, b - a).transpose();
      ls.gram[f][j] = x.transpose() * x;
      ls.cross[f][j] = x.transpose() * y;
      ls.energy[f][j] = y.squaredNorm();
    }
  }

  // Criterion pieces for a column set.
  const std::vector<bool> all_folds(ls.folds, true);
  const double sse_floor = 1e-24 * (1.0 + ctx.tau.squaredNorm());
  struct Eval {
    Eigen::VectorXd beta, sse;
    double ebic = 0;
  };
  auto columns_of = [&](const std::vector<int>& set) {
    std::vector<int> s;
    for (int c : set) {
      for (int col : ls.candidates[c].columns) {
        if (std::find(s.begin(), s.end(), col) == s.end()) s.push_back(col);
      }
    }
    return s;
  };
  auto weights_for = [&](const Eigen::VectorXd& sse) {
    return (1.0 / (sse.array() / train_count + sse_floor)).matrix().eval();
  };
  auto evaluate = [&](const std::vector<int>& set, const Eigen::VectorXd& w) {
    Eval e;
    const std::vector<int> s = columns_of(set);
    // Two passes of feasible GLS: weights from this set's own per-joint SSE.
    Eigen::VectorXd weights = w;
    for (int pass = 0; pass < 2; ++pass) {
      e.beta = FitColumns(ls, s, all_folds, weights);
      e.sse = Eigen::VectorXd::Zero(n);
      for (int f = 0; f < ls.folds; ++f) {
        for (int j = 0; j < n; ++j) e.sse[j] += FoldSse(ls, s, e.beta, f, j);
      }
      weights = weights_for(e.sse);
    }
    int k_params = 0;
    for (int c : set) k_params += ls.candidates[c].n_params;
    e.ebic = k_params * std::log(n_eff) + 2.0 * LogBinomial(distinct, static_cast<int>(set.size()));
    for (int j = 0; j < n; ++j) e.ebic += n_eff * std::log(e.sse[j] / train_count + sse_floor);
    return e;
  };
  auto cross_validate = [&](const std::vector<int>& set, const Eigen::VectorXd& w) {
    const std::vector<int> s = columns_of(set);
    double total = 0;
    for (int f = 0; f < ls.folds; ++f) {
      std::vector<bool> use(ls.folds, true);
      use[f] = false;
      const Eigen::VectorXd beta = FitColumns(ls, s, use, w);
      for (int j = 0; j < n; ++j) total += w[j] * FoldSse(ls, s, beta, f, j);
    }
    return total;
  };
  auto conflicts = [&](int a, int b) {
    const Candidate& x = ls.candidates[a];
    const Candidate& y = ls.candidates[b];
    const bool fx = IsFriction(x.kind), fy = IsFriction(y.kind);
    return x.joint == y.joint && x.joint > 0 && fx && fy;
  };
  // Torque RMS of candidate `c`'s part of the fit over the train rows, relative to noise.
  auto contribution_to_noise = [&](const std::vector<int>& set, const Eval& e, int c) {
    const std::vector<int> s = columns_of(set);
    Eigen::MatrixXd part = Eigen::MatrixXd::Zero(n, train_count);
    for (std::size_t a = 0; a < s.size(); ++a) {
      const auto& cols = ls.candidates[c].columns;
      if (std::find(cols.begin(), cols.end(), s[a]) == cols.end()) continue;
      part += e.beta[a] * ls.column_data[s[a]].leftCols(train_count);
    }
    const Candidate& cand = ls.candidates[c];
    if (cand.joint > 0) {
      const double noise = sd.tau_noise[cand.joint - 1];
      const double rms = std::sqrt(part.row(cand.joint - 1).squaredNorm() / train_count);
      return noise > 0 ? rms / noise : std::numeric_limits<double>::infinity();
    }
    const double noise = std::sqrt(sd.tau_noise.squaredNorm() / n);
    const double rms = std::sqrt(part.squaredNorm() / (n * train_count));
    return noise > 0 ? rms / noise : std::numeric_limits<double>::infinity();
  };

  // The mass matrix of the extended model must stay positive definite:
  // M_ext(q) = M(q) + sum diag(I_a) + m_p M_tip(q), where M_tip (the unit tip
  // mass's inertia) is positive semi-definite. A negative armature or payload
  // estimate can break this; it is checked on every training row.
  std::vector<Eigen::MatrixXd> mass_rows, tip_mass_rows;
  auto mass_definite = [&](const std::vector<Effect>& effects) {
    bool negative = false;
    for (const Effect& e : effects) {
      if ((e.kind == EffectKind::kArmature || e.kind == EffectKind::kPayload) && e.params[0] < 0) negative = true;
    }
    if (!negative) return true;
    if (mass_rows.empty()) {
      const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
      for (int i = 0; i < train_count; ++i) {
        const Eigen::VectorXd q = sd.q.col(sd.rows[ctx.train[i]]);
        mass_rows.push_back(model->MassMatrix(q, ctx.params));
        const Eigen::VectorXd bias = model->TipLoad(q, zero, zero, ctx.params);
        Eigen::MatrixXd tm(n, n);
        for (int c = 0; c < n; ++c) tm.col(c) = model->TipLoad(q, zero, Eigen::VectorXd::Unit(n, c), ctx.params) - bias;
        tip_mass_rows.push_back(0.5 * (tm + tm.transpose()));
      }
    }
    for (std::size_t i = 0; i < mass_rows.size(); ++i) {
      Eigen::MatrixXd m = mass_rows[i];
      for (const Effect& e : effects) {
        if (e.kind == EffectKind::kArmature) m(e.joint - 1, e.joint - 1) += e.params[0];
        if (e.kind == EffectKind::kPayload) m += e.params[0] * tip_mass_rows[i];
      }
      const Eigen::LDLT<Eigen::MatrixXd> ldlt(m);
      if (ldlt.info() != Eigen::Success || !ldlt.isPositive() ||
          ldlt.vectorD().minCoeff() <= 1e-9 * m.diagonal().cwiseAbs().maxCoeff()) {
        return false;
      }
    }
    return true;
  };
  // The inertial effects (armature, payload) of `set` with their linear-fit values.
  auto inertial_effects = [&](const std::vector<int>& set, const Eval& e) {
    const std::vector<int> s = columns_of(set);
    std::vector<Effect> out;
    for (int c : set) {
      const Candidate& cand = ls.candidates[c];
      if (cand.kind != EffectKind::kArmature && cand.kind != EffectKind::kPayload) continue;
      const int at = static_cast<int>(std::find(s.begin(), s.end(), cand.columns[0]) - s.begin());
      out.push_back({cand.kind, cand.joint, {e.beta[at]}, {}});
    }
    return out;
  };

  // ---- forward stepwise selection ----
  std::vector<int> current;
  Eval cur = evaluate(current, weights_for(residual.leftCols(train_count).rowwise().squaredNorm()));
  std::vector<bool> excluded(ls.candidates.size(), false);
  while (static_cast<int>(current.size()) < options.max_effects) {
    int best = -1;
    Eval best_eval;
    std::vector<int> best_set;
    for (int c = 0; c < static_cast<int>(ls.candidates.size()); ++c) {
      if (excluded[c] || std::find(current.begin(), current.end(), c) != current.end()) continue;
      std::vector<int> set;
      for (int s : current) {
        if (!conflicts(s, c)) set.push_back(s);
      }
      set.push_back(c);
      const Eval e = evaluate(set, weights_for(cur.sse));
      if (best < 0 || e.ebic < best_eval.ebic) {
        best = c;
        best_eval = e;
        best_set = set;
      }
    }
    if (best < 0) break;
    SelectionStep step;
    step.candidate = ls.candidates[best].label;
    step.ebic_before = cur.ebic;
    step.ebic_after = best_eval.ebic;
    const Eigen::VectorXd w = weights_for(cur.sse);
    step.cv_before = cross_validate(current, w);
    step.cv_after = cross_validate(best_set, w);
    step.contribution_to_noise = contribution_to_noise(best_set, best_eval, best);
    if (best_eval.ebic >= cur.ebic) {
      step.reason = "no candidate lowers the information criterion";
      result.steps.push_back(step);
      break;
    }
    if (step.cv_after >= step.cv_before) {
      step.reason = "held-out (cross-validated) error does not fall";
      result.steps.push_back(step);
      break;
    }
    if (!mass_definite(inertial_effects(best_set, best_eval))) {
      step.reason = "the extended mass matrix would not be positive definite";
      result.steps.push_back(step);
      excluded[best] = true;
      continue;
    }
    if (step.contribution_to_noise < options.min_effect_to_noise) {
      step.reason = "torque contribution below the sensor-noise level";
      result.steps.push_back(step);
      // Excluding every grid point of the same effect.
      for (std::size_t c = 0; c < ls.candidates.size(); ++c) {
        if (ls.candidates[c].label == ls.candidates[best].label) excluded[c] = true;
      }
      continue;
    }
    step.accepted = true;
    step.reason = "accepted";
    result.steps.push_back(step);
    current = best_set;
    cur = best_eval;
  }

  if (cv_gain != nullptr) {
    // Unweighted blocked cross-validation of the selected set against nothing.
    const std::vector<int> s = columns_of(current);
    const Eigen::VectorXd w = weights_for(cur.sse);
    double sse_nominal = 0, sse_selected = 0;
    for (int f = 0; f < ls.folds; ++f) {
      std::vector<bool> use(ls.folds, true);
      use[f] = false;
      const Eigen::VectorXd beta = FitColumns(ls, s, use, w);
      for (int j = 0; j < n; ++j) {
        sse_nominal += ls.energy[f][j];
        sse_selected += FoldSse(ls, s, beta, f, j);
      }
    }
    *cv_gain = sse_nominal > 0 ? 1.0 - sse_selected / sse_nominal : 0.0;
    result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
  }

  // ---- effects from the linear fit (values and standard errors) ----
  std::vector<Effect> effects;
  {
    const std::vector<int> s = columns_of(current);
    const Eigen::VectorXd w = weights_for(cur.sse);
    Eigen::MatrixXd g;
    const Eigen::VectorXd beta = FitColumns(ls, s, all_folds, w, &g);
    Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(s.size(), s.size());
    if (!s.empty()) cov = g.completeOrthogonalDecomposition().pseudoInverse() * inflation;
    auto at = [&](int col) {
      return static_cast<int>(std::find(s.begin(), s.end(), col) - s.begin());
    };
    for (int c : current) {
      const Candidate& cand = ls.candidates[c];
      Effect e;
      e.kind = cand.kind;
      e.joint = cand.joint;
      const int i0 = at(cand.columns[0]);
      const double b0 = beta[i0], s0 = std::sqrt(std::max(0.0, cov(i0, i0)));
      switch (cand.kind) {
        case EffectKind::kStribeck: {
          const int i1 = at(cand.columns[1]);
          e.params = {b0, b0 + beta[i1], cand.v_s};
          e.stderrs = {s0, std::sqrt(std::max(0.0, cov(i0, i0) + cov(i1, i1) + 2 * cov(i0, i1))), 0.0};
          break;
        }
        case EffectKind::kGain:
          e.params = {1.0 / (1.0 + b0)};
          e.stderrs = {s0 / ((1.0 + b0) * (1.0 + b0))};
          break;
        default:
          e.params = {b0};
          e.stderrs = {s0};
      }
      effects.push_back(e);
    }
  }
  ExtendedModel extended(model, ctx.params, effects);
  const Eigen::VectorXd inv_sigma =
      (cur.sse.array() / train_count + sse_floor).rsqrt().matrix();
  if (options.refit && !effects.empty()) {
    const ExtendedModel refitted = RefitEffects(ctx, extended, ctx.train, inv_sigma, inflation);
    if (mass_definite(refitted.effects())) {
      extended = refitted;
    } else {
      result.notes.push_back("refit rejected: its armature or payload made the mass matrix indefinite; "
                             "the linear-stage values are kept");
    }
  }

  // ---- free motion: dissipation from the energy balance ----
  // Without input torque, a conservative mismatch (inertia, lengths) dominates
  // the torque residual but does no net work, while dissipation drains energy
  // steadily. Over windows w of the training rows the work the extended model
  // leaves unexplained, y_w = int_w qd . (tau - tau_hat) dt, is regressed on
  // x_wj = int_w qd_j^2 dt (viscous j) by forward selection with the same
  // EBIC and blocked cross-validation over windows; a coefficient b_j > 0
  // (dissipative) is named viscous j with its regression standard error.
  if (!data.has_tau && (options.kinds.empty() || wanted(EffectKind::kViscous))) {
    const Eigen::MatrixXd pred = PredictAll(ctx, extended);
    std::vector<double> y;
    std::vector<Eigen::VectorXd> x;
    double acc = 0, start_t = sd.t[sd.rows[ctx.train.front()]];
    Eigen::VectorXd acc_x = Eigen::VectorXd::Zero(n);
    for (std::size_t i = 1; i < ctx.train.size(); ++i) {
      const int ra = ctx.train[i - 1], rb = ctx.train[i];
      const int ka = sd.rows[ra], kb = sd.rows[rb];
      if (sd.segment_of[ka] != sd.segment_of[kb]) {
        acc = 0;
        acc_x.setZero();
        start_t = sd.t[kb];
        continue;
      }
      const double dt = sd.t[kb] - sd.t[ka];
      acc += 0.5 * dt * (sd.qd.col(ka).dot(ctx.tau.col(ra) - pred.col(ra)) +
                         sd.qd.col(kb).dot(ctx.tau.col(rb) - pred.col(rb)));
      acc_x += 0.5 * dt * (sd.qd.col(ka).array().square() + sd.qd.col(kb).array().square()).matrix();
      if (sd.t[kb] - start_t >= options.energy_window) {
        y.push_back(acc);
        x.push_back(acc_x);
        acc = 0;
        acc_x.setZero();
        start_t = sd.t[kb];
      }
    }
    const int windows = static_cast<int>(y.size());
    if (windows >= 2 * options.folds) {
      const Eigen::VectorXd yv = Eigen::Map<const Eigen::VectorXd>(y.data(), windows);
      Eigen::MatrixXd xm(windows, n);
      for (int w = 0; w < windows; ++w) xm.row(w) = x[w].transpose();
      auto fit = [&](const std::vector<int>& set, const std::vector<int>& rows_used) {
        Eigen::MatrixXd a(rows_used.size(), set.size());
        Eigen::VectorXd b(rows_used.size());
        for (std::size_t r = 0; r < rows_used.size(); ++r) {
          for (std::size_t c = 0; c < set.size(); ++c) a(r, c) = xm(rows_used[r], set[c]);
          b[r] = yv[rows_used[r]];
        }
        return Eigen::VectorXd(a.colPivHouseholderQr().solve(b));
      };
      auto sse_of = [&](const std::vector<int>& set, const Eigen::VectorXd& beta, const std::vector<int>& rows_used) {
        double sse = 0;
        for (int r : rows_used) {
          double p = 0;
          for (std::size_t c = 0; c < set.size(); ++c) p += beta[c] * xm(r, set[c]);
          sse += (yv[r] - p) * (yv[r] - p);
        }
        return sse;
      };
      std::vector<int> all(windows);
      std::iota(all.begin(), all.end(), 0);
      auto ebic = [&](const std::vector<int>& set) {
        const double sse = set.empty() ? yv.squaredNorm() : sse_of(set, fit(set, all), all);
        return windows * std::log(sse / windows + 1e-300) + set.size() * std::log(windows) +
               2.0 * LogBinomial(n, static_cast<int>(set.size()));
      };
      auto cv = [&](const std::vector<int>& set) {
        double total = 0;
        for (int f = 0; f < options.folds; ++f) {
          const int a = f * windows / options.folds, b = (f + 1) * windows / options.folds;
          std::vector<int> train_w, test_w;
          for (int w = 0; w < windows; ++w) (w >= a && w < b ? test_w : train_w).push_back(w);
          if (set.empty()) {
            total += sse_of(set, Eigen::VectorXd(), test_w);
          } else {
            total += sse_of(set, fit(set, train_w), test_w);
          }
        }
        return total;
      };
      std::vector<int> chosen;
      while (static_cast<int>(chosen.size()) < n) {
        int best = -1;
        double best_ebic = 0;
        for (int j = 0; j < n; ++j) {
          if (std::find(chosen.begin(), chosen.end(), j) != chosen.end()) continue;
          bool has_friction = false;
          for (const Effect& e : extended.effects()) {
            has_friction = has_friction || (e.joint == j + 1 && (IsFriction(e.kind) || e.kind == EffectKind::kViscous));
          }
          if (has_friction) continue;
          std::vector<int> set = chosen;
          set.push_back(j);
          const double e = ebic(set);
          if (best < 0 || e < best_ebic) {
            best = j;
            best_ebic = e;
          }
        }
        if (best < 0) break;
        std::vector<int> set = chosen;
        set.push_back(best);
        SelectionStep step;
        step.candidate = StrCat("viscous j", best + 1, " (energy balance over ", windows, " windows)");
        step.ebic_before = ebic(chosen);
        step.ebic_after = best_ebic;
        step.cv_before = cv(chosen);
        step.cv_after = cv(set);
        step.contribution_to_noise = std::numeric_limits<double>::infinity();
        const Eigen::VectorXd beta = fit(set, all);
        if (step.ebic_after >= step.ebic_before) {
          step.reason = "no dissipation lowers the information criterion";
        } else if (step.cv_after >= step.cv_before) {
          step.reason = "held-out (cross-validated) error does not fall";
        } else if (beta[set.size() - 1] <= 0) {
          step.reason = "not dissipative (b <= 0)";
        } else {
          step.accepted = true;
          step.reason = "accepted";
        }
        result.steps.push_back(step);
        if (!step.accepted) break;
        chosen = set;
      }
      if (!chosen.empty()) {
        const Eigen::VectorXd beta = fit(chosen, all);
        Eigen::MatrixXd a(windows, chosen.size());
        for (std::size_t c = 0; c < chosen.size(); ++c) a.col(c) = xm.col(chosen[c]);
        const double s2 = sse_of(chosen, beta, all) / std::max(1, windows - static_cast<int>(chosen.size()));
        const Eigen::MatrixXd cov = Eigen::MatrixXd(a.transpose() * a).inverse() * s2;
        std::vector<Effect> effects_all = extended.effects();
        for (std::size_t c = 0; c < chosen.size(); ++c) {
          effects_all.push_back({EffectKind::kViscous, chosen[c] + 1, {beta[c]}, {std::sqrt(cov(c, c))}});
        }
        extended = ExtendedModel(model, ctx.params, effects_all);
      }
    }
  }

  // ---- learned residuals ----
  auto inputs_of = [&](const std::vector<int>& idx) {
    Eigen::MatrixXd x(3 * n, idx.size());
    for (std::size_t i = 0; i < idx.size(); ++i) {
      const int k = sd.rows[idx[i]];
      // qdd left out (zeros): a residual r(q, qd) keeps the extended mass
      // matrix the physical one, so forward dynamics stays well posed.
      x.col(i) << sd.q.col(k), sd.qd.col(k), Eigen::VectorXd::Zero(n);
    }
    return x;
  };
  auto targets_of = [&](const Eigen::MatrixXd& res, const std::vector<int>& idx) {
    Eigen::MatrixXd y(n, idx.size());
    for (std::size_t i = 0; i < idx.size(); ++i) y.col(i) = res.col(idx[i]);
    return y;
  };
  // Fits a residual network on `train` (ridge chosen on its last 20 %); returns
  // the network and the validation SSE drop it achieved.
  auto fit_residual = [&](const Eigen::MatrixXd& res, const std::vector<int>& train,
                          double* validation_gain) {
    const int cut = static_cast<int>(0.8 * train.size());
    const std::vector<int> inner(train.begin(), train.begin() + cut);
    const std::vector<int> valid(train.begin() + cut, train.end());
    const Eigen::MatrixXd yv = targets_of(res, valid);
    const Eigen::VectorXd wv = weights_for(targets_of(res, train).rowwise().squaredNorm());
    const Eigen::MatrixXd xv = inputs_of(valid);
    double best_lambda = 1e-3, best_sse = std::numeric_limits<double>::infinity();
    for (double lambda : {1e-5, 1e-4, 1e-3, 1e-2, 1e-1}) {
      Rng rng(options.seed);
      const ResidualNetwork net = ResidualNetwork::Fit(inputs_of(inner), targets_of(res, inner),
                                                       options.residual_hidden, lambda, rng);
      double sse = 0;
      for (int i = 0; i < xv.cols(); ++i) {
        const Eigen::VectorXd x = xv.col(i);
        const Eigen::VectorXd pred = net(Eigen::VectorXd(x.head(n)), Eigen::VectorXd(x.segment(n, n)),
                                         Eigen::VectorXd(x.tail(n)));
        sse += (wv.array() * (yv.col(i) - pred).array().square()).sum();
      }
      if (sse < best_sse) {
        best_sse = sse;
        best_lambda = lambda;
      }
    }
    const double base = (wv.asDiagonal() * yv.array().square().matrix()).sum();
    if (validation_gain) *validation_gain = base > 0 ? 1.0 - best_sse / base : 0.0;
    Rng rng(options.seed);
    return std::make_shared<const ResidualNetwork>(ResidualNetwork::Fit(
        inputs_of(train), targets_of(res, train), options.residual_hidden, best_lambda, rng));
  };
  auto residual_prediction = [&](const ResidualNetwork& net) {
    Eigen::MatrixXd out(n, rows);
    for (int r = 0; r < rows; ++r) {
      const int k = sd.rows[r];
      out.col(r) = net(Eigen::VectorXd(sd.q.col(k)), Eigen::VectorXd(sd.qd.col(k)),
                       Eigen::VectorXd(sd.qdd.col(k)));
    }
    return out;
  };
  const Eigen::MatrixXd learned_only =
      ctx.id_nominal + residual_prediction(*fit_residual(residual, ctx.train, nullptr));

  // A residual network on top of the named effects, kept if it clearly helps.
  {
    const Eigen::VectorXd theta = extended.EffectParams();
    const double k_gain = extended.Gain<double>(theta);
    const Eigen::MatrixXd remaining = (ctx.tau - PredictAll(ctx, extended)) * k_gain;
    double gain = 0;
    auto net = fit_residual(remaining, ctx.train, &gain);
    result.notes.push_back(StrCat("learned residual on top of the named effects: validation SSE drop ",
                                  100 * gain, "% (named when above ",
                                  100 * options.residual_min_gain, "%)"));
    if (gain > options.residual_min_gain) extended = extended.WithResidual(net);
  }
  {
    std::vector<Effect> named = extended.effects();
    if (extended.residual()) named.push_back({EffectKind::kResidual, 0, {}, {}});
    result.named_effects = named;
  }
  result.no_significant_discrepancy = result.named_effects.empty();

  // ---- scores on the held-out rows ----
  const Eigen::MatrixXd pred_ext = PredictAll(ctx, extended);
  auto baseline_prediction = [&]() {
    Eigen::MatrixXd out = ctx.id_nominal;
    for (int r = 0; r < rows; ++r) {
      for (int j = 0; j < n; ++j) {
        out(j, r) += SmoothedFeature<double>(sd, r, j, [j](double v) {
          Eigen::VectorXd qd = Eigen::VectorXd::Zero(7);
          qd[j] = v;
          return PandaSigmoidFriction(qd)[j];
        });
      }
    }
    return out;
  };
  const bool panda = model->name() == "panda";
  const Eigen::MatrixXd pred_baseline = panda ? baseline_prediction() : Eigen::MatrixXd();
  auto score = [&](const std::string& name, const std::vector<int>& held, const Eigen::MatrixXd& ext_pred,
                   const Eigen::MatrixXd& learned_pred) {
    SplitScore s;
    s.name = name;
    s.heldout_rows = static_cast<int>(held.size());
    s.sse_nominal = Sse(ctx, ctx.id_nominal, held);
    s.sse_extended = Sse(ctx, ext_pred, held);
    const double base = s.sse_nominal.sum();
    s.sse_removed = base > 0 ? 1.0 - s.sse_extended.sum() / base : 0.0;
    s.sse_removed_learned = base > 0 ? 1.0 - Sse(ctx, learned_pred, held).sum() / base : 0.0;
    if (panda) s.sse_removed_baseline = base > 0 ? 1.0 - Sse(ctx, pred_baseline, held).sum() / base : 0.0;
    return s;
  };
  result.splits.push_back(score(StrCat("last ", std::lround(100 * options.holdout_fraction), "% in time"),
                                ctx.heldout, pred_ext, learned_only));
  const SplitScore& main = result.splits[0];
  result.heldout_sse_removed = main.sse_removed;
  result.heldout_sse_removed_learned = main.sse_removed_learned;
  result.sse_removed_per_joint = (1.0 - main.sse_extended.array() / main.sse_nominal.array().max(1e-300)).matrix();
  result.nominal_rmse = (main.sse_nominal / std::max(1, main.heldout_rows)).cwiseSqrt();
  result.extended_rmse = (main.sse_extended / std::max(1, main.heldout_rows)).cwiseSqrt();

  // A held-out phase window of a periodic motion: refit the same effects on the rest.
  if (options.phase_period > 0) {
    std::vector<int> train, held;
    const double lo = 1.0 - options.phase_window_fraction;
    for (int r = 0; r < rows; ++r) {
      const double phase = std::fmod(sd.t[sd.rows[r]] - sd.t[0], options.phase_period) / options.phase_period;
      (phase >= lo ? held : train).push_back(r);
    }
    if (held.size() >= 5 && train.size() >= 10) {
      ExtendedModel refit = extended.WithResidual(nullptr);
      if (!refit.effects().empty()) refit = RefitEffects(ctx, refit, train, inv_sigma, inflation);
      if (extended.residual()) {
        const Eigen::MatrixXd remaining = (ctx.tau - PredictAll(ctx, refit)) * refit.Gain<double>(refit.EffectParams());
        refit = refit.WithResidual(fit_residual(remaining, train, nullptr));
      }
      const Eigen::MatrixXd learned = ctx.id_nominal + residual_prediction(*fit_residual(residual, train, nullptr));
      result.splits.push_back(score(StrCat("phase window [", lo * options.phase_period, ", ",
                                           options.phase_period, ") s of the ", options.phase_period,
                                           " s period"),
                                    held, PredictAll(ctx, refit), learned));
    }
  }

  // ---- rollouts over short windows of the held-out part ----
  {
    const int count = sd.t.size();
    const ExtendedModel nominal_ext(model, ctx.params, {});
    const Eigen::VectorXd theta = extended.EffectParams();
    const double delay = extended.Delay<double>(theta);
    Eigen::VectorXd sq_q_nom = Eigen::VectorXd::Zero(n), sq_q_ext = sq_q_nom, sq_v_nom = sq_q_nom,
                    sq_v_ext = sq_q_nom;
    int windows = 0, failed = 0;
    double next_start = -1e300;
    for (int r : ctx.heldout) {
      const int k0 = sd.rows[r];
      const double t0 = sd.t[k0];
      if (t0 < next_start) continue;
      const int seg = sd.segment_of[k0];
      if (t0 + options.rollout_horizon > sd.t[sd.segment_bounds[seg + 1] - 1] - 3 * sd.sigma_t) continue;
      next_start = t0 + options.rollout_horizon;
      // Torque input at time t (measured, smoothed), optionally delayed.
      auto tau_at = [&](double time) {
        Eigen::VectorXd q, qd, qdd;
        (void)q;
        const int begin = sd.segment_bounds[seg], end = sd.segment_bounds[seg + 1];
        const double tt = std::clamp(time, sd.t[begin], sd.t[end - 1]);
        int lo = std::max(begin, static_cast<int>(std::upper_bound(sd.t.data() + begin, sd.t.data() + end, tt) - sd.t.data()) - 1);
        lo = std::min(lo, end - 2);
        const double w = (tt - sd.t[lo]) / (sd.t[lo + 1] - sd.t[lo]);
        return Eigen::VectorXd(sd.tau.col(lo) + w * (sd.tau.col(lo + 1) - sd.tau.col(lo)));
      };
      const double dt_median = (sd.t[std::min(count - 1, k0 + 1)] - sd.t[k0]);
      const int steps = std::max(10, static_cast<int>(std::ceil(options.rollout_horizon / std::max(1e-3, dt_median))));
      auto roll = [&](const ExtendedModel& m, double d) {
        Eigen::VectorXd q = sd.q.col(k0), v = sd.qd.col(k0);
        IntegrateJointMotion(m, [&](double time) { return tau_at(time - d); }, t0,
                             t0 + options.rollout_horizon, steps, q, v);
        return std::make_pair(q, v);
      };
      Eigen::VectorXd q_end, v_end, unused;
      sd.StateAt<double>(t0 + options.rollout_horizon, seg, q_end, v_end, unused);
      Eigen::VectorXd qn, vn;
      try {
        std::tie(qn, vn) = roll(nominal_ext, 0.0);
      } catch (const NumericalError&) {
        ++failed;
        qn = Eigen::VectorXd::Constant(n, kNaN);
        vn = qn;
      }
      // An extended mass matrix that is not positive definite (e.g. a negative
      // armature) makes the extended rollout meaningless: counted, reported NaN.
      Eigen::VectorXd qe, ve;
      try {
        std::tie(qe, ve) = roll(extended, delay);
      } catch (const NumericalError&) {
        ++failed;
        qe = Eigen::VectorXd::Constant(n, kNaN);
        ve = qe;
      }
      sq_q_nom += (qn - q_end).array().square().matrix();
      sq_v_nom += (vn - v_end).array().square().matrix();
      sq_q_ext += (qe - q_end).array().square().matrix();
      sq_v_ext += (ve - v_end).array().square().matrix();
      ++windows;
    }
    const double wn = std::max(1, windows);
    result.rollout_q_nominal = (sq_q_nom / wn).cwiseSqrt();
    result.rollout_q_extended = (sq_q_ext / wn).cwiseSqrt();
    result.rollout_qd_nominal = (sq_v_nom / wn).cwiseSqrt();
    result.rollout_qd_extended = (sq_v_ext / wn).cwiseSqrt();
    result.notes.push_back(StrCat("rollouts: ", windows, " held-out windows of ", options.rollout_horizon,
                                  " s from the measured state, RK4, measured torque as input",
                                  failed > 0 ? StrCat("; a mass matrix was not positive "
                                                      "definite in ", failed, " rollouts (NaN)")
                                             : std::string()));
  }

  // ---- energy balance over windows: the integral of qd . (tau - tau_hat) ----
  {
    auto energy_error = [&](const Eigen::MatrixXd& pred) {
      double sum_sq = 0, acc = 0, window_start = sd.t[sd.rows[ctx.heldout.front()]];
      int windows = 0;
      for (std::size_t i = 1; i < ctx.heldout.size(); ++i) {
        const int ra = ctx.heldout[i - 1], rb = ctx.heldout[i];
        const int ka = sd.rows[ra], kb = sd.rows[rb];
        if (sd.segment_of[ka] != sd.segment_of[kb]) {
          acc = 0;
          window_start = sd.t[kb];
          continue;
        }
        const double pa = sd.qd.col(ka).dot(ctx.tau.col(ra) - pred.col(ra));
        const double pb = sd.qd.col(kb).dot(ctx.tau.col(rb) - pred.col(rb));
        acc += 0.5 * (pa + pb) * (sd.t[kb] - sd.t[ka]);
        if (sd.t[kb] - window_start >= options.energy_window) {
          sum_sq += acc * acc;
          ++windows;
          acc = 0;
          window_start = sd.t[kb];
        }
      }
      return windows > 0 ? std::sqrt(sum_sq / windows) : 0.0;
    };
    result.energy_error_nominal = energy_error(ctx.id_nominal);
    result.energy_error_extended = energy_error(pred_ext);
  }

  // ---- plot arrays ----
  result.row_t.resize(rows);
  result.row_q.resize(n, rows);
  result.row_qd.resize(n, rows);
  result.row_heldout.assign(rows, false);
  for (int r = 0; r < rows; ++r) {
    const int k = sd.rows[r];
    result.row_t[r] = sd.t[k];
    result.row_q.col(r) = sd.q.col(k);
    result.row_qd.col(r) = sd.qd.col(k);
    result.row_heldout[r] = r >= train_count;
  }
  result.residual_nominal = residual;
  result.residual_extended = ctx.tau - pred_ext;
  result.extended = extended;
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace

DiagnosisResult Diagnose(std::shared_ptr<const AnalyticModel> model, const Eigen::VectorXd& params,
                         const JointData& data, const DiagnosisOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  DIFFDYN_CHECK(options.cutoff_hz >= 0 && options.cutoff_hz <= kMaxCutoffHz, "--cutoff-hz ",
                options.cutoff_hz, ": must be in (0, ", kMaxCutoffHz, "] Hz (0 chooses it)");
  // The torque-noise estimate comes from the highest cutoff, where the motion
  // does not leak into tau - smooth(tau).
  const Eigen::VectorXd tau_noise = SmoothJointData(data, kMaxCutoffHz).tau_noise;
  if (options.cutoff_hz > 0) return DiagnoseAtCutoff(model, params, data, options, tau_noise, nullptr);
  // Calibrated nominal parameters change with the cutoff, so the scores below
  // would compare different nominal models: such runs keep the highest cutoff.
  if (!options.fit_params.empty() || !options.scale_params.empty()) {
    DiagnosisOptions at = options;
    at.cutoff_hz = kMaxCutoffHz;
    DiagnosisResult result = DiagnoseAtCutoff(model, params, data, at, tau_noise, nullptr);
    result.notes.insert(result.notes.begin(),
                        StrCat("cutoff ", kMaxCutoffHz, " Hz: nominal parameters are calibrated, so "
                               "cutoffs (whose nominal models differ) are not compared"));
    return result;
  }
  // Automatic cutoff: the selection stage at each cutoff of the grid, scored by
  // the cross-validated SSE fraction its named effects remove on the training
  // rows; the highest cutoff within kCutoffTolerance of the best score wins.
  std::vector<double> scores;
  std::string tried;
  for (double cutoff : kCutoffGrid) {
    DiagnosisOptions at = options;
    at.cutoff_hz = cutoff;
    double gain = 0.0;
    try {
      DiagnoseAtCutoff(model, params, data, at, tau_noise, &gain);
    } catch (const Error&) {
      gain = -std::numeric_limits<double>::infinity();  // record too short for this cutoff
    }
    scores.push_back(gain);
    tried += StrCat(tried.empty() ? "" : ", ", cutoff, " Hz: ", gain);
  }
  const double best = *std::max_element(scores.begin(), scores.end());
  double chosen = kCutoffGrid[0];
  for (std::size_t i = 0; i < scores.size(); ++i) {
    if (scores[i] >= best - kCutoffTolerance) {
      chosen = kCutoffGrid[i];
      break;
    }
  }
  DiagnosisOptions at = options;
  at.cutoff_hz = chosen;
  DiagnosisResult result = DiagnoseAtCutoff(model, params, data, at, tau_noise, nullptr);
  result.cutoff_hz = chosen;
  result.notes.insert(result.notes.begin(),
                      StrCat("cutoff chosen: ", chosen, " Hz, the highest whose cross-validated SSE "
                             "removed on the training rows is within ", kCutoffTolerance,
                             " of the best (", tried, ")"));
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace diffdyn
