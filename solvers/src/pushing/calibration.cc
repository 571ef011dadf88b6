#include "diffdyn/solvers/pushing/calibration.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <numeric>
#include <utility>

#include <ceres/ceres.h>

#include "diffdyn/autodiff_ode/str_printf.h"
#include "diffdyn/models/parallel.h"
#include "diffdyn/models/random.h"
#include "diffdyn/physics/pushing/oracle.h"
#include "diffdyn/physics/pushing/system.h"

namespace diffdyn {
namespace {

// Transitions as columns: start states, actions, measured next states, and where
// each came from (trajectory index, step).
struct Transitions {
  Eigen::Matrix3Xd states, actions, next;
  std::vector<int> trajectory, step;

  int size() const { return static_cast<int>(states.cols()); }
};

Transitions Gather(const std::vector<Trajectory>& data, const std::vector<int>& which) {
  int n = 0;
  for (int t : which) n += data[t].transitions();
  Transitions out;
  out.states.resize(3, n);
  out.actions.resize(3, n);
  out.next.resize(3, n);
  int i = 0;
  for (int t : which) {
    for (int k = 0; k < data[t].transitions(); ++k, ++i) {
      out.states.col(i) = data[t].states.col(k);
      out.actions.col(i) = data[t].actions.col(k);
      out.next.col(i) = data[t].states.col(k + 1);
      out.trajectory.push_back(t);
      out.step.push_back(k);
    }
  }
  return out;
}

// The first `count` columns of a seeded permutation of `all`, in their original order.
Transitions Subsample(const Transitions& all, int count, std::uint64_t seed) {
  if (count <= 0 || count >= all.size()) return all;
  std::vector<int> order(all.size());
  std::iota(order.begin(), order.end(), 0);
  Rng rng = TrajectoryRng(seed, 1);
  Shuffle(order.begin(), order.end(), rng);
  order.resize(count);
  std::sort(order.begin(), order.end());
  Transitions out;
  out.states.resize(3, count);
  out.actions.resize(3, count);
  out.next.resize(3, count);
  for (int i = 0; i < count; ++i) {
    out.states.col(i) = all.states.col(order[i]);
    out.actions.col(i) = all.actions.col(order[i]);
    out.next.col(i) = all.next.col(order[i]);
    out.trajectory.push_back(all.trajectory[order[i]]);
    out.step.push_back(all.step[order[i]]);
  }
  return out;
}

const PusherParameterInfo& Info(const std::string& name) {
  for (const PusherParameterInfo& info : PusherParameters()) {
    if (info.name == name) return info;
  }
  std::string known;
  for (const PusherParameterInfo& info : PusherParameters())
    known += (known.empty() ? "" : ", ") + info.name;
  throw Error(StrCat("pusher parameter '", name, "' is not one of ", known));
}

PushingConfig WithParameters(PushingConfig config, const std::vector<std::string>& names,
                             const double* values) {
  for (std::size_t k = 0; k < names.size(); ++k) SetPusherParameter(config, names[k], values[k]);
  return config;
}

// Ceres residual functor: the weighted one-step errors of the fit transitions.
class ReplayResiduals {
 public:
  ReplayResiduals(const PushingConfig& nominal, const std::vector<std::string>& names,
                  const Transitions& fit, int threads, int* replays)
      : nominal_(nominal), names_(names), fit_(fit), threads_(threads), replays_(replays) {}

  bool operator()(double const* const* parameters, double* residuals) const {
    const PushingConfig config = WithParameters(nominal_, names_, parameters[0]);
    const Eigen::Matrix3Xd predicted = ReplayPushes(config, fit_.states, fit_.actions, threads_);
    *replays_ += fit_.size();
    const double w = std::sqrt(kBlockRadiusOfGyration);
    for (int i = 0; i < fit_.size(); ++i) {
      residuals[3 * i + 0] = predicted(0, i) - fit_.next(0, i);
      residuals[3 * i + 1] = predicted(1, i) - fit_.next(1, i);
      residuals[3 * i + 2] = w * (predicted(2, i) - fit_.next(2, i));
    }
    return true;
  }

