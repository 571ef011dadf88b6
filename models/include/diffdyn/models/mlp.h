// The multilayer perceptron / deep differential network (DDN).
//
// An Mlp with layer sizes n_0 (inputs), n_1, ..., n_L (outputs) computes, for
// layers l = 0 .. L-1 with W_l of size n_{l+1} x n_l and b_l of size n_{l+1},
//
//   h_0 = x,   a_l = W_l h_l + b_l,   h_{l+1} = g_l(a_l)   (hidden layers),
//   y = a_{L-1}                                            (linear output).
//
// Deep differential network: the input Jacobian comes out of the same pass,
// chaining Z_l = dh_l/dx (n_l x n_0) from Z_0 = I:
//
//   U_l = W_l Z_l,   Z_{l+1} = diag(g_l'(a_l)) U_l,   dy/dx = U_{L-1}.
//
// Batched paths put samples in columns: X is n_0 x B, Y is n_L x B, and the B
// Jacobians are stacked side by side, J = [J_1 J_2 ... J_B] (n_L x n_0 B), so
// each layer of the chain is one GEMM W_l [Z_l^1 ... Z_l^B].
//
// Reverse mode (Backward) takes cotangents Gy = dL/dY and, optionally,
// GJ = dL/dJ (same layout as J) and returns dL/dtheta and dL/dX. Walking the
// layers backwards with abar = dL/da_l and ubar = dL/dU_l:
//
//   dL/dW_l += abar h_l^T + ubar Z_l^T,       dL/db_l += sum_b abar,
//   hbar = W_l^T abar,   zbar = W_l^T ubar               (to layer l-1),
//   dbar = sum_j zbar[:, j] .* U_{l-1}[:, j]             (cotangent of g'),
//   abar = hbar .* g'(a_{l-1}) + dbar .* g''(a_{l-1}),   ubar = diag(g') zbar,
//   dL/dx = W_0^T abar.
//
// This is why every activation carries g'': a loss on the Jacobian reaches the
// weights through the derivative of g'. All products are GEMMs over the batch.
//
// Parameters: ONE flat vector theta = [vec(W_0), b_0, vec(W_1), b_1, ...], each
// W_l column-major. Optimisers, Ceres and model files all see this vector.
//
// Threads: the batch is cut into chunks of MlpWorkspace::chunk_size() samples
// (independent of the thread count); each chunk works in its own buffers and
// the per-chunk parameter gradients are summed in chunk order, so results are
// bit-identical at any thread count.
//
//   Mlp<double> net(MlpArchitecture{{2, 64, 64, 1}, {Activation::Softplus(),
//                                                  Activation::Softplus()}}, theta);
//   MlpWorkspace ws(net.architecture(), 256);
//   net.Forward(X, &Y, &J, &ws);                   // values and Jacobians
//   net.Backward(Gy, GJ, &grad, nullptr, &ws);     // dL/dtheta
//   net.Evaluate(X, Y, &ws);                       // values only, no tape (fast path)
//
// Precision: the batched paths run in the network's scalar, double or float.
// A float network multiplies in sgemm and keeps its scratch in an MlpWorkspaceF;
// the parameter gradient is summed in float, chunk by chunk, as in double.
//
//   const Mlp<float> net_f = net.cast<float>();
//   MlpWorkspaceF ws_f(net_f.architecture(), 256);
//   net_f.Forward(X.cast<float>(), &Y_f, &J_f, &ws_f);  // Y_f, J_f: MatrixXf
#pragma once

#include <algorithm>
#include <numeric>
#include <type_traits>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/activations.h"
#include "diffdyn/models/gemm.h"
#include "diffdyn/models/layer_kernel.h"
#include "diffdyn/models/parallel.h"

namespace diffdyn {

/// Layer sizes [n_0 = inputs, n_1, ..., n_L = outputs] and one activation per
/// hidden layer (L - 1 of them); the output layer is linear.
struct MlpArchitecture {
  /// [n_0, n_1, ..., n_L], all positive.
  std::vector<int> sizes;
  /// g_0 .. g_{L-2} of the hidden layers.
  std::vector<Activation> activations;

  /// Number of affine layers L = sizes.size() - 1.
  int num_layers() const { return static_cast<int>(sizes.size()) - 1; }
  /// n_0.
  int num_inputs() const { return sizes.front(); }
  /// n_L.
  int num_outputs() const { return sizes.back(); }
  /// Largest layer width max_l n_l.
  int max_width() const { return *std::max_element(sizes.begin(), sizes.end()); }
  /// Largest weight matrix, max_l n_{l+1} n_l entries.
  Eigen::Index max_weight_count() const {
    Eigen::Index count = 0;
    for (int l = 0; l < num_layers(); ++l) {
      count = std::max(count, Eigen::Index(sizes[l + 1]) * sizes[l]);
    }
    return count;
  }
  /// Offset of vec(W_l) in the flat parameter vector.
  Eigen::Index WeightOffset(int l) const {
    Eigen::Index offset = 0;
    for (int k = 0; k < l; ++k) offset += Eigen::Index(sizes[k + 1]) * (sizes[k] + 1);
    return offset;
  }
  /// Offset of b_l in the flat parameter vector.
  Eigen::Index BiasOffset(int l) const {
    return WeightOffset(l) + Eigen::Index(sizes[l + 1]) * sizes[l];
  }
  /// Total parameter count sum_l n_{l+1} (n_l + 1).
  Eigen::Index num_parameters() const { return WeightOffset(num_layers()); }

  /// Throws diffdyn::Error unless there are >= 2 sizes, all positive, and
  /// exactly L - 1 activations with valid parameters.
  void Validate() const {
    DIFFDYN_CHECK(sizes.size() >= 2, "MLP needs at least an input and an output size, got ",
                  sizes.size(), " sizes");
    for (int s : sizes) DIFFDYN_CHECK(s > 0, "MLP layer sizes must be positive, got ", s);
    DIFFDYN_CHECK(static_cast<int>(activations.size()) == num_layers() - 1, "MLP with ",
                  num_layers() - 1, " hidden layers needs as many activations, got ",
                  activations.size());
    for (const Activation& a : activations) {
      DIFFDYN_CHECK(std::isfinite(a.param), "MLP activation parameter is not finite");
      DIFFDYN_CHECK(a.kind != ActivationKind::kSoftplus || a.param > 0.0,
                    "softplus beta must be positive, got ", a.param);
    }
  }

  /// Same sizes and activations.
  bool operator==(const MlpArchitecture&) const = default;
};

/// Scratch buffers of the batched paths, for one thread of work: per chunk of
/// samples, the pre-activations, activations, g', g'', the Jacobian chain and
/// the backward cotangents. Sized once (Reserve); afterwards the batched calls
/// do not allocate for batches up to the reserved size. Not shared between
/// concurrent calls; one model may be used with many workspaces at once.
/// S is the scalar of the batched paths it serves (MlpWorkspace for Mlp<double>,
/// MlpWorkspaceF for Mlp<float>).
template <typename S>
class BasicMlpWorkspace {
 public:
  /// Default chunk size: 256 samples per chunk (a batch of 500 = 2 chunks).
  static constexpr int kDefaultChunkSize = 256;

