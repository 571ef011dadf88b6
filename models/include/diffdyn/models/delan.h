// Deep Lagrangian networks (DeLaN): inverse dynamics with the Euler-Lagrange
// structure, learned from torques alone.
//
// One deep differential network (mlp.h) maps the joint positions q (n) to
//
//   y(q) = [V, o_1 .. o_{n(n-1)/2}, d_1 .. d_n]        (m = 1 + n(n+1)/2 outputs)
//
// and, in the same pass, its Jacobian dy/dq (m x n). From them
//
//   L     lower triangular, L_ij = o(i, j) below the diagonal (row by row),
//         L_ii = softplus(d_i + shift) + floor > 0 (a diagonal that cannot die),
//   H     = L L^T + eps I                                    (mass matrix, n x n)
//   g     = dV/dq                                            (gravity, n)
//   L_k   = dL/dq_k,   Ldot = sum_k qd_k L_k
//   c     = Hdot qd - 1/2 [qd^T (dH/dq_k) qd]_k              (Coriolis, centrifugal)
//   f     = softplus(w_v) * qd + softplus(w_c) * tanh(qd / v_c)   (friction, kind
//           delan-friction: viscous and Coulomb coefficients >= 0 per joint)
//   tau   = H qdd + c + g [+ f]                              (inverse dynamics)
//
// Joints listed in `periodic` enter the trunk as (sin q, cos q) (input_features.h),
// so H and V are periodic in them and data that wind a joint over many turns stay
// in the network's range; dy/dq = (dy/dz)(dz/dq) then feeds everything below.
//
// computed without forming H's derivatives: with a = L^T qd, b = L^T qdd and
// e = Ldot^T qd,
//
//   H qdd = L b + eps qdd,   c = Ldot a + L e - s,   s_k = qd^T L_k a,
//   T = 1/2 |a|^2 + eps/2 |qd|^2,   dE/dt = a.b + eps qd.qdd + a.e + qd.g.
//
// Everything comes from the network's closed-form Jacobian: no finite differences,
// and no Jets in training. Training minimises (1/B) sum_b |tau^(q, qd, qdd) - tau|^2
// by batched reverse mode: DelanHead::Backward takes dL/dtau to dL/dy and dL/dJ per
// sample, and Mlp::Backward takes those to dL/dtheta (through g'' of the
// activations, mlp.h). The single-sample paths are templated on the scalar (double
// or ceres::Jet), so a DeLaN can be linearised or integrated with Jets.
//
// Precision: SetPrecision(Precision::kF32) runs the batched paths (TorqueLoss,
// Decompose) on a float copy of the network (sgemm, float heads); the loss and its
// chunk sums, the friction head and the parameters stay double (the network's
// gradient is summed in float chunk by chunk, as Mlp<float> does, then widened),
// and results are the same at any thread count in either precision.
//
//   Delan model = Delan::Initialized({.dof = 2}, /*seed=*/0);
//   Delan cartpole = Delan::Initialized({.dof = 2, .periodic = {1}, .friction = true}, 0);
//   DelanWorkspace ws;
//   double loss = model.TorqueLoss(q, qd, qdd, tau, &grad, &ws);   // n x B each
//   Eigen::VectorXd tau1 = model.InverseDynamics(q0, qd0, qdd0);    // one sample
//   Eigen::VectorXd acc = model.ForwardDynamics(q0, qd0, tau0);     // H^-1 (tau - c - g)
#pragma once

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/autodiff_ode/spd_solve.h"
#include "diffdyn/models/activations.h"
#include "diffdyn/models/init.h"
#include "diffdyn/models/input_features.h"
#include "diffdyn/models/json_io.h"
#include "diffdyn/models/mlp.h"
#include "diffdyn/models/model_file.h"
#include "diffdyn/models/parallel.h"
#include "diffdyn/models/precision.h"

namespace diffdyn {

/// Architecture of a DeLaN (what a model file records).
struct DelanOptions {
  /// n, the number of joints (>= 1).
  int dof = 2;
  /// Width and number of hidden layers of the trunk on q.
  int hidden = 64;
  int depth = 2;
  /// Activation of the trunk (needs g'' for training: softplus, tanh, ...).
  Activation activation = Activation::Softplus();
  /// eps of H = L L^T + eps I (> 0: H is positive definite whatever L is).
  double epsilon = 0.01;
  /// L_ii = softplus(d_i + diagonal_shift) + diagonal_floor. The defaults start L_ii
  /// near 0.36 (the characters' H has diagonal 0.5 to 2.4); on the characters
  /// (seed 0, 10,000 epochs) they reach a test torque MSE of 1.4e-4, against 2.5e-4
  /// with shift 0 and 1.3e-3 with the DeLaN authors' later softplus(d + 2) + 0.1.
  double diagonal_shift = -1.0;
  double diagonal_floor = 0.05;
  /// 0-based joints that enter the trunk as (sin q, cos q) (input_features.h).
  std::vector<int> periodic{};
  /// The friction head f(qd) (file comment): kind "delan-friction".
  bool friction = false;
  /// v_c of the smoothed sign tanh(qd / v_c) (m/s or rad/s; the coulomb effect's 0.01).
  double coulomb_velocity = 0.01;