 private:
  const PushingConfig& nominal_;
  const std::vector<std::string>& names_;
  const Transitions& fit_;
  int threads_;
  int* replays_;
};

// Coarse search: each parameter in turn over a geometric grid of its search range
// (the others at the best so far), `sweeps` times; `values` ends at the best point.
// Returns its pose loss on `sample`.
double CoarseSearch(const PushingConfig& nominal, const std::vector<std::string>& names,
                    const Transitions& sample, const PusherCalibrationOptions& o,
                    std::vector<double>& values, int* replays) {
  auto loss = [&](const std::vector<double>& v) {
    *replays += sample.size();
    return PusherPoseLoss(ReplayPushes(WithParameters(nominal, names, v.data()), sample.states,
                                       sample.actions, o.threads),
                          sample.next);
  };
  double best = loss(values);
  for (int sweep = 0; sweep < o.coarse_sweeps; ++sweep) {
    for (std::size_t k = 0; k < names.size(); ++k) {
      const PusherParameterInfo& info = Info(names[k]);
      for (int g = 0; g < o.coarse_points; ++g) {
        std::vector<double> trial = values;
        const double f = o.coarse_points > 1 ? static_cast<double>(g) / (o.coarse_points - 1) : 0.5;
        trial[k] = info.search_lower * std::pow(info.search_upper / info.search_lower, f);
        const double l = loss(trial);
        if (l < best) {
          best = l;
          values = trial;
        }
      }
      if (o.progress) {
        o.progress(StrPrintf("coarse sweep %d: %s = %.4g, pose loss %.4g", sweep + 1,
                             names[k].c_str(), values[k], best));
      }
    }
  }
  return best;
}

// One progress line per Levenberg-Marquardt iteration.
class ProgressLines : public ceres::IterationCallback {
 public:
  ProgressLines(const std::function<void(const std::string&)>& progress, int transitions)
      : progress_(progress), transitions_(transitions) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    if (progress_) {
      progress_(StrPrintf("fit iteration %d: pose loss %.4g (%s)", s.iteration,
                          2 * s.cost / transitions_,
                          s.step_is_successful ? "step taken" : "step refused"));
    }
    return ceres::SOLVER_CONTINUE;
  }

 private:
  const std::function<void(const std::string&)>& progress_;
  int transitions_;
};

void CheckOptions(const std::vector<Trajectory>& measured, const PusherCalibrationOptions& o) {
  DIFFDYN_CHECK(!o.parameters.empty(), "pusher calibration: no parameter to fit");
  for (std::size_t k = 0; k < o.parameters.size(); ++k) {
    Info(o.parameters[k]);
    DIFFDYN_CHECK(std::count(o.parameters.begin(), o.parameters.end(), o.parameters[k]) == 1,
                  "pusher parameter '", o.parameters[k], "' is named twice");
  }
  const bool px = std::count(o.parameters.begin(), o.parameters.end(), "tip_pad_x") > 0;
  const bool py = std::count(o.parameters.begin(), o.parameters.end(), "tip_pad_y") > 0;
  DIFFDYN_CHECK(
      px == py,
      "pusher parameters tip_pad_x and tip_pad_y are fitted together (one names the other)");
  DIFFDYN_CHECK(o.holdout_fraction > 0 && o.holdout_fraction <= 0.9,
                "pusher calibration: holdout fraction ", o.holdout_fraction, " is not in (0, 0.9]");
  DIFFDYN_CHECK(
      o.max_iterations >= 0 && o.relative_step > 0 && o.relative_step < 1,
      "pusher calibration: iterations must be non-negative and the relative step in (0, 1)");
  DIFFDYN_CHECK(o.coarse_sweeps >= 0 && o.coarse_points >= 1 && o.coarse_transitions >= 0,
                "pusher calibration: the coarse search needs non-negative sweeps and transitions "
                "and a grid point");
  DIFFDYN_CHECK(measured.size() >= 2, "pusher calibration: ", measured.size(),
                " trajectories; at least 2 are needed (one to fit, one held out)");
  for (const Trajectory& t : measured) {
    DIFFDYN_CHECK(t.states.rows() == 3 && t.actions.rows() == 3,
                  "pusher calibration: trajectories of block poses (3 states) and pushes (3 "
                  "actions) expected, got ",
                  t.states.rows(), " states and ", t.actions.rows(), " actions");
  }
}

// Open-loop rollouts of the trajectories `which` from their first poses.
std::vector<Eigen::Matrix3Xd> Rollouts(const PushingConfig& config,
                                       const std::vector<Trajectory>& data,
                                       const std::vector<int>& which, int threads) {
  std::vector<Eigen::Matrix3Xd> out(which.size());
  const int n = static_cast<int>(which.size());
  ParallelForChunks(n, 1, threads, [&](int, int begin, int end) {
    PushingEnv env(config);
    for (int r = begin; r < end; ++r) {
      const Trajectory& t = data[which[r]];
      Eigen::Matrix3Xd poses(3, t.transitions() + 1);
      poses.col(0) = t.states.col(0);
      bool on_table = PushingEnv::OnTable(poses(0, 0), poses(1, 0));
      for (int k = 0; k < t.transitions(); ++k) {
        poses.col(k + 1) = poses.col(k);
        if (!on_table) continue;
        env.Reset(poses.col(k));
        const PushResult result = env.Step(t.actions.col(k));
        if (result.status != PushStatus::kUnreachable) poses.col(k + 1) = result.pose;
        on_table = result.status != PushStatus::kOffTable;
      }
      out[r] = poses;
    }
  });
  return out;
}

double MeanFinalError(const std::vector<Eigen::Matrix3Xd>& predicted,
                      const std::vector<Eigen::Matrix3Xd>& measured) {
  double sum = 0;
  for (std::size_t r = 0; r < predicted.size(); ++r) {
    const Eigen::Index last = measured[r].cols() - 1;
    sum += (predicted[r].col(last).head<2>() - measured[r].col(last).head<2>()).norm();
  }
  return predicted.empty() ? 0.0 : sum / static_cast<double>(predicted.size());
}

// Mean over trajectories of their summed loss reduction, over its standard error.
double GainT(const Transitions& test, const Eigen::Matrix3Xd& nominal,
             const Eigen::Matrix3Xd& calibrated) {
  const Eigen::Vector3d w(1, 1, kBlockRadiusOfGyration);
  std::vector<double> gain;
  for (int i = 0; i < test.size(); ++i) {
    if (i == 0 || test.trajectory[i] != test.trajectory[i - 1]) gain.push_back(0);
    gain.back() += w.dot((nominal.col(i) - test.next.col(i)).cwiseAbs2()) -
                   w.dot((calibrated.col(i) - test.next.col(i)).cwiseAbs2());
  }
  const double n = static_cast<double>(gain.size());
  if (n < 2) return 0.0;
  const double mean = std::accumulate(gain.begin(), gain.end(), 0.0) / n;
  double var = 0;
  for (double g : gain) var += (g - mean) * (g - mean);
  const double se = std::sqrt(var / (n - 1) / n);
  return se > 0 ? mean / se : 0.0;
}

Eigen::Vector3d ChannelRmse(const Eigen::Matrix3Xd& predicted, const Eigen::Matrix3Xd& measured) {
  const Eigen::Index n = std::max<Eigen::Index>(1, predicted.cols());
  return ((predicted - measured).array().square().rowwise().sum() / static_cast<double>(n)).sqrt();
}

}  // namespace

