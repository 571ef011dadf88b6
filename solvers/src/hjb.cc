#include "diffdyn/solvers/hjb.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/init.h"
#include "diffdyn/models/parallel.h"
#include "diffdyn/models/random.h"
#include "diffdyn/solvers/lqr.h"

namespace diffdyn {

TaskHjb::TaskHjb(const ControlTask& task, double rho)
    : task_(task),
      model_(task.plant.Model()),
      params_(ParseParams(*model_, task.plant.params)),
      damping_(TaskDamping(task)),
      actuated_(TaskActuatedJoints(task)) {
  set_rho(rho);
  DIFFDYN_CHECK(task.action_size() <= kDiagJetSize, "TaskHjb: at most ", kDiagJetSize, " actions, got ",
                task.action_size());
}

void TaskHjb::set_rho(double rho) {
  DIFFDYN_CHECK(rho > 0 && std::isfinite(rho), "hjb: the discount rho must be positive, got ", rho);
  rho_ = rho;
}

void TaskHjb::Affine(const Eigen::VectorXd& x, Eigen::VectorXd* a, Eigen::MatrixXd* b) const {
  AffineScratch scratch;
  Affine(x, &scratch, a, b);
}

void TaskHjb::Affine(const Eigen::Ref<const Eigen::VectorXd>& x, AffineScratch* s, Eigen::VectorXd* a,
                     Eigen::MatrixXd* b) const {
  // One pass at u = 0 with the m actions seeded: values a(x), derivatives B(x) (exact: f is affine in u).
  const int n = task_.state_size(), m = task_.action_size();
  s->xj = x.cast<DiagJet>();
  if (s->uj.size() != m) {
    s->uj = VectorX<DiagJet>::Zero(m);
    for (int j = 0; j < m; ++j) s->uj[j].v[j] = 1.0;
  }
  const VectorX<DiagJet> dxdt = model_->Dynamics(params_, actuated_, damping_, s->xj, s->uj);
  a->resize(n);
  b->resize(n, m);
  for (int i = 0; i < n; ++i) {
    (*a)[i] = dxdt[i].a;
    for (int j = 0; j < m; ++j) (*b)(i, j) = dxdt[i].v[j];
  }
}

Eigen::VectorXd TaskHjb::Policy(const Eigen::VectorXd& x, const Eigen::VectorXd& p) const {
  Eigen::VectorXd a;
  Eigen::MatrixXd b;
  Affine(x, &a, &b);
  return task_.action_cost.ConjugateGradient(-b.transpose() * p);
}

void TaskHjb::Evaluate(const Eigen::MatrixXd& x, const Eigen::VectorXd& v, const Eigen::MatrixXd& p,
                       Eigen::VectorXd* f, Eigen::VectorXd* f_v, Eigen::MatrixXd* f_p, int threads) const {
  const int batch = static_cast<int>(x.cols());
  f->resize(batch);
  f_p->resize(x.rows(), batch);
  *f_v = Eigen::VectorXd::Constant(batch, rho_);
  // Each state is independent: chunks of a size fixed here, so any thread count gives the same bits.
  // Per chunk the buffers are sized once; per state only the plant's Dynamics and the
  // policy's vector are allocated.
  constexpr int kStatesPerChunk = 64;
  ParallelForChunks(batch, kStatesPerChunk, threads, [&](int, int begin, int end) {
    AffineScratch scratch;
    Eigen::VectorXd a, w;
    Eigen::MatrixXd b;
    for (int i = begin; i < end; ++i) {
      Affine(x.col(i), &scratch, &a, &b);
      w.noalias() = -b.transpose() * p.col(i);
      const Eigen::VectorXd u = task_.action_cost.ConjugateGradient(w);
      (*f)[i] = rho_ * v[i] - task_.StateCost(x.col(i)) - p.col(i).dot(a) + task_.action_cost.Conjugate(w);
      f_p->col(i).noalias() = -a;
      f_p->col(i).noalias() -= b * u;
    }
  });
}

TrainOptions HjbOptions::DefaultTrain() {
  TrainOptions t;
  t.epochs = 40;
  t.learning_rate = 1e-3;
  t.batch_size = 256;
  t.val_fraction = 0.05;
  t.chunk_size = 64;  // 4 chunks per batch of 256: both threads busy
  t.progress = false;
  return t;
}

void HjbOptions::Validate() const {
  DIFFDYN_CHECK(!hidden.empty() && hidden.size() <= 16, "hjb: between 1 and 16 hidden layers, got ", hidden.size());
  for (int w : hidden) DIFFDYN_CHECK(w >= 1 && w <= 4096, "hjb: hidden widths must be in [1, 4096], got ", w);
  DIFFDYN_CHECK(std::isfinite(rho_start) && std::isfinite(rho_final) && rho_final > 0 && rho_start >= rho_final,
                "hjb: the discounts need rho_start >= rho_final > 0, got ", rho_start, " and ", rho_final);
  DIFFDYN_CHECK(stages >= 1 && stages <= 1000, "hjb: stages must be in [1, 1000], got ", stages);
  DIFFDYN_CHECK(polish_stages >= 0 && polish_stages <= 1000, "hjb: polish stages must be in [0, 1000], got ",
                polish_stages);
  DIFFDYN_CHECK(samples >= 2 && samples <= 10000000, "hjb: samples must be in [2, 1e7], got ", samples);
  DIFFDYN_CHECK(std::isfinite(goal_anchor_weight) && goal_anchor_weight >= 0,
                "hjb: the goal anchor weight must be finite and >= 0, got ", goal_anchor_weight);
  DIFFDYN_CHECK(rollout_stages >= 0 && rollout_stages <= 1000, "hjb: rollout stages must be in [0, 1000], got ",
                rollout_stages);
  DIFFDYN_CHECK(rollout_starts >= 1 && rollout_starts <= 100000, "hjb: rollout starts must be in [1, 100000], got ",
                rollout_starts);
  DIFFDYN_CHECK(std::isfinite(rollout_weight) && rollout_weight >= 0,
                "hjb: the rollout weight must be finite and >= 0, got ", rollout_weight);
  DIFFDYN_CHECK(rollout_epochs >= 1 && rollout_epochs <= 1000000, "hjb: rollout epochs must be in [1, 1e6], got ",
                rollout_epochs);
  DIFFDYN_CHECK(std::isfinite(rollout_learning_rate) && rollout_learning_rate > 0,
                "hjb: the rollout learning rate must be finite and > 0, got ", rollout_learning_rate);
  DIFFDYN_CHECK(candidates >= 1 && candidates <= 1000, "hjb: candidates must be in [1, 1000], got ", candidates);
  DIFFDYN_CHECK(validation_starts >= 1 && validation_starts <= 100000,
                "hjb: validation starts must be in [1, 100000], got ", validation_starts);
}

ValueFunction MakeTaskValueFunction(const ControlTask& task, const HjbOptions& options) {
  options.Validate();
  InputFeatures features;
  for (int i = 0; i < task.state_size(); ++i) {
    if (task.periodic[static_cast<std::size_t>(i)]) features.periodic.push_back(i);
  }
  const int d = features.size(task.state_size());
  MlpArchitecture arch;
  arch.sizes.push_back(d);
  for (int w : options.hidden) {
    arch.sizes.push_back(w);
    arch.activations.push_back(options.activation);
  }
  arch.sizes.push_back(ValueFunction::OutputsFor(ValueForm::kQuadratic, d));
  return ValueFunction::Quadratic(MakeInitializedMlp(arch, InitOptions::Ddn(), options.seed), task.goal, features);
}

ValueAnchors GoalAnchors(const ControlTask& task, double rho, double weight, double h) {
  const LqrSolution lqr = TaskLqr(task);
  const int n = task.state_size();
  const Eigen::MatrixXd p =
      SolveLqr(lqr.A - 0.5 * rho * Eigen::MatrixXd::Identity(n, n), lqr.B, lqr.Q, lqr.R).P;
  // Directions +-e_i, then +-(e_i + e_j) / sqrt(2) and +-(e_i - e_j) / sqrt(2) for i < j.
  std::vector<Eigen::VectorXd> directions;
  for (int i = 0; i < n; ++i) directions.push_back(Eigen::VectorXd::Unit(n, i));
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      directions.push_back((Eigen::VectorXd::Unit(n, i) + Eigen::VectorXd::Unit(n, j)) / std::sqrt(2.0));
      directions.push_back((Eigen::VectorXd::Unit(n, i) - Eigen::VectorXd::Unit(n, j)) / std::sqrt(2.0));
    }
  }
  const Eigen::Index a = 2 * static_cast<Eigen::Index>(directions.size());
  ValueAnchors anchors{Eigen::MatrixXd(n, a), Eigen::VectorXd(a), Eigen::VectorXd::Constant(a, h * h), weight};
  for (std::size_t k = 0; k < directions.size(); ++k) {
    for (int sign : {1, -1}) {
      const Eigen::Index c = 2 * static_cast<Eigen::Index>(k) + (sign > 0 ? 0 : 1);
      anchors.states.col(c) = task.goal + (sign * h) * directions[k];
      anchors.values[c] = h * h * directions[k].dot(p * directions[k]);
    }
  }
  return anchors;
}

