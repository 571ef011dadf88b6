#include "diffdyn/solvers/hidden_effects.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "diffdyn/models/random.h"
#include "diffdyn/physics/model_registry.h"

namespace diffdyn {
namespace {

// Centre and amplitude scale of the reference per joint (rad or m).
void ReferenceShape(const std::string& model, int n, Eigen::VectorXd& centre, Eigen::VectorXd& amp) {
  centre = Eigen::VectorXd::Zero(n);
  amp = Eigen::VectorXd::Constant(n, 0.8);
  if (model == "pendulum") amp[0] = 1.2;
  if (model == "cartpole") amp << 0.25, 0.6;
  if (model == "arm2") centre << -0.6, 1.7;
  if (model == "panda") {
    centre << 0.0, -0.3, 0.0, -1.9, 0.0, 1.7, 0.8;
    amp = Eigen::VectorXd::Constant(n, 0.35);
  }
}

struct Reference {
  Eigen::VectorXd centre;
  Eigen::MatrixXd amp, freq, phase;  // n x 3
  void At(double t, Eigen::VectorXd& q, Eigen::VectorXd& qd, Eigen::VectorXd& qdd) const {
    const int n = static_cast<int>(centre.size());
    q = centre;
    qd = Eigen::VectorXd::Zero(n);
    qdd = Eigen::VectorXd::Zero(n);
    for (int j = 0; j < n; ++j) {
      for (int l = 0; l < amp.cols(); ++l) {
        const double w = 2 * std::numbers::pi * freq(j, l), a = w * t + phase(j, l);
        q[j] += amp(j, l) * std::sin(a);
        qd[j] += amp(j, l) * w * std::cos(a);
        qdd[j] -= amp(j, l) * w * w * std::sin(a);
      }
    }
  }
};

double Rms(const Eigen::VectorXd& v) { return std::sqrt(v.squaredNorm() / std::max<Eigen::Index>(1, v.size())); }

}  // namespace

HiddenEffectCase GenerateHiddenEffectCase(const std::string& model_name, std::uint64_t seed,
                                          bool control, const HiddenEffectOptions& options) {
  const auto model = MakeAnalyticModel(model_name);
  const int n = model->dof();
  const Eigen::VectorXd p = model->DefaultParams();
  Rng rng(seed * 0x9E3779B97F4A7C15ULL + 17);
  HiddenEffectCase out;
  out.model = model_name;
  out.control = control;

  // Random smooth reference.
  Reference ref;
  Eigen::VectorXd amp_scale;
  ReferenceShape(model_name, n, ref.centre, amp_scale);
  ref.amp.resize(n, 3);
  ref.freq.resize(n, 3);
  ref.phase.resize(n, 3);
  for (int j = 0; j < n; ++j) {
    const double base = Uniform(rng, 0.15, 0.35);
    for (int l = 0; l < 3; ++l) {
      ref.amp(j, l) = amp_scale[j] * (l == 0 ? 0.6 : 0.25) * Uniform(rng, 0.7, 1.0);
      ref.freq(j, l) = base * (l + 1) * Uniform(rng, 0.9, 1.1);
      ref.phase(j, l) = Uniform(rng, 0, 2 * std::numbers::pi);
    }
  }

  // Reference torques and the effect's unit contribution along the reference.
  const int samples = static_cast<int>(std::lround(options.duration * options.sample_hz)) + 1;
  const double dt_s = 1.0 / options.sample_hz;
  Eigen::MatrixXd id_ref(n, samples), qr(n, samples), vr(n, samples), ar(n, samples), tip(n, samples);
  for (int k = 0; k < samples; ++k) {
    Eigen::VectorXd q, qd, qdd;
    ref.At(k * dt_s, q, qd, qdd);
    qr.col(k) = q;
    vr.col(k) = qd;
    ar.col(k) = qdd;
    id_ref.col(k) = model->InverseDynamics(q, qd, qdd, p);
    tip.col(k) = model->TipLoad(q, qd, qdd, p);
  }
  // Torque-sensor noise: one level (0.5 % of the overall torque RMS) or per joint
  // (1 % of the joint's own torque RMS).
  out.tau_noise = Eigen::VectorXd::Constant(n, 0.005 * std::sqrt(id_ref.squaredNorm() / id_ref.size()));
  if (options.per_joint_noise) {
    for (int j = 0; j < n; ++j) out.tau_noise[j] = 0.01 * Rms(id_ref.row(j).transpose());
  }

  std::vector<Effect> effects;
  if (!control) {
    std::vector<EffectKind> kinds = options.kinds;
    if (kinds.empty()) {
      for (const auto& info : AllEffectKinds()) {
        if (info.kind != EffectKind::kResidual) kinds.push_back(info.kind);
      }
    }
    Effect e;
    e.kind = kinds[rng() % kinds.size()];
    const EffectKindInfo& info = Info(e.kind);
    e.joint = info.per_joint ? 1 + static_cast<int>(rng() % n) : 0;
    out.ratio = Uniform(rng, options.ratio_min, options.ratio_max);
    const int j = e.joint - 1;
    const double noise = info.per_joint ? out.tau_noise[j] : Rms(out.tau_noise);
    const double target = out.ratio * noise;
    auto joint_rms = [&](auto&& f) {
      Eigen::VectorXd c(samples);
      for (int k = 0; k < samples; ++k) c[k] = f(k);
      return Rms(c);
    };
    auto all_rms = [&](const Eigen::MatrixXd& m) { return std::sqrt(m.squaredNorm() / m.size()); };
    const double sign = UniformUnit(rng) < 0.5 ? -1.0 : 1.0;
    switch (e.kind) {
      case EffectKind::kViscous:
        e.params = {target / joint_rms([&](int k) { return vr(j, k); })};
        break;
      case EffectKind::kCoulomb:
        e.params = {target / joint_rms([&](int k) { return std::tanh(vr(j, k) / kCoulombVelocityScale); })};
        break;
      case EffectKind::kStribeck: {
        const double ratio_s = Uniform(rng, 1.5, 3.0), vs = Uniform(rng, 0.03, 0.2);
        const double unit = joint_rms([&](int k) {
          const double v = vr(j, k);
          return (1 + (ratio_s - 1) * std::exp(-(v / vs) * (v / vs))) * std::tanh(v / kCoulombVelocityScale);
        });
        const double fc = target / unit;
        e.params = {fc, fc * ratio_s, vs};
        break;
      }
      case EffectKind::kOffset:
        e.params = {sign * target};
        break;
      case EffectKind::kSpring:
        e.params = {target / joint_rms([&](int k) { return qr(j, k); })};
        break;
      case EffectKind::kArmature:
        e.params = {target / joint_rms([&](int k) { return ar(j, k); })};
        break;
      case EffectKind::kGain:
        // tau_meas = ID / k: contribution (1/k - 1) ID.
        e.params = {1.0 / (1.0 + sign * target / all_rms(id_ref))};
        break;
      case EffectKind::kDelay: {
        Eigen::MatrixXd rate(n, samples - 2);
        for (int k = 1; k + 1 < samples; ++k) rate.col(k - 1) = (id_ref.col(k + 1) - id_ref.col(k - 1)) / (2 * dt_s);
        e.params = {target / all_rms(rate)};
        break;
      }
      case EffectKind::kPayload:
        e.params = {target / all_rms(tip)};
        break;
      default:
        throw Error(StrCat("hidden effects: cannot hide kind ", info.name));
    }
    out.effect = e;
    effects.push_back(e);
  }
  const ExtendedModel truth(model, p, effects);
  const double delay = truth.Delay<double>(truth.EffectParams());

  // Closed-loop simulation: torque held per control period, fine RK4 inside.
  const double w = 2 * std::numbers::pi * 3.0;
  const double dt_c = 1.0 / options.control_hz;
  const int control_steps = static_cast<int>(std::lround(options.duration * options.control_hz));
  const int record_every = static_cast<int>(std::lround(options.control_hz / options.sample_hz));
  std::vector<Eigen::VectorXd> commands;
  commands.reserve(control_steps + 1);
  Eigen::VectorXd q, qd, unused;
  ref.At(0.0, q, qd, unused);
  // The recorded samples; the dataset is made of them at the end.
  const std::string path = StrCat("hidden-effect case ", model_name, " seed ", seed);
  struct {
    Eigen::VectorXd t;
    Eigen::MatrixXd q, qd, tau;
  } data;
  data.t.resize(control_steps / record_every + 1);
  data.q.resize(n, data.t.size());
  data.qd.resize(n, data.t.size());
  data.tau.resize(n, data.t.size());
  int recorded = 0;
  for (int c = 0; c <= control_steps; ++c) {
    const double t = c * dt_c;
    Eigen::VectorXd q_ref, qd_ref, qdd_ref;
    ref.At(t, q_ref, qd_ref, qdd_ref);
    const Eigen::VectorXd command =
        model->InverseDynamics(q_ref, qd_ref, qdd_ref, p) +
        model->MassMatrix(q_ref, p) * (w * w * (q_ref - q) + 2 * w * (qd_ref - qd));
    commands.push_back(command);
    if (c % record_every == 0 && recorded < data.t.size()) {
      data.t[recorded] = t;
      for (int j = 0; j < n; ++j) {
        data.q(j, recorded) = q[j] + options.q_noise * StandardNormal(rng);
        data.qd(j, recorded) = qd[j] + options.qd_noise * StandardNormal(rng);
        data.tau(j, recorded) = command[j] + out.tau_noise[j] * StandardNormal(rng);
      }
      ++recorded;
    }
    if (c == control_steps) break;
    // The torque the joints receive at time s: the command held at s - d.
    auto applied = [&](double s) {
      const long idx = static_cast<long>(std::floor((s - delay) / dt_c + 1e-9));
      return commands[std::clamp<long>(idx, 0, static_cast<long>(commands.size()) - 1)];
    };
    try {
      IntegrateJointMotion(truth, applied, t, t + dt_c, options.substeps, q, qd);
    } catch (const NumericalError& e) {
      throw NumericalError(StrCat("hidden effects: simulation of ", path, " diverged: ", e.what()));
    }
  }
  data.t.conservativeResize(recorded);
  data.q.conservativeResize(n, recorded);
  data.qd.conservativeResize(n, recorded);
  data.tau.conservativeResize(n, recorded);
  JointLayout layout{.all_actuated = true};
  for (int j = 0; j < n; ++j) {
    if (model->prismatic(j)) layout.prismatic.push_back(j + 1);
  }
  out.data = JointSpaceDataset(path, data.t, data.q, data.qd, data.tau, layout);
  return out;
}

bool MatchesHiddenEffect(const std::string& model, const Effect& truth,
                         const std::vector<Effect>& named, double tolerance, double* magnitude_error) {
  double best = std::numeric_limits<double>::infinity();
  const double pendulum_mass = 1.0;  // default m of the pendulum
  for (const Effect& e : named) {
    double rel = std::numeric_limits<double>::infinity();
    if (e.kind == truth.kind && e.joint == truth.joint && !e.params.empty()) {
      if (truth.kind == EffectKind::kGain) {
        rel = std::abs((1.0 / e.params[0] - 1.0) - (1.0 / truth.params[0] - 1.0)) /
              std::abs(1.0 / truth.params[0] - 1.0);
      } else {
        rel = std::abs(e.params[0] - truth.params[0]) / std::abs(truth.params[0]);
      }
    } else if (model == "pendulum" && !e.params.empty()) {
      // Payload dm and gain k = m / (m + dm) produce the same data.
      if (truth.kind == EffectKind::kPayload && e.kind == EffectKind::kGain) {
        const double dm = pendulum_mass * (1.0 / e.params[0] - 1.0);
        rel = std::abs(dm - truth.params[0]) / std::abs(truth.params[0]);
      } else if (truth.kind == EffectKind::kGain && e.kind == EffectKind::kPayload) {
        const double dm_true = pendulum_mass * (1.0 / truth.params[0] - 1.0);
        rel = std::abs(e.params[0] - dm_true) / std::abs(dm_true);
      }
    }
    best = std::min(best, rel);
  }
  if (magnitude_error) *magnitude_error = best;
  return best <= tolerance;
}

}  // namespace diffdyn