  /// Empty workspace; the first Forward sizes it.
  BasicMlpWorkspace() = default;
  /// Workspace for `arch` and batches up to `max_batch` samples, cut into
  /// chunks of `chunk_size` samples; `jacobian` reserves the Jacobian chain.
  BasicMlpWorkspace(const MlpArchitecture& arch, int max_batch,
                    int chunk_size = kDefaultChunkSize, bool jacobian = true)
      : chunk_size_(chunk_size) {
    DIFFDYN_CHECK(chunk_size > 0, "MlpWorkspace: chunk size must be positive, got ", chunk_size);
    Reserve(arch, max_batch, jacobian);
  }

  /// Samples per chunk (fixes the summation order, so the results).
  int chunk_size() const { return chunk_size_; }

  /// A layer with a side of at most this many units is thin: the reverse sweep
  /// multiplies by a transposed copy of its weights (see Mlp::GemmTransposedWeight).
  static constexpr int kThinSide = 16;

  /// Makes room for `batch` samples of `arch` (allocates only when growing).
  void Reserve(const MlpArchitecture& arch, int batch, bool jacobian) {
    if (!(arch == arch_)) {
      arch_ = arch;
      chunks_.clear();
      jacobian_ = false;
    }
    const int needed = NumChunks(batch, chunk_size_);
    if (static_cast<int>(chunks_.size()) >= needed && (jacobian_ || !jacobian)) return;
    jacobian_ = jacobian_ || jacobian;
    chunks_.resize(std::max<std::size_t>(chunks_.size(), needed));
    for (Chunk& c : chunks_) c.Allocate(arch_, chunk_size_, jacobian_);
  }

 private:
  template <typename>
  friend class Mlp;

  // Buffers of one chunk of at most `chunk_size_` samples.
  struct Chunk {
    using Matrix = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;
    using Vector = Eigen::Matrix<S, Eigen::Dynamic, 1>;
    std::vector<Matrix> h;    // h_l, n_l x cap, l = 0 .. L-1
    std::vector<Matrix> dg;   // g'(a_l), hidden layers
    std::vector<Matrix> ddg;  // g''(a_l), hidden layers (Jacobian mode)
    std::vector<Matrix> u;    // U_l, n_{l+1} x n_0 cap (Jacobian mode)
    std::vector<Matrix> z;    // Z_l, n_l x n_0 cap, l >= 1 (Jacobian mode)
    Matrix abar[2], dbar, ubar[2], zbar;
    Vector weight_t;          // W_l^T for the reverse sweep: of a thin layer (kThinSide x
                              // width), or of any layer where Gemm has its panel kernel
    Vector grad;
    Vector block;             // feature-major blocks of kLayerBlock samples (Evaluate,
                              // and InputJacobianReverse with the layer kernel)
    std::vector<int> rows;             // 2 lists of a block's live rows, width each (Evaluate)
    int count = 0;                 // samples in this chunk after the last Forward
    bool has_jacobian = false;     // whether the last Forward built the chain
    bool allocated_jacobian = false;
    int allocated_cap = 0;

    void Allocate(const MlpArchitecture& arch, int cap, bool jacobian) {
      if (allocated_cap == cap && (allocated_jacobian || !jacobian)) return;
      const int layers = arch.num_layers();
      const int n0 = arch.num_inputs();
      const int width = arch.max_width();
      h.resize(layers);
      dg.resize(layers - 1);
      for (int l = 0; l < layers; ++l) h[l].resize(arch.sizes[l], cap);
      for (int l = 0; l + 1 < layers; ++l) dg[l].resize(arch.sizes[l + 1], cap);
      abar[0].resize(width, cap);
      weight_t.resize(kHavePanelGemm ? arch.max_weight_count()
                                     : Eigen::Index(kThinSide) * width);
      abar[1].resize(width, cap);
      grad.resize(arch.num_parameters());
      if (jacobian) {
        ddg.resize(layers);
        u.resize(layers);
        z.resize(layers);
        for (int l = 0; l < layers; ++l) {
          ddg[l].resize(arch.sizes[l + 1], cap);
          u[l].resize(arch.sizes[l + 1], Eigen::Index(n0) * cap);
          z[l].resize(arch.sizes[l], Eigen::Index(n0) * cap);
        }
        dbar.resize(width, cap);
        zbar.resize(width, Eigen::Index(n0) * cap);
      }
      // ubar (the Jacobian cotangents) also holds the n_L stacked sweeps of
      // InputJacobianReverse, which sizes it on first use.
      if (jacobian) {
        ubar[0].resize(width, Eigen::Index(n0) * cap);
        ubar[1].resize(width, Eigen::Index(n0) * cap);
      }
      allocated_cap = cap;
      allocated_jacobian = jacobian;
    }
  };

  MlpArchitecture arch_;
  int chunk_size_ = kDefaultChunkSize;
  bool jacobian_ = false;
  int batch_ = 0;  // batch size of the last Forward; -1 after Evaluate (no tape)
  std::vector<Chunk> chunks_;
  // W_l^T of every layer (column-major n_l x n_{l+1}, one after the other) and
  // max_width zeros: the reverse sweeps of InputJacobianReverse's layer-kernel path.
  Eigen::Matrix<S, Eigen::Dynamic, 1> transposed_;
};

/// Workspace of Mlp<double>'s batched paths.
using MlpWorkspace = BasicMlpWorkspace<double>;
/// Workspace of Mlp<float>'s batched paths.
using MlpWorkspaceF = BasicMlpWorkspace<float>;

/// A fully connected network with hidden activations and a linear output, held as
/// its architecture plus one flat parameter vector of scalar type T (double or
/// float, or a ceres::Jet to differentiate with respect to parameters). The
/// batched paths exist for T = double and T = float. Immutable during
/// evaluation: scratch lives in an MlpWorkspace (MlpWorkspaceF for float).
template <typename T>
class Mlp {
 public:
  /// Scalar type of the parameters.
  using Scalar = T;
  /// Vector of T (the flat parameters theta).
  using VectorT = Eigen::Matrix<T, Eigen::Dynamic, 1>;
  /// Scalar of T * S (a Jet if either is a Jet).
  template <typename S>
  using ResultScalar = decltype(std::declval<T>() * std::declval<S>());
  /// Scalar of the batched paths: T for float and double (double otherwise, unused).
  using B = std::conditional_t<std::is_floating_point_v<T>, T, double>;
  /// Matrix of B (batches, samples in columns).
  using MatrixB = Eigen::Matrix<B, Eigen::Dynamic, Eigen::Dynamic>;
  /// Vector of B (gradients).
  using VectorB = Eigen::Matrix<B, Eigen::Dynamic, 1>;
  /// Workspace of the batched paths.
  using Workspace = BasicMlpWorkspace<B>;