ValueAnchors RolloutAnchors(const ControlTask& task, const ValueFunction& value, double rho, double weight,
                            int starts, std::uint64_t seed, int threads) {
  HjbController controller(task, value);
  const std::vector<ControlRun> runs =
      EvaluateController(task, controller, {.starts = starts, .seed = seed, .threads = threads});
  Eigen::Index total = 0;
  for (const ControlRun& run : runs) total += run.trajectory.states.cols() - 1;
  const int n = task.state_size();
  ValueAnchors anchors{Eigen::MatrixXd(n, total), Eigen::VectorXd(total), Eigen::VectorXd::Ones(total), weight, 256};
  const double decay = std::exp(-rho * task.period);
  Eigen::Index c = 0;
  for (const ControlRun& run : runs) {
    // Backwards from V at the last state: G_k = T c_k + e^{-rho T} G_{k+1}.
    const Eigen::MatrixXd& x = run.trajectory.states;
    const Eigen::MatrixXd& u = run.trajectory.actions;
    const Eigen::Index steps = x.cols() - 1;
    Eigen::VectorXd v;
    Eigen::MatrixXd p;
    value.Evaluate(x.col(steps), &v, &p);
    double g = v[0];
    for (Eigen::Index k = steps - 1; k >= 0; --k) {
      g = task.period * task.RunningCost(x.col(k), u.col(k)) + decay * g;
      anchors.states.col(c + k) = x.col(k);
      anchors.values[c + k] = g;
    }
    c += steps;
  }
  // A seeded order, so that each mini-batch sees states of many runs.
  std::vector<Eigen::Index> order(static_cast<std::size_t>(total));
  for (Eigen::Index i = 0; i < total; ++i) order[static_cast<std::size_t>(i)] = i;
  Rng rng = TrajectoryRng(seed, 0);
  Shuffle(order.begin(), order.end(), rng);
  anchors.states = anchors.states(Eigen::all, order).eval();
  anchors.values = anchors.values(order).eval();
  return anchors;
}

