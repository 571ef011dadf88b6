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
// Built only where the compiler targets AVX-512 (kHaveLayerKernel); elsewhere
// Mlp::Evaluate runs the BLAS products of Mlp::Forward instead.
//
//   double h[6 * kLayerBlock], c[100 * kLayerBlock];                // feature-major blocks
//   internal::LayerBlock(W.data(), 100, 6, b.data(), h, true, c);   // c = relu(W h + b)
#pragma once

namespace diffdyn {

#if defined(__AVX512F__) && defined(__GNUC__)
/// Whether LayerBlock is built (AVX-512 targets with GCC-style vectors).
inline constexpr bool kHaveLayerKernel = true;
#else
inline constexpr bool kHaveLayerKernel = false;
#endif

/// Samples per feature-major block of LayerBlock (4 vectors of 8 doubles).
inline constexpr int kLayerBlock = 32;

#if defined(__AVX512F__) && defined(__GNUC__)
namespace internal {

/// Doubles per SIMD vector.
inline constexpr int kLayerLanes = 8;
/// Output units per register tile: 5 x 4 accumulators of the 32 registers.
inline constexpr int kLayerRows = 5;

using LayerVec = double __attribute__((vector_size(kLayerLanes * sizeof(double))));
// The same vector at any double alignment, for loads and stores.
using LayerVecU = double __attribute__((vector_size(kLayerLanes * sizeof(double)), aligned(8),
                                         may_alias));

// Rows [0, R) of C = g(W H + b) for one block; w, b and c point at the tile's
// first row (w's columns keep the stride ldw).
template <int R, bool kRelu>
inline void LayerTile(const double* w, int ldw, int k, const double* b, const double* h,
                      double* c) {
  constexpr int kVecs = kLayerBlock / kLayerLanes;
  LayerVec acc[R][kVecs];
  for (int r = 0; r < R; ++r) {
    for (int v = 0; v < kVecs; ++v) acc[r][v] = LayerVec{} + b[r];
  }
  // k >= 1 (layer widths are positive): a do-while keeps the accumulators in
  // registers from the start (with a zero-trip path GCC parks them on the stack).
  int j = 0;
  do {
    LayerVec x[kVecs];
    for (int v = 0; v < kVecs; ++v) {
      x[v] = *reinterpret_cast<const LayerVecU*>(h + j * kLayerBlock + v * kLayerLanes);
    }
    for (int r = 0; r < R; ++r) {
      const double wr = w[j * ldw + r];
      for (int v = 0; v < kVecs; ++v) acc[r][v] += wr * x[v];
    }
  } while (++j < k);
  for (int r = 0; r < R; ++r) {
    for (int v = 0; v < kVecs; ++v) {
      LayerVec a = acc[r][v];
      if constexpr (kRelu) a = a > 0.0 ? a : 0.0;
      *reinterpret_cast<LayerVecU*>(c + r * kLayerBlock + v * kLayerLanes) = a;
    }
  }
}

template <bool kRelu>
inline void LayerRows(const double* w, int m, int k, const double* b, const double* h,
                      double* c) {
  int i = 0;
  for (; i + kLayerRows <= m; i += kLayerRows) {
    LayerTile<kLayerRows, kRelu>(w + i, m, k, b + i, h, c + i * kLayerBlock);
  }
  const double* wi = w + i;
  double* ci = c + i * kLayerBlock;
  switch (m - i) {
    case 1: LayerTile<1, kRelu>(wi, m, k, b + i, h, ci); break;
    case 2: LayerTile<2, kRelu>(wi, m, k, b + i, h, ci); break;
    case 3: LayerTile<3, kRelu>(wi, m, k, b + i, h, ci); break;
    case 4: LayerTile<4, kRelu>(wi, m, k, b + i, h, ci); break;
    default: break;
  }
}

/// One layer on one block: c = g(W h + b) with g = ReLU if `relu`, else the
/// identity. W is m x k column-major (leading dimension m, k >= 1), b has m entries,
/// h is k x kLayerBlock and c is m x kLayerBlock, both feature-major (row
/// stride kLayerBlock); c must not overlap h.
inline void LayerBlock(const double* w, int m, int k, const double* b, const double* h, bool relu,
                       double* c) {
  if (relu) {
    LayerRows<true>(w, m, k, b, h, c);
  } else {
    LayerRows<false>(w, m, k, b, h, c);
  }
}

}  // namespace internal
#endif

}  // namespace diffdyn