  /// Empty network (no layers); assign a real one before use.
  Mlp() = default;
  /// Network with all parameters zero.
  explicit Mlp(MlpArchitecture arch) : arch_(std::move(arch)) {
    arch_.Validate();
    params_ = VectorT::Zero(arch_.num_parameters());
  }
  /// Network with the flat parameters theta (size num_parameters()).
  Mlp(MlpArchitecture arch, VectorT theta) : arch_(std::move(arch)), params_(std::move(theta)) {
    arch_.Validate();
    DIFFDYN_CHECK(params_.size() == arch_.num_parameters(), "MLP expects ",
                  arch_.num_parameters(), " parameters, got ", params_.size());
  }

  /// Layer sizes and activations.
  const MlpArchitecture& architecture() const { return arch_; }
  /// n_0.
  int num_inputs() const { return arch_.num_inputs(); }
  /// n_L.
  int num_outputs() const { return arch_.num_outputs(); }
  /// Size of theta: sum_l n_{l+1} (n_l + 1).
  Eigen::Index num_parameters() const { return params_.size(); }
  /// The flat parameters theta.
  const VectorT& parameters() const { return params_; }
  /// Mutable flat parameters (for optimisers; do not resize).
  VectorT& mutable_parameters() { return params_; }
  /// Replaces theta; the size must stay num_parameters().
  void set_parameters(const VectorT& theta) {
    DIFFDYN_CHECK(theta.size() == params_.size(), "MLP expects ", params_.size(),
                  " parameters, got ", theta.size());
    params_ = theta;
  }

  /// W_l (n_{l+1} x n_l), a view into theta.
  Eigen::Map<const Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic>> W(int l) const {
    return {params_.data() + arch_.WeightOffset(l), arch_.sizes[l + 1], arch_.sizes[l]};
  }
  /// b_l (n_{l+1}), a view into theta.
  Eigen::Map<const VectorT> b(int l) const {
    return {params_.data() + arch_.BiasOffset(l), arch_.sizes[l + 1]};
  }

  /// A copy with parameters converted to U (e.g. double -> Jet to seed
  /// derivatives with respect to some parameters).
  template <typename U>
  Mlp<U> cast() const {
    return Mlp<U>(arch_, params_.template cast<U>());
  }

  // ---------------------------------------------------------------------------
  // Single sample, generic scalar.

  /// y = f(x) for one input x (size n_0) of scalar S; the result scalar is
  /// the product type of T and S (Jet if either is a Jet).
  template <typename Derived>
  auto operator()(const Eigen::MatrixBase<Derived>& x) const {
    using R = ResultScalar<typename Derived::Scalar>;
    CheckInput(x.size());
    Eigen::Matrix<R, Eigen::Dynamic, 1> h = x.template cast<R>();
    for (int l = 0; l < arch_.num_layers(); ++l) {
      Eigen::Matrix<R, Eigen::Dynamic, 1> a;
      if constexpr (std::is_same_v<T, double>) {
        a = W(l) * h;  // double weights times R inputs: no cast of W
        a += b(l).template cast<R>();
      } else {
        a = W(l).template cast<R>() * h + b(l).template cast<R>();
      }
      if (l + 1 < arch_.num_layers()) {
        for (Eigen::Index i = 0; i < a.size(); ++i) a[i] = ActivationValue(arch_.activations[l], a[i]);
      }
      h = std::move(a);
    }
    return h;
  }

  /// Value y (n_L) and closed-form input Jacobian J = dy/dx (n_L x n_0) of one
  /// sample in one forward pass (U_l = W_l Z_l, Z_{l+1} = diag(g'(a_l)) U_l).
  /// With Jet inputs, J carries the derivatives of the Jacobian (Hessians).
  template <typename Derived, typename R = ResultScalar<typename Derived::Scalar>>
  void ValueAndJacobian(const Eigen::MatrixBase<Derived>& x, Eigen::Matrix<R, Eigen::Dynamic, 1>* y,
                        Eigen::Matrix<R, Eigen::Dynamic, Eigen::Dynamic>* jac) const {
    CheckInput(x.size());
    using Vec = Eigen::Matrix<R, Eigen::Dynamic, 1>;
    using Mat = Eigen::Matrix<R, Eigen::Dynamic, Eigen::Dynamic>;
    Vec h = x.template cast<R>();
    Mat z = Mat::Identity(num_inputs(), num_inputs());
    for (int l = 0; l < arch_.num_layers(); ++l) {
      const Mat w = W(l).template cast<R>();
      Vec a = w * h + b(l).template cast<R>();
      Mat u = w * z;
      if (l + 1 < arch_.num_layers()) {
        const Activation& act = arch_.activations[l];
        for (Eigen::Index i = 0; i < a.size(); ++i) {
          u.row(i) *= ActivationDerivative(act, a[i]);
          a[i] = ActivationValue(act, a[i]);
        }
      }
      h = std::move(a);
      z = std::move(u);
    }
    if (y) *y = std::move(h);
    if (jac) *jac = std::move(z);
  }

  /// Closed-form second derivatives of one sample (double only):
  /// hessians[k](i, j) = d^2 y_k / dx_i dx_j, k < n_L, each n_0 x n_0, via the
  /// second-order chain S_{l+1} = g''(a) .* (U e_i) .* (U e_j) + g'(a) .* W_l S_l.
  /// y and jac may be null.
  void ValueJacobianHessian(const Eigen::VectorXd& x, Eigen::VectorXd* y, Eigen::MatrixXd* jac,
                            std::vector<Eigen::MatrixXd>* hessians) const
    requires std::is_same_v<T, double>
  {
    CheckInput(x.size());
    const int n0 = num_inputs();
    Eigen::VectorXd h = x;
    Eigen::MatrixXd z = Eigen::MatrixXd::Identity(n0, n0);
    Eigen::MatrixXd s = Eigen::MatrixXd::Zero(n0, n0 * n0);  // column i*n0+j: d2h/dxi dxj
    for (int l = 0; l < arch_.num_layers(); ++l) {
      Eigen::VectorXd a = W(l) * h + b(l);
      Eigen::MatrixXd u = W(l) * z;
      Eigen::MatrixXd v = W(l) * s;
      if (l + 1 < arch_.num_layers()) {
        const Activation& act = arch_.activations[l];
        for (Eigen::Index r = 0; r < a.size(); ++r) {
          const double d1 = ActivationDerivative(act, a[r]);
          const double d2 = ActivationSecondDerivative(act, a[r]);
          for (int i = 0; i < n0; ++i) {
            for (int j = 0; j < n0; ++j) {
              v(r, i * n0 + j) = d2 * u(r, i) * u(r, j) + d1 * v(r, i * n0 + j);
            }
          }
          u.row(r) *= d1;
          a[r] = ActivationValue(act, a[r]);
        }
      }
      h = std::move(a);
      z = std::move(u);
      s = std::move(v);
    }
    if (y) *y = h;
    if (jac) *jac = z;
    if (hessians) {
      hessians->assign(num_outputs(), Eigen::MatrixXd(n0, n0));
      for (int k = 0; k < num_outputs(); ++k) {
        for (int i = 0; i < n0; ++i) {
          for (int j = 0; j < n0; ++j) (*hessians)[k](i, j) = s(k, i * n0 + j);
        }
      }
    }
  }