  /// The model-file kind: "delan" or "delan-friction".
  std::string kind() const { return friction ? "delan-friction" : "delan"; }
  /// The trunk's input map q -> z.
  InputFeatures features() const { return {periodic}; }
  /// Parameters of the friction head after the network's: 2n (w_v, then w_c) or 0.
  int num_friction_parameters() const { return friction ? 2 * dof : 0; }

  /// m = 1 + n(n+1)/2 network outputs: V, the n(n-1)/2 entries below L's diagonal, n diagonal inputs.
  int num_outputs() const { return 1 + dof * (dof + 1) / 2; }
  /// The trunk and heads as one Mlp architecture: [n, hidden x depth, m].
  MlpArchitecture NetworkArchitecture() const {
    std::vector<int> sizes{features().size(dof)};
    for (int l = 0; l < depth; ++l) sizes.push_back(hidden);
    sizes.push_back(num_outputs());
    return {sizes, std::vector<Activation>(depth, activation)};
  }
  /// Throws diffdyn::Error for sizes out of range or eps <= 0.
  void Validate() const {
    DIFFDYN_CHECK(dof >= 1 && dof <= 64, "DeLaN: dof must be in [1, 64], got ", dof);
    DIFFDYN_CHECK(hidden >= 1 && depth >= 1, "DeLaN: hidden width and depth must be >= 1, got ",
                  hidden, " and ", depth);
    DIFFDYN_CHECK(epsilon > 0.0 && std::isfinite(epsilon), "DeLaN: epsilon must be positive, got ",
                  epsilon);
    DIFFDYN_CHECK(std::isfinite(diagonal_shift) && diagonal_floor >= 0.0 && std::isfinite(diagonal_floor),
                  "DeLaN: diagonal shift must be finite and floor >= 0, got ", diagonal_shift, " and ",
                  diagonal_floor);
    features().Validate(dof);
    DIFFDYN_CHECK(coulomb_velocity > 0.0 && std::isfinite(coulomb_velocity),
                  "DeLaN: coulomb_velocity must be positive, got ", coulomb_velocity);
  }
};

/// Per-sample part of DeLaN on scalar S: from the network's y (m) and J = dy/dq
/// (m x n) to L, its derivatives, and tau with its parts. Owns its buffers, so
/// repeated Forward calls of one size allocate nothing. Backward (the VJP) needs
/// the preceding Forward's buffers.
template <typename S>
class DelanHead {
 public:
  using Vec = Eigen::Matrix<S, Eigen::Dynamic, 1>;
  using Mat = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;

  explicit DelanHead(const DelanOptions& options) : o_(options), n_(options.dof) {
    L_ = Mat::Zero(n_, n_);
    Ldot_ = Mat::Zero(n_, n_);
    Lk_.assign(n_, Mat::Zero(n_, n_));
    Lkbar_ = Lk_;
    Lbar_ = ldot_bar_ = L_;
    sig_ = bbar_ = abar_ = Vec::Zero(n_);
    g_ = a_ = b_ = e_ = s_ = inertial_ = coriolis_ = qd_ = qdd_ = Vec::Zero(n_);
  }

  /// n.
  int dof() const { return n_; }
  /// Index of L(i, j), i > j, and of d_i in y.
  static int Off(int i, int j) { return 1 + i * (i - 1) / 2 + j; }
  int Diag(int i) const { return 1 + n_ * (n_ - 1) / 2 + i; }

  /// Builds L, dL/dq_k and g from y (m) and J (m x n), then the parts of tau for (qd, qdd).
  template <typename Y, typename J, typename V1, typename V2>
  void Forward(const Y& y, const J& jac, const V1& qd, const V2& qdd) {
    using std::exp;
    potential_ = y[0];
    for (int i = 0; i < n_; ++i) {
      const S z = y[Diag(i)] + S(o_.diagonal_shift);
      sig_[i] = ActivationDerivative(Activation::Softplus(), z);
      L_(i, i) = ActivationValue(Activation::Softplus(), z) + S(o_.diagonal_floor);
      for (int j = 0; j < i; ++j) L_(i, j) = y[Off(i, j)];
    }
    for (int k = 0; k < n_; ++k) {
      g_[k] = jac(0, k);
      Mat& lk = Lk_[k];
      for (int i = 0; i < n_; ++i) {
        lk(i, i) = sig_[i] * jac(Diag(i), k);
        for (int j = 0; j < i; ++j) lk(i, j) = jac(Off(i, j), k);
      }
    }
    qd_ = qd.template cast<S>();
    qdd_ = qdd.template cast<S>();
    Ldot_.setZero();
    for (int k = 0; k < n_; ++k) Ldot_ += qd_[k] * Lk_[k];
    a_.noalias() = L_.transpose() * qd_;
    b_.noalias() = L_.transpose() * qdd_;
    e_.noalias() = Ldot_.transpose() * qd_;
    for (int k = 0; k < n_; ++k) s_[k] = qd_.dot(Lk_[k] * a_);
    inertial_.noalias() = L_ * b_;
    inertial_ += S(o_.epsilon) * qdd_;
    coriolis_.noalias() = Ldot_ * a_;
    coriolis_.noalias() += L_ * e_;
    coriolis_ -= s_;
  }