namespace {

// Fresh uniform states over the task's domain for stage k.
Eigen::MatrixXd SampleStates(const ControlTask& task, const HjbOptions& options, std::uint64_t stage) {
  Rng rng = TrajectoryRng(options.seed, stage);
  Eigen::MatrixXd states(task.state_size(), options.samples);
  for (int j = 0; j < options.samples; ++j) {
    for (int i = 0; i < task.state_size(); ++i) states(i, j) = Uniform(rng, task.domain_low[i], task.domain_high[i]);
  }
  return states;
}

}  // namespace

void SolveHjb(const ControlTask& task, const HjbOptions& options, ValueFunction* value,
              const std::function<void(const HjbStageReport&)>& on_stage) {
  options.Validate();
  const int n = task.state_size();
  DIFFDYN_CHECK(value->state_size() == n, "hjb: the value function has ", value->state_size(), " states, the task ",
                n);
  DIFFDYN_CHECK(task.domain_low.size() == n && task.domain_high.size() == n && task.domain_low.allFinite() &&
                    task.domain_high.allFinite() && (task.domain_low.array() < task.domain_high.array()).all(),
                "hjb: the task has no finite state domain to learn over");
  TaskHjb hjb(task, options.rho_start);
  const int total = options.stages + options.polish_stages + options.rollout_stages;
  for (int k = 0; k < total; ++k) {
    const auto start = std::chrono::steady_clock::now();
    // The discount of stage k (geometric, then held) and its learning rate.
    const double fraction = options.stages == 1 ? 1.0 : std::min(1.0, k / double(options.stages - 1));
    hjb.set_rho(options.rho_start * std::pow(options.rho_final / options.rho_start, fraction));
    const bool rollout = k >= options.stages + options.polish_stages;
    TrainOptions train = options.train;
    if (rollout) {
      train.epochs = options.rollout_epochs;
      train.learning_rate = options.rollout_learning_rate;
    } else if (k >= options.stages) {
      train.learning_rate /= std::pow(3.0, k - options.stages + 1);
    }
    train.seed = SplitMix64Hash(options.seed * 1000 + static_cast<std::uint64_t>(k));
    const Eigen::MatrixXd states = SampleStates(task, options, static_cast<std::uint64_t>(k));
    std::optional<ValueAnchors> anchors =
        options.goal_anchor_weight > 0
            ? std::optional(GoalAnchors(task, hjb.rho(), options.goal_anchor_weight))
            : std::nullopt;
    if (rollout) {
      // The current policy's runs from starts of their own seed (apart from any evaluation's).
      anchors = RolloutAnchors(task, *value, hjb.rho(), options.rollout_weight, options.rollout_starts,
                               SplitMix64Hash(options.seed * 1000 + static_cast<std::uint64_t>(k) + 777),
                               options.train.threads);
    }
    HjbStageReport report{k, total, hjb.rho(), train.learning_rate,
                          SolveResidual(hjb, states, train, value, {}, anchors ? &*anchors : nullptr), 0.0};
    if (!std::isfinite(report.result.final_train_loss) || !value->net().parameters().allFinite()) {
      throw NumericalError(StrCat("hjb: stage ", k + 1, " (rho ", hjb.rho(), ") diverged: the residual is ",
                                  report.result.final_train_loss, " (try a smaller --lr); nothing written"));
    }
    report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (on_stage) on_stage(report);
  }
}