  // ---------------------------------------------------------------------------
  // Batched paths (samples in columns), for T = double or float: matrices of T,
  // products in T's BLAS gemm, workspaces of T (MlpWorkspace, MlpWorkspaceF).

  /// Forward pass over the batch X (n_0 x B): Y = f(X) (n_L x B) and, if `jac`
  /// is not null, the stacked input Jacobians J = [J_1 ... J_B] (n_L x n_0 B).
  /// Stores what Backward needs in `ws` (which must not be used concurrently).
  /// Work is split in chunks of ws->chunk_size() samples over `threads` threads
  /// (<= 0: all cores). Y, jac are resized (allocation only if their size changes).
  void Forward(const MatrixB& X, MatrixB* Y, MatrixB* jac,
               Workspace* ws, int threads = 1) const
    requires std::is_floating_point_v<T>
  {
    PrepareForward(X, Y, jac, ws);
    ParallelForChunks(static_cast<int>(X.cols()), ws->chunk_size(), threads,
                      [&](int c, int begin, int end) {
                        ForwardChunk(X.middleCols(begin, end - begin),
                                     Y->middleCols(begin, end - begin), jac ? &*jac : nullptr,
                                     begin, &ws->chunks_[c]);
                      });
  }

  /// Values only: Y = f(X) for the batch X (n_0 x B) into Y (n_L x B, sized by
  /// the caller), keeping no tape: a Backward on `ws` afterwards needs a Forward
  /// first. Equal to Forward's Y up to rounding (about 1e-15 relative in double). Where
  /// kHaveLayerKernel holds (AVX-512 or AVX2), blocks of kLayerBlock samples run through
  /// all layers in registers and cache (layer_kernel.h), ReLU and bias fused into
  /// the products, skipping the ReLU units that are zero for the whole block (their
  /// terms are w * 0); each sample's value then does not depend on the batch, the
  /// chunking or the thread count. Elsewhere it runs Forward's BLAS products.
  /// Chunks of ws->chunk_size() samples over `threads` threads (<= 0: all cores).
  void Evaluate(const Eigen::Ref<const MatrixB>& X, Eigen::Ref<MatrixB> Y,
                Workspace* ws, int threads = 1) const
    requires std::is_floating_point_v<T>
  {
    DIFFDYN_CHECK(X.rows() == num_inputs(), "MLP expects inputs with ", num_inputs(),
                  " rows, got ", X.rows());
    DIFFDYN_CHECK(Y.rows() == num_outputs() && Y.cols() == X.cols(), "Mlp::Evaluate: output is ",
                  Y.rows(), " x ", Y.cols(), ", expected ", num_outputs(), " x ", X.cols());
    DIFFDYN_CHECK(ws != nullptr, "Mlp::Evaluate needs a workspace");
    const int batch = static_cast<int>(X.cols());
    ws->Reserve(arch_, batch, false);
    ws->batch_ = -1;
    if constexpr (kUseLayerKernel) {
      // The kernel's block buffers, only in workspaces that evaluate (not in tapes).
      const Eigen::Index block_size = Eigen::Index(2) * arch_.max_width() * kLayerBlock;
      for (int c = 0; c < NumChunks(batch, ws->chunk_size()); ++c) {
        if (ws->chunks_[c].block.size() < block_size) ws->chunks_[c].block.resize(block_size);
        ws->chunks_[c].rows.resize(std::size_t(2) * arch_.max_width());
      }
    }
    ParallelForChunks(batch, ws->chunk_size(), threads, [&](int c, int begin, int end) {
      const auto x = X.middleCols(begin, end - begin);
      auto y = Y.middleCols(begin, end - begin);
      if constexpr (kUseLayerKernel) {
        EvaluateChunk(x, y, &ws->chunks_[c]);
      } else {
        ForwardChunk(x, y, nullptr, begin, &ws->chunks_[c]);
      }
    });
  }

  /// Reverse mode after Forward(X, ...) on the same workspace. Given cotangents
  /// gy = dL/dY (n_L x B, or empty for none) and gjac = dL/dJ (n_L x n_0 B in
  /// the layout of Forward's J, or empty for none; needs Forward with J), writes
  /// grad_params = dL/dtheta (num_parameters(), summed over the batch) and, if
  /// not null, grad_inputs = dL/dX (n_0 x B). Either output may be null. With
  /// `accumulate`, grad_params (already of size num_parameters()) is added to
  /// instead of overwritten.
  void Backward(const MatrixB& gy, const MatrixB& gjac,
                VectorB* grad_params, MatrixB* grad_inputs, Workspace* ws,
                int threads = 1, bool accumulate = false) const
    requires std::is_floating_point_v<T>
  {
    if (grad_params) {
      DIFFDYN_CHECK(!accumulate || grad_params->size() == num_parameters(),
                    "Mlp::Backward: accumulating into a gradient of size ", grad_params->size(),
                    ", expected ", num_parameters());
      if (grad_params->size() != num_parameters()) grad_params->resize(num_parameters());
    }
    BackwardImpl(gy, gjac, grad_params ? grad_params->data() : nullptr, accumulate, grad_inputs,
                 ws, threads);
  }

  /// Backward with an output cotangent only, adding dL/dtheta to grad_params
  /// (size num_parameters(), e.g. a segment of a larger vector) and writing
  /// dL/dX to grad_inputs (may be null). No copies of gy; for ODE adjoints that
  /// sum the parameter gradient over many evaluations. With `scratch` (a
  /// workspace whose chunk size is at least ws's), the reverse sweep's cotangent buffers
  /// come from it instead of ws: many recorded forward passes (the stages of an
  /// ODE tape) then share one set of buffers that stays in cache.
  void BackwardAccumulate(const Eigen::Ref<const MatrixB>& gy,
                          Eigen::Ref<VectorB> grad_params, MatrixB* grad_inputs,
                          Workspace* ws, int threads = 1, Workspace* scratch = nullptr) const
    requires std::is_floating_point_v<T>
  {
    DIFFDYN_CHECK(grad_params.size() == num_parameters(), "Mlp::BackwardAccumulate: gradient has ",
                  grad_params.size(), " entries, expected ", num_parameters());
    static const MatrixB kNone;
    BackwardImpl(gy, kNone, grad_params.data(), true, grad_inputs, ws, threads, scratch);
  }

