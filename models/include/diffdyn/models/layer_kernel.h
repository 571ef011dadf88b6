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
// is computed in register tiles of kLayerRows units x kLayerBlock samples: per
// input unit one vector load per kLayerBlock / kLayerLanes samples and one
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
// Built only where the compiler targets AVX-512 (kHaveLayerKernel); elsewhere
// Mlp::Evaluate runs the BLAS products of Mlp::Forward instead.
//
//   double h[6 * kLayerBlock], c[100 * kLayerBlock];     // feature-major blocks
//   int in[6] = {0, 1, 2, 3, 4, 5}, live[100];            // the inputs used; c's live rows
//   int n_live = internal::LayerBlock(W.data(), 100, b.data(), h, in, 6, true, c, live);
//   // c = relu(W h + b); rows live[0 .. n_live) may be nonzero, the others are 0
#pragma once

namespace diffdyn {

// 1 where LayerBlock is built (AVX-512 targets with GCC-style vectors), else 0;
// code that calls LayerBlock must sit under #if DIFFDYN_LAYER_KERNEL.
#if defined(__AVX512F__) && defined(__GNUC__)
#define DIFFDYN_LAYER_KERNEL 1
#else
#define DIFFDYN_LAYER_KERNEL 0
#endif

/// Whether LayerBlock is built (AVX-512 targets with GCC-style vectors).
inline constexpr bool kHaveLayerKernel = DIFFDYN_LAYER_KERNEL != 0;

/// Samples per feature-major block of LayerBlock (4 vectors of 8 doubles).
inline constexpr int kLayerBlock = 32;

#if DIFFDYN_LAYER_KERNEL
namespace internal {

/// Doubles per SIMD vector.
inline constexpr int kLayerLanes = 8;
/// Output units per register tile: 5 x 4 accumulators of the 32 registers.
inline constexpr int kLayerRows = 5;

using LayerVec = double __attribute__((vector_size(kLayerLanes * sizeof(double))));
// The same vector at any double alignment, for loads and stores.
using LayerVecU = double __attribute__((vector_size(kLayerLanes * sizeof(double)), aligned(8),
                                         may_alias));

// Rows [0, R) of C = g(W H + b) for one block, summing over the input rows
// rows[0 .. n) (n >= 1); w, b and c point at the tile's first row (w's columns
// keep the stride ldw). Appends the tile's rows that hold a positive value (all
// rows without ReLU), as first + r, to live; returns their count.
template <int R, bool kRelu>
inline int LayerTile(const double* w, int ldw, const int* rows, int n, const double* b,
                     const double* h, double* c, int first, int* live) {
  constexpr int kVecs = kLayerBlock / kLayerLanes;
  LayerVec acc[R][kVecs];
  for (int r = 0; r < R; ++r) {
    for (int v = 0; v < kVecs; ++v) acc[r][v] = LayerVec{} + b[r];
  }
  // n >= 1: a do-while keeps the accumulators in registers from the start (with a
  // zero-trip path GCC parks them on the stack).
  int q = 0;
  do {
    const int j = rows[q];
    LayerVec x[kVecs];
    for (int v = 0; v < kVecs; ++v) {
      x[v] = *reinterpret_cast<const LayerVecU*>(h + j * kLayerBlock + v * kLayerLanes);
    }
    for (int r = 0; r < R; ++r) {
      const double wr = w[j * ldw + r];
      for (int v = 0; v < kVecs; ++v) acc[r][v] += wr * x[v];
    }
  } while (++q < n);
  int count = 0;
  for (int r = 0; r < R; ++r) {
    LayerVec any{};
    for (int v = 0; v < kVecs; ++v) {
      LayerVec a = acc[r][v];
      if constexpr (kRelu) {
        a = a > 0.0 ? a : 0.0;
        any = any > a ? any : a;
      }
      *reinterpret_cast<LayerVecU*>(c + r * kLayerBlock + v * kLayerLanes) = a;
    }
    bool positive = !kRelu;
    if constexpr (kRelu) {
      for (int e = 0; e < kLayerLanes; ++e) positive = positive || any[e] > 0.0;
    }
    if (positive) live[count++] = first + r;
  }
  return count;
}

template <bool kRelu>
inline int LayerRows(const double* w, int m, const int* rows, int n, const double* b,
                     const double* h, double* c, int* live) {
  int count = 0;
  int i = 0;
  for (; i + kLayerRows <= m; i += kLayerRows) {
    count += LayerTile<kLayerRows, kRelu>(w + i, m, rows, n, b + i, h, c + i * kLayerBlock, i,
                                          live + count);
  }
  const double* wi = w + i;
  double* ci = c + i * kLayerBlock;
  int* li = live + count;
  switch (m - i) {
    case 1: count += LayerTile<1, kRelu>(wi, m, rows, n, b + i, h, ci, i, li); break;
    case 2: count += LayerTile<2, kRelu>(wi, m, rows, n, b + i, h, ci, i, li); break;
    case 3: count += LayerTile<3, kRelu>(wi, m, rows, n, b + i, h, ci, i, li); break;
    case 4: count += LayerTile<4, kRelu>(wi, m, rows, n, b + i, h, ci, i, li); break;
    default: break;
  }
  return count;
}

/// One layer on one block: c = g(W h + b) with g = ReLU if `relu`, else the
/// identity, where the sum W h runs over the input rows rows[0 .. n) only, in
/// increasing order: the caller guarantees that every other row of h is zero for
/// all kLayerBlock samples (pass 0 .. k-1 when it does not know). W is m x k
/// column-major (leading dimension m), b has m entries, h is k x kLayerBlock and c
/// is m x kLayerBlock, both feature-major (row stride kLayerBlock); c must not
/// overlap h. Writes to live (m entries) the rows of c, in increasing order, that
/// may be nonzero (with ReLU those with a positive value, else all) and returns
/// their count, ready to be the next layer's `rows`.
inline int LayerBlock(const double* w, int m, const double* b, const double* h, const int* rows,
                      int n, bool relu, double* c, int* live) {
  // No input row left means h is zero: row 0 then adds w * 0, leaving c = g(b).
  static constexpr int kZeroRow[1] = {0};
  if (n == 0) {
    rows = kZeroRow;
    n = 1;
  }
  return relu ? LayerRows<true>(w, m, rows, n, b, h, c, live)
              : LayerRows<false>(w, m, rows, n, b, h, c, live);
}

}  // namespace internal
#endif

}  // namespace diffdyn
