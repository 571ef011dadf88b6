#include "diffdyn/solvers/multiple_shooting.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <numbers>

#include <Eigen/Cholesky>
#include <ceres/ceres.h>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/autodiff_ode/integrate.h"
#include "diffdyn/solvers/lqr.h"

namespace diffdyn {

TaskStep::TaskStep(const ControlTask& task)
    : plant_(TaskModel(task, task.period, kSubsteps)), workspace_(plant_->MakeWorkspace(1)) {}

TaskStep::~TaskStep() = default;

Eigen::VectorXd TaskStep::Value(const Eigen::VectorXd& x, const Eigen::VectorXd& u) const {
  Eigen::VectorXd next(x.size());
  plant_->PredictBatch(x, u, next, *workspace_);
  return next;
}

Eigen::VectorXd TaskStep::Jacobians(const Eigen::VectorXd& x, const Eigen::VectorXd& u,
                                    Eigen::MatrixXd* fx, Eigen::MatrixXd* fu) const {
  Eigen::MatrixXd jac;
  const Eigen::VectorXd next = plant_->Jacobian(x, u, &jac);
  *fx = jac.leftCols(x.size());
  *fu = jac.rightCols(u.size());
  return next;
}

namespace {

using RowMajorMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// r (n) with |r|^2 = period * StateCost(x), and dr/dx (diagonal, n).
void StateSquares(const ControlTask& task, const double* x, double* r, double* drdx) {
  for (int i = 0; i < task.state_size(); ++i) {
    const double s = std::sqrt(task.period * task.weights[i]), d = x[i] - task.goal[i];
    const bool periodic = task.periodic[static_cast<std::size_t>(i)];
    r[i] = s * (periodic ? std::numbers::pi * std::sin(0.5 * d) : d);
    if (drdx) drdx[i] = s * (periodic ? 0.5 * std::numbers::pi * std::cos(0.5 * d) : 1.0);
  }
}

// r (m) with |r|^2 = period * g(u), and dr/du (diagonal, m): quadratic rho_j = sqrt(r_j)
// u_j; log-cosine rho = sign(u) sqrt(g(u)), g = (beta / a) (-log cos(a u)), a = pi / (2 u_max).
void ActionSquares(const ControlTask& task, const double* u, double* r, double* drdu) {
  const ActionCost& g = task.action_cost;
  const double sp = std::sqrt(task.period);
  if (g.kind == ActionCost::Kind::kQuadratic) {
    for (int j = 0; j < task.action_size(); ++j) {
      r[j] = sp * std::sqrt(g.r[j]) * u[j];
      if (drdu) drdu[j] = sp * std::sqrt(g.r[j]);
    }
    return;
  }
  const double a = std::numbers::pi / (2.0 * g.u_max), z = a * u[0];
  if (std::abs(z) < 1e-6) {  // g = beta a u^2 / 2 (1 + O(z^2))
    const double slope = std::sqrt(0.5 * g.beta * a);
    r[0] = sp * slope * u[0];
    if (drdu) drdu[0] = sp * slope;
    return;
  }
  const double value = -(g.beta / a) * std::log(std::cos(z)), root = std::sqrt(value);
  r[0] = sp * std::copysign(root, u[0]);
  if (drdu)
    drdu[0] = sp * g.beta * std::tan(z) / (2.0 * std::copysign(root, u[0]));  // g' / (2 rho)
}

// r = Lt e(x) (n) with |r|^2 = e^T P e, P = L L^T the LQR cost-to-go at the goal (Lt
// zero: none), e_i = 2 sin(d_i / 2) for a periodic component, d_i otherwise; drdx = Lt diag(de/dx).
void TerminalSquares(const ControlTask& task, const Eigen::MatrixXd& lt, const double* x, double* r,
                     double* drdx) {
  const int n = task.state_size();
  Eigen::VectorXd e(n), de(n);
  for (int i = 0; i < n; ++i) {
    const double d = x[i] - task.goal[i];
    const bool periodic = task.periodic[static_cast<std::size_t>(i)];
    e[i] = periodic ? 2.0 * std::sin(0.5 * d) : d;
    de[i] = periodic ? std::cos(0.5 * d) : 1.0;
  }
  Eigen::Map<Eigen::VectorXd>(r, n) = lt * e;
  if (drdx) Eigen::Map<RowMajorMatrix>(drdx, n, n) = lt * de.asDiagonal();
}

// The terminal cost's squares on x_K (one block).
class TerminalResidual final : public ceres::CostFunction {
 public:
  TerminalResidual(const ControlTask& task, const Eigen::MatrixXd& lt) : task_(task), lt_(lt) {
    set_num_residuals(task.state_size());
    mutable_parameter_block_sizes()->assign({task.state_size()});
  }
  bool Evaluate(double const* const* params, double* residuals, double** jacobians) const override {
    TerminalSquares(task_, lt_, params[0], residuals, jacobians ? jacobians[0] : nullptr);
    return true;
  }

