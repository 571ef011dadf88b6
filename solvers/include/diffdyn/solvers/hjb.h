// The Hamilton-Jacobi-Bellman equation of a control task, as a first-order equation for
// residual minimisation (residual_solver.h).
//
// A task's plant is control-affine, dx/dt = a(x) + B(x) u (the manipulator equation:
// a = (qd, M^-1 (-ID(q, qd, 0) - D qd)), B = (0; M^-1 S), S the actuated joints), and
// its running cost is q(x) + g(u) with g strictly convex (control_task.h). With discount
// rho the value function V solves
//
//   rho V = min_u [q + g(u) + p^T (a + B u)],   p = dV/dx,
//
// whose minimiser is closed form through the convex conjugate g~ (ActionCost::Conjugate):
//
//   u*(x, p) = grad g~(-B^T p),
//   F(x, V, p) = rho V - q(x) - p^T a(x) + g~(-B(x)^T p) = 0,
//   F_V = rho,   F_p = -(a(x) + B(x) u*).
//
// For the log-cosine cost u* = (2 u_max / pi) atan(-B^T p / beta) stays within the
// bounds by construction (lutter_facts.md (d)). a(x) and B(x) come from one Jet pass of
// AnalyticModel::Dynamics at u = 0 with the actions seeded.
//
// SolveHjb learns V over the task's state domain (ControlTask::domain_low/high) with
// the structured value network V = (z - z0)^T L L^T (z - z0) (ValueForm::kQuadratic;
// z the state's features, sin/cos for periodic components, z0 the goal's), so that
// V >= 0 and V(goal) = 0 hold by construction. The discount is annealed from large
// (short-sighted, an easy equation) to the task's small one, rho_k geometric from
// rho_start to rho_final over `stages` stages, each a residual minimisation from the
// previous stage's parameters on fresh uniform states; `polish_stages` more at
// rho_final divide the learning rate by 3 each. The squared residual is O(|x - goal|^4)
// near the goal, so it leaves V's Hessian there nearly free; with goal_anchor_weight > 0
// each stage's loss also holds V near the goal to the discounted LQR cost-to-go
// (GoalAnchors), the second-order solution of the same equation. `rollout_stages` more
// at rho_final then evaluate the current policy where it goes (one step of policy
// iteration each): the policy runs from seeded starts of the task, and each visited
// state's discounted cost-to-go along its run (RolloutAnchors) is a value target beside
// the residual, so that V, whose gradient is the policy, also matches what the policy
// costs. HjbController then acts by u = u*(x, dV/dx(x)): one network pass per command,
// no replanning.
//
//   const ControlTask task = ControlTaskByName("pendulum");
//   ValueFunction value = SolveHjb(task, HjbOptions{});
//   HjbController controller(task, value);                        // control.h
//   std::vector<ControlRun> runs = EvaluateController(task, controller, {.starts = 300, .seed = 1});
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/physics/analytic_model.h"
#include "diffdyn/models/model_file.h"
#include "diffdyn/physics/control_task.h"
#include "diffdyn/solvers/control.h"
#include "diffdyn/solvers/residual_solver.h"

namespace diffdyn {

/// The discounted HJB of a control task (file comment). Keeps a reference to the task.
class TaskHjb final : public FirstOrderEquation {
 public:
  /// Throws diffdyn::Error unless rho > 0 is finite, or when the task's plant has an
  /// effect other than viscous friction.
  TaskHjb(const ControlTask& task, double rho);
  int state_size() const override { return task_.state_size(); }
  /// The states' a(x), B(x) and policy, in chunks of 64 states over `threads`.
  void Evaluate(const Eigen::MatrixXd& x, const Eigen::VectorXd& v, const Eigen::MatrixXd& p, Eigen::VectorXd* f,
                Eigen::VectorXd* f_v, Eigen::MatrixXd* f_p, int threads) const override;

