#include "diffdyn/solvers/pushing/trials.h"

#include <cmath>
#include <numbers>
#include <tuple>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/random.h"
#include "diffdyn/solvers/statistics.h"

namespace diffdyn {

Eigen::Vector3d PushTaskStart(bool obstacle) {
  return {0.4, 0.0, (obstacle ? -0.2 : 0.2) * std::numbers::pi};
}

Eigen::Vector3d PushTaskGoal(bool obstacle) { return {0.8, obstacle ? -0.1 : 0.0, 0.0}; }

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

constexpr double kPi = std::numbers::pi;

// One trial's plant: the ODE world, one push per step.
class PushingRun final : public TaskRun {
 public:
  explicit PushingRun(const PushingTask& task)
      : task_(task), env_(task.world()), seed_cost_(task.goal(), task.options().obstacle, 100.0,
                                                   task.world().block_size) {}

  Eigen::VectorXd Reset(const Eigen::VectorXd& x0) override {
    env_.Reset(Eigen::Vector3d(x0[0], x0[1], x0[2]));
    pose_ = env_.pose();
    return pose_;
  }

  StepOutcome Step(const Eigen::VectorXd& u, Eigen::VectorXd* x) override {
    const PushResult result = env_.Step(Eigen::Vector3d(u[0], u[1], u[2]));
    StepOutcome step;
    Eigen::VectorXd cost = Eigen::VectorXd::Zero(1);
    seed_cost_.AccumulateStep(0, pose_, u, result.pose, cost);
    step.cost = cost[0];
    pose_ = result.pose;
    *x = pose_;
    const PushTaskOptions& o = task_.options();
    // Any block-obstacle contact (during the push, or overlap after settling) fails.
    if (o.obstacle && (result.block_hit_obstacle ||
                       PushingEnv::ObstaclePenetration(result.pose, task_.world().block_size) > 0)) {
      step.outcome = "obstacle_contact";
    } else if (result.status == PushStatus::kOffTable) {
      step.outcome = "off_table";
    } else if (result.status == PushStatus::kUnreachable) {
      step.outcome = "unreachable";
    } else if ((result.pose.head<2>() - task_.goal().head<2>()).norm() < o.goal_tolerance) {
      step.outcome = "success";
    }
    step.done = !step.outcome.empty();
    return step;
  }

  std::string Finish() override { return "max_steps"; }

 private:
  const PushingTask& task_;
  PushingEnv env_;
  PushingCost seed_cost_;
  Eigen::VectorXd pose_;
};

// The trial record of one evaluator run, with the model's prediction of each push.
PushTrial ToPushTrial(const ControlRun& run, const TransitionModel& model, const Eigen::Vector3d& goal) {
  PushTrial trial;
  trial.success = run.success;
  trial.outcome = run.outcome;
  trial.start = run.x0;
  trial.goal = goal;
  trial.command_ms = run.command_ms;
  const Trajectory& tr = run.trajectory;
  trial.pushes = tr.transitions();
  auto ws = model.MakeWorkspace(1);
  Eigen::MatrixXd next(3, 1);
  trial.poses.push_back(tr.states.col(0));
  for (int k = 0; k < trial.pushes; ++k) {
    model.PredictBatch(tr.states.col(k), tr.actions.col(k), next, *ws);
    trial.predicted.push_back(next.col(0));
    trial.actions.push_back(tr.actions.col(k));
    trial.poses.push_back(tr.states.col(k + 1));
  }
  return trial;
}

}  // namespace

PushingTask::PushingTask(const PushTaskOptions& options) : options_(options), world_(options.world) {
  ValidatePushTaskOptions(options_);
  world_.obstacle = options_.obstacle;
  world_.goal = options_.goal.value_or(PushTaskGoal(options_.obstacle));
}

Eigen::VectorXd PushingTask::Clip(const Eigen::Ref<const Eigen::VectorXd>& u) const {
  return u.cwiseMax(Eigen::Vector3d(-1.0, -kPi / 2, 0.0)).cwiseMin(Eigen::Vector3d(1.0, kPi / 2, 1.0));
}

std::vector<TaskStart> PushingTask::Starts(int count, std::uint64_t seed) const {
  std::vector<TaskStart> starts;
  for (int i = 0; i < count; ++i) {
    // The trial's randomness: start perturbation, then the MPPI seed.
    Rng rng = TrajectoryRng(seed, static_cast<std::uint64_t>(i));
    const double r = options_.start_xy_jitter * std::sqrt(UniformUnit(rng));
    const double phi = Uniform(rng, -kPi, kPi);
    const double dtheta = Uniform(rng, -options_.start_theta_jitter, options_.start_theta_jitter);
    Eigen::Vector3d x0 = options_.start.value_or(PushTaskStart(options_.obstacle));
    x0 += Eigen::Vector3d(r * std::cos(phi), r * std::sin(phi), dtheta);
    x0.z() = std::remainder(x0.z(), 2 * kPi);
    starts.push_back({x0, rng()});
  }
  return starts;
}