  /// Input Jacobians by batched reverse mode (n_L backward sweeps per sample):
  /// J = [J_1 ... J_B] (n_L x n_0 B), same layout as Forward's, and Y = f(X).
  /// Cheaper than the forward chain when n_L < n_0. Where kHaveLayerKernel holds
  /// and the net has a hidden layer, blocks of kLayerBlock samples run the forward
  /// pass and the sweeps abar_{l-1} = (W_l^T abar_l) .* g'(a_{l-1}) through the
  /// layer kernel on transposed weight copies, in cache and without packing; each
  /// sample's J then does not depend on the batch, chunking or thread count.
  /// Elsewhere the sweeps of a chunk are stacked into one BLAS product per layer.
  /// Chunks of ws->chunk_size() samples over `threads` threads; the same bytes at
  /// any thread count.
  void InputJacobianReverse(const MatrixB& X, MatrixB* Y, MatrixB* jac,
                            Workspace* ws, int threads = 1) const
    requires std::is_floating_point_v<T>
  {
    DIFFDYN_CHECK(jac != nullptr, "Mlp::InputJacobianReverse needs an output Jacobian");
    PrepareForward(X, Y, nullptr, ws);
    const int batch = static_cast<int>(X.cols());
    const int n0 = num_inputs();
    const int m = num_outputs();
    if (jac->rows() != m || jac->cols() != Eigen::Index(n0) * batch) {
      jac->resize(m, Eigen::Index(n0) * batch);
    }
    const int cap = ws->chunk_size();
    const int L = arch_.num_layers();
    if constexpr (kUseLayerKernel) {
      if (L >= 2) {
        InputJacobianByBlocks(X, Y, jac, ws, threads);
        return;
      }
    }
    // Each chunk's forward pass and its sweeps run back to back on one thread,
    // so the tape is still in cache when the sweeps read it.
    ParallelForChunks(batch, cap, threads, [&](int c, int begin, int end) {
      typename Workspace::Chunk& ch = ws->chunks_[c];
      const int nb = end - begin;
      ForwardChunk(X.middleCols(begin, nb), Y->middleCols(begin, nb), nullptr, begin, &ch);
      const int width = arch_.max_width();
      // The chain below reads g' stored; ReLU's comes off its output: 1 .* [h > 0].
      for (int l = 0; l + 1 < L; ++l) {
        if (!DerivativeFromOutput(ch, l)) continue;
        ch.dg[l].leftCols(nb).setOnes();
        MultiplyByReluDerivative(ch.dg[l].leftCols(nb), ch.h[l + 1].leftCols(nb));
      }
      for (MatrixB& buffer : ch.ubar) {
        if (buffer.rows() < width || buffer.cols() < Eigen::Index(m) * cap) {
          buffer.resize(width, std::max(buffer.cols(), Eigen::Index(m) * cap));
        }
      }
      // The m sweeps of each sample side by side: column b*m + k is output k
      // of sample b (workspace buffers ubar hold max(n_0, n_L) cap columns).
      MatrixB* cur = &ch.ubar[0];
      MatrixB* nxt = &ch.ubar[1];
      const Eigen::Index sweeps = Eigen::Index(m) * nb;
      int rows = arch_.sizes[L - 1];
      // Cotangent of the last hidden pre-activation: W_{L-1}^T e_k .* g'(a_{L-2}).
      for (int bb = 0; bb < nb; ++bb) {
        for (int k = 0; k < m; ++k) {
          auto col = cur->col(Eigen::Index(bb) * m + k).head(rows);
          if (L >= 2) {
            col = W(L - 1).row(k).transpose().cwiseProduct(ch.dg[L - 2].col(bb));
          } else {
            col = W(0).row(k).transpose();
          }
        }
      }
      // Hidden layers: abar_{l-1} = (W_l^T abar_l) .* g'(a_{l-1}), one GEMM each.
      for (int l = L - 2; l >= 1; --l) {
        const int rows_in = arch_.sizes[l];
        Gemm(1.0, W(l), true, cur->topLeftCorner(rows, sweeps), false, 0.0,
             nxt->topLeftCorner(rows_in, sweeps));
        for (int bb = 0; bb < nb; ++bb) {
          nxt->block(0, Eigen::Index(bb) * m, rows_in, m).array().colwise() *=
              ch.dg[l - 1].col(bb).array();
        }
        std::swap(cur, nxt);
        rows = rows_in;
      }
      // dy_k/dx = W_0^T abar_0, transposed into the layout of J.
      if (L >= 2) {
        Gemm(1.0, W(0), true, cur->topLeftCorner(rows, sweeps), false, 0.0,
             nxt->topLeftCorner(n0, sweeps));
        std::swap(cur, nxt);
      }
      for (int bb = 0; bb < nb; ++bb) {
        jac->middleCols(Eigen::Index(begin + bb) * n0, n0) =
            cur->block(0, Eigen::Index(bb) * m, n0, m).transpose();
      }
    });
  }

 private:

  // Checks X, sizes the workspace for the batch and Y (n_L x B) and jac (n_L x n_0 B, when
  // not null): what every forward pass needs before its chunks run.
  void PrepareForward(const MatrixB& X, MatrixB* Y, MatrixB* jac, Workspace* ws) const {
    DIFFDYN_CHECK(X.rows() == num_inputs(), "MLP expects inputs with ", num_inputs(),
                  " rows, got ", X.rows());
    DIFFDYN_CHECK(ws != nullptr && Y != nullptr, "Mlp::Forward needs Y and a workspace");
    const int batch = static_cast<int>(X.cols());
    const int n0 = num_inputs();
    ws->Reserve(arch_, batch, jac != nullptr);
    ws->batch_ = batch;
    if (Y->rows() != num_outputs() || Y->cols() != batch) Y->resize(num_outputs(), batch);
    if (jac && (jac->rows() != num_outputs() || jac->cols() != Eigen::Index(n0) * batch)) {
      jac->resize(num_outputs(), Eigen::Index(n0) * batch);
    }
  }

  // Whether Evaluate runs the layer kernel (AVX-512 or AVX2 targets; double and float).
  static constexpr bool kUseLayerKernel =
      kHaveLayerKernel && (std::is_same_v<T, double> || std::is_same_v<T, float>);

  // Whether hidden layer l's g' is read off its output instead of stored: ReLU's
  // g' = [g > 0], on a forward pass without the Jacobian chain (which needs the
  // stored g'). Half the memory traffic of a training tape.
  bool DerivativeFromOutput(const typename Workspace::Chunk& ch, int l) const {
    return !ch.has_jacobian && arch_.activations[l].kind == ActivationKind::kRelu;
  }

  // abar .*= [h > 0] column by column (abar and h rows x nb): ReLU's g' applied from
  // its output (the product keeps NaN and signed zeros).
  template <typename ABlock, typename HBlock>
  static void MultiplyByReluDerivative(ABlock&& abar, const HBlock& h) {
    for (Eigen::Index c = 0; c < abar.cols(); ++c) {
      internal::MultiplyByPositiveIndicator(abar.col(c).data(), h.col(c).data(), abar.rows());
    }
  }

  void CheckInput(Eigen::Index n) const {
    DIFFDYN_CHECK(n == num_inputs(), "MLP expects ", num_inputs(), " inputs, got ", n);
  }

