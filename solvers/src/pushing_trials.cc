#include "diffdyn/solvers/pushing_trials.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <optional>
#include <tuple>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/autodiff_ode/random.h"
#include "diffdyn/physics/pushing_collect.h"
#include "diffdyn/physics/reach_limited_model.h"
#include "diffdyn/solvers/mppi.h"
#include "diffdyn/solvers/pushing_cost.h"

namespace diffdyn {

Eigen::Vector3d PushTaskStart(bool obstacle) {
  return {0.4, 0.0, (obstacle ? -0.2 : 0.2) * std::numbers::pi};
}

Eigen::Vector3d PushTaskGoal(bool obstacle) { return {0.8, obstacle ? -0.1 : 0.0, 0.0}; }

std::pair<double, double> WilsonInterval(int successes, int trials, double z) {
  DIFFDYN_CHECK(trials >= 1 && successes >= 0 && successes <= trials,
                "WilsonInterval: need 0 <= successes <= trials and trials >= 1, got ", successes,
                " of ", trials);
  DIFFDYN_CHECK(std::isfinite(z) && z > 0, "WilsonInterval: z must be positive, got ", z);
  const double n = trials, p = successes / n, z2 = z * z;
  const double denom = 1 + z2 / n;
  const double centre = (p + z2 / (2 * n)) / denom;
  const double half = z * std::sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / denom;
  return {std::max(0.0, centre - half), std::min(1.0, centre + half)};
}

void ValidatePushTaskOptions(const PushTaskOptions& o) {
  DIFFDYN_CHECK(o.samples >= 1, "--samples: must be >= 1, got ", o.samples);
  DIFFDYN_CHECK(o.horizon >= 1, "--horizon: must be >= 1, got ", o.horizon);
  DIFFDYN_CHECK(o.max_steps >= 1, "--max-steps: must be >= 1, got ", o.max_steps);
  DIFFDYN_CHECK(std::isfinite(o.start_xy_jitter) && o.start_xy_jitter >= 0,
                "start_xy_jitter: must be >= 0, got ", o.start_xy_jitter);
  DIFFDYN_CHECK(std::isfinite(o.start_theta_jitter) && o.start_theta_jitter >= 0,
                "start_theta_jitter: must be >= 0, got ", o.start_theta_jitter);
  DIFFDYN_CHECK(std::isfinite(o.goal_tolerance) && o.goal_tolerance > 0,
                "goal_tolerance: must be > 0, got ", o.goal_tolerance);
  DIFFDYN_CHECK(std::isfinite(o.lambda) && o.lambda > 0, "lambda: must be > 0, got ", o.lambda);
  DIFFDYN_CHECK(std::isfinite(o.noise_variance) && o.noise_variance > 0,
                "noise_variance: must be > 0, got ", o.noise_variance);
  DIFFDYN_CHECK(std::isfinite(o.collision_margin) && o.collision_margin >= 0,
                "--collision-margin: must be >= 0, got ", o.collision_margin);
  DIFFDYN_CHECK(std::isfinite(o.clearance) && o.clearance >= 0,
                "--clearance: must be >= 0, got ", o.clearance);
  DIFFDYN_CHECK(std::isfinite(o.clearance_weight) && o.clearance_weight >= 0,
                "--clearance-weight: must be >= 0, got ", o.clearance_weight);
  DIFFDYN_CHECK(std::isfinite(o.reach_weight) && o.reach_weight >= 0,
                "--reach-weight: must be >= 0, got ", o.reach_weight);
  DIFFDYN_CHECK(o.reach_steps >= 1, "--reach-steps: must be >= 1, got ", o.reach_steps);
  DIFFDYN_CHECK(o.fallback_margin >= 0, "--fallback-margin: must be >= 0 (inf: off), got ",
                o.fallback_margin);
  DIFFDYN_CHECK(o.collision_substeps >= 0, "--collision-substeps: must be >= 0, got ",
                o.collision_substeps);
  if (o.start) DIFFDYN_CHECK(o.start->allFinite(), "start pose: not finite");
  if (o.goal) DIFFDYN_CHECK(o.goal->allFinite(), "goal pose: not finite");
}

namespace {

void CheckModel(const TransitionModel& model) {
  DIFFDYN_CHECK(model.state_size() == 3 && model.action_size() == 3, "model ", model.kind(),
                " has state size ", model.state_size(), " and action size ", model.action_size(),
                "; pushing needs 3 and 3");
}

// The reach annulus of the task's world when a reach term is on (IK bisections,
// computed once per series).
std::optional<PushReach> TaskReach(const PushTaskOptions& options) {
  if (options.reach_weight <= 0 && !options.reach_limited) return std::nullopt;
  return PushingEnv::Reach(options.world);
}

// RunPushTrial with the series' reach annulus (set when a reach term is on).
PushTrial RunTrial(const TransitionModel& model, int index, const PushTaskOptions& options,
                   std::uint64_t seed, const std::optional<PushReach>& reach) {
  DIFFDYN_CHECK(index >= 0, "trial index must be >= 0, got ", index);
  constexpr double kPi = std::numbers::pi;

  // The trial's randomness: start perturbation, then the MPPI seed.
  Rng rng = TrajectoryRng(seed, static_cast<std::uint64_t>(index));
  const double r = options.start_xy_jitter * std::sqrt(UniformUnit(rng));
  const double phi = Uniform(rng, -kPi, kPi);
  const double dtheta = Uniform(rng, -options.start_theta_jitter, options.start_theta_jitter);
  const std::uint64_t mppi_seed = rng();

  PushTrial trial;
  trial.start = options.start.value_or(PushTaskStart(options.obstacle));
  trial.start += Eigen::Vector3d(r * std::cos(phi), r * std::sin(phi), dtheta);
  trial.start.z() = std::remainder(trial.start.z(), 2 * kPi);
  trial.goal = options.goal.value_or(PushTaskGoal(options.obstacle));

  PushingConfig world = options.world;
  world.obstacle = options.obstacle;
  world.goal = trial.goal;
  PushingEnv env(world);
  env.Reset(trial.start);
  trial.poses.push_back(env.pose());

  PushingCost cost(trial.goal, options.obstacle, 100.0, world.block_size);
  cost.set_collision_margin(options.collision_margin);
  cost.set_collision_substeps(options.collision_substeps);
  cost.set_clearance(options.clearance, options.clearance_weight);
  if (options.reach_weight > 0) cost.set_reach(*reach, options.reach_weight, options.reach_steps);
  MppiOptions mo;
  mo.samples = options.samples;
  mo.horizon = options.horizon;
  mo.lambda = options.lambda;
  mo.noise_variance = options.noise_variance;
  mo.u_min = Eigen::Vector3d(-1.0, -kPi / 2, 0.0);
  mo.u_max = Eigen::Vector3d(1.0, kPi / 2, 1.0);
  mo.threads = options.threads;
  mo.fallback_margin = options.fallback_margin;
  // MPPI rolls out the model, or the model that leaves unreachable pushes unexecuted.
  std::optional<ReachLimitedModel> limited;
  if (options.reach_limited) limited.emplace(model, *reach);
  Mppi mppi(limited ? static_cast<const TransitionModel&>(*limited) : model, cost, mo, mppi_seed);
  // One-sample batch for the model's prediction of each executed push.
  auto predict_ws = model.MakeWorkspace(1);
  Eigen::MatrixXd predict_next(3, 1);

  trial.outcome = "max_steps";
  for (int step = 0; step < options.max_steps; ++step) {
    const Eigen::VectorXd x = trial.poses.back();
    const auto t0 = std::chrono::steady_clock::now();
    const Eigen::VectorXd u = mppi.Command(x);
    const auto t1 = std::chrono::steady_clock::now();
    trial.command_ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
    DIFFDYN_CHECK(u.allFinite(), "MPPI returned a non-finite action in trial ", index);
    const Eigen::Vector3d action(u[0], u[1], u[2]);
    model.PredictBatch(x, u, predict_next, *predict_ws);
    trial.predicted.emplace_back(predict_next(0, 0), predict_next(1, 0), predict_next(2, 0));
    const PushResult result = env.Step(action);
    trial.actions.push_back(action);
    trial.poses.push_back(result.pose);
    ++trial.pushes;
    // Any block-obstacle contact (during the push, or overlap after settling) fails.
    if (options.obstacle &&
        (result.block_hit_obstacle ||
         PushingEnv::ObstaclePenetration(result.pose, world.block_size) > 0)) {
      trial.outcome = "obstacle_contact";
      break;
    }
    if (result.status == PushStatus::kOffTable) {
      trial.outcome = "off_table";
      break;
    }
    if (result.status == PushStatus::kUnreachable) {
      trial.outcome = "unreachable";
      break;
    }
    if ((result.pose.head<2>() - trial.goal.head<2>()).norm() < options.goal_tolerance) {
      trial.outcome = "success";
      trial.success = true;
      break;
    }
  }
  trial.fallbacks = mppi.fallbacks();
  return trial;
}

}  // namespace

PushTrial RunPushTrial(const TransitionModel& model, int index, const PushTaskOptions& options,
                       std::uint64_t seed) {
  ValidatePushTaskOptions(options);
  CheckModel(model);
  return RunTrial(model, index, options, seed, TaskReach(options));
}

PushTrialsSummary RunPushTrials(const TransitionModel& model, int trials,
                                const PushTaskOptions& options, std::uint64_t seed,
                                ProgressBar* progress) {
  DIFFDYN_CHECK(trials >= 1, "--trials: must be >= 1, got ", trials);
  ValidatePushTaskOptions(options);
  CheckModel(model);
  const std::optional<PushReach> reach = TaskReach(options);
  PushTrialsSummary summary;
  summary.trials = trials;
  std::vector<double> command_ms;
  long pushes = 0;
  for (int i = 0; i < trials; ++i) {
    PushTrial trial = RunTrial(model, i, options, seed, reach);
    summary.successes += trial.success ? 1 : 0;
    pushes += trial.pushes;
    command_ms.insert(command_ms.end(), trial.command_ms.begin(), trial.command_ms.end());
    summary.runs.push_back(std::move(trial));
    if (progress != nullptr) {
      progress->Update(i + 1, StrCat("trial ", i + 1, "/", trials, ", ",
                                     summary.successes, " successes"));
    }
  }
  summary.success_rate = static_cast<double>(summary.successes) / trials;
  std::tie(summary.ci95_low, summary.ci95_high) = WilsonInterval(summary.successes, trials);
  summary.mean_pushes = static_cast<double>(pushes) / trials;
  if (!command_ms.empty()) {
    const std::size_t mid = command_ms.size() / 2;
    std::nth_element(command_ms.begin(), command_ms.begin() + mid, command_ms.end());
    double median = command_ms[mid];
    if (command_ms.size() % 2 == 0) {
      median = (median + *std::max_element(command_ms.begin(), command_ms.begin() + mid)) / 2;
    }
    summary.ms_per_command = median;
  }
  return summary;
}

}  // namespace diffdyn
