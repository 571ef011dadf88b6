#include "diffdyn/solvers/joint_collect.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <numbers>
#include <thread>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/parallel.h"
#include "diffdyn/models/random.h"

namespace diffdyn {
namespace {

constexpr int kSinusoids = 5;

// The seeded excitation of one trajectory: per actuated joint, 5 sinusoids.
struct Excitation {
  Eigen::MatrixXd amplitude, frequency, phase;  // a x 5 each

  Excitation(const JointTask& task, Rng& rng) {
    const int a = static_cast<int>(task.actuated.size());
    amplitude.resize(a, kSinusoids);
    frequency.resize(a, kSinusoids);
    phase.resize(a, kSinusoids);
    for (int j = 0; j < a; ++j) {
      for (int l = 0; l < kSinusoids; ++l) {
        frequency(j, l) = Uniform(rng, 0.2, 3.0);
        phase(j, l) = Uniform(rng, 0.0, 2.0 * std::numbers::pi);
        amplitude(j, l) = UniformUnit(rng);
      }
      amplitude.row(j) *= 0.6 * task.bound[j] / std::max(amplitude.row(j).sum(), 1e-12);
    }
  }

  Eigen::VectorXd operator()(double t) const {
    const Eigen::ArrayXXd angle = 2.0 * std::numbers::pi * frequency.array() * t + phase.array();
    return (amplitude.array() * angle.sin()).rowwise().sum().matrix();
  }
};

// V(q) - V(0) = int_0^1 g(s q)^T q ds by 5-point Gauss-Legendre on segments along
// which q moves at most pi / 4 (exact to rounding for the models' trigonometric terms).
double Potential(const AnalyticModel& model, const Eigen::VectorXd& p, const Eigen::VectorXd& q) {
  static constexpr double kNode[5] = {-0.9061798459386640, -0.5384693101056831, 0.0, 0.5384693101056831,
                                      0.9061798459386640};
  static constexpr double kWeight[5] = {0.2369268850561891, 0.4786286704993665, 0.5688888888888889,
                                        0.4786286704993665, 0.2369268850561891};
  const int n = static_cast<int>(q.size());
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  const int segments =
      std::max(1, static_cast<int>(std::ceil(q.cwiseAbs().maxCoeff() / (0.25 * std::numbers::pi))));
  double sum = 0.0;
  for (int i = 0; i < segments; ++i) {
    for (int k = 0; k < 5; ++k) {
      const double s = (i + 0.5 * (kNode[k] + 1.0)) / segments;
      sum += kWeight[k] * model.InverseDynamics(s * q, zero, zero, p).dot(q);
    }
  }
  return 0.5 * sum / segments;
}

// The channels of one sample (state q, qd; torque tau_applied as the plant sees it).
void RecordSample(const ExtendedModel& plant, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                  const Eigen::VectorXd& tau_seen, Trajectory& traj, int k) {
  const AnalyticModel& model = plant.model();
  const Eigen::VectorXd& p = plant.params();
  const int n = static_cast<int>(q.size());
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  const Eigen::VectorXd qdd = plant.ForwardDynamics(q, qd, tau_seen);
  const Eigen::VectorXd gravity = model.InverseDynamics(q, zero, zero, p);
  const Eigen::VectorXd bias = model.InverseDynamics(q, qd, zero, p);
  const Eigen::VectorXd rigid = model.InverseDynamics(q, qd, qdd, p);
  traj.channels["qdd"].col(k) = qdd;
  traj.channels["m"].col(k) = rigid - bias;
  traj.channels["c"].col(k) = bias - gravity;
  traj.channels["g"].col(k) = gravity;
  traj.channels["f"].col(k) = plant.JointTorque(q, qd, qdd) - rigid;
  traj.channels["kinetic"](0, k) = 0.5 * qd.dot(model.MassMatrix(q, p) * qd);
  traj.channels["potential"](0, k) = Potential(model, p, q);
}

// One trajectory of `task` from generator `rng`.
Trajectory SimulateTrajectory(const JointTask& task, const ExtendedModel& plant,
                              const JointCollectOptions& o, int transitions, Rng& rng) {
  const int n = plant.dof(), a = static_cast<int>(task.actuated.size()), samples = transitions + 1;
  const double delay = plant.Delay<double>(plant.EffectParams());
  Trajectory traj;
  traj.t = Eigen::VectorXd::LinSpaced(samples, 0.0, transitions * o.dt);
  traj.states.resize(2 * n, samples);
  traj.actions.resize(a, transitions);
  for (const char* name : {"tau", "qdd", "m", "c", "g", "f"}) traj.channels[name].resize(n, samples);
  traj.channels["kinetic"].resize(1, samples);
  traj.channels["potential"].resize(1, samples);
  Eigen::VectorXd x(2 * n);
  for (int i = 0; i < 2 * n; ++i) x[i] = Uniform(rng, task.start_low[i], task.start_high[i]);
  const Excitation excite(task, rng);
  Eigen::MatrixXd& tau = traj.channels["tau"];
  // The torque the plant sees at time t in interval `current`: the sample held at
  // t - delay (the interval's own sample at its right end).
  int current = 0;
  const auto seen = [&](double t) -> Eigen::VectorXd {
    const int k = std::clamp(static_cast<int>(std::floor((t - delay) / o.dt + 1e-9)), 0, current);
    return tau.col(k);
  };
  Eigen::VectorXd q = x.head(n), qd = x.tail(n);
  for (int k = 0; k < samples; ++k) {
    current = k;
    traj.states.col(k) << q, qd;
    Eigen::VectorXd u = excite(traj.t[k]);
    if (task.feedback.size() > 0) u -= task.feedback * traj.states.col(k);
    u = u.cwiseMax(-task.bound).cwiseMin(task.bound);
    tau.col(k) = task.FullTorque(u, n);
    if (k < transitions) traj.actions.col(k) = u;
    RecordSample(plant, q, qd, seen(traj.t[k]), traj, k);
    if (k < transitions) IntegrateJointMotion(plant, seen, traj.t[k], traj.t[k + 1], o.substeps, q, qd);
  }
  return traj;
}

}  // namespace

Dataset CollectJointSpace(const JointTask& task, const JointCollectOptions& o) {
  DIFFDYN_CHECK(o.trajectories >= 1, "--trajectories must be at least 1, got ", o.trajectories);
  DIFFDYN_CHECK(o.dt > 0 && std::isfinite(o.dt), "--dt must be positive, got ", o.dt);
  DIFFDYN_CHECK(o.seconds >= 2 * o.dt && std::isfinite(o.seconds), "--seconds must be at least 2 dt (",
                2 * o.dt, " s), got ", o.seconds);
  DIFFDYN_CHECK(o.substeps >= 1, "substeps must be >= 1, got ", o.substeps);
  DIFFDYN_CHECK(o.threads >= 1, "--threads must be at least 1, got ", o.threads);
  const double transitions_real = std::round(o.seconds / o.dt);
  DIFFDYN_CHECK(transitions_real * o.trajectories <= 5e7, "--seconds / --dt x --trajectories: ",
                transitions_real * o.trajectories, " samples is more than the limit of 5e7");
  const int transitions = static_cast<int>(transitions_real);
  const auto plant = task.Plant();
  Dataset data;
  data.system = task.System();
  data.format = "joint-csv";
  data.trajectories.resize(o.trajectories);
  std::atomic<int> done{0};
  const auto caller = std::this_thread::get_id();
  ParallelForChunks(o.trajectories, 1, o.threads, [&](int, int begin, int end) {
    for (int i = begin; i < end; ++i) {
      Rng rng = TrajectoryRng(o.seed, static_cast<std::uint64_t>(i));
      data.trajectories[i] = SimulateTrajectory(task, *plant, o, transitions, rng);
      data.trajectories[i].label = std::to_string(i);
      const int finished = ++done;
      if (o.progress && std::this_thread::get_id() == caller) o.progress(finished);
    }
  });
  data.Validate();
  return data;
}

void AddGroundTruth(const JointTask& task, Trajectory* traj) {
  const auto plant = task.Plant();
  const int n = plant->dof(), samples = static_cast<int>(traj->states.cols());
  DIFFDYN_CHECK(traj->states.rows() == 2 * n && samples >= 2 &&
                    traj->actions.rows() == static_cast<Eigen::Index>(task.actuated.size()) &&
                    traj->actions.cols() == samples - 1,
                task.name, ": a trajectory needs 2n x K+1 states and m x K actions, got ", traj->states.rows(),
                " x ", samples, " and ", traj->actions.rows(), " x ", traj->actions.cols());
  DIFFDYN_CHECK(plant->Delay<double>(plant->EffectParams()) == 0.0, task.name,
                ": ground truth of a trajectory needs a plant without delay");
  for (const char* name : {"tau", "qdd", "m", "c", "g", "f"}) traj->channels[name].resize(n, samples);
  traj->channels["kinetic"].resize(1, samples);
  traj->channels["potential"].resize(1, samples);
  for (int k = 0; k < samples; ++k) {
    const Eigen::VectorXd tau = task.FullTorque(traj->actions.col(std::min(k, samples - 2)), n);
    traj->channels["tau"].col(k) = tau;
    RecordSample(*plant, traj->states.col(k).head(n), traj->states.col(k).tail(n), tau, *traj, k);
  }
}

}  // namespace diffdyn