  // Forward over one chunk; jac (full-batch matrix) is written at sample offset `begin`.
  template <typename XBlock, typename YBlock>
  void ForwardChunk(const XBlock& x, YBlock y, MatrixB* jac, int begin,
                    typename Workspace::Chunk* ch) const {
    const int nb = static_cast<int>(x.cols());
    const int L = arch_.num_layers();
    const int n0 = num_inputs();
    const Eigen::Index nz = Eigen::Index(n0) * nb;
    ch->count = nb;
    ch->has_jacobian = jac != nullptr;
    ch->h[0].leftCols(nb) = x;
    for (int l = 0; l < L; ++l) {
      const int rows = arch_.sizes[l + 1];
      // a_l = b_l + W_l h_l with the bias added as the product is stored, written
      // where g(a_l) goes (activation in place). A ReLU whose g' is read off its
      // output later is applied in the same store.
      if (l + 1 < L) {
        auto a = ch->h[l + 1].leftCols(nb);
        const bool relu_in_store = DerivativeFromOutput(*ch, l);
        GemmFused(W(l), false, ch->h[l].leftCols(nb), false,
                  GemmOutput<B>{b(l).data(), relu_in_store}, a);
        if (!relu_in_store) {
          ApplyActivation(arch_.activations[l], a.data(), a.size(), a.data(), ch->dg[l].data(),
                          jac ? ch->ddg[l].data() : nullptr);
        }
      } else {
        GemmFused(W(l), false, ch->h[l].leftCols(nb), false, GemmOutput<B>{b(l).data()}, y);
      }
      if (!jac) continue;
      // Jacobian chain: U_0 = W_0 per sample, U_l = W_l Z_l; Z_{l+1} = diag(g') U_l.
      auto u = ch->u[l].topLeftCorner(rows, nz);
      if (l == 0) {
        for (int bb = 0; bb < nb; ++bb) u.middleCols(Eigen::Index(bb) * n0, n0) = W(0);
      } else {
        Gemm(1.0, W(l), false, ch->z[l].topLeftCorner(arch_.sizes[l], nz), false, 0.0, u);
      }
      if (l + 1 < L) {
        auto z = ch->z[l + 1].topLeftCorner(rows, nz);
        for (int bb = 0; bb < nb; ++bb) {
          z.middleCols(Eigen::Index(bb) * n0, n0) =
              u.middleCols(Eigen::Index(bb) * n0, n0).array().colwise() * ch->dg[l].col(bb).array();
        }
      } else {
        jac->middleCols(Eigen::Index(begin) * n0, nz) = u;
      }
    }
  }

  // Evaluate over one chunk with the layer kernel: per block of kLayerBlock
  // samples, inputs transposed to feature-major (zero-padded), every layer
  // between the chunk's two block buffers, each summing over the rows its input
  // layer reported live, outputs transposed back.
  template <typename XBlock, typename YBlock>
  void EvaluateChunk([[maybe_unused]] const XBlock& x, [[maybe_unused]] YBlock& y,
                     [[maybe_unused]] typename Workspace::Chunk* ch) const {
#if DIFFDYN_LAYER_KERNEL
    constexpr int kB = kLayerBlock;
    const int nb = static_cast<int>(x.cols());
    const int L = arch_.num_layers();
    B* const first = ch->block.data();
    B* const second = first + Eigen::Index(arch_.max_width()) * kB;
    int* const rows_first = ch->rows.data();
    int* const rows_second = rows_first + arch_.max_width();
    for (int s0 = 0; s0 < nb; s0 += kB) {
      const int ns = std::min(kB, nb - s0);
      ToFeatureMajor(x, s0, ns, first);
      B* in = first;
      B* out = second;
      int* in_rows = rows_first;
      int* out_rows = rows_second;
      int n_in = num_inputs();
      for (int i = 0; i < n_in; ++i) in_rows[i] = i;
      for (int l = 0; l < L; ++l) {
        const int rows = arch_.sizes[l + 1];
        const bool hidden = l + 1 < L;
        const bool relu = hidden && arch_.activations[l].kind == ActivationKind::kRelu;
        n_in = internal::LayerBlock(W(l).data(), rows, b(l).data(), in, in_rows, n_in, relu, out,
                                    out_rows);
        if (hidden && !relu) {
          ApplyActivation(arch_.activations[l], out, Eigen::Index(rows) * kB, out, nullptr,
                          nullptr);
        }
        std::swap(in, out);
        std::swap(in_rows, out_rows);
      }
      FromFeatureMajor(in, s0, ns, y);
    }
#endif
  }

  // Columns [s0, s0 + ns) of x (ns <= kLayerBlock) into the feature-major block
  // (row stride kLayerBlock), zero-padded to kLayerBlock samples.
  template <typename XBlock>
  static void ToFeatureMajor(const XBlock& x, int s0, int ns, B* block) {
    for (Eigen::Index i = 0; i < x.rows(); ++i) {
      B* row = block + i * kLayerBlock;
      for (int s = 0; s < ns; ++s) row[s] = x(i, s0 + s);
      std::fill(row + ns, row + kLayerBlock, B(0));
    }
  }

  // The first ns samples of a feature-major block into columns [s0, s0 + ns) of y.
  template <typename YBlock>
  static void FromFeatureMajor(const B* block, int s0, int ns, YBlock&& y) {
    for (int s = 0; s < ns; ++s) {
      for (Eigen::Index i = 0; i < y.rows(); ++i) y(i, s0 + s) = block[i * kLayerBlock + s];
    }
  }

  // InputJacobianReverse with the layer kernel (L >= 2, kUseLayerKernel): per block of
  // kLayerBlock samples, feature-major, the forward pass keeps each hidden layer's
  // g'(a_l) (sum of hidden widths x kLayerBlock), then each output k's sweep runs
  //   abar_{L-2} = W_{L-1}^T e_k .* g'(a_{L-2}),
  //   abar_{l-1} = (W_l^T abar_l) .* g'(a_{l-1}),  l = L-2 .. 1,   dy_k/dx = W_0^T abar_0,
  // through LayerBlock on transposed copies of the weights (zero bias): nothing is
  // packed and every sample's sums run in the same order whatever the chunking.
  void InputJacobianByBlocks(const MatrixB& X, MatrixB* Y, MatrixB* jac, Workspace* ws,
                             int threads) const {
    constexpr int kB = kLayerBlock;
    const int L = arch_.num_layers();
    const int width = arch_.max_width();
    // W_l^T, l = 0 .. L-2, then zeros (the sweeps' bias), shared by the chunks.
    Eigen::Index transposed_size = width;
    for (int l = 0; l + 1 < L; ++l) transposed_size += Eigen::Index(arch_.sizes[l]) * arch_.sizes[l + 1];
    if (ws->transposed_.size() < transposed_size) ws->transposed_.resize(transposed_size);
    B* wt = ws->transposed_.data();
    for (int l = 0; l + 1 < L; ++l) {
      internal::TransposeInto<B>(arch_.sizes[l + 1], arch_.sizes[l], W(l).data(),
                                 arch_.sizes[l + 1], wt);
      wt += Eigen::Index(arch_.sizes[l]) * arch_.sizes[l + 1];
    }
    std::fill(wt, wt + width, B(0));
    // Per chunk: two blocks to run the layers between, then the hidden g' blocks.
    Eigen::Index hidden = 0;
    for (int l = 0; l + 1 < L; ++l) hidden += arch_.sizes[l + 1];
    const Eigen::Index block_size = (Eigen::Index(2) * width + hidden) * kB;
    const int batch = static_cast<int>(X.cols());
    // rows[0 .. width) = 0 .. width-1: every input row of a layer is summed.
    for (int c = 0; c < NumChunks(batch, ws->chunk_size()); ++c) {
      typename Workspace::Chunk& ch = ws->chunks_[c];
      if (ch.block.size() < block_size) ch.block.resize(block_size);
      if (static_cast<int>(ch.rows.size()) < 2 * width) ch.rows.resize(std::size_t(2) * width);
      std::iota(ch.rows.begin(), ch.rows.begin() + width, 0);
    }
    const B* zero_bias = wt;
    ParallelForChunks(batch, ws->chunk_size(), threads, [&](int c, int begin, int end) {
      typename Workspace::Chunk& ch = ws->chunks_[c];
      for (int s0 = begin; s0 < end; s0 += kB) {
        JacobianBlock(X, s0, std::min(kB, end - s0), zero_bias, Y, jac, &ch);
      }
    });
  }