 private:
  const ControlTask& task_;
  const Eigen::MatrixXd& lt_;
};

// s (x_{k+1} - Phi(x_k, u_k)) over the blocks (x_k, u_k, x_{k+1}); s is shared by all
// such residuals so that a stage only changes one number.
class ContinuityResidual final : public ceres::CostFunction {
 public:
  ContinuityResidual(const TaskStep& step, const double& weight, int n, int m)
      : step_(step), weight_(weight), n_(n), m_(m) {
    set_num_residuals(n);
    mutable_parameter_block_sizes()->assign({n, m, n});
  }

  bool Evaluate(double const* const* params, double* residuals, double** jacobians) const override {
    const Eigen::Map<const Eigen::VectorXd> x(params[0], n_), u(params[1], m_), next(params[2], n_);
    Eigen::VectorXd phi;
    Eigen::MatrixXd fx, fu;
    phi = jacobians ? step_.Jacobians(x, u, &fx, &fu) : step_.Value(x, u);
    Eigen::Map<Eigen::VectorXd>(residuals, n_) = weight_ * (next - phi);
    if (jacobians) {
      if (jacobians[0]) Eigen::Map<RowMajorMatrix>(jacobians[0], n_, n_) = -weight_ * fx;
      if (jacobians[1]) Eigen::Map<RowMajorMatrix>(jacobians[1], n_, m_) = -weight_ * fu;
      if (jacobians[2])
        Eigen::Map<RowMajorMatrix>(jacobians[2], n_, n_) =
            weight_ * RowMajorMatrix::Identity(n_, n_);
    }
    return Eigen::Map<Eigen::VectorXd>(residuals, n_).allFinite();
  }

 private:
  const TaskStep& step_;
  const double& weight_;
  int n_, m_;
};

// The running cost's squares of one state or one action (one block).
class CostResidual final : public ceres::CostFunction {
 public:
  CostResidual(const ControlTask& task, bool state) : task_(task), state_(state) {
    const int size = state ? task.state_size() : task.action_size();
    set_num_residuals(size);
    mutable_parameter_block_sizes()->assign({size});
  }

  bool Evaluate(double const* const* params, double* residuals, double** jacobians) const override {
    const int size = num_residuals();
    Eigen::VectorXd diagonal(size);
    const bool jacobian = jacobians && jacobians[0];
    (state_ ? StateSquares : ActionSquares)(task_, params[0], residuals,
                                            jacobian ? diagonal.data() : nullptr);
    if (jacobian) Eigen::Map<RowMajorMatrix>(jacobians[0], size, size) = diagonal.asDiagonal();
    return true;
  }

 private:
  const ControlTask& task_;
  bool state_;
};

// The single-shooting residuals over all actions U (m K, u_k at k m): the state
// squares of the rollout x_1..x_{K-1} from x0, then the action squares.
class RolloutResidual final : public ceres::CostFunction {
 public:
  RolloutResidual(const ControlTask& task, const TaskStep& step, const Eigen::MatrixXd& lt,
                  Eigen::VectorXd x0)
      : task_(task),
        step_(step),
        lt_(lt),
        x0_(std::move(x0)),
        n_(task.state_size()),
        m_(task.action_size()),
        k_(task.periods()) {
    set_num_residuals(n_ * (k_ - 1) + m_ * k_ + n_);
    mutable_parameter_block_sizes()->assign({m_ * k_});
  }