  /// tau = H qdd + c + g of the last Forward, into *tau (size n).
  template <typename Out>
  void Torque(Out&& tau) const { tau = inertial_ + coriolis_ + g_; }

  /// VJP of tau: given tbar = dL/dtau (n), writes dL/dy into ybar (m) and dL/dJ
  /// into jbar (m x n) for the last Forward (reverse of the equations above).
  template <typename T1, typename Y, typename J, typename YB, typename JB>
  void Backward(const T1& tbar, const Y& y, const J& jac, YB&& ybar, JB&& jbar) {
    (void)y;
    // tau = L (b + e) + eps qdd + Ldot a - s + g, with b = L^T qdd, e = Ldot^T qd, a = L^T qd.
    Lbar_.noalias() = tbar * (b_ + e_).transpose();
    bbar_.noalias() = L_.transpose() * tbar;  // also ebar
    ldot_bar_.noalias() = tbar * a_.transpose();
    ldot_bar_.noalias() += qd_ * bbar_.transpose();
    abar_.noalias() = Ldot_.transpose() * tbar;
    for (int k = 0; k < n_; ++k) {
      // s_k = qd^T L_k a, and L_k's share of Ldot = sum_k qd_k L_k.
      Lkbar_[k].noalias() = (-tbar[k]) * qd_ * a_.transpose();
      Lkbar_[k] += qd_[k] * ldot_bar_;
      abar_.noalias() -= tbar[k] * (Lk_[k].transpose() * qd_);
    }
    Lbar_.noalias() += qdd_ * bbar_.transpose();
    Lbar_.noalias() += qd_ * abar_.transpose();
    ybar.setZero();
    jbar.setZero();
    for (int k = 0; k < n_; ++k) jbar(0, k) = tbar[k];
    for (int i = 0; i < n_; ++i) {
      const S dsig = sig_[i] * (S(1.0) - sig_[i]);
      S d_bar = Lbar_(i, i) * sig_[i];
      for (int k = 0; k < n_; ++k) {
        d_bar += Lkbar_[k](i, i) * dsig * jac(Diag(i), k);
        jbar(Diag(i), k) = Lkbar_[k](i, i) * sig_[i];
        for (int j = 0; j < i; ++j) jbar(Off(i, j), k) = Lkbar_[k](i, j);
      }
      ybar[Diag(i)] = d_bar;
      for (int j = 0; j < i; ++j) ybar[Off(i, j)] = Lbar_(i, j);
    }
  }

  /// Results of the last Forward.
  const Mat& L() const { return L_; }
  /// dL/dq_k.
  const Mat& Lk(int k) const { return Lk_[k]; }
  /// H = L L^T + eps I.
  Mat MassMatrix() const {
    Mat h = L_ * L_.transpose();
    h.diagonal().array() += S(o_.epsilon);
    return h;
  }
  /// H qdd, c, g.
  const Vec& inertial() const { return inertial_; }
  const Vec& coriolis() const { return coriolis_; }
  const Vec& gravity() const { return g_; }
  /// V (up to a constant), T = 1/2 qd^T H qd.
  S potential() const { return potential_; }
  S kinetic() const { return S(0.5) * (a_.squaredNorm() + S(o_.epsilon) * qd_.squaredNorm()); }
  /// dE/dt = qd^T H qdd + 1/2 qd^T Hdot qd + qd^T g.
  S power() const { return a_.dot(b_) + S(o_.epsilon) * qd_.dot(qdd_) + a_.dot(e_) + qd_.dot(g_); }

 private:
  DelanOptions o_;
  int n_;
  Mat L_, Ldot_, Lbar_, ldot_bar_;
  std::vector<Mat> Lk_, Lkbar_;
  Vec sig_, bbar_, abar_, g_, a_, b_, e_, s_, inertial_, coriolis_, qd_, qdd_;
  S potential_{};
};

/// Buffers of the batched DeLaN paths in one precision S (double or float).
template <typename S>
struct DelanBuffers {
  using Mat = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;
  BasicMlpWorkspace<S> mlp;
  Mat z, y, jac, ybar, jbar;                 // network inputs, outputs, dy/dz and cotangents
  Eigen::Matrix<S, Eigen::Dynamic, 1> net_grad;
  std::vector<DelanHead<S>> heads;           // one per chunk
  std::vector<Mat> jq, jq_bar;               // dy/dq and dL/d(dy/dq) of one sample, per chunk
};

/// Buffers of the batched DeLaN paths (one per concurrent caller), for either precision.
struct DelanWorkspace {
  DelanWorkspace() = default;
  /// Buffers for batches of up to `max_batch` samples in chunks of `chunk_size`
  /// (the chunks fix the summation order) for a network `arch` in `precision`.
  DelanWorkspace(const MlpArchitecture& arch, int max_batch, int chunk_size, Precision precision) {
    if (precision == Precision::kF32) {
      f32.mlp = MlpWorkspaceF(arch, max_batch, chunk_size, true);
    } else {
      f64.mlp = MlpWorkspace(arch, max_batch, chunk_size, true);
    }
  }