  /// The discount rho (1/s).
  double rho() const { return rho_; }
  /// Changes the discount (the homotopy's stages); throws diffdyn::Error unless rho > 0.
  void set_rho(double rho);
  /// a(x) (n) and B(x) (n x m) of the plant at one state x (n).
  void Affine(const Eigen::VectorXd& x, Eigen::VectorXd* a, Eigen::MatrixXd* b) const;
  /// u*(x, p) = grad g~(-B(x)^T p) (m) at one state x and value gradient p (n each).
  Eigen::VectorXd Policy(const Eigen::VectorXd& x, const Eigen::VectorXd& p) const;

 private:
  // The Jet copies of one state and of the seeded zero action, kept across the states
  // of a chunk.
  struct AffineScratch {
    VectorX<DiagJet> xj, uj;
  };
  void Affine(const Eigen::Ref<const Eigen::VectorXd>& x, AffineScratch* s, Eigen::VectorXd* a,
              Eigen::MatrixXd* b) const;

  const ControlTask& task_;
  std::shared_ptr<const AnalyticModel> model_;
  Eigen::VectorXd params_, damping_;
  std::vector<int> actuated_;
  double rho_ = 1.0;
};

/// Settings of SolveHjb (file comment). The defaults are those measured for the
/// pendulum in paper_figures/hjb_pendulum/.
struct HjbOptions {
  /// Hidden widths and activation of the network of L (cFVI: tanh, 96 wide).
  std::vector<int> hidden = {96, 96};
  Activation activation = Activation::Tanh();
  /// The homotopy: `stages` discounts geometric from rho_start to rho_final (1/s;
  /// rho_final = -ln(0.65) / 5, the cFVI discount), then `polish_stages` at rho_final.
  double rho_start = 5.0;
  double rho_final = 0.0862;
  int stages = 6;
  int polish_stages = 2;
  /// Uniform states drawn afresh over the task's domain for each stage.
  int samples = 51200;
  /// Weight of the goal anchors (GoalAnchors) in each stage's loss; 0 leaves them out.
  double goal_anchor_weight = 0.0;
  /// Policy-evaluation stages after the polish, at rho_final (RolloutAnchors): each runs
  /// the current policy from `rollout_starts` starts of the task and adds the runs'
  /// discounted costs-to-go as value targets of weight `rollout_weight` to its residual
  /// loss, for `rollout_epochs` epochs of Adam at `rollout_learning_rate`.
  int rollout_stages = 3;
  int rollout_starts = 64;
  double rollout_weight = 10.0;
  int rollout_epochs = 20;
  double rollout_learning_rate = 1e-4;
  /// Adam per stage (epochs, learning rate, batch, held-out fraction, chunk, threads);
  /// its seed is replaced per stage from `seed`. The chunk (64 states) splits a batch
  /// of 256 evenly over two threads.
  TrainOptions train = DefaultTrain();
  /// Seeds the network's initial parameters and the states.
  std::uint64_t seed = 0;
  /// LearnTaskValue: candidates trained from seeds seed, seed + 1, ...; the one whose
  /// policy has the lowest mean cost from `validation_starts` starts of the task (drawn
  /// with validation_seed, apart from any evaluation's starts) is kept.
  int candidates = 1;
  int validation_starts = 40;
  std::uint64_t validation_seed = 1000003;