std::unique_ptr<TaskRun> PushingTask::Begin() const { return std::make_unique<PushingRun>(*this); }

PushingMppiController::PushingMppiController(const PushingTask& task, const TransitionModel& model)
    : model_(model), cost_(task.goal(), task.options().obstacle, 100.0, task.world().block_size) {
  DIFFDYN_CHECK(model.state_size() == 3 && model.action_size() == 3, "model ", model.kind(),
                " has state size ", model.state_size(), " and action size ", model.action_size(),
                "; pushing needs 3 and 3");
  const PushTaskOptions& o = task.options();
  cost_.set_collision_margin(o.collision_margin);
  cost_.set_collision_substeps(o.collision_substeps);
  cost_.set_clearance(o.clearance, o.clearance_weight);
  // The reach annulus (IK bisections, once per controller) when a reach term is on.
  if (o.reach_weight > 0 || o.reach_limited) {
    const PushReach reach = PushingEnv::Reach(task.world());
    if (o.reach_weight > 0) cost_.set_reach(reach, o.reach_weight, o.reach_steps);
    // MPPI rolls out the model that leaves unreachable pushes unexecuted.
    if (o.reach_limited) limited_.emplace(model, reach);
  }
  mppi_options_.samples = o.samples;
  mppi_options_.horizon = o.horizon;
  mppi_options_.lambda = o.lambda;
  mppi_options_.noise_variance = o.noise_variance;
  mppi_options_.u_min = Eigen::Vector3d(-1.0, -kPi / 2, 0.0);
  mppi_options_.u_max = Eigen::Vector3d(1.0, kPi / 2, 1.0);
  mppi_options_.threads = o.threads;
  mppi_options_.fallback_margin = o.fallback_margin;
}

void PushingMppiController::Reset(const Eigen::VectorXd&, std::uint64_t seed) {
  past_fallbacks_ = fallbacks();
  const TransitionModel& rolled = limited_ ? static_cast<const TransitionModel&>(*limited_) : model_;
  mppi_ = std::make_unique<Mppi>(rolled, cost_, mppi_options_, seed);
}

Eigen::VectorXd PushingMppiController::Command(const Eigen::VectorXd& x) {
  DIFFDYN_CHECK(mppi_ != nullptr, "PushingMppiController: Command before Reset");
  return mppi_->Command(x);
}

int PushingMppiController::fallbacks() const { return past_fallbacks_ + (mppi_ ? mppi_->fallbacks() : 0); }

PushTrial RunPushTrial(const TransitionModel& model, int index, const PushTaskOptions& options,
                       std::uint64_t seed) {
  DIFFDYN_CHECK(index >= 0, "trial index must be >= 0, got ", index);
  const PushingTask task(options);
  PushingMppiController controller(task, model);
  const ControlRun run = RunEpisode(task, controller, task.Starts(index + 1, seed)[static_cast<std::size_t>(index)]);
  return ToPushTrial(run, model, task.goal());
}

PushTrialsSummary RunPushTrials(const TransitionModel& model, int trials, const PushTaskOptions& options,
                                std::uint64_t seed, const std::function<void(int, int)>& progress) {
  DIFFDYN_CHECK(trials >= 1, "--trials: must be >= 1, got ", trials);
  const PushingTask task(options);
  PushingMppiController controller(task, model);
  const std::vector<ControlRun> runs =
      EvaluateController(task, controller, {.starts = trials, .seed = seed, .threads = 1, .progress = progress});
  PushTrialsSummary summary;
  summary.trials = trials;
  std::vector<double> command_ms;
  long pushes = 0;
  for (const ControlRun& run : runs) {
    summary.runs.push_back(ToPushTrial(run, model, task.goal()));
    summary.successes += run.success ? 1 : 0;
    pushes += summary.runs.back().pushes;
    command_ms.insert(command_ms.end(), run.command_ms.begin(), run.command_ms.end());
  }
  summary.success_rate = static_cast<double>(summary.successes) / trials;
  std::tie(summary.ci95_low, summary.ci95_high) = WilsonInterval(summary.successes, trials);
  summary.mean_pushes = static_cast<double>(pushes) / trials;
  if (!command_ms.empty()) summary.ms_per_command = Percentile(command_ms, 0.5);
  summary.fallbacks = controller.fallbacks();
  return summary;
}

}  // namespace diffdyn