  DelanBuffers<double> f64;
  DelanBuffers<float> f32;
  std::vector<Eigen::VectorXd> friction_grad;  // per chunk (2n), summed in double
  std::vector<double> chunk_loss;              // per chunk, summed in double
};

/// The DeLaN parts of a batch (n x B each, energies 1 x B).
struct DelanParts {
  Eigen::MatrixXd torque, inertial, coriolis, gravity, friction;
  Eigen::RowVectorXd kinetic, potential, power, min_mass_eigenvalue;
};

/// A deep Lagrangian network: one Mlp<double> (the trunk and the heads' linear
/// outputs), the structure of delan.h and, for kind delan-friction, 2n friction
/// parameters. Parameters are theta = [the Mlp's flat theta, w_v (n), w_c (n)].
class Delan {
 public:
  /// The DeLaN authors' initialisation: xavier-normal, hidden gain sqrt(2),
  /// output gain 0.125, bias 1e-4.
  static InitOptions DefaultInit() { return {InitScheme::kXavierNormal, std::sqrt(2.0), 0.125, 1e-4}; }
  /// Initial w_v = w_c: softplus(-4.6) = 0.01.
  static constexpr double kInitialFrictionRaw = -4.6;

  /// A DeLaN with parameters drawn by DefaultInit from Rng(seed) (friction at kInitialFrictionRaw).
  static Delan Initialized(const DelanOptions& options, std::uint64_t seed) {
    options.Validate();
    const Eigen::VectorXd net = MakeInitializedMlp(options.NetworkArchitecture(), DefaultInit(), seed).parameters();
    Eigen::VectorXd theta(net.size() + options.num_friction_parameters());
    theta << net, Eigen::VectorXd::Constant(options.num_friction_parameters(), kInitialFrictionRaw);
    return Delan(options, std::move(theta));
  }

  Delan() = default;
  /// A DeLaN with flat parameters theta (size num_parameters()).
  Delan(const DelanOptions& options, const Eigen::VectorXd& theta) : options_(options) {
    options.Validate();
    const MlpArchitecture arch = options.NetworkArchitecture();
    const Eigen::Index k = arch.num_parameters();
    DIFFDYN_CHECK(theta.size() == k + options.num_friction_parameters(), "DeLaN: expected ",
                  k + options.num_friction_parameters(), " parameters, got ", theta.size());
    net_ = Mlp<double>(arch, theta.head(k));
    friction_ = theta.tail(options.num_friction_parameters());
  }

  /// The precision of the batched paths (TorqueLoss, Decompose): float64, or
  /// float32 on a float copy of the network, with the loss, its chunk sums and
  /// the friction head in double. Parameters stay double; the single-sample
  /// paths compute in their own scalar.
  Precision precision() const { return precision_; }
  /// Sets the precision of the batched paths.
  void SetPrecision(Precision p) {
    precision_ = p;
    SyncFloatNetwork();
  }

  const DelanOptions& options() const { return options_; }
  int dof() const { return options_.dof; }
  const Mlp<double>& network() const { return net_; }
  Eigen::Index num_parameters() const { return net_.num_parameters() + friction_.size(); }
  /// theta = [network, w_v, w_c] (a copy).
  Eigen::VectorXd parameters() const {
    Eigen::VectorXd theta(num_parameters());
    theta << net_.parameters(), friction_;
    return theta;
  }
  /// Sets theta (size num_parameters()).
  void SetParameters(const Eigen::VectorXd& theta) {
    DIFFDYN_CHECK(theta.size() == num_parameters(), "DeLaN: expected ", num_parameters(), " parameters, got ",
                  theta.size());
    net_.mutable_parameters() = theta.head(net_.num_parameters());
    friction_ = theta.tail(friction_.size());
    SyncFloatNetwork();
  }

  /// Viscous and Coulomb coefficients softplus(w) (n each; zeros without friction head).
  Eigen::VectorXd viscous() const { return FrictionCoefficients(0); }
  Eigen::VectorXd coulomb() const { return FrictionCoefficients(1); }

  /// f(qd) = viscous * qd + coulomb * tanh(qd / v_c) (n; zeros without friction head), on double or Jets.
  template <typename S>
  Eigen::Matrix<S, Eigen::Dynamic, 1> Friction(const Eigen::Matrix<S, Eigen::Dynamic, 1>& qd) const {
    Eigen::Matrix<S, Eigen::Dynamic, 1> f = Eigen::Matrix<S, Eigen::Dynamic, 1>::Zero(dof());
    if (!options_.friction) return f;
    for (int j = 0; j < dof(); ++j) f[j] = JointFriction(j, qd[j]);
    return f;
  }

  /// tau = H(q) qdd + c(q, qd) + g(q) + f(qd) of one sample, on double or Jets.
  template <typename S>
  Eigen::Matrix<S, Eigen::Dynamic, 1> InverseDynamics(const Eigen::Matrix<S, Eigen::Dynamic, 1>& q,
                                                      const Eigen::Matrix<S, Eigen::Dynamic, 1>& qd,
                                                      const Eigen::Matrix<S, Eigen::Dynamic, 1>& qdd) const {
    DelanHead<S> head = Head(q, qd, qdd);
    Eigen::Matrix<S, Eigen::Dynamic, 1> tau(dof());
    head.Torque(tau);
    return tau + Friction(qd);
  }