ValueFunction LearnTaskValue(const ControlTask& task, const HjbOptions& options,
                             const std::function<void(const HjbStageReport&)>& on_stage,
                             const std::function<void(const HjbCandidateReport&)>& on_candidate, int* kept) {
  options.Validate();
  ValueFunction best;
  double best_cost = std::numeric_limits<double>::infinity();
  for (int c = 0; c < options.candidates; ++c) {
    HjbOptions o = options;
    o.seed = options.seed + static_cast<std::uint64_t>(c);
    ValueFunction value = MakeTaskValueFunction(task, o);
    HjbCandidateReport report{c, o.seed, 0, 0.0, 0.0};
    SolveHjb(task, o, &value, [&](const HjbStageReport& r) {
      report.residual = r.result.final_val_loss;
      if (on_stage) on_stage(r);
    });
    // The policy's mean cost from the validation starts.
    HjbController controller(task, value);
    for (const ControlRun& run : EvaluateController(task, controller,
                                                    {.starts = options.validation_starts,
                                                     .seed = options.validation_seed,
                                                     .threads = options.train.threads})) {
      report.successes += run.success ? 1 : 0;
      report.mean_cost += run.cost / options.validation_starts;
    }
    if (on_candidate) on_candidate(report);
    if (c == 0 || report.mean_cost < best_cost) {
      best_cost = report.mean_cost;
      best = std::move(value);
      if (kept) *kept = c;
    }
  }
  return best;
}

HjbController::HjbController(const ControlTask& task, const ValueFunction& value)
    : task_(task), value_(value), hjb_(task, 1.0), ws_(value.MakeWorkspace(1)) {
  DIFFDYN_CHECK(value.state_size() == task.state_size(), "hjb: the value function has ", value.state_size(),
                " states, the task ", task.state_size());
}