const std::vector<PusherParameterInfo>& PusherParameters() {
  static const std::vector<PusherParameterInfo> parameters = {
      {"block_table_friction", "1", 0.01, 1.0, 0.03, 0.5,
       "Coulomb coefficient between block and table"},
      {"tip_block_friction", "1", 0.0, 1.5, 0.02, 1.0,
       "Coulomb coefficient between pusher tip and block"},
      {"block_mass", "kg", 0.5, 50.0, 1.0, 30.0, "mass of the block"},
      {"block_inertia", "kg m^2", 1e-3, 2.0, 5e-3, 1.0, "block inertia about each axis"},
      {"tip_radius", "m", 1e-3, 0.03, 2e-3, 0.025, "radius of the round tip (capsule)"},
      {"tip_pad_x", "m", 1e-3, 0.03, 2e-3, 0.025,
       "half width of a flat tip pad along the world x axis"},
      {"tip_pad_y", "m", 1e-3, 0.03, 2e-3, 0.025,
       "half width of a flat tip pad along the world y axis"},
      {"push_speed", "m/s", 0.02, 1.0, 0.05, 0.6, "peak tip speed while pushing"},
  };
  return parameters;
}

double PusherParameter(const PushingConfig& c, const std::string& name) {
  Info(name);
  if (name == "block_table_friction") return c.block_table_friction;
  if (name == "tip_block_friction") return c.tip_block_friction;
  if (name == "block_mass") return c.block_mass;
  if (name == "block_inertia") {
    return c.block_inertia > 0 ? c.block_inertia
                               : c.block_mass * 2 * c.block_size * c.block_size / 12;
  }
  if (name == "tip_radius") return c.tip_radius;
  if (name == "tip_pad_x") return c.tip_pad_x > 0 ? c.tip_pad_x : c.tip_radius;
  if (name == "tip_pad_y") return c.tip_pad_y > 0 ? c.tip_pad_y : c.tip_radius;
  return c.push_speed;
}