  /// qdd = H^-1 (tau - c - g - f) by a Cholesky solve (H is positive definite), on double or Jets.
  template <typename S>
  Eigen::Matrix<S, Eigen::Dynamic, 1> ForwardDynamics(const Eigen::Matrix<S, Eigen::Dynamic, 1>& q,
                                                      const Eigen::Matrix<S, Eigen::Dynamic, 1>& qd,
                                                      const Eigen::Matrix<S, Eigen::Dynamic, 1>& tau) const {
    using Vec = Eigen::Matrix<S, Eigen::Dynamic, 1>;
    DelanHead<S> head = Head(q, qd, Vec::Zero(dof()).eval());
    const Vec rhs = tau - head.coriolis() - head.gravity() - Friction(qd);
    return SpdSolve(head.MassMatrix(), rhs);
  }

  /// The full per-sample head (L, H, c, g, energies; no friction) of one sample.
  template <typename S>
  DelanHead<S> Head(const Eigen::Matrix<S, Eigen::Dynamic, 1>& q, const Eigen::Matrix<S, Eigen::Dynamic, 1>& qd,
                    const Eigen::Matrix<S, Eigen::Dynamic, 1>& qdd) const {
    DIFFDYN_CHECK(q.size() == dof() && qd.size() == dof() && qdd.size() == dof(), "DeLaN: expected ",
                  dof(), " joints, got q, qd, qdd of sizes ", q.size(), ", ", qd.size(), ", ", qdd.size());
    const InputFeatures features = options_.features();
    Eigen::Matrix<S, Eigen::Dynamic, 1> y;
    Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic> jz, jq(options_.num_outputs(), dof());
    net_.ValueAndJacobian(features.EncodeOne<S>(q), &y, &jz);
    features.ChainJacobian<S>(q, jz, &jq);
    DelanHead<S> head(options_);
    head.Forward(y, jq, qd, qdd);
    return head;
  }

  /// Training loss (1/B) sum_b sum_j w_j (tau^_bj - tau_bj)^2 over the batch (q, qd,
  /// qdd, tau: n x B; w = `joint_weights` (n), or ones when empty) and, if grad is
  /// not null, dL/dtheta (resized). Chunks of ws->mlp.chunk_size() samples on
  /// `threads` threads (<= 0: all cores), summed in chunk order: the same result at
  /// any thread count.
  double TorqueLoss(const Eigen::MatrixXd& q, const Eigen::MatrixXd& qd, const Eigen::MatrixXd& qdd,
                    const Eigen::MatrixXd& tau, Eigen::VectorXd* grad, DelanWorkspace* ws,
                    int threads = 0, const Eigen::VectorXd& joint_weights = {}) const {
    const int batch = static_cast<int>(q.cols());
    CheckBatch(q, qd, qdd, batch);
    DIFFDYN_CHECK(tau.rows() == dof() && tau.cols() == batch, "DeLaN: tau must be ", dof(), " x ", batch);
    DIFFDYN_CHECK(joint_weights.size() == 0 || joint_weights.size() == dof(), "DeLaN: ", dof(),
                  " joint weights expected, got ", joint_weights.size());
    const Batch in{q, qd, qdd, tau, joint_weights};
    if (precision_ == Precision::kF32) return TorqueLossIn(net_f_, in, grad, &ws->f32, ws, threads);
    return TorqueLossIn(net_, in, grad, &ws->f64, ws, threads);
  }

  /// tau^ and its parts for the batch (q, qd, qdd: n x B), with the energies, the
  /// power dE/dt (friction excluded: qd^T tau^ = dE/dt + qd^T f) and the smallest
  /// eigenvalue of H per sample.
  DelanParts Decompose(const Eigen::MatrixXd& q, const Eigen::MatrixXd& qd, const Eigen::MatrixXd& qdd,
                       DelanWorkspace* ws, int threads = 0) const {
    CheckBatch(q, qd, qdd, static_cast<int>(q.cols()));
    if (precision_ == Precision::kF32) return DecomposeIn(net_f_, q, qd, qdd, &ws->f32, threads);
    return DecomposeIn(net_, q, qd, qdd, &ws->f64, threads);
  }

 private:
  // The training batch of TorqueLoss (n x B each; weights n or empty).
  struct Batch {
    const Eigen::MatrixXd &q, &qd, &qdd, &tau;
    const Eigen::VectorXd& joint_weights;
  };

