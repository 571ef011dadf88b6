#include "diffdyn/solvers/residual_solver.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <Eigen/Cholesky>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/parallel.h"
#include "diffdyn/solvers/lqr.h"

namespace diffdyn {

LinearQuadraticHjb::LinearQuadraticHjb(Eigen::MatrixXd a, const Eigen::MatrixXd& b, Eigen::MatrixXd q,
                                       const Eigen::MatrixXd& r, double rho)
    : a_(std::move(a)), b_(b), q_(std::move(q)), r_(r), rho_(rho) {
  const Eigen::Index n = a_.rows();
  DIFFDYN_CHECK(a_.cols() == n && b_.rows() == n && q_.rows() == n && q_.cols() == n && r_.rows() == b_.cols() &&
                    r_.cols() == b_.cols(),
                "LinearQuadraticHjb: A must be n x n, B n x m, Q n x n and R m x m");
  DIFFDYN_CHECK(rho > 0 && std::isfinite(rho), "LinearQuadraticHjb: rho must be positive, got ", rho);
  const Eigen::LLT<Eigen::MatrixXd> llt(r_);
  DIFFDYN_CHECK(llt.info() == Eigen::Success, "LinearQuadraticHjb: R must be positive definite");
  s_ = b_ * llt.solve(b_.transpose());
}

void LinearQuadraticHjb::Evaluate(const Eigen::MatrixXd& x, const Eigen::VectorXd& v, const Eigen::MatrixXd& p,
                                  Eigen::VectorXd* f, Eigen::VectorXd* f_v, Eigen::MatrixXd* f_p,
                                  int /*threads*/) const {
  // F = rho V - x^T Q x - p^T A x + p^T S p / 4;  F_V = rho;  F_p = -A x + S p / 2.
  const Eigen::MatrixXd ax = a_ * x, sp = s_ * p;
  *f = rho_ * v - (x.cwiseProduct(q_ * x)).colwise().sum().transpose() -
       (p.cwiseProduct(ax)).colwise().sum().transpose() + 0.25 * (p.cwiseProduct(sp)).colwise().sum().transpose();
  *f_v = Eigen::VectorXd::Constant(x.cols(), rho_);
  *f_p = -ax + 0.5 * sp;
}

Eigen::MatrixXd LinearQuadraticHjb::SolutionMatrix() const {
  // rho P = Q + A^T P + P A - P S P: the Riccati equation of A - rho/2 I.
  const Eigen::Index n = a_.rows();
  return SolveLqr(a_ - 0.5 * rho_ * Eigen::MatrixXd::Identity(n, n), b_, q_, r_).P;
}

namespace {

// The quadratic form's small matrices live on the stack: at most this many features.
constexpr int kMaxQuadraticFeatures = 8;
using Small = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxQuadraticFeatures, kMaxQuadraticFeatures>;
using SmallVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxQuadraticFeatures, 1>;

// Output index of L_ik (i >= k), row by row.
int TriangleIndex(int i, int k) { return i * (i + 1) / 2 + k; }

// softplus(y) = log(1 + e^y) without overflow.
double Softplus(double y) { return std::max(y, 0.0) + std::log1p(std::exp(-std::abs(y))); }

// One sample of the quadratic form: L, its entries' first and second derivatives in y
// (s1, s2), e = z - z0, S = L^T e and G = dS/dz (d x d).
struct QuadraticSample {
  Small l, s1, s2, g;
  SmallVector e, s;
  QuadraticSample(const Eigen::Ref<const Eigen::VectorXd>& y, const Eigen::Ref<const Eigen::MatrixXd>& jac,
                  const Eigen::Ref<const Eigen::VectorXd>& z, const Eigen::VectorXd& z0, double epsilon) {
    const int d = static_cast<int>(z.size());
    l.setZero(d, d);
    s1.setZero(d, d);
    s2.setZero(d, d);
    for (int i = 0; i < d; ++i) {
      for (int k = 0; k <= i; ++k) {
        const double yi = y[TriangleIndex(i, k)];
        if (i == k) {
          const double sigmoid = 1.0 / (1.0 + std::exp(-yi));
          l(i, k) = Softplus(yi) + epsilon;
          s1(i, k) = sigmoid;
          s2(i, k) = sigmoid * (1.0 - sigmoid);
        } else {
          l(i, k) = yi;
          s1(i, k) = 1.0;
        }
      }
    }
    e = z - z0;
    s = l.transpose() * e;
    // G_kj = L_jk [j >= k] + sum_{i >= k} e_i s1_ik dy_ik/dz_j.
    g = l.transpose();
    for (int k = 0; k < d; ++k) {
      for (int i = k; i < d; ++i) g.row(k) += (e[i] * s1(i, k)) * jac.row(TriangleIndex(i, k));
    }
  }
};

// Runs per_state(i) for each of the b states: every state's head is independent, so
// the network workspace's chunks go over the threads (the same bits at any count).
template <typename PerState>
void ForEachState(Eigen::Index b, const ValueWorkspace& ws, int threads, PerState&& per_state) {
  ParallelForChunks(static_cast<int>(b), ws.mlp.chunk_size(), threads, [&](int, int begin, int end) {
    for (int i = begin; i < end; ++i) per_state(i);
  });
}

}  // namespace

ValueFunction::ValueFunction(Mlp<double> net, int n, InputFeatures features, ValueForm form, Eigen::VectorXd goal,
                             double epsilon)
    : net_(std::move(net)), n_(n), features_(std::move(features)), form_(form), goal_(std::move(goal)),
      epsilon_(epsilon) {
  DIFFDYN_CHECK(n >= 1, "ValueFunction: the state size must be positive, got ", n);
  for (std::size_t k = 0; k < features_.periodic.size(); ++k) {
    DIFFDYN_CHECK(features_.periodic[k] >= 0 && features_.periodic[k] < n &&
                      (k == 0 || features_.periodic[k] > features_.periodic[k - 1]),
                  "ValueFunction: periodic components must be increasing state indices below ", n);
  }
  const int d = features_.size(n);
  DIFFDYN_CHECK(net_.num_inputs() == d && net_.num_outputs() == OutputsFor(form, d),
                "ValueFunction: the network must map ", d, " features to ", OutputsFor(form, d),
                " outputs, it maps ", net_.num_inputs(), " to ", net_.num_outputs());
  if (form == ValueForm::kQuadratic) {
    DIFFDYN_CHECK(d <= kMaxQuadraticFeatures, "ValueFunction: the quadratic form takes at most ",
                  kMaxQuadraticFeatures, " features, got ", d);
    DIFFDYN_CHECK(goal_.size() == n && goal_.allFinite(), "ValueFunction: the goal must be ", n, " finite values");
    DIFFDYN_CHECK(epsilon > 0 && std::isfinite(epsilon), "ValueFunction: epsilon must be positive, got ", epsilon);
    goal_features_ = features_.Encode(goal_);
  }
}

ValueFunction ValueFunction::Direct(Mlp<double> net, int n, InputFeatures features) {
  return ValueFunction(std::move(net), n, std::move(features), ValueForm::kDirect, Eigen::VectorXd(), 1e-3);
}

ValueFunction ValueFunction::Quadratic(Mlp<double> net, const Eigen::VectorXd& goal, InputFeatures features,
                                       double epsilon) {
  const int n = static_cast<int>(goal.size());
  return ValueFunction(std::move(net), n, std::move(features), ValueForm::kQuadratic, goal, epsilon);
}

ValueWorkspace ValueFunction::MakeWorkspace(int max_batch, int chunk_size) const {
  ValueWorkspace ws;
  ws.mlp = MlpWorkspace(net_.architecture(), max_batch, chunk_size, true);
  return ws;
}

void ValueFunction::QuadraticHead(const ValueWorkspace& ws, Eigen::Index b, double* v,
                                  Eigen::Ref<Eigen::VectorXd> dvdz) const {
  const Eigen::Index d = ws.z.rows();
  const QuadraticSample q(ws.y.col(b), ws.jac.middleCols(b * d, d), ws.z.col(b), goal_features_, epsilon_);
  *v = q.s.squaredNorm();
  dvdz = 2.0 * q.g.transpose() * q.s;
}

void ValueFunction::QuadraticHeadBackward(const ValueWorkspace& ws, Eigen::Index b, double gv,
                                          const Eigen::Ref<const Eigen::VectorXd>& gdvdz,
                                          Eigen::Ref<Eigen::VectorXd> gy, Eigen::Ref<Eigen::MatrixXd> gjac) const {
  const int d = static_cast<int>(ws.z.rows());
  const auto jac = ws.jac.middleCols(b * d, d);
  const QuadraticSample q(ws.y.col(b), jac, ws.z.col(b), goal_features_, epsilon_);
  // dvdz = 2 G^T S and V = S^T S: cotangents of G (2 S gdvdz^T) and of S.
  const Small gg = 2.0 * q.s * gdvdz.transpose();
  const SmallVector gs = 2.0 * q.g * gdvdz + 2.0 * gv * q.s;
  for (int i = 0; i < d; ++i) {
    for (int k = 0; k <= i; ++k) {
      const int idx = TriangleIndex(i, k);
      // L_ik enters S_k (times e_i) and G_ki; s1_ik and dy_ik/dz enter row k of G times e_i.
      const double gl = gs[k] * q.e[i] + gg(k, i);
      gjac.row(idx) = (q.e[i] * q.s1(i, k)) * gg.row(k);
      const double gs1 = q.e[i] * gg.row(k).dot(jac.row(idx));
      gy[idx] = gl * q.s1(i, k) + gs1 * q.s2(i, k);
    }
  }
}

void ValueFunction::Evaluate(const Eigen::MatrixXd& x, Eigen::VectorXd* v, Eigen::MatrixXd* p, ValueWorkspace* ws,
                             int threads) const {
  DIFFDYN_CHECK(x.rows() == n_, "ValueFunction: states must have ", n_, " rows, got ", x.rows());
  const Eigen::Index b = x.cols(), d = net_.num_inputs();
  features_.Encode(x, &ws->z);
  net_.Forward(ws->z, &ws->y, &ws->jac, &ws->mlp, threads);
  if (form_ == ValueForm::kDirect) {
    *v = ws->y.row(0).transpose();
    ws->dvdz = Eigen::Map<const Eigen::MatrixXd>(ws->jac.data(), d, b);
  } else {
    v->resize(b);
    ws->dvdz.resize(d, b);
    ForEachState(b, *ws, threads, [&](int i) { QuadraticHead(*ws, i, &(*v)[i], ws->dvdz.col(i)); });
  }
  features_.PullBack(x, ws->dvdz, p);
}

void ValueFunction::Evaluate(const Eigen::MatrixXd& x, Eigen::VectorXd* v, Eigen::MatrixXd* p) const {
  ValueWorkspace ws = MakeWorkspace(std::max<int>(1, static_cast<int>(x.cols())));
  Evaluate(x, v, p, &ws);
}

void ValueFunction::Backward(const Eigen::MatrixXd& x, const Eigen::VectorXd& gv, const Eigen::MatrixXd& gp,
                             Eigen::VectorXd* grad, ValueWorkspace* ws, int threads) const {
  const Eigen::Index b = x.cols(), d = net_.num_inputs(), m = net_.num_outputs();
  DIFFDYN_CHECK(ws->z.cols() == b && gv.size() == b && gp.rows() == n_ && gp.cols() == b,
                "ValueFunction::Backward: cotangents must match the last Evaluate's ", ws->z.cols(), " states");
  features_.PushForward(x, gp, &ws->gdvdz);
  if (form_ == ValueForm::kDirect) {
    ws->gy = gv.transpose();
    ws->gjac = Eigen::Map<const Eigen::MatrixXd>(ws->gdvdz.data(), 1, d * b);
  } else {
    ws->gy.resize(m, b);
    ws->gjac.resize(m, d * b);
    ForEachState(b, *ws, threads, [&](int i) {
      QuadraticHeadBackward(*ws, i, gv[i], ws->gdvdz.col(i), ws->gy.col(i), ws->gjac.middleCols(i * d, d));
    });
  }
  net_.Backward(ws->gy, ws->gjac, grad, nullptr, &ws->mlp, threads);
}

double ResidualLoss(const FirstOrderEquation& equation, const ValueFunction& value, const Eigen::MatrixXd& x,
                    Eigen::VectorXd* grad, ValueWorkspace* ws, int threads) {
  const Eigen::Index b = x.cols();
  value.Evaluate(x, &ws->v, &ws->p, ws, threads);
  equation.Evaluate(x, ws->v, ws->p, &ws->f, &ws->f_v, &ws->f_p, threads);
  if (grad) {
    // dL/dV_i = 2 F_i F_V,i / B and dL/dp_i = 2 F_i F_p,i / B, from gv = 2 F / B.
    ws->gv = (2.0 / static_cast<double>(b)) * ws->f;
    ws->gp = ws->f_p * ws->gv.asDiagonal();
    ws->gv.array() *= ws->f_v.array();
    value.Backward(x, ws->gv, ws->gp, grad, ws, threads);
  }
  return ws->f.squaredNorm() / static_cast<double>(b);
}

double AnchorLoss(const ValueAnchors& anchors, const ValueFunction& value, Eigen::VectorXd* grad,
                  ValueWorkspace* ws, int threads) {
  const Eigen::Index a = anchors.states.cols();
  value.Evaluate(anchors.states, &ws->v, &ws->p, ws, threads);
  // The scaled errors r_a = (V_a - v_a) / scale_a are this term's residuals.
  ws->f = (ws->v - anchors.values).cwiseQuotient(anchors.scales);
  if (grad) {
    // dL/dV_a = 2 w r_a / (A scale_a); V's gradient p does not enter.
    ws->gv = (2.0 * anchors.weight / static_cast<double>(a)) * ws->f.cwiseQuotient(anchors.scales);
    ws->gp.setZero(ws->p.rows(), a);
    value.Backward(anchors.states, ws->gv, ws->gp, &ws->grad, ws, threads);
    *grad += ws->grad;
  }
  return anchors.weight * ws->f.squaredNorm() / static_cast<double>(a);
}

TrainResult SolveResidual(const FirstOrderEquation& equation, const Eigen::MatrixXd& states,
                          const TrainOptions& options, ValueFunction* value,
                          const std::function<void(const EpochReport&)>& on_epoch, const ValueAnchors* anchors) {
  const int n = equation.state_size();
  DIFFDYN_CHECK(value->state_size() == n, "SolveResidual: the value function has ", value->state_size(),
                " states, the equation ", n);
  DIFFDYN_CHECK(states.rows() == n && states.cols() >= 2 && states.allFinite(), "SolveResidual: states must be ", n,
                " x N with N >= 2, finite");
  std::vector<int> train, val;
  SplitWindows(static_cast<int>(states.cols()), options.val_fraction, options.seed, &train, &val);
  const int batch = std::min<int>(options.batch_size, static_cast<int>(train.size()));
  ValueWorkspace ws = value->MakeWorkspace(batch, options.chunk_size);
  ValueWorkspace val_ws = value->MakeWorkspace(std::max<int>(1, static_cast<int>(val.size())), options.chunk_size);
  if (anchors) {
    DIFFDYN_CHECK(anchors->states.rows() == n && anchors->states.cols() >= 1 &&
                      anchors->values.size() == anchors->states.cols() &&
                      anchors->scales.size() == anchors->states.cols() && (anchors->scales.array() > 0).all() &&
                      std::isfinite(anchors->weight) && anchors->weight >= 0 && anchors->batch >= 0,
                  "SolveResidual: anchors must have n x A states (A >= 1), A values and A positive scales, "
                  "weight >= 0 and batch >= 0");
  }
  // The anchors of one mini-batch: all of them, or the next `batch` columns in turn.
  const Eigen::Index anchor_count = anchors ? anchors->states.cols() : 0;
  const Eigen::Index anchor_batch =
      anchors && anchors->batch > 0 ? std::min<Eigen::Index>(anchors->batch, anchor_count) : anchor_count;
  ValueAnchors slice;
  if (anchors && anchor_batch < anchor_count) {
    slice = {Eigen::MatrixXd(n, anchor_batch), Eigen::VectorXd(anchor_batch), Eigen::VectorXd(anchor_batch),
             anchors->weight, 0};
  }
  Eigen::Index anchor_next = 0;
  const auto next_anchors = [&]() -> const ValueAnchors& {
    if (anchor_batch == anchor_count) return *anchors;
    for (Eigen::Index c = 0; c < anchor_batch; ++c, anchor_next = (anchor_next + 1) % anchor_count) {
      slice.states.col(c) = anchors->states.col(anchor_next);
      slice.values[c] = anchors->values[anchor_next];
      slice.scales[c] = anchors->scales[anchor_next];
    }
    return slice;
  };
  ValueWorkspace anchor_ws = value->MakeWorkspace(std::max<int>(1, static_cast<int>(anchor_batch)));
  const Eigen::MatrixXd val_states = states(Eigen::all, val);
  Eigen::MatrixXd x;
  MinibatchProblem problem;
  problem.n_train = static_cast<int>(train.size());
  problem.n_val = static_cast<int>(val.size());
  problem.batch_loss = [&](std::span<const int> positions, Eigen::VectorXd* grad) {
    x.resize(n, static_cast<Eigen::Index>(positions.size()));  // no-op unless the batch size changes
    for (std::size_t i = 0; i < positions.size(); ++i) {
      x.col(static_cast<Eigen::Index>(i)) = states.col(train[static_cast<std::size_t>(positions[i])]);
    }
    const double loss = ResidualLoss(equation, *value, x, grad, &ws, options.threads);
    return anchors ? loss + AnchorLoss(next_anchors(), *value, grad, &anchor_ws, options.threads) : loss;
  };
  problem.validation_loss = [&] {
    return ResidualLoss(equation, *value, val_states, nullptr, &val_ws, options.threads);
  };
  return FitMinibatches(problem, options, &value->mutable_net()->mutable_parameters(), on_epoch);
}

}  // namespace diffdyn