  /// Throws diffdyn::Error naming the bad setting.
  void Validate() const;
  static TrainOptions DefaultTrain();
};

/// What one stage of SolveHjb did.
struct HjbStageReport {
  int stage = 0;  // 0-based, over stages + polish_stages
  int stages = 0;
  double rho = 0.0;
  double learning_rate = 0.0;
  TrainResult result;
  /// Wall time of the stage (s).
  double seconds = 0.0;
};

/// The boundary condition at the goal as value anchors (residual_solver.h): near the goal
/// the discounted HJB's solution is the LQR cost-to-go of the discounted linearisation,
/// V(goal + e) = e^T P_rho e + O(|e|^3), P_rho the Riccati solution for (A - rho/2 I, B, Q, R)
/// (lqr.h). Anchors at e = h d for d = +-e_i and +-(e_i +- e_j)/sqrt(2) (2 n^2 states),
/// values h^2 d^T P_rho d, scales h^2: they pin V's Hessian at the goal, which the squared
/// residual, O(|e|^4) there, leaves free. Throws diffdyn::NumericalError when the
/// discounted linearisation has no stabilising Riccati solution.
ValueAnchors GoalAnchors(const ControlTask& task, double rho, double weight, double h = 1e-3);

/// Value targets from the policy of `value` (HjbController): runs from `starts` starts
/// of the task (task.Starts(starts, seed)); at every state x_k of a run of K steps of
/// period T, the discounted cost-to-go of the rest of the run,
///   G_k = sum_{k <= j < K} e^{-rho (j - k) T} T c(x_j, u_j) + e^{-rho (K - k) T} V(x_K),
/// scale 1, in a seeded order, `batch` (256) of them per mini-batch.
ValueAnchors RolloutAnchors(const ControlTask& task, const ValueFunction& value, double rho, double weight,
                            int starts, std::uint64_t seed, int threads = 1);

/// The structured value network of the task, initialised from seed (file comment).
ValueFunction MakeTaskValueFunction(const ControlTask& task, const HjbOptions& options);

/// Learns the task's value function by the discount homotopy (file comment) from
/// `value`'s parameters, in place; on_stage is called after every stage. Throws
/// diffdyn::Error for bad options and diffdyn::NumericalError when a stage diverges.
void SolveHjb(const ControlTask& task, const HjbOptions& options, ValueFunction* value,
              const std::function<void(const HjbStageReport&)>& on_stage = {});

/// What one candidate of LearnTaskValue gave on the validation starts.
struct HjbCandidateReport {
  int candidate = 0;
  std::uint64_t seed = 0;
  int successes = 0;
  double mean_cost = 0.0;
  /// The last stage's held-out mean squared residual.
  double residual = 0.0;
};

/// Trains options.candidates value functions by SolveHjb (seeds seed, seed + 1, ...)
/// and returns the one whose policy has the lowest mean validation cost (HjbOptions);
/// on_stage sees every stage of every candidate, on_candidate each candidate's score;
/// *kept (if not null) receives the kept candidate's index.
ValueFunction LearnTaskValue(const ControlTask& task, const HjbOptions& options,
                             const std::function<void(const HjbStageReport&)>& on_stage = {},
                             const std::function<void(const HjbCandidateReport&)>& on_candidate = {},
                             int* kept = nullptr);

/// The feedback policy u = u*(x, dV/dx(x)) of a learned value function (file comment).
/// Copyable for the evaluator's threads; keeps references to task and value.
class HjbController final : public Controller {
 public:
  /// Throws diffdyn::Error when value's state size is not the task's.
  HjbController(const ControlTask& task, const ValueFunction& value);
  void Reset(const Eigen::VectorXd& /*x0*/, std::uint64_t /*seed*/) override {}
  Eigen::VectorXd Command(const Eigen::VectorXd& x) override;
  std::unique_ptr<Controller> Clone() const override { return std::make_unique<HjbController>(task_, value_); }

 private:
  const ControlTask& task_;
  const ValueFunction& value_;
  TaskHjb hjb_;
  ValueWorkspace ws_;
  Eigen::VectorXd v_;
  Eigen::MatrixXd p_;
};

/// Saves a task's value function as a model file of kind "value": architecture
/// {"task", "form", "periodic", "goal", "epsilon", "mlp"} (model_file.h), atomically.
void SaveValueFunction(const std::filesystem::path& path, const ValueFunction& value, const std::string& task,
                       const nlohmann::json& provenance = nlohmann::json::object(),
                       const nlohmann::json& metrics = nlohmann::json::object());

/// Loads a model file of kind "value"; *task receives its task's name. Throws
/// diffdyn::Error with one line naming the path.
ValueFunction LoadValueFunction(const std::filesystem::path& path, std::string* task,
                                ModelFile* contents = nullptr);

}  // namespace diffdyn
