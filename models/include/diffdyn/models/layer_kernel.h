// Register-blocked dense layer for the values-only MLP pass (Mlp::Evaluate).
//
// A values-only pass (MPPI rollouts, evaluation, the untaped stages of an ODE
// solve) needs no tape, so it can keep a block of samples on chip through all
// layers. The activations of a block are held feature-major, kLayerBlock
// samples contiguous per unit,
//
//   H (k x kLayerBlock, row stride kLayerBlock):  H[i * kLayerBlock + s] = h_i of sample s,
//
// so one SIMD vector holds one unit of several samples, and a layer
//
//   C = g(W H + b),   W m x k column-major (leading dimension m), b of size m,
//
// is computed in register tiles of LayerShape::kRows units x kLayerBlock samples: per
// input unit one vector load per LayerShape::kLanes samples and one
// broadcast weight per output unit, with the bias as the accumulators' start
// and ReLU applied before the single store. Nothing is packed and no pass over
// memory is spent on the bias or the activation. Every sample's sum is taken
// in the same order (k = 0, 1, ...) whatever the block, chunk or thread count.
//
// Inactive units are skipped: a ReLU layer reports which of its units are
// positive for at least one sample of the block, and the next layer's sum runs
// over those inputs only. A unit that is zero for the whole block adds w * 0 to
// every sum, so skipping it leaves every value unchanged (up to the sign of a
// zero) and saves its column of multiply-adds (10-30 % of a trained ReLU
// network's middle layer for MPPI's blocks, whose samples share a start state).
//
// Built for double and float where the compiler targets AVX-512 (32 vector
// registers of 64 bytes) or AVX2 with FMA (16 of 32 bytes) (kHaveLayerKernel);
// elsewhere Mlp::Evaluate runs the BLAS products of Mlp::Forward instead. A tile
// is R units x V vectors of samples (LayerShape): R V accumulators, V inputs and
// a broadcast weight fit the register file; where V vectors hold fewer than
// kLayerBlock samples (AVX2: 8 doubles or 16 floats of 32), the tile runs over
// the block's sample groups in turn.
//
//   double h[6 * kLayerBlock], c[100 * kLayerBlock];     // feature-major blocks
//   int in[6] = {0, 1, 2, 3, 4, 5}, live[100];            // the inputs used; c's live rows
//   int n_live = internal::LayerBlock(W.data(), 100, b.data(), h, in, 6, true, c, live);
//   // c = relu(W h + b); rows live[0 .. n_live) may be nonzero, the others are 0
#pragma once

#include <algorithm>
#include <type_traits>