  // One block of InputJacobianByBlocks: samples [s0, s0 + ns), ns <= kLayerBlock.
  // zero_bias: the workspace's max_width zeros, right after the last W_l^T copy.
  void JacobianBlock([[maybe_unused]] const MatrixB& X, [[maybe_unused]] int s0,
                     [[maybe_unused]] int ns, [[maybe_unused]] const B* zero_bias,
                     [[maybe_unused]] MatrixB* Y, [[maybe_unused]] MatrixB* jac,
                     [[maybe_unused]] typename Workspace::Chunk* ch) const {
#if DIFFDYN_LAYER_KERNEL
    constexpr int kB = kLayerBlock;
    const int L = arch_.num_layers();
    const int width = arch_.max_width();
    const int n0 = num_inputs();
    B* in = ch->block.data();
    B* out = in + Eigen::Index(width) * kB;
    B* const dg = out + Eigen::Index(width) * kB;
    const int* const all_rows = ch->rows.data();  // 0 .. width-1 (InputJacobianByBlocks)
    int* const sink = ch->rows.data() + width;     // LayerBlock's live rows, unused here
    // Forward: h_{l+1} = g(W_l h_l + b_l), g' kept.
    ToFeatureMajor(X, s0, ns, in);
    B* dg_l = dg;
    for (int l = 0; l < L; ++l) {
      const int rows = arch_.sizes[l + 1];
      internal::LayerBlock(W(l).data(), rows, b(l).data(), in, all_rows, arch_.sizes[l], false,
                           out, sink);
      if (l + 1 < L) {
        ApplyActivation(arch_.activations[l], out, Eigen::Index(rows) * kB, out, dg_l, nullptr);
        dg_l += Eigen::Index(rows) * kB;
      }
      std::swap(in, out);
    }
    FromFeatureMajor(in, s0, ns, *Y);
    // The sweeps, one output at a time, walking the g' blocks (dg_l is past the last)
    // and the W_l^T copies (which end at zero_bias) backwards.
    const int m = num_outputs();
    for (int k = 0; k < m; ++k) {
      // abar_{L-2} = W_{L-1}(k, :)^T .* g'(a_{L-2}).
      const int last = arch_.sizes[L - 1];
      const B* dg_last = dg_l - Eigen::Index(last) * kB;
      for (int i = 0; i < last; ++i) {
        const B w = W(L - 1)(k, i);
        for (int s = 0; s < kB; ++s) in[i * kB + s] = w * dg_last[i * kB + s];
      }
      const B* dg_prev = dg_last;
      const B* wt_l = zero_bias;
      for (int l = L - 2; l >= 0; --l) {
        const int rows = arch_.sizes[l];
        wt_l -= Eigen::Index(rows) * arch_.sizes[l + 1];
        internal::LayerBlock(wt_l, rows, zero_bias, in, all_rows, arch_.sizes[l + 1], false, out,
                             sink);
        if (l >= 1) {
          dg_prev -= Eigen::Index(rows) * kB;
          for (Eigen::Index e = 0; e < Eigen::Index(rows) * kB; ++e) out[e] *= dg_prev[e];
        }
        std::swap(in, out);
      }
      // dy_k/dx_j of sample s is in[j * kB + s]; J's column of sample s, input j is s n0 + j.
      for (int s = 0; s < ns; ++s) {
        for (int j = 0; j < n0; ++j) (*jac)(k, Eigen::Index(s0 + s) * n0 + j) = in[j * kB + s];
      }
    }
#endif
  }

  // out = W_l^T abar. W_l is transposed into the chunk's buffer first where Gemm
  // has its panel kernel (which takes A untransposed; the copy of a 100 x 100 W
  // costs some 0.6 us in float, 1.6 in double, against 27 and 55 us for the
  // product of 250 samples), and
  // elsewhere if W_l is thin (a side of at most kThinSide): BLAS runs the plain
  // product of the copy up to 2.5x faster than the transposed one for these
  // shapes (6 x 100 times 6 x 250).
  // `stages` (none by default) are applied as the product is stored (GemmFused).
  template <typename ABlock, typename OutBlock>
  void GemmTransposedWeight(int l, const ABlock& abar, OutBlock&& out,
                            typename Workspace::Chunk* buf,
                            const GemmOutput<B>& stages = GemmOutput<B>{}) const {
    const int rows = arch_.sizes[l + 1];
    const int cols = arch_.sizes[l];
    if (!kHavePanelGemm && std::min(rows, cols) > Workspace::kThinSide) {
      GemmFused(W(l), true, abar, false, stages, out);
      return;
    }
    internal::TransposeInto<B>(rows, cols, W(l).data(), rows, buf->weight_t.data());
    const Eigen::Map<const MatrixB> wt(buf->weight_t.data(), cols, rows);
    GemmFused(wt, false, abar, false, stages, out);
  }