  // Rows: x_1..x_{K-1} (n each), u_0..u_{K-1} (m each), the terminal cost on x_K (n).
  bool Evaluate(double const* const* params, double* residuals, double** jacobians) const override {
    const Eigen::Map<const Eigen::MatrixXd> u(params[0], m_, k_);
    const bool jacobian = jacobians && jacobians[0];
    Eigen::Map<RowMajorMatrix> jac(jacobian ? jacobians[0] : nullptr,
                                   jacobian ? num_residuals() : 0, m_ * k_);
    if (jacobian) jac.setZero();
    const int action_rows = n_ * (k_ - 1), terminal_row = action_rows + m_ * k_;
    // s = dx_{k+1} / dU (n x m K); only its first (k + 1) m columns are nonzero.
    Eigen::MatrixXd s = Eigen::MatrixXd::Zero(n_, m_ * k_), fx, fu;
    Eigen::VectorXd x = x0_, diagonal(std::max(n_, m_));
    RowMajorMatrix dr(n_, n_);
    for (int k = 0; k < k_; ++k) {
      ActionSquares(task_, u.col(k).data(), residuals + action_rows + m_ * k,
                    jacobian ? diagonal.data() : nullptr);
      if (jacobian)
        jac.block(action_rows + m_ * k, m_ * k, m_, m_) = diagonal.head(m_).asDiagonal();
      if (jacobian) {
        x = step_.Jacobians(x, u.col(k), &fx, &fu);
        s.leftCols(m_ * k) = (fx * s.leftCols(m_ * k)).eval();
        s.middleCols(m_ * k, m_) = fu;
      } else {
        x = step_.Value(x, u.col(k));
      }
      if (!x.allFinite()) return false;
      const auto columns = m_ * (k + 1);
      if (k < k_ - 1) {
        StateSquares(task_, x.data(), residuals + n_ * k, jacobian ? diagonal.data() : nullptr);
        if (jacobian)
          jac.block(n_ * k, 0, n_, columns) = diagonal.head(n_).asDiagonal() * s.leftCols(columns);
      } else {
        TerminalSquares(task_, lt_, x.data(), residuals + terminal_row,
                        jacobian ? dr.data() : nullptr);
        if (jacobian) jac.block(terminal_row, 0, n_, columns) = dr * s.leftCols(columns);
      }
    }
    return true;
  }