  // TorqueLoss on the network `net` of precision S with its buffers `buf`; the
  // loss and the friction gradient are summed in double, chunk by chunk.
  template <typename S>
  double TorqueLossIn(const Mlp<S>& net, const Batch& in, Eigen::VectorXd* grad, DelanBuffers<S>* buf,
                      DelanWorkspace* ws, int threads) const {
    using Vec = Eigen::Matrix<S, Eigen::Dynamic, 1>;
    const int batch = static_cast<int>(in.q.cols());
    const bool weighted = in.joint_weights.size() > 0;
    const InputFeatures features = options_.features();
    features.Encode(in.q, &buf->z);
    net.Forward(buf->z, &buf->y, &buf->jac, &buf->mlp, threads);
    const int n = dof(), nz = static_cast<int>(buf->z.rows()), chunk = buf->mlp.chunk_size();
    const int chunks = NumChunks(batch, chunk);
    PrepareHeads(buf, chunks);
    ws->friction_grad.resize(chunks);
    for (Eigen::VectorXd& g : ws->friction_grad) g.setZero(options_.num_friction_parameters());
    ws->chunk_loss.assign(chunks, 0.0);
    if (grad) {
      buf->ybar.resize(buf->y.rows(), batch);
      buf->jbar.resize(buf->jac.rows(), buf->jac.cols());
    }
    const double scale = 1.0 / batch;
    ParallelForChunks(batch, chunk, threads, [&](int c, int begin, int end) {
      DelanHead<S>& head = buf->heads[c];
      auto& jq = buf->jq[c];
      auto& jq_bar = buf->jq_bar[c];
      Vec tau_hat(n), tbar(n);
      double sum = 0.0;
      for (int b = begin; b < end; ++b) {
        features.ChainJacobian<S>(in.q.col(b), buf->jac.middleCols(Eigen::Index(b) * nz, nz), &jq);
        head.Forward(buf->y.col(b), jq, in.qd.col(b), in.qdd.col(b));
        head.Torque(tau_hat);
        AddFriction(in.qd.col(b), &tau_hat);
        tbar = tau_hat - in.tau.col(b).template cast<S>();
        for (int j = 0; j < n; ++j) {
          const double r = static_cast<double>(tbar[j]), w = weighted ? in.joint_weights[j] : 1.0;
          sum += w * r * r;
          if (weighted) tbar[j] *= S(w);
        }
        if (!grad) continue;
        tbar *= S(2.0 * scale);
        head.Backward(tbar, buf->y.col(b), jq, buf->ybar.col(b), jq_bar);
        auto jbar_b = buf->jbar.middleCols(Eigen::Index(b) * nz, nz);
        features.ChainJacobianTranspose(in.q.col(b), jq_bar, &jbar_b);
        AddFrictionGradient(in.qd.col(b), tbar, &ws->friction_grad[c]);
      }
      ws->chunk_loss[c] = sum;
    });
    double loss = 0.0;
    for (int c = 0; c < chunks; ++c) loss += ws->chunk_loss[c];
    if (grad) {
      net.Backward(buf->ybar, buf->jbar, &buf->net_grad, nullptr, &buf->mlp, threads);
      grad->resize(num_parameters());
      grad->head(net_.num_parameters()) = buf->net_grad.template cast<double>();
      auto tail = grad->tail(friction_.size());
      tail.setZero();
      for (int c = 0; c < chunks; ++c) tail += ws->friction_grad[c];
    }
    return loss * scale;
  }

  // Decompose on the network `net` of precision S (parts returned in double).
  template <typename S>
  DelanParts DecomposeIn(const Mlp<S>& net, const Eigen::MatrixXd& q, const Eigen::MatrixXd& qd,
                         const Eigen::MatrixXd& qdd, DelanBuffers<S>* buf, int threads) const {
    const int batch = static_cast<int>(q.cols()), n = dof();
    const InputFeatures features = options_.features();
    features.Encode(q, &buf->z);
    net.Forward(buf->z, &buf->y, &buf->jac, &buf->mlp, threads);
    const int nz = static_cast<int>(buf->z.rows()), chunk = buf->mlp.chunk_size();
    PrepareHeads(buf, NumChunks(batch, chunk));
    DelanParts p;
    for (Eigen::MatrixXd* m : {&p.torque, &p.inertial, &p.coriolis, &p.gravity, &p.friction}) m->resize(n, batch);
    for (Eigen::RowVectorXd* r : {&p.kinetic, &p.potential, &p.power, &p.min_mass_eigenvalue}) r->resize(batch);
    ParallelForChunks(batch, chunk, threads, [&](int c, int begin, int end) {
      DelanHead<S>& head = buf->heads[c];
      Eigen::Matrix<S, Eigen::Dynamic, 1> tau_hat(n);
      for (int b = begin; b < end; ++b) {
        features.ChainJacobian<S>(q.col(b), buf->jac.middleCols(Eigen::Index(b) * nz, nz), &buf->jq[c]);
        head.Forward(buf->y.col(b), buf->jq[c], qd.col(b), qdd.col(b));
        head.Torque(tau_hat);
        p.friction.col(b) = Friction<double>(qd.col(b));
        p.torque.col(b) = tau_hat.template cast<double>() + p.friction.col(b);
        p.inertial.col(b) = head.inertial().template cast<double>();
        p.coriolis.col(b) = head.coriolis().template cast<double>();
        p.gravity.col(b) = head.gravity().template cast<double>();
        p.kinetic[b] = static_cast<double>(head.kinetic());
        p.potential[b] = static_cast<double>(head.potential());
        p.power[b] = static_cast<double>(head.power());
        p.min_mass_eigenvalue[b] = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(
                                       head.MassMatrix().template cast<double>(), Eigen::EigenvaluesOnly)
                                       .eigenvalues()[0];
      }
    });
    return p;
  }

