#include "diffdyn/solvers/delan_training.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/smoothing.h"

namespace diffdyn {
namespace {

// The characters the DeLaN authors hold out.
bool IsTestCharacter(const std::string& label) { return label == "e" || label == "q" || label == "v"; }

// (1/N) sum_samples sum_rows (a - b)^2 and, where b varies, the same over its total variance.
void AddScore(const std::string& key, const Eigen::MatrixXd& predicted, const Eigen::MatrixXd& truth,
              std::map<std::string, double>* scores) {
  (*scores)[key + "_mse"] = (predicted - truth).squaredNorm() / static_cast<double>(truth.cols());
  const double nmse = NormalizedMse(predicted, truth);
  if (std::isfinite(nmse)) (*scores)[key + "_nmse"] = nmse;
}

}  // namespace

double NormalizedMse(const Eigen::MatrixXd& predicted, const Eigen::MatrixXd& truth) {
  const double n = static_cast<double>(truth.cols());
  const double mse = (predicted - truth).squaredNorm() / n;
  const Eigen::VectorXd mean = truth.rowwise().mean();
  const double variance = (truth.colwise() - mean).squaredNorm() / n;
  return variance > 0 ? mse / variance : std::numeric_limits<double>::quiet_NaN();
}

DelanSamples SamplesOf(const Dataset& data) {
  const int n = JointCount(data);
  DIFFDYN_CHECK(data.samples() > 0, data.path, ": no samples");
  DelanSamples out;
  out.path = data.path;
  out.measured_torque = data.IsMeasured("tau");
  bool has_qdd = true;
  for (const Trajectory& t : data.trajectories) has_qdd = has_qdd && t.channels.count("qdd");
  if (has_qdd) {
    out.q = StackTrajectories(data, [n](const Trajectory& t) { return t.states.topRows(n); });
    out.qd = StackTrajectories(data, [n](const Trajectory& t) { return t.states.bottomRows(n); });
    out.qdd = StackChannel(data, "qdd");
    out.tau = StackChannel(data, "tau");
  } else {
    // Estimated as diagnose does: q, qd, tau smoothed alike, qdd = d/dt of smoothed qd.
    const SmoothedData s = SmoothJointSpace(data, 10.0);
    out.q = s.q;
    out.qd = s.qd;
    out.qdd = s.qdd;
    out.tau = s.tau;
  }
  // The ground-truth channels every trajectory has.
  for (const auto& [name, values] : data.trajectories.front().channels) {
    bool everywhere = name != "tau" && name != "qdd";
    for (const Trajectory& t : data.trajectories) everywhere = everywhere && t.channels.count(name);
    if (everywhere) out.channels[name] = StackChannel(data, name);
  }
  return out;
}

DelanSamples SelectSamples(const DelanSamples& samples, const std::vector<int>& index) {
  const int count = static_cast<int>(index.size());
  const auto pick = [&](const Eigen::MatrixXd& m) {
    Eigen::MatrixXd r(m.rows(), count);
    for (int i = 0; i < count; ++i) r.col(i) = m.col(index[i]);
    return r;
  };
  DelanSamples out;
  out.path = samples.path;
  out.measured_torque = samples.measured_torque;
  out.q = pick(samples.q);
  out.qd = pick(samples.qd);
  out.qdd = pick(samples.qdd);
  out.tau = pick(samples.tau);
  for (const auto& [name, m] : samples.channels) out.channels[name] = pick(m);
  return out;
}

DelanSplit SplitForDelan(const Dataset& data, double val_fraction, std::uint64_t seed) {
  const DelanSamples all = SamplesOf(data);
  std::vector<int> train, test;
  DelanSplit split;
  if (data.format == "delan-characters") {
    int a = 0;
    for (const Trajectory& t : data.trajectories) {
      std::vector<int>& side = IsTestCharacter(t.label) ? test : train;
      for (int i = 0; i < t.states.cols(); ++i) side.push_back(a + i);
      a += static_cast<int>(t.states.cols());
    }
    split.how = "characters e, q, v held out";
  } else {
    SplitWindows(all.size(), val_fraction, seed, &train, &test);
    std::sort(train.begin(), train.end());
    std::sort(test.begin(), test.end());
    split.how = "seeded split of samples";
  }
  DIFFDYN_CHECK(!train.empty() && !test.empty(), data.path, ": the split leaves ", train.size(),
                " training and ", test.size(), " held-out samples (--val-fraction ", val_fraction, ")");
  split.train = SelectSamples(all, train);
  split.test = SelectSamples(all, test);
  return split;
}

TrainOptions DelanTrainDefaults() {
  TrainOptions o;
  o.epochs = 10000;
  o.batch_size = 512;
  o.learning_rate = 5e-4;
  o.weight_decay = 1e-5;
  o.amsgrad = true;
  o.chunk_size = 256;
  return o;
}

Eigen::VectorXd BalancedJointWeights(const DelanSamples& train) {
  const Eigen::VectorXd mean = train.tau.rowwise().mean();
  const Eigen::VectorXd var = (train.tau.colwise() - mean).rowwise().squaredNorm() / std::max(1, train.size());
  double largest = 0.0;
  for (Eigen::Index j = 0; j < var.size(); ++j) {
    if (var[j] > 0) largest = std::max(largest, 1.0 / var[j]);
  }
  DIFFDYN_CHECK(largest > 0 && std::isfinite(largest), train.path, ": no joint's torque varies");
  Eigen::VectorXd w(var.size());
  for (Eigen::Index j = 0; j < var.size(); ++j) w[j] = var[j] > 0 ? 1.0 / var[j] : largest;
  return w;
}

TrainResult TrainDelan(Delan* model, const DelanSamples& train, const DelanSamples& val,
                       const TrainOptions& options,
                       const std::function<void(const EpochReport&)>& on_epoch,
                       const Eigen::VectorXd& joint_weights) {
  for (const DelanSamples* d : {&train, &val}) {
    if (d->size() == 0 && d == &val) continue;
    DIFFDYN_CHECK(d->dof() == model->dof(), d->path, ": ", d->dof(), " joints, the DeLaN has ",
                  model->dof());
    DIFFDYN_CHECK(d->qdd.cols() == d->size() && d->tau.cols() == d->size(), d->path,
                  ": DeLaN needs accelerations qdd and torques tau of every sample");
  }
  DIFFDYN_CHECK(train.measured_torque, train.path, ": no measured torques (free motion); DeLaN learns from torques");
  const int n = model->dof();
  const int batch = std::min(options.batch_size, train.size());
  DelanWorkspace ws(model->network().architecture(), batch, options.chunk_size, model->precision()), val_ws;
  Eigen::MatrixXd q(n, batch), qd(n, batch), qdd(n, batch), tau(n, batch);
  // FitMinibatches updates theta; each loss evaluation first hands it to the model.
  Eigen::VectorXd theta = model->parameters();
  MinibatchProblem problem;
  problem.n_train = train.size();
  problem.n_val = val.size();
  problem.batch_loss = [&](std::span<const int> positions, Eigen::VectorXd* grad) {
    model->SetParameters(theta);
    const int b = static_cast<int>(positions.size());
    for (Eigen::MatrixXd* m : {&q, &qd, &qdd, &tau}) m->resize(n, b);  // no-op unless b changes
    for (int i = 0; i < b; ++i) {
      q.col(i) = train.q.col(positions[i]);
      qd.col(i) = train.qd.col(positions[i]);
      qdd.col(i) = train.qdd.col(positions[i]);
      tau.col(i) = train.tau.col(positions[i]);
    }
    return model->TorqueLoss(q, qd, qdd, tau, grad, &ws, options.threads, joint_weights);
  };
  problem.validation_loss = [&] {
    model->SetParameters(theta);
    return model->TorqueLoss(val.q, val.qd, val.qdd, val.tau, nullptr, &val_ws, options.threads, joint_weights);
  };
  const TrainResult result = FitMinibatches(problem, options, &theta, on_epoch);
  model->SetParameters(theta);
  return result;
}

std::map<std::string, double> ScoreDelan(const Delan& model, const DelanSamples& data, int threads) {
  DIFFDYN_CHECK(data.dof() == model.dof(), data.path, ": ", data.dof(), " joints, the DeLaN has ",
                model.dof());
  DIFFDYN_CHECK(data.size() > 0 && data.qdd.cols() == data.size(), data.path,
                ": DeLaN scores need samples with accelerations qdd");
  DelanWorkspace ws;
  const DelanParts p = model.Decompose(data.q, data.qd, data.qdd, &ws, threads);
  std::map<std::string, double> scores;
  scores["n_samples"] = data.size();
  AddScore("torque", p.torque, data.tau, &scores);
  const auto channel = [&](const char* name) -> const Eigen::MatrixXd* {
    const auto it = data.channels.find(name);
    return it == data.channels.end() ? nullptr : &it->second;
  };
  if (const auto* m = channel("m")) AddScore("inertial", p.inertial, *m, &scores);
  if (const auto* c = channel("c")) AddScore("coriolis", p.coriolis, *c, &scores);
  if (const auto* g = channel("g")) AddScore("gravity", p.gravity, *g, &scores);
  if (const auto* f = channel("f")) AddScore("friction", p.friction, *f, &scores);
  if (const auto* k = channel("kinetic")) AddScore("kinetic", p.kinetic, *k, &scores);
  if (const auto* v = channel("potential")) {
    // V is identifiable up to a constant: match the means.
    const double offset = v->mean() - p.potential.mean();
    AddScore("potential", (p.potential.array() + offset).matrix(), *v, &scores);
  }
  // Power: dE^/dt + qd^T f^ (what tau^ delivers) against the measured qd^T tau.
  const Eigen::RowVectorXd measured = (data.qd.array() * data.tau.array()).colwise().sum();
  const Eigen::RowVectorXd dissipated = (data.qd.array() * p.friction.array()).colwise().sum();
  AddScore("power", p.power + dissipated, measured, &scores);
  scores["min_mass_eigenvalue"] = p.min_mass_eigenvalue.minCoeff();
  return scores;
}

}  // namespace diffdyn