Eigen::VectorXd HjbController::Command(const Eigen::VectorXd& x) {
  value_.Evaluate(x, &v_, &p_, &ws_);
  return hjb_.Policy(x, p_.col(0));
}

namespace {

// Checks a "value" architecture object and returns its network's architecture.
MlpArchitecture ValueArchitectureFromJson(const nlohmann::json& j, ValueFunction* shape) {
  DIFFDYN_CHECK(j.is_object() && j.contains("task") && j["task"].is_string() && j.contains("form") &&
                    j["form"] == "quadratic" && j.contains("goal") && j["goal"].is_array() &&
                    j.contains("periodic") && j["periodic"].is_array() && j.contains("epsilon") &&
                    j["epsilon"].is_number() && j.contains("mlp"),
                "architecture must have task, form \"quadratic\", goal, periodic, epsilon and mlp");
  const std::vector<std::string> tasks = ControlTaskNames();
  DIFFDYN_CHECK(std::find(tasks.begin(), tasks.end(), j["task"].get<std::string>()) != tasks.end(),
                "task must name a control task (pendulum or cartpole)");
  const MlpArchitecture arch = MlpArchitectureFromJson(j["mlp"]);
  DIFFDYN_CHECK(j["goal"].size() >= 1 && j["goal"].size() <= 64, "goal must have 1 to 64 values");
  Eigen::VectorXd goal(static_cast<Eigen::Index>(j["goal"].size()));
  for (std::size_t i = 0; i < j["goal"].size(); ++i) {
    DIFFDYN_CHECK(j["goal"][i].is_number(), "goal values must be numbers");
    goal[static_cast<Eigen::Index>(i)] = j["goal"][i].get<double>();
  }
  InputFeatures features;
  for (const auto& i : j["periodic"]) {
    DIFFDYN_CHECK(i.is_number_integer() && i.get<long long>() >= 0 && i.get<long long>() < goal.size(),
                  "periodic entries must be state indices below ", goal.size());
    features.periodic.push_back(i.get<int>());
  }
  // The constructor checks sizes, order, goal and epsilon.
  *shape = ValueFunction::Quadratic(Mlp<double>(arch), goal, features, j["epsilon"].get<double>());
  return arch;
}

void RegisterValueKind() {
  static std::once_flag once;
  std::call_once(once, [] {
    RegisterModelKind("value", [](const nlohmann::json& j) {
      ValueFunction shape;
      return ValueArchitectureFromJson(j, &shape).num_parameters();
    });
  });
}

}  // namespace

void SaveValueFunction(const std::filesystem::path& path, const ValueFunction& value, const std::string& task,
                       const nlohmann::json& provenance, const nlohmann::json& metrics) {
  DIFFDYN_CHECK(value.form() == ValueForm::kQuadratic, path.string(), ": only the quadratic form is saved");
  RegisterValueKind();
  const nlohmann::json architecture = {{"task", task},
                                       {"form", "quadratic"},
                                       {"periodic", value.features().periodic},
                                       {"goal", std::vector<double>(value.goal().begin(), value.goal().end())},
                                       {"epsilon", value.epsilon()},
                                       {"mlp", MlpArchitectureToJson(value.net().architecture())}};
  SaveModelFile(path, ModelFile{"value", architecture, value.net().parameters(), provenance, metrics, nullptr});
}

ValueFunction LoadValueFunction(const std::filesystem::path& path, std::string* task, ModelFile* contents) {
  RegisterValueKind();
  ModelFile file = LoadModelFile(path);
  DIFFDYN_CHECK(file.kind == "value", path.string(), ": model kind is '", file.kind, "', expected value");
  ValueFunction shape;
  ValueArchitectureFromJson(file.architecture, &shape);
  *task = file.architecture["task"].get<std::string>();
  ValueFunction value = ValueFunction::Quadratic(Mlp<double>(shape.net().architecture(), file.parameters),
                                                 shape.goal(), shape.features(), shape.epsilon());
  if (contents) *contents = std::move(file);
  return value;
}

}  // namespace diffdyn