  // Reverse sweep over one chunk of nb samples starting at `begin`.
  // Backward / BackwardAccumulate: grad (num_parameters() entries, or null) is
  // overwritten, or added to if `accumulate`.
  template <typename GyMatrix>
  void BackwardImpl(const GyMatrix& gy, const MatrixB& gjac, B* grad, bool accumulate,
                    MatrixB* grad_inputs, Workspace* ws, int threads,
                    Workspace* scratch = nullptr) const {
    DIFFDYN_CHECK(ws != nullptr, "Mlp::Backward needs a workspace");
    DIFFDYN_CHECK(ws->batch_ >= 0, "Mlp::Backward needs a Forward on this workspace; its last ",
                  "pass was Evaluate, which keeps no tape");
    if (scratch == nullptr) scratch = ws;
    const int batch = ws->batch_;
    const int n0 = num_inputs();
    const bool has_gy = gy.size() > 0;
    const bool has_gj = gjac.size() > 0;
    DIFFDYN_CHECK(!has_gy || (gy.rows() == num_outputs() && gy.cols() == batch),
                  "Mlp::Backward: output cotangent is ", gy.rows(), " x ", gy.cols(),
                  ", expected ", num_outputs(), " x ", batch);
    DIFFDYN_CHECK(!has_gj || (gjac.rows() == num_outputs() &&
                              gjac.cols() == Eigen::Index(n0) * batch),
                  "Mlp::Backward: Jacobian cotangent is ", gjac.rows(), " x ", gjac.cols(),
                  ", expected ", num_outputs(), " x ", Eigen::Index(n0) * batch);
    DIFFDYN_CHECK(!has_gj || batch == 0 || ws->chunks_[0].has_jacobian,
                  "Mlp::Backward: a Jacobian cotangent needs Forward with a Jacobian");
    if (grad_inputs && (grad_inputs->rows() != n0 || grad_inputs->cols() != batch)) {
      grad_inputs->resize(n0, batch);
    }
    const Eigen::Index p = num_parameters();
    const int chunks = NumChunks(batch, ws->chunk_size());
    // One chunk writes straight into grad; several write their own slots.
    const bool direct = chunks <= 1;
    if (scratch != ws) {
      DIFFDYN_CHECK(scratch->chunk_size() >= ws->chunk_size(), "Mlp::Backward: scratch chunk size ",
                    scratch->chunk_size(), " is below the workspace's ", ws->chunk_size());
      scratch->Reserve(arch_, chunks * scratch->chunk_size(), false);
    }
    ParallelForChunks(batch, ws->chunk_size(), threads, [&](int c, int begin, int end) {
      typename Workspace::Chunk& buf = scratch->chunks_[c];
      BackwardChunk(has_gy ? &gy : nullptr, has_gj ? &gjac : nullptr, begin, end - begin,
                    grad != nullptr, direct && grad ? grad : buf.grad.data(), direct && accumulate,
                    grad_inputs, &ws->chunks_[c], &buf);
    });
    if (grad == nullptr) return;
    Eigen::Map<VectorB> g(grad, p);
    if (!accumulate && (batch == 0 || !direct)) g.setZero();
    // Chunk gradients summed in chunk order: identical at any thread count.
    if (!direct) {
      for (int c = 0; c < chunks; ++c) g += scratch->chunks_[c].grad;
    }
  }

  // Parameter gradients go to grad_out (num_parameters()), added if `accumulate`.
  // ch holds the forward pass; buf the cotangents abar (may be ch).
  template <typename GyMatrix>
  void BackwardChunk(const GyMatrix* gy, const MatrixB* gjac, int begin, int nb,
                     bool want_params, B* grad_out, bool accumulate,
                     MatrixB* grad_inputs, typename Workspace::Chunk* ch,
                     typename Workspace::Chunk* buf) const {
    const int L = arch_.num_layers();
    const int n0 = num_inputs();
    const Eigen::Index nz = Eigen::Index(n0) * nb;
    int cur = 0;
    const int m = num_outputs();
    auto abar = [&](int which, int rows) { return buf->abar[which].topLeftCorner(rows, nb); };
    auto ubar = [&](int which, int rows) { return ch->ubar[which].topLeftCorner(rows, nz); };
    if (gy) {
      abar(cur, m) = gy->middleCols(begin, nb);
    } else {
      abar(cur, m).setZero();
    }
    if (gjac) ubar(cur, m) = gjac->middleCols(Eigen::Index(begin) * n0, nz);
    for (int l = L - 1; l >= 0; --l) {
      const int rows = arch_.sizes[l + 1];
      const int cols = arch_.sizes[l];
      const int nxt = 1 - cur;
      // Whether layer l-1's g' is ReLU's, read off h_l.
      const bool relu_mask = l > 0 && DerivativeFromOutput(*ch, l - 1);
      // Cotangents of layer l-1: abar' = (W^T abar) .* g' (for l = 0 the input gradient).
      auto input_cotangent = [&] {
        if (l > 0) {
          auto next_abar = abar(nxt, cols);
          if (relu_mask) {
            // ReLU's g' = [h_l > 0] applied as the product is stored.
            const auto h = ch->h[l].leftCols(nb);
            GemmTransposedWeight(l, abar(cur, rows), next_abar, buf,
                                 GemmOutput<B>{nullptr, false, h.data(), h.outerStride()});
          } else {
            GemmTransposedWeight(l, abar(cur, rows), next_abar, buf);
            next_abar.array() *= ch->dg[l - 1].leftCols(nb).array();
          }
        } else if (grad_inputs) {
          GemmTransposedWeight(0, abar(cur, rows), grad_inputs->middleCols(begin, nb), buf);
        }
      };
      // Parameter gradients of layer l: dW += abar h_l^T, db += abar 1.
      auto parameter_gradient = [&] {
        if (!want_params) return;
        Eigen::Map<MatrixB> gw(grad_out + arch_.WeightOffset(l), rows, cols);
        Eigen::Map<VectorB> gb(grad_out + arch_.BiasOffset(l), rows);
        if (!accumulate) {
          gw.setZero();
          gb.setZero();
        }
        Gemm(1.0, abar(cur, rows), false, ch->h[l].leftCols(nb), true, 1.0, gw);
        gb += abar(cur, rows).rowwise().sum();
        if (gjac) {
          if (l == 0) {
            for (int bb = 0; bb < nb; ++bb) gw += ubar(cur, rows).middleCols(Eigen::Index(bb) * n0, n0);
          } else {
            Gemm(1.0, ubar(cur, rows), false, ch->z[l].topLeftCorner(cols, nz), true, 1.0, gw);
          }
        }
      };
      // Whichever pass reads h_l first brings it into the cache for the other. A ReLU
      // mask reads h_l as one contiguous stream, so it goes first: the weight-gradient
      // product's transposed packing of h_l runs at half speed when h_l is cold (as on
      // a solver's tape, written long before). Otherwise the product goes first.
      if (relu_mask) {
        input_cotangent();
        parameter_gradient();
      } else {
        parameter_gradient();
        input_cotangent();
      }
      if (l == 0) break;
      // Jacobian cotangents of layer l-1: zbar = W^T ubar, and their share of abar'.
      if (gjac) {
        auto zbar = ch->zbar.topLeftCorner(cols, nz);
        Gemm(1.0, W(l), true, ubar(cur, rows), false, 0.0, zbar);
        const auto u_prev = ch->u[l - 1].topLeftCorner(cols, nz);
        auto dbar = ch->dbar.topLeftCorner(cols, nb);
        auto next_ubar = ubar(nxt, cols);
        for (int bb = 0; bb < nb; ++bb) {
          const Eigen::Index c0 = Eigen::Index(bb) * n0;
          dbar.col(bb) = zbar.middleCols(c0, n0).cwiseProduct(u_prev.middleCols(c0, n0)).rowwise().sum();
          next_ubar.middleCols(c0, n0) =
              zbar.middleCols(c0, n0).array().colwise() * ch->dg[l - 1].col(bb).array();
        }
        abar(nxt, cols) += dbar.cwiseProduct(ch->ddg[l - 1].leftCols(nb));
      }
      cur = nxt;
    }
  }

  MlpArchitecture arch_;
  VectorT params_;
};

}  // namespace diffdyn