 private:
  const ControlTask& task_;
  const TaskStep& step_;
  const Eigen::MatrixXd& lt_;
  Eigen::VectorXd x0_;
  int n_, m_, k_;
};

// Levenberg-Marquardt settings shared by the stages and the polish.
ceres::Solver::Options LmOptions(int max_iterations, ceres::LinearSolverType solver) {
  ceres::Solver::Options o;
  o.linear_solver_type = solver;
  o.max_num_iterations = max_iterations;
  o.function_tolerance = 1e-12;
  o.gradient_tolerance = 1e-14;
  o.parameter_tolerance = 1e-14;
  o.num_threads = 1;
  o.logging_type = ceres::SILENT;
  return o;
}

// Keeps every action within the task's bounds.
void BoundActions(const ControlTask& task, ceres::Problem& problem, double* block, int count) {
  const int m = task.action_size();
  for (int i = 0; i < count; ++i) {
    problem.SetParameterLowerBound(block, i, -task.plant.bound[i % m]);
    problem.SetParameterUpperBound(block, i, task.plant.bound[i % m]);
  }
}

// Keeps x_1..x_K within the task's finite state limits, |x_i - goal_i| <= limit_i.
void BoundStates(const ControlTask& task, ceres::Problem& problem, Eigen::MatrixXd& states) {
  for (int i = 0; i < task.state_size(); ++i) {
    if (!std::isfinite(task.limit[i])) continue;
    for (Eigen::Index k = 1; k < states.cols(); ++k) {
      states(i, k) =
          std::clamp(states(i, k), task.goal[i] - task.limit[i], task.goal[i] + task.limit[i]);
      problem.SetParameterLowerBound(states.col(k).data(), i, task.goal[i] - task.limit[i]);
      problem.SetParameterUpperBound(states.col(k).data(), i, task.goal[i] + task.limit[i]);
    }
  }
}

// The warm start of `direction` (file comment): states n x (K + 1), actions zero.
Eigen::MatrixXd WarmStates(const ControlTask& task, const Eigen::VectorXd& x0, int direction,
                           double fraction) {
  const int n = task.state_size(), periods = task.periods();
  Eigen::VectorXd target = task.goal;
  for (int i = 0; i < n; ++i) {
    if (!task.periodic[static_cast<std::size_t>(i)]) continue;
    const double up = std::fmod(
        std::fmod(-task.Deviation(i, x0[i]), 2.0 * std::numbers::pi) + 2.0 * std::numbers::pi,
        2.0 * std::numbers::pi);  // in [0, 2 pi): increasing to a goal copy
    target[i] = x0[i] + (direction > 0 ? up : up - 2.0 * std::numbers::pi);
  }
  const int reach = std::max(1, static_cast<int>(std::lround(fraction * periods)));
  Eigen::MatrixXd states(n, periods + 1);
  for (int k = 0; k <= periods; ++k) {
    const double t = std::min(1.0, static_cast<double>(k) / reach);
    states.col(k) = x0 + t * (target - x0);
  }
  return states;
}

// Multiple shooting from (states, actions) in place through the continuity `weights`
// (file comment); returns the final objective, sum_k period c(x_k, u_k) + |defects|^2
// weighted; iterations are added up.
double RunStages(const ControlTask& task, const TaskStep& step, const Eigen::MatrixXd& lt,
                 const std::vector<double>& weights, const MultipleShootingOptions& options,
                 Eigen::MatrixXd& states, Eigen::MatrixXd& actions, int* iterations) {
  const int periods = task.periods(), n = task.state_size(), m = task.action_size();
  double weight = weights.front();
  ceres::Problem problem;
  for (int k = 0; k < periods; ++k) {
    problem.AddResidualBlock(new ContinuityResidual(step, weight, n, m), nullptr,
                             states.col(k).data(), actions.col(k).data(), states.col(k + 1).data());
    problem.AddResidualBlock(new CostResidual(task, false), nullptr, actions.col(k).data());
    BoundActions(task, problem, actions.col(k).data(), m);
    if (k > 0)
      problem.AddResidualBlock(new CostResidual(task, true), nullptr, states.col(k).data());
  }
  BoundStates(task, problem, states);
  problem.AddResidualBlock(new TerminalResidual(task, lt), nullptr, states.col(periods).data());
  problem.SetParameterBlockConstant(states.col(0).data());
  ceres::Solver::Options lm = LmOptions(options.max_iterations, ceres::SPARSE_NORMAL_CHOLESKY);
  ceres::Solver::Summary summary;
  for (const double w : weights) {
    weight = w;
    // Intermediate weights only steer; the last one is solved tightly.
    lm.function_tolerance = w == weights.back() ? 1e-12 : options.stage_tolerance;
    ceres::Solve(lm, &problem, &summary);
    *iterations += static_cast<int>(summary.iterations.size());
  }
  return 2.0 * summary.final_cost;
}

// Single shooting over the actions alone from x0 (file comment), in place.
void Polish(const ControlTask& task, const TaskStep& step, const Eigen::MatrixXd& lt,
            const Eigen::VectorXd& x0, const MultipleShootingOptions& options,
            Eigen::MatrixXd& actions, int* iterations) {
  ceres::Problem problem;
  problem.AddResidualBlock(new RolloutResidual(task, step, lt, x0), nullptr, actions.data());
  BoundActions(task, problem, actions.data(), static_cast<int>(actions.size()));
  ceres::Solver::Summary summary;
  ceres::Solver::Options lm = LmOptions(options.max_iterations, ceres::DENSE_NORMAL_CHOLESKY);
  lm.function_tolerance = 0.01 * options.stage_tolerance;
  lm.dense_linear_algebra_library_type = ceres::LAPACK;
  ceres::Solve(lm, &problem, &summary);
  *iterations += static_cast<int>(summary.iterations.size());
}

// x_0..x_K (n x (K + 1)) of the actions from x0 on the evaluator's plant.
Eigen::MatrixXd Rollout(const TaskStep& step, const Eigen::VectorXd& x0,
                        const Eigen::MatrixXd& actions) {
  Eigen::MatrixXd states(x0.size(), actions.cols() + 1);
  states.col(0) = x0;
  for (Eigen::Index k = 0; k < actions.cols(); ++k)
    states.col(k + 1) = step.Value(states.col(k), actions.col(k));
  return states;
}

// max_k |x_{k+1} - Phi(x_k, u_k)|_inf by the Jet integrator.
double LargestDefect(const TaskStep& step, const Eigen::MatrixXd& states,
                     const Eigen::MatrixXd& actions) {
  double largest = 0.0;
  Eigen::MatrixXd fx, fu;
  for (Eigen::Index k = 0; k < actions.cols(); ++k) {
    const Eigen::VectorXd phi = step.Jacobians(states.col(k), actions.col(k), &fx, &fu);
    largest = std::max(largest, (states.col(k + 1) - phi).cwiseAbs().maxCoeff());
  }
  return largest;
}

void CheckShootingOptions(const MultipleShootingOptions& o) {
  DIFFDYN_CHECK(o.final_weight >= 1e-3 && o.final_weight <= 1e8,
                "shooting: the final continuity weight must be in [1e-3, 1e8], got ", o.final_weight);
  DIFFDYN_CHECK(!o.warm_starts.empty() && o.warm_starts.size() <= 16,
                "shooting: 1 to 16 warm starts expected, got ", o.warm_starts.size());
  for (const ShootingWarmStart& w : o.warm_starts) {
    DIFFDYN_CHECK(w.first_weight > 0 && w.first_weight <= o.final_weight,
                  "shooting: a warm start's first weight must be in (0, final weight], got ",
                  w.first_weight);
    DIFFDYN_CHECK(w.reach_fraction > 0 && w.reach_fraction <= 1,
                  "shooting: a warm start's reach fraction must be in (0, 1], got ",
                  w.reach_fraction);
  }
  DIFFDYN_CHECK(o.stage_tolerance >= 1e-15 && o.stage_tolerance <= 0.1,
                "shooting: the stage tolerance must be in [1e-15, 0.1], got ", o.stage_tolerance);
  DIFFDYN_CHECK(o.max_iterations >= 1 && o.max_iterations <= 100000,
                "shooting: --iterations must be in [1, 100000], got ", o.max_iterations);
  DIFFDYN_CHECK(o.defect_tolerance > 0 && o.defect_tolerance <= 1,
                "shooting: the defect tolerance must be in (0, 1], got ", o.defect_tolerance);
}

// L^T with P = L L^T the LQR cost-to-go at the goal, or zero without a terminal cost.
Eigen::MatrixXd TerminalFactor(const ControlTask& task, const MultipleShootingOptions& options) {
  const int n = task.state_size();
  if (!options.terminal_lqr) return Eigen::MatrixXd::Zero(n, n);
  const Eigen::LLT<Eigen::MatrixXd> llt(TaskLqr(task).P);
  if (llt.info() != Eigen::Success)
    throw NumericalError("shooting: the LQR cost-to-go is not positive definite");
  return llt.matrixL().transpose();
}

// first, 10 first, 100 first, ... up to `last` (included).
std::vector<double> WeightsFrom(double first, double last) {
  std::vector<double> weights;
  for (double w = first; w < last * (1 - 1e-9); w *= 10.0) weights.push_back(w);
  weights.push_back(last);
  return weights;
}

}  // namespace

MultipleShootingSolution SolveMultipleShooting(const ControlTask& task, const Eigen::VectorXd& x0,
                                               const MultipleShootingOptions& options) {
  CheckShootingOptions(options);
  const int n = task.state_size(), m = task.action_size(), periods = task.periods();
  DIFFDYN_CHECK(x0.size() == n && x0.allFinite(), "shooting: the start needs ", n,
                " finite entries");
  const TaskStep step(task);
  const Eigen::MatrixXd lt = TerminalFactor(task, options);
  MultipleShootingSolution best;
  double best_objective = std::numeric_limits<double>::infinity();
  Eigen::MatrixXd states;
  // Every warm start in both directions; the smallest final objective is kept.
  for (const ShootingWarmStart& warm : options.warm_starts) {
    for (const int direction : {1, -1}) {
      Eigen::MatrixXd s = WarmStates(task, x0, direction, warm.reach_fraction);
      Eigen::MatrixXd a = Eigen::MatrixXd::Zero(m, periods);
      const double objective =
          RunStages(task, step, lt, WeightsFrom(warm.first_weight, options.final_weight), options,
                    s, a, &best.iterations);
      if (std::isfinite(objective) && objective < best_objective) {
        best_objective = objective;
        best.actions = a;
        best.direction = direction;
        states = s;
      }
    }
  }
  if (!std::isfinite(best_objective))
    throw NumericalError("shooting: no warm start gave a finite solution");
  best.shooting_defect = LargestDefect(step, states, best.actions);
  if (options.polish) {
    // Stalled with a defect (a swing the penalty could not add): single shooting makes
    // the trajectory continuous, multiple shooting from its rollout (weights from 1e3)
    // refines it.
    if (best.shooting_defect > options.defect_tolerance) {
      Polish(task, step, lt, x0, options, best.actions, &best.iterations);
      states = Rollout(step, x0, best.actions);
      RunStages(task, step, lt,
                WeightsFrom(std::min(1e3, options.final_weight), options.final_weight), options,
                states, best.actions, &best.iterations);
    }
    Polish(task, step, lt, x0, options, best.actions, &best.iterations);
  }
  // The rollout on the evaluator's plant, its cost and its defects against the Jet integrator.
  best.states = Rollout(step, x0, best.actions);
  best.cost = 0.0;  // the evaluator's cost: no terminal term
  for (int k = 0; k < periods; ++k)
    best.cost += task.period * task.RunningCost(best.states.col(k), best.actions.col(k));
  best.defect = LargestDefect(step, best.states, best.actions);
  return best;
}

struct MultipleShootingController::Shared {
  std::mutex mutex;
  ShootingTotals totals;
};

MultipleShootingController::MultipleShootingController(const ControlTask& task,
                                                       MultipleShootingOptions options)
    : MultipleShootingController(task, std::move(options), std::make_shared<Shared>()) {}

MultipleShootingController::MultipleShootingController(const ControlTask& task,
                                                       MultipleShootingOptions options,
                                                       std::shared_ptr<Shared> shared)
    : task_(task), options_(std::move(options)), shared_(std::move(shared)) {
  CheckShootingOptions(options_);
}

std::unique_ptr<Controller> MultipleShootingController::Clone() const {
  return std::unique_ptr<Controller>(new MultipleShootingController(task_, options_, shared_));
}

ShootingTotals MultipleShootingController::totals() const {
  const std::lock_guard<std::mutex> lock(shared_->mutex);
  return shared_->totals;
}

void MultipleShootingController::Reset(const Eigen::VectorXd& x0, std::uint64_t) {
  solution_ = SolveMultipleShooting(task_, x0, options_);
  next_ = 0;
  const std::lock_guard<std::mutex> lock(shared_->mutex);
  ShootingTotals& t = shared_->totals;
  ++t.solves;
  t.largest_shooting_defect = std::max(t.largest_shooting_defect, solution_.shooting_defect);
  t.largest_defect = std::max(t.largest_defect, solution_.defect);
  t.iterations += solution_.iterations;
}

Eigen::VectorXd MultipleShootingController::Command(const Eigen::VectorXd&) {
  const int k = std::min(next_, static_cast<int>(solution_.actions.cols()) - 1);
  ++next_;
  return solution_.actions.col(k);
}

}  // namespace diffdyn