  // The float network follows the double parameters when the precision is float32.
  void SyncFloatNetwork() {
    if (precision_ == Precision::kF32) net_f_ = net_.cast<float>();
  }
  // softplus(w) of the viscous (block 0) or Coulomb (block 1) raw parameters.
  Eigen::VectorXd FrictionCoefficients(int block) const {
    if (!options_.friction) return Eigen::VectorXd::Zero(dof());
    Eigen::VectorXd v(dof());
    for (int j = 0; j < dof(); ++j) v[j] = ActivationValue(Activation::Softplus(), friction_[block * dof() + j]);
    return v;
  }
  // f_j(qd_j) = softplus(w_v,j) qd_j + softplus(w_c,j) tanh(qd_j / v_c), no allocation.
  template <typename S>
  S JointFriction(int j, const S& qd) const {
    using std::tanh;
    const Activation softplus = Activation::Softplus();
    return S(ActivationValue(softplus, friction_[j])) * qd +
           S(ActivationValue(softplus, friction_[dof() + j])) * tanh(qd / S(options_.coulomb_velocity));
  }
  // tau += f(qd), f computed in double (tau of either precision).
  template <typename V, typename T>
  void AddFriction(const V& qd, T* tau) const {
    using S = typename T::Scalar;
    if (!options_.friction) return;
    for (int j = 0; j < dof(); ++j) (*tau)[j] += static_cast<S>(JointFriction(j, double(qd[j])));
  }
  // dL/dw += tbar_j * softplus'(w) * (qd_j | tanh(qd_j / v_c)), in double.
  template <typename V, typename TB>
  void AddFrictionGradient(const V& qd, const TB& tbar, Eigen::VectorXd* grad) const {
    if (!options_.friction) return;
    const int n = dof();
    for (int j = 0; j < n; ++j) {
      const double t = static_cast<double>(tbar[j]);
      (*grad)[j] += t * ActivationDerivative(Activation::Softplus(), friction_[j]) * qd[j];
      (*grad)[n + j] += t * ActivationDerivative(Activation::Softplus(), friction_[n + j]) *
                        std::tanh(qd[j] / options_.coulomb_velocity);
    }
  }
  void CheckBatch(const Eigen::MatrixXd& q, const Eigen::MatrixXd& qd, const Eigen::MatrixXd& qdd,
                  int batch) const {
    DIFFDYN_CHECK(batch > 0 && q.rows() == dof() && qd.rows() == dof() && qdd.rows() == dof() &&
                      qd.cols() == batch && qdd.cols() == batch,
                  "DeLaN: q, qd, qdd must be ", dof(), " x B with one B, got ", q.rows(), " x ", q.cols(),
                  ", ", qd.rows(), " x ", qd.cols(), ", ", qdd.rows(), " x ", qdd.cols());
  }
  // Sizes the per-chunk heads and Jacobians of `buf`.
  template <typename S>
  void PrepareHeads(DelanBuffers<S>* buf, int chunks) const {
    if (!buf->heads.empty() && buf->heads.front().dof() != dof()) {
      buf->heads.clear();
      buf->jq.clear();
      buf->jq_bar.clear();
    }
    while (static_cast<int>(buf->heads.size()) < chunks) buf->heads.emplace_back(options_);
    const int m = options_.num_outputs();
    buf->jq.resize(chunks);
    buf->jq_bar.resize(chunks);
    for (int c = 0; c < chunks; ++c) {
      buf->jq[c].resize(m, dof());  // no-op after the first call
      buf->jq_bar[c].resize(m, dof());
    }
  }

  DelanOptions options_;
  Mlp<double> net_;
  Eigen::VectorXd friction_;  // w_v (n), w_c (n), or empty
  Precision precision_ = Precision::kF64;
  Mlp<float> net_f_;          // net_ in float when precision_ is float32
};

/// A DeLaN as a continuous-time system for ContinuousTransitionModel
/// (continuous_model.h): x = (q, qd) (2n), dx/dt = (qd, H^-1 (tau - c - g - f)),
/// u = the torques of the `actuated` joints (0-based, increasing; empty: all n),
/// the other joints' torque 0.
struct DelanDynamics {
  std::shared_ptr<const Delan> model;
  std::vector<int> actuated{};