void SetPusherParameter(PushingConfig& c, const std::string& name, double value) {
  Info(name);
  if (name == "tip_pad_x" || name == "tip_pad_y") {
    const double x = PusherParameter(c, "tip_pad_x"), y = PusherParameter(c, "tip_pad_y");
    c.tip_pad_x = name == "tip_pad_x" ? value : x;
    c.tip_pad_y = name == "tip_pad_y" ? value : y;
    return;
  }
  if (name == "block_table_friction") c.block_table_friction = value;
  if (name == "tip_block_friction") c.tip_block_friction = value;
  if (name == "block_mass") c.block_mass = value;
  if (name == "block_inertia") c.block_inertia = value;
  if (name == "tip_radius") c.tip_radius = value;
  if (name == "push_speed") c.push_speed = value;
}

Eigen::Matrix3Xd ReplayPushes(const PushingConfig& config, const Eigen::Matrix3Xd& states,
                              const Eigen::Matrix3Xd& actions, int threads) {
  DIFFDYN_CHECK(states.cols() == actions.cols(), "ReplayPushes: ", states.cols(), " states and ",
                actions.cols(), " actions");
  // The oracle's semantics (unreachable or unholdable: the state itself), one
  // world per chunk of pushes.
  const PushingOracle oracle(config);
  const int n = static_cast<int>(states.cols());
  Eigen::Matrix3Xd next(3, n);
  constexpr int kChunk = 16;
  ParallelForChunks(n, kChunk, threads, [&](int, int begin, int end) {
    const auto workspace = oracle.MakeWorkspace(end - begin);
    oracle.PredictBatch(states.middleCols(begin, end - begin), actions.middleCols(begin, end - begin),
                        next.middleCols(begin, end - begin), *workspace);
  });
  return next;
}

double PusherPoseLoss(const Eigen::Matrix3Xd& predicted, const Eigen::Matrix3Xd& measured) {
  if (predicted.cols() == 0) return 0.0;
  const Eigen::Vector3d mse = (predicted - measured).array().square().rowwise().sum() /
                              static_cast<double>(predicted.cols());
  return mse[0] + mse[1] + kBlockRadiusOfGyration * mse[2];
}

