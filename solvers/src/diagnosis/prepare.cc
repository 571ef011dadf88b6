#include "diffdyn/solvers/diagnosis/prepare.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>
#include <functional>

#include <ceres/ceres.h>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/diagnosis/refit.h"

namespace diffdyn {
namespace {

double Median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

// Median spacing of consecutive samples within trajectories (s); 0 without any.
double MedianSpacing(const Dataset& data) {
  return data.transitions() > 0 ? data.Intervals().median : 0.0;
}

// Residuals tau - ID(p(x)) on the first `count` rows, divided by the diagonal of
// M(q; p) (acceleration units, so shrinking the whole model cannot fit free motion).
class CalibrationCost : public ceres::CostFunction {
 public:
  using ParamsOf = std::function<VectorX<DiagJet>(const VectorX<DiagJet>&)>;
  CalibrationCost(const PreparedData& prep, int count, int free, ParamsOf params_of)
      : prep_(prep), count_(count), free_(free), params_of_(std::move(params_of)) {
    set_num_residuals(prep.n * count);
    mutable_parameter_block_sizes()->push_back(free);
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const int n = prep_.n;
    VectorX<DiagJet> xj(free_);
    for (int i = 0; i < free_; ++i) xj[i] = DiagJet(parameters[0][i], i);
    const VectorX<DiagJet> p = params_of_(xj);
    const VectorX<DiagJet> zero = VectorX<DiagJet>::Zero(n);
    for (int r = 0; r < count_; ++r) {
      const int k = prep_.Sample(r);
      const VectorX<DiagJet> q = prep_.sd.q.col(k).cast<DiagJet>();
      const VectorX<DiagJet> tau = prep_.model->InverseDynamics(
          q, VectorX<DiagJet>(prep_.sd.qd.col(k).cast<DiagJet>()),
          VectorX<DiagJet>(prep_.sd.qdd.col(k).cast<DiagJet>()), p);
      const VectorX<DiagJet> bias = prep_.model->InverseDynamics(q, zero, zero, p);
      for (int j = 0; j < n; ++j) {
        VectorX<DiagJet> unit = zero;
        unit[j] = DiagJet(1.0);
        const DiagJet mjj = prep_.model->InverseDynamics(q, zero, unit, p)[j] - bias[j];
        const DiagJet res = (DiagJet(prep_.tau(j, r)) - tau[j]) / mjj;
        const int row = r * n + j;
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
  const PreparedData& prep_;
  int count_, free_;
  ParamsOf params_of_;
};

// Index of each named parameter; throws naming `option`.
std::vector<int> ParamIndices(const AnalyticModel& model, const std::vector<std::string>& names,
                              const char* option) {
  std::vector<int> out;
  for (const auto& name : names) {
    const int i = model.ParamIndex(name);
    DIFFDYN_CHECK(i >= 0, option, " ", name, ": model ", model.name(), " has no such parameter");
    out.push_back(i);
  }
  return out;
}

// Fits the named nominal parameters (and one common scale) on the first rows.
void CalibrateNominal(const PrepareOptions& options, PreparedData* prep) {
  const AnalyticModel& model = *prep->model;
  const std::vector<int> fit_index = ParamIndices(model, options.fit_params, "--fit-param");
  const std::vector<int> scale_index = ParamIndices(model, options.scale_params, "--scale-param");
  const int free = static_cast<int>(fit_index.size()) + (scale_index.empty() ? 0 : 1);
  DIFFDYN_CHECK(free <= kDiagJetSize, "at most ", kDiagJetSize, " calibrated parameters");
  const int count = std::max(10, static_cast<int>(options.calibration_fraction * prep->rows));
  const Eigen::VectorXd given = prep->params;
  Eigen::VectorXd x(free);
  for (std::size_t i = 0; i < fit_index.size(); ++i) x[i] = given[fit_index[i]];
  if (!scale_index.empty()) x[free - 1] = 1.0;
  auto assemble = [&](const auto& xv, auto tag) {
    using T = decltype(tag);
    VectorX<T> p = given.template cast<T>();
    for (std::size_t i = 0; i < fit_index.size(); ++i) p[fit_index[i]] = xv[i];
    for (int i : scale_index) p[i] = T(given[i]) * xv[free - 1];
    return p;
  };
  ceres::Problem problem;
  problem.AddResidualBlock(
      new CalibrationCost(*prep, std::min(count, prep->rows), free,
                          [&](const VectorX<DiagJet>& xv) { return assemble(xv, DiagJet()); }),
      nullptr, x.data());
  for (int i = 0; i < free; ++i) problem.SetParameterLowerBound(x.data(), i, 1e-6);
  ceres::Solver::Options solver_options;
  solver_options.max_num_iterations = 100;
  solver_options.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);
  DIFFDYN_CHECK(x.allFinite(), "calibration of the nominal parameters failed");
  prep->params = assemble(x, 0.0);
  std::string text = StrCat("nominal parameters fitted on the first ",
                            static_cast<int>(100 * options.calibration_fraction), "% of the rows:");
  for (int i : fit_index) text += StrCat(" ", model.param_specs()[i].name, "=", prep->params[i]);
  for (int i : scale_index) text += StrCat(" ", model.param_specs()[i].name, "=", prep->params[i]);
  if (!scale_index.empty()) text += " (common scale of the scaled parameters)";
  prep->notes.push_back(text);
}

// The nominal model's torque, unit-payload torque and residual at every row.
void EvaluateNominal(PreparedData* prep) {
  const SmoothedData& sd = prep->sd;
  prep->id_nominal = PredictAll(*prep, *prep->nominal);
  prep->tip.resize(prep->n, prep->rows);
  for (int r = 0; r < prep->rows; ++r) {
    const int k = prep->Sample(r);
    const Eigen::VectorXd q = sd.q.col(k), qd = sd.qd.col(k), qdd = sd.qdd.col(k);
    prep->tip.col(r) = prep->model->TipLoad(q, qd, qdd, prep->params);
  }
  prep->residual = prep->tau - prep->id_nominal;
  if (!prep->residual.allFinite()) throw NumericalError("diagnose: non-finite nominal residual");
}

// The time split and the independent-sample count of the train rows.
void SplitRows(const Dataset& data, double holdout_fraction, PreparedData* prep) {
  const int rows = prep->rows;
  const int train_count = static_cast<int>(std::lround((1.0 - holdout_fraction) * rows));
  DIFFDYN_CHECK(train_count >= 10 && rows - train_count >= 5, "--measured ", data.path,
                ": too few rows (", rows, ") to hold out ", holdout_fraction);
  for (int r = 0; r < rows; ++r) (r < train_count ? prep->train : prep->heldout).push_back(r);
  const SmoothedData& sd = prep->sd;
  double seconds = 0;
  for (std::size_t i = 1; i < prep->train.size(); ++i) {
    const int a = prep->Sample(prep->train[i - 1]), b = prep->Sample(prep->train[i]);
    if (sd.segment_of[a] == sd.segment_of[b]) seconds += sd.t[b] - sd.t[a];
  }
  prep->n_eff = std::clamp(seconds * sd.IndependentRate(), 2.0, static_cast<double>(train_count));
}

}  // namespace

Eigen::VectorXd EstimateWhiteNoise(const Eigen::VectorXd& t, const Eigen::MatrixXd& signal,
                                   const std::vector<int>& segment_starts) {
  const int n = static_cast<int>(signal.rows()), count = static_cast<int>(signal.cols());
  Eigen::VectorXd out = Eigen::VectorXd::Zero(n);
  for (int j = 0; j < n; ++j) {
    std::vector<double> scaled;
    for (std::size_t s = 0; s < segment_starts.size(); ++s) {
      const int begin = segment_starts[s];
      const int end = s + 1 < segment_starts.size() ? segment_starts[s + 1] : count;
      for (int k = begin + 1; k + 1 < end; ++k) {
        const double span = t[k + 1] - t[k - 1];
        if (!(span > 0)) continue;
        const double w0 = (t[k + 1] - t[k]) / span, w2 = (t[k] - t[k - 1]) / span;
        const double e = signal(j, k) - w0 * signal(j, k - 1) - w2 * signal(j, k + 1);
        scaled.push_back(std::abs(e) / std::sqrt(1.0 + w0 * w0 + w2 * w2));
      }
    }
    out[j] = 1.4826 * Median(std::move(scaled));
  }
  return out;
}

bool IsBackwardDifference(const Dataset& data) {
  const int n = JointCount(data);
  double diff = 0, norm = 0;
  for (const Trajectory& traj : data.trajectories) {
    const Eigen::VectorXd& t = traj.t;
    const auto q = traj.states.topRows(n), qd = traj.states.bottomRows(n);
    for (Eigen::Index k = 1; k < t.size(); ++k) {
      const double dt = t[k] - t[k - 1];
      if (!(dt > 0)) return false;
      diff += ((q.col(k) - q.col(k - 1)) / dt - qd.col(k)).squaredNorm();
      norm += qd.col(k).squaredNorm();
    }
  }
  return norm > 0 && diff <= 1e-5 * norm;
}

Dataset RecentreVelocity(const Dataset& data) {
  const int n = JointCount(data);
  Dataset out = data;
  for (std::size_t i = 0; i < data.trajectories.size(); ++i) {
    const Eigen::VectorXd& t = data.trajectories[i].t;
    const auto qd = data.trajectories[i].states.bottomRows(n);
    auto out_qd = out.trajectories[i].states.bottomRows(n);
    // qd_k belongs to m_k = (t_{k-1} + t_k) / 2; interpolate between m_k and m_{k+1}.
    for (Eigen::Index k = 1; k + 1 < t.size(); ++k) {
      const double m0 = 0.5 * (t[k - 1] + t[k]), m1 = 0.5 * (t[k] + t[k + 1]);
      const double w = (t[k] - m0) / (m1 - m0);
      out_qd.col(k) = qd.col(k) + w * (qd.col(k + 1) - qd.col(k));
    }
    if (t.size() >= 2) out_qd.col(0) = out_qd.col(1);
  }
  return out;
}

namespace {

// The lowest frequency below which `fraction` of one trajectory's torque power
// lies (header), searched up to max_hz (returned when not reached); -1 without
// power. DFT bins k / (N dt) on the samples' own times, Hann-weighted.
double TrajectoryTorqueBandwidth(const Eigen::VectorXd& t, const Eigen::MatrixXd& tau, double fraction,
                                 double max_hz) {
  const Eigen::Index count = t.size();
  const double span = t[count - 1] - t[0];
  Eigen::RowVectorXd w(count);
  for (Eigen::Index k = 0; k < count; ++k) w[k] = 0.5 - 0.5 * std::cos(2 * std::numbers::pi * (t[k] - t[0]) / span);
  Eigen::MatrixXd x = tau;
  for (Eigen::Index j = 0; j < x.rows(); ++j) {
    x.row(j).array() -= x.row(j).dot(w) / w.sum();
    x.row(j).array() *= w.array();
  }
  const double total = count * x.squaredNorm();  // Parseval: sum over all N bins
  if (!(total > 0)) return -1;
  const double bin = (count - 1) / (count * span);
  double power = 0;
  Eigen::VectorXd re(count), im(count);
  for (int k = 0; k * bin <= max_hz; ++k) {
    for (Eigen::Index n = 0; n < count; ++n) {
      const double angle = 2 * std::numbers::pi * k * bin * (t[n] - t[0]);
      re[n] = std::cos(angle);
      im[n] = std::sin(angle);
    }
    power += (k == 0 ? 1.0 : 2.0) * ((x * re).squaredNorm() + (x * im).squaredNorm());
    if (power >= fraction * total) return k * bin;
  }
  return max_hz;
}

}  // namespace

double TorqueBandwidthHz(const Dataset& data, double fraction, double max_hz) {
  std::vector<double> per_trajectory;
  for (const Trajectory& trajectory : data.trajectories) {
    const auto tau = trajectory.channels.find("tau");
    if (tau == trajectory.channels.end() || trajectory.t.size() < 16) continue;
    const double f = TrajectoryTorqueBandwidth(trajectory.t, tau->second, fraction, max_hz);
    if (f >= 0) per_trajectory.push_back(f);
  }
  return Median(per_trajectory);
}

double DefaultCutoffHz(const Dataset& data) {
  const double median = MedianSpacing(data);
  if (!(median > 0)) return kMaxCutoffHz;
  const double fs = 1.0 / median;
  if (kMinKernelSpan * fs >= kMaxCutoffHz) return kMaxCutoffHz;
  const double floor = 2 * TorqueBandwidthHz(data, 0.99, kMaxCutoffHz / 2);
  return std::min({kMaxCutoffHz, fs / 4, std::max(kMinKernelSpan * fs, floor)});
}

PreparedData PrepareData(const ExtendedModel& nominal, const Dataset& data, const PrepareOptions& options) {
  const std::shared_ptr<const AnalyticModel> model = nominal.model_ptr();
  const Eigen::VectorXd& params = nominal.params();
  const int dof = JointCount(data);
  DIFFDYN_CHECK(dof == model->dof(), "--measured ", data.path, " has ", dof,
                " joints, --model ", model->name(), " has ", model->dof());
  DIFFDYN_CHECK(params.size() == static_cast<int>(model->param_specs().size()),
                "diagnose: model ", model->name(), " needs ", model->param_specs().size(),
                " parameters, got ", params.size());
  DIFFDYN_CHECK(options.holdout_fraction > 0 && options.holdout_fraction < 1,
                "--holdout ", options.holdout_fraction, ": must be in (0, 1)");
  DIFFDYN_CHECK(options.cutoff_hz >= 0 && options.cutoff_hz <= kMaxCutoffHz, "--cutoff-hz ",
                options.cutoff_hz, ": must be in (0, ", kMaxCutoffHz, "] Hz (0 = the default rule)");
  PreparedData prep;
  prep.model = model;
  prep.params = params;
  prep.n = model->dof();
  const double cutoff = options.cutoff_hz > 0 ? options.cutoff_hz : DefaultCutoffHz(data);
  prep.velocity_recentred = data.IsMeasured("qd1") && IsBackwardDifference(data);
  prep.sd = SmoothJointSpace(prep.velocity_recentred ? RecentreVelocity(data) : data, cutoff);
  prep.rows = static_cast<int>(prep.sd.rows.size());
  prep.tau.resize(prep.n, prep.rows);
  for (int r = 0; r < prep.rows; ++r) prep.tau.col(r) = prep.sd.tau.col(prep.Sample(r));
  const std::vector<int> starts(prep.sd.segment_bounds.begin(), prep.sd.segment_bounds.end() - 1);
  prep.noise_std = EstimateWhiteNoise(prep.sd.t, prep.sd.tau_raw, starts);
  prep.qd_noise_std = EstimateWhiteNoise(prep.sd.t, prep.sd.qd_raw, starts);
  prep.median_dt = MedianSpacing(data);
  if (prep.velocity_recentred) {
    prep.notes.push_back("qd is the backward difference of q (half a sample late): re-centred on the sample times");
  }
  prep.notes.push_back(StrCat("smoothing: local-linear Gaussian kernel, cutoff ", cutoff, " Hz (s = ",
                              prep.sd.sigma_t * 1e3, " ms), same weights for q, qd, tau; qdd = d/dt of "
                              "smoothed qd"));
  if (!options.fit_params.empty() || !options.scale_params.empty()) CalibrateNominal(options, &prep);
  prep.nominal = std::make_shared<const ExtendedModel>(nominal.WithNominalParams(prep.params));
  EvaluateNominal(&prep);
  SplitRows(data, options.holdout_fraction, &prep);
  return prep;
}

}  // namespace diffdyn