  template <typename T>
  void operator()(const Eigen::Matrix<T, Eigen::Dynamic, 1>& x, const Eigen::Matrix<T, Eigen::Dynamic, 1>& u,
                  const Eigen::Matrix<T, Eigen::Dynamic, 1>& /*theta*/, double /*t*/,
                  Eigen::Matrix<T, Eigen::Dynamic, 1>& dxdt) const {
    const int n = model->dof();
    const Eigen::Matrix<T, Eigen::Dynamic, 1> q = x.head(n), qd = x.tail(n);
    dxdt.resize(2 * n);
    dxdt.head(n) = qd;
    if (actuated.empty()) {
      dxdt.tail(n) = model->ForwardDynamics<T>(q, qd, u);
      return;
    }
    Eigen::Matrix<T, Eigen::Dynamic, 1> tau = Eigen::Matrix<T, Eigen::Dynamic, 1>::Zero(n);
    for (std::size_t k = 0; k < actuated.size(); ++k) tau[actuated[k]] = u[static_cast<Eigen::Index>(k)];
    dxdt.tail(n) = model->ForwardDynamics<T>(q, qd, tau);
  }
};

/// The architecture object of a "delan" or "delan-friction" model file:
/// {"dof", "epsilon", "diagonal_shift", "diagonal_floor", "periodic" (0-based joints),
/// ["coulomb_velocity" (delan-friction),] "mlp": {...}}.
inline nlohmann::json DelanArchitectureToJson(const DelanOptions& o) {
  nlohmann::json j = {{"dof", o.dof},
                      {"epsilon", o.epsilon},
                      {"diagonal_shift", o.diagonal_shift},
                      {"diagonal_floor", o.diagonal_floor},
                      {"periodic", o.periodic},
                      {"mlp", MlpArchitectureToJson(o.NetworkArchitecture())}};
  if (o.friction) j["coulomb_velocity"] = o.coulomb_velocity;
  return j;
}

/// DelanOptions from the architecture object of a model file of kind "delan"
/// (friction false) or "delan-friction"; "periodic" may be absent (none). Throws
/// diffdyn::Error naming the bad field.
inline DelanOptions DelanArchitectureFromJson(const nlohmann::json& j, bool friction) {
  DIFFDYN_CHECK(j.is_object(), "architecture must be an object");
  for (const char* key : {"dof", "epsilon", "diagonal_shift", "diagonal_floor", "mlp"}) {
    DIFFDYN_CHECK(j.contains(key), "architecture: missing '", key, "'");
  }
  DIFFDYN_CHECK(!friction || j.contains("coulomb_velocity"), "architecture: missing 'coulomb_velocity'");
  for (const char* key : {"epsilon", "diagonal_shift", "diagonal_floor", "coulomb_velocity"}) {
    DIFFDYN_CHECK(!j.contains(key) || j[key].is_number(), "architecture: '", key, "' must be a number");
  }
  DelanOptions o;
  o.dof = static_cast<int>(JsonInt(j["dof"], 1, 64, "architecture: 'dof'"));
  o.epsilon = j["epsilon"].get<double>();
  o.diagonal_shift = j["diagonal_shift"].get<double>();
  o.diagonal_floor = j["diagonal_floor"].get<double>();
  o.friction = friction;
  if (friction) o.coulomb_velocity = j["coulomb_velocity"].get<double>();
  if (j.contains("periodic")) {
    DIFFDYN_CHECK(j["periodic"].is_array() && j["periodic"].size() <= 64,
                  "architecture: 'periodic' must be an array of joint indices");
    for (const auto& i : j["periodic"]) {
      o.periodic.push_back(static_cast<int>(JsonInt(i, 0, o.dof - 1, "architecture: 'periodic' entry")));
    }
  }
  const MlpArchitecture mlp = MlpArchitectureFromJson(j["mlp"]);
  DIFFDYN_CHECK(mlp.sizes.size() >= 3 && !mlp.activations.empty(),
                "architecture: 'mlp' needs at least one hidden layer");
  o.hidden = mlp.sizes[1];
  o.depth = static_cast<int>(mlp.sizes.size()) - 2;
  o.activation = mlp.activations.front();
  o.Validate();
  DIFFDYN_CHECK(mlp == o.NetworkArchitecture(), "architecture: 'mlp' is not a DeLaN network for ",
                o.dof, " joints (sizes [", o.features().size(o.dof), ", hidden..., ", o.num_outputs(),
                "], one activation)");
  return o;
}

/// Registers the kinds "delan" and "delan-friction" with the model-file loader (idempotent).
inline void RegisterDelanKind() {
  static std::once_flag once;
  std::call_once(once, [] {
    for (const bool friction : {false, true}) {
      RegisterModelKind(friction ? "delan-friction" : "delan", [friction](const nlohmann::json& j) {
        const DelanOptions o = DelanArchitectureFromJson(j, friction);
        return o.NetworkArchitecture().num_parameters() + o.num_friction_parameters();
      });
    }
  });
}

/// Whether `kind` is a DeLaN model-file kind.
inline bool IsDelanKind(const std::string& kind) { return kind == "delan" || kind == "delan-friction"; }

/// Saves `model` atomically as a model file of kind model.options().kind(), with its precision.
inline void SaveDelan(const std::filesystem::path& path, const Delan& model,
                      const nlohmann::json& provenance = nlohmann::json::object(),
                      const nlohmann::json& metrics = nlohmann::json::object()) {
  RegisterDelanKind();
  SaveModelFile(path, ModelFile{model.options().kind(), DelanArchitectureToJson(model.options()),
                                model.parameters(), provenance, metrics, nullptr, model.precision()});
}

/// Loads a model file of kind "delan" or "delan-friction" in the precision it
/// records; throws diffdyn::Error
/// with one line naming the path.
inline Delan LoadDelan(const std::filesystem::path& path, ModelFile* contents = nullptr) {
  RegisterDelanKind();
  ModelFile file = LoadModelFile(path);
  DIFFDYN_CHECK(IsDelanKind(file.kind), path.string(), ": model kind is '", file.kind,
                "', expected delan or delan-friction");
  DelanOptions options;
  try {
    options = DelanArchitectureFromJson(file.architecture, file.kind == "delan-friction");
  } catch (const Error& e) {
    throw Error(StrCat(path.string(), ": ", e.what()));
  }
  Delan model(options, file.parameters);
  model.SetPrecision(file.precision);
  if (contents) *contents = std::move(file);
  return model;
}

}  // namespace diffdyn