PusherCalibration CalibratePusher(const std::vector<Trajectory>& measured,
                                  const PushingConfig& nominal, const PusherCalibrationOptions& o) {
  CheckOptions(measured, o);
  PusherCalibration result;
  result.nominal = nominal;
  auto say = [&](const std::string& line) {
    if (o.progress) o.progress(line);
  };

  // Seeded split by trajectory, then a seeded subsample of the training transitions.
  const int count = static_cast<int>(measured.size());
  std::vector<int> order(count);
  std::iota(order.begin(), order.end(), 0);
  Rng rng = TrajectoryRng(o.seed, 0);
  Shuffle(order.begin(), order.end(), rng);
  const int held =
      std::clamp(static_cast<int>(std::ceil(o.holdout_fraction * count)), 1, count - 1);
  std::vector<int> heldout(order.begin(), order.begin() + held),
      train(order.begin() + held, order.end());
  std::sort(heldout.begin(), heldout.end());
  std::sort(train.begin(), train.end());
  const Transitions fit = Subsample(Gather(measured, train), o.fit_transitions, o.seed);
  const Transitions test = Gather(measured, heldout);
  result.train_trajectories = static_cast<int>(train.size());
  result.heldout_trajectories = held;
  result.fit_transitions = fit.size();
  DIFFDYN_CHECK(fit.size() > static_cast<int>(o.parameters.size()),
                "pusher calibration: ", fit.size(), " training transitions for ",
                o.parameters.size(), " parameters");

  // Levenberg-Marquardt with bounds over forward differences of the replays.
  const int p = static_cast<int>(o.parameters.size());
  std::vector<double> values(p);
  for (int k = 0; k < p; ++k) values[k] = PusherParameter(nominal, o.parameters[k]);
  ceres::NumericDiffOptions diff;
  diff.relative_step_size = o.relative_step;
  auto* cost = new ceres::DynamicNumericDiffCostFunction<ReplayResiduals, ceres::FORWARD>(
      new ReplayResiduals(nominal, o.parameters, fit, o.threads, &result.replays),
      ceres::TAKE_OWNERSHIP, diff);
  cost->AddParameterBlock(p);
  cost->SetNumResiduals(3 * fit.size());
  ceres::Problem problem;
  problem.AddResidualBlock(cost, nullptr, values.data());
  for (int k = 0; k < p; ++k) {
    const PusherParameterInfo& info = Info(o.parameters[k]);
    values[k] = std::clamp(values[k], info.lower, info.upper);
    problem.SetParameterLowerBound(values.data(), k, info.lower);
    problem.SetParameterUpperBound(values.data(), k, info.upper);
  }
  result.fit_loss_nominal =
      PusherPoseLoss(ReplayPushes(nominal, fit.states, fit.actions, o.threads), fit.next);
  result.replays += fit.size();
  if (o.coarse_sweeps > 0) {
    const Transitions coarse = Subsample(fit, o.coarse_transitions, o.seed + 1);
    CoarseSearch(nominal, o.parameters, coarse, o, values, &result.replays);
  }
  double start_cost = 0;
  problem.Evaluate(ceres::Problem::EvaluateOptions(), &start_cost, nullptr, nullptr, nullptr);
  result.fit_loss_coarse = 2 * start_cost / fit.size();
  say(StrPrintf("fitting %d parameters on %d transitions of %zu trajectories (%d held out)", p,
                fit.size(), train.size(), held));
  ceres::Solver::Options solver;
  solver.max_num_iterations = o.max_iterations;
  solver.linear_solver_type = ceres::DENSE_QR;
  solver.num_threads = 1;
  solver.logging_type = ceres::SILENT;
  ProgressLines lines(o.progress, fit.size());
  solver.callbacks.push_back(&lines);
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
  result.iterations = static_cast<int>(summary.iterations.size()) - 1;
  result.fit_loss_calibrated = 2 * summary.final_cost / fit.size();
  result.calibrated = WithParameters(nominal, o.parameters, values.data());

  // Standard errors: s^2 (J^T J)^-1 with s^2 = SSE / (3n - P).
  ceres::Covariance::Options covariance_options;
  covariance_options.algorithm_type = ceres::DENSE_SVD;
  covariance_options.null_space_rank = -1;
  ceres::Covariance covariance(covariance_options);
  std::vector<double> cov(p * p, std::numeric_limits<double>::quiet_NaN());
  const std::vector<std::pair<const double*, const double*>> block = {
      {values.data(), values.data()}};
  if (covariance.Compute(block, &problem)) {
    covariance.GetCovarianceBlock(values.data(), values.data(), cov.data());
  }
  const double s2 = 2 * summary.final_cost / std::max(1, 3 * fit.size() - p);

  // Held-out scores: nominal, calibrated, and each parameter alone.
  say(StrPrintf("scoring %d held-out transitions", test.size()));
  const Eigen::Matrix3Xd nominal_next = ReplayPushes(nominal, test.states, test.actions, o.threads);
  const Eigen::Matrix3Xd calibrated_next =
      ReplayPushes(result.calibrated, test.states, test.actions, o.threads);
  result.replays += 2 * test.size();
  result.heldout_loss_nominal = PusherPoseLoss(nominal_next, test.next);
  result.heldout_loss_calibrated = PusherPoseLoss(calibrated_next, test.next);
  result.heldout_loss_identity = PusherPoseLoss(test.states, test.next);
  result.heldout_gain_t = GainT(test, nominal_next, calibrated_next);
  result.heldout_rmse_nominal = ChannelRmse(nominal_next, test.next);
  result.heldout_rmse_calibrated = ChannelRmse(calibrated_next, test.next);
  for (int k = 0; k < p; ++k) {
    PusherParameterFit fitted;
    fitted.name = o.parameters[k];
    fitted.unit = Info(fitted.name).unit;
    fitted.nominal = PusherParameter(nominal, fitted.name);
    fitted.value = values[k];
    fitted.standard_error = std::sqrt(s2 * cov[k * p + k]);
    PushingConfig alone = nominal;
    SetPusherParameter(alone, fitted.name, fitted.value);
    fitted.heldout_loss_alone =
        PusherPoseLoss(ReplayPushes(alone, test.states, test.actions, o.threads), test.next);
    result.replays += test.size();
    result.parameters.push_back(fitted);
  }
  for (int i = 0; i < test.size(); ++i) {
    result.heldout.push_back({test.trajectory[i], test.step[i], test.states.col(i),
                              test.actions.col(i), test.next.col(i), nominal_next.col(i),
                              calibrated_next.col(i)});
  }

  // Open-loop rollouts of the held-out trajectories.
  say(StrPrintf("rolling out %d held-out trajectories", held));
  for (int t : heldout) result.rollout_measured.push_back(measured[t].states);
  result.rollout_nominal = Rollouts(nominal, measured, heldout, o.threads);
  result.rollout_calibrated = Rollouts(result.calibrated, measured, heldout, o.threads);
  result.replays += 2 * test.size();
  result.rollout_error_nominal = MeanFinalError(result.rollout_nominal, result.rollout_measured);
  result.rollout_error_calibrated =
      MeanFinalError(result.rollout_calibrated, result.rollout_measured);
  return result;
}

}  // namespace diffdyn