namespace diffdyn {

// 1 where LayerBlock is built (AVX-512, or AVX2 with FMA, with GCC-style vectors),
// else 0; code that calls LayerBlock must sit under #if DIFFDYN_LAYER_KERNEL.
#if defined(__GNUC__) && (defined(__AVX512F__) || (defined(__AVX2__) && defined(__FMA__)))
#define DIFFDYN_LAYER_KERNEL 1
#else
#define DIFFDYN_LAYER_KERNEL 0
#endif

/// Whether LayerBlock is built (AVX-512, or AVX2 with FMA).
inline constexpr bool kHaveLayerKernel = DIFFDYN_LAYER_KERNEL != 0;

/// Samples per feature-major block of LayerBlock.
inline constexpr int kLayerBlock = 32;

#if DIFFDYN_LAYER_KERNEL
namespace internal {

#if defined(__AVX512F__)
/// Bytes per SIMD vector and vector registers of the target.
inline constexpr int kLayerVectorBytes = 64;
inline constexpr int kLayerRegisters = 32;
#else
inline constexpr int kLayerVectorBytes = 32;
inline constexpr int kLayerRegisters = 16;
#endif

// The SIMD vector of S (Vec) and the same vector at any element alignment, for
// loads and stores (VecU).
template <typename S>
struct LayerVectors;
template <>
struct LayerVectors<double> {
  using Vec = double __attribute__((vector_size(kLayerVectorBytes)));
  using VecU = double __attribute__((vector_size(kLayerVectorBytes), aligned(alignof(double)), may_alias));
};
template <>
struct LayerVectors<float> {
  using Vec = float __attribute__((vector_size(kLayerVectorBytes)));
  using VecU = float __attribute__((vector_size(kLayerVectorBytes), aligned(alignof(float)), may_alias));
};

/// The register tile of scalar S (double or float): kLanes samples per vector,
/// kVecs vectors (kVecs kLanes samples) per sample group, kGroups groups per
/// block, kRows units per tile (at most 5; R kVecs + kVecs + 1 <= registers).
/// AVX-512: 4 vectors x 5 rows (double, one group). AVX2: 2 vectors x 5 rows, the
/// faster of the shapes tried on a Zen AVX2 core for 6-100-100-6 ReLU, 1000
/// samples, one thread (best of 15 x 50 calls): double 610-640 us against 680-1170
/// us with 4 vectors x 2 rows and 730-890 us through OpenBLAS; float 310 us against
/// 400-525 us through OpenBLAS.
template <typename S>
struct LayerShape {
  static_assert(std::is_same_v<S, double> || std::is_same_v<S, float>);
  static constexpr int kLanes = kLayerVectorBytes / static_cast<int>(sizeof(S));
  static constexpr int kVecs = std::min(kLayerBlock / kLanes, kLayerRegisters == 32 ? 4 : 2);
  static constexpr int kGroups = kLayerBlock / (kVecs * kLanes);
  static constexpr int kRows = std::min(5, (kLayerRegisters - kVecs - 1) / kVecs);
};

// Rows [0, R) of C = g(W H + b) for one block, summing over the input rows
// rows[0 .. n) (n >= 1), one sample group after the other; w, b and c point at
// the tile's first row (w's columns keep the stride ldw). Appends the tile's rows
// that hold a positive value in any sample (all rows without ReLU), as first + r,
// to live; returns their count.
template <typename S, int R, bool kRelu>
inline int LayerTile(const S* w, int ldw, const int* rows, int n, const S* b, const S* h, S* c,
                     int first, int* live) {
  using Shape = LayerShape<S>;
  using Vec = typename LayerVectors<S>::Vec;
  using VecU = typename LayerVectors<S>::VecU;
  constexpr int kVecs = Shape::kVecs, kLanes = Shape::kLanes;
  bool positive[R];
  for (int r = 0; r < R; ++r) positive[r] = !kRelu;
  for (int g = 0; g < Shape::kGroups; ++g) {
    const int s0 = g * kVecs * kLanes;
    Vec acc[R][kVecs];
    for (int r = 0; r < R; ++r) {
      for (int v = 0; v < kVecs; ++v) acc[r][v] = Vec{} + b[r];
    }
    // n >= 1: a do-while keeps the accumulators in registers from the start (with a
    // zero-trip path GCC parks them on the stack).
    int q = 0;
    do {
      const int j = rows[q];
      Vec x[kVecs];
      for (int v = 0; v < kVecs; ++v) {
        x[v] = *reinterpret_cast<const VecU*>(h + j * kLayerBlock + s0 + v * kLanes);
      }
      for (int r = 0; r < R; ++r) {
        const S wr = w[j * ldw + r];
        for (int v = 0; v < kVecs; ++v) acc[r][v] += wr * x[v];
      }
    } while (++q < n);
    for (int r = 0; r < R; ++r) {
      Vec any{};
      for (int v = 0; v < kVecs; ++v) {
        Vec a = acc[r][v];
        if constexpr (kRelu) {
          a = a > S(0) ? a : S(0);
          any = any > a ? any : a;
        }
        *reinterpret_cast<VecU*>(c + r * kLayerBlock + s0 + v * kLanes) = a;
      }
      if constexpr (kRelu) {
        for (int e = 0; e < kLanes; ++e) positive[r] = positive[r] || any[e] > S(0);
      }
    }
  }
  int count = 0;
  for (int r = 0; r < R; ++r) {
    if (positive[r]) live[count++] = first + r;
  }
  return count;
}

// The last `left` (< R) rows of a layer: LayerTile of exactly that height.
template <typename S, int R, bool kRelu>
inline int LayerTail(int left, const S* w, int ldw, const int* rows, int n, const S* b, const S* h,
                     S* c, int first, int* live) {
  if constexpr (R == 0) {
    return 0;
  } else {
    if (left == R) return LayerTile<S, R, kRelu>(w, ldw, rows, n, b, h, c, first, live);
    return LayerTail<S, R - 1, kRelu>(left, w, ldw, rows, n, b, h, c, first, live);
  }
}

template <typename S, bool kRelu>
inline int LayerRows(const S* w, int m, const int* rows, int n, const S* b, const S* h, S* c,
                     int* live) {
  constexpr int kRows = LayerShape<S>::kRows;
  int count = 0;
  int i = 0;
  for (; i + kRows <= m; i += kRows) {
    count += LayerTile<S, kRows, kRelu>(w + i, m, rows, n, b + i, h, c + i * kLayerBlock, i,
                                        live + count);
  }
  return count + LayerTail<S, kRows - 1, kRelu>(m - i, w + i, m, rows, n, b + i, h,
                                                c + i * kLayerBlock, i, live + count);
}

/// One layer on one block: c = g(W h + b) with g = ReLU if `relu`, else the
/// identity, where the sum W h runs over the input rows rows[0 .. n) only, in
/// increasing order: the caller guarantees that every other row of h is zero for
/// all kLayerBlock samples (pass 0 .. k-1 when it does not know). S is double or
/// float. W is m x k column-major (leading dimension m), b has m entries, h is
/// k x kLayerBlock and c is m x kLayerBlock, both feature-major (row stride
/// kLayerBlock); c must not overlap h. Writes to live (m entries) the rows of c,
/// in increasing order, that may be nonzero (with ReLU those with a positive
/// value, else all) and returns their count, ready to be the next layer's `rows`.
template <typename S>
inline int LayerBlock(const S* w, int m, const S* b, const S* h, const int* rows, int n, bool relu,
                      S* c, int* live) {
  // No input row left means h is zero: row 0 then adds w * 0, leaving c = g(b).
  static constexpr int kZeroRow[1] = {0};
  if (n == 0) {
    rows = kZeroRow;
    n = 1;
  }
  return relu ? LayerRows<S, true>(w, m, rows, n, b, h, c, live)
              : LayerRows<S, false>(w, m, rows, n, b, h, c, live);
}

}  // namespace internal
#endif

}  // namespace diffdyn
