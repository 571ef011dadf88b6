// Dense float and double matrix products for the batched network paths.
//
// The batched MLP passes are a handful of matrix products per layer (for a
// 6-100-100-6 network and a chunk of 256 samples, 100 x 100 times 100 x 256).
// On x86 CPUs with AVX-512 an optimised BLAS runs these shapes 20-50 % faster
// than Eigen's own product kernels, so when the build found a BLAS (CMake
// option DIFFDYN_USE_BLAS, on by default; OpenBLAS preferred) Gemm calls its
// dgemm (double operands) or sgemm (float operands); otherwise it falls back to
// Eigen. Either way:
//
//   auto c = workspace.topLeftCorner(m, n);             // any column-major block
//   diffdyn::Gemm(1.0, W, /*transpose_a=*/false, h, false, 0.0, c);   // c = W h
//
// Operands are column-major with unit inner stride, all of one scalar type
// (double or float): MatrixXd or MatrixXf, their blocks
// (leftCols, middleCols, topLeftCorner, ...) and Maps of them.
//
// Products whose C has few rows (2 to 2 SIMD vectors of them: a network's thin
// output layer, 6 x 100 times 100 x 250) run a kernel of their own where the
// layer kernel is built (internal::ThinGemm): BLAS packs the whole 100 x 250
// operand for 150 k multiply-adds there and ran these shapes 1.4-2.6x slower on a
// Zen 3 core (float and double, 2026-12-01). Its sums run in the order of
// BLAS's kernels (k = 0, 1, ... from zero, then added to beta C): the abs-NODE
// and res-NN trained on it are byte-identical to those of the BLAS products.
// OpenBLAS sums some other shapes in another order (one column goes to its gemv,
// and its kernel's column tails), where results differ in the last bits. Where C's
// rows fill at most half a SIMD vector, each vector holds two columns of C
// (internal::PairedColumns), with the same sums; on AVX-512, where they fill less
// than half a vector and B is untransposed (a 6-row product in float), C^T = B^T A^T
// runs with B's columns transposed in registers instead (internal::TransposedColumns:
// 4.4 against 6.0 us for 6 x 250 of 100 terms, one Zen 5 core, 2026-12-07), with the
// same sums again.
//
// On AVX-512 builds every other product with at most kThinGemmMaxInner terms per
// sum and A untransposed runs a kernel of its own too (internal::PanelGemm: row
// panels of two vectors, register tiles of 12 columns, nothing packed), in the
// same summation order. OpenBLAS 0.3.21 runs its AVX2 kernels on AVX-512 CPUs it
// does not know (Zen 4 and 5), where the panel kernel ran the epoch's 100 x 100
// times 100 x 250 products 1.45-1.7x faster (one Zen 5 core, 2026-12-02, double
// and float); against OpenBLAS's AVX-512 kernels 1.25-1.4x faster in double and
// 10 % slower in float, so float products stay with OpenBLAS when it runs those
// (internal::BlasRunsAvx512Kernels). A thin C whose rows fill at most half a vector
// times a transposed B (a 6-wide layer's weight gradient in float) runs there as
// its transpose on the panel kernel, in full vectors (internal::TransposedThinGemm:
// 2.3 us against the thin kernel's 5.8-6.5 for 6 x 250 times 250 x 100, one Zen 5
// core, 2026-12-07), with the thin kernel's sums.
//
// GemmFused adds a network layer's output stages to the product: a bias and ReLU
// (the forward pass), or ReLU's derivative as a mask (the backward pass), applied
// while the kernels' register tiles are stored rather than in passes over C:
//
//   diffdyn::GemmFused(W, false, h, false, diffdyn::GemmOutput<double>{b.data(), true}, a);
//
// Threads: diffdyn splits batches over its own threads in fixed chunks, so a
// threaded BLAS inside each chunk would only oversubscribe the cores. The
// first product therefore sets OpenBLAS (when it is the BLAS in use) to one
// thread for the process. Products of fixed chunks on one BLAS thread are
// deterministic, so results stay identical at any diffdyn thread count.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cstddef>
#include <string_view>
#include <type_traits>
#include <utility>

#include "diffdyn/models/activations.h"
#include "diffdyn/models/layer_kernel.h"

#if defined(__AVX512F__)
#include <immintrin.h>
#endif

#if defined(DIFFDYN_HAVE_BLAS)
extern "C" {
// Fortran BLAS (every BLAS provides it; character arguments of length one).
void dgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k,
            const double* alpha, const double* a, const int* lda, const double* b, const int* ldb,
            const double* beta, double* c, const int* ldc);
void sgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k,
            const float* alpha, const float* a, const int* lda, const float* b, const int* ldb,
            const float* beta, float* c, const int* ldc);
// OpenBLAS only; null when another BLAS is linked.
void openblas_set_num_threads(int num_threads) __attribute__((weak));
char* openblas_get_corename(void) __attribute__((weak));
}
#endif

namespace diffdyn {

#if defined(DIFFDYN_HAVE_BLAS)
namespace internal {
// Sets OpenBLAS (if linked) to one thread, once per process, whatever the
// Gemm instantiation that asks first.
inline void UseOneBlasThread() {
  static const bool once = [] {
    if (openblas_set_num_threads != nullptr) openblas_set_num_threads(1);
    return true;
  }();
  (void)once;
}
}  // namespace internal
#endif

namespace internal {
/// Whether the BLAS in use runs AVX-512 kernels: OpenBLAS's kernel set (chosen
/// for the CPU when it loads, or by OPENBLAS_CORETYPE) is SkylakeX, Cooperlake or
/// SapphireRapids. Read once per process; false without OpenBLAS.
inline bool BlasRunsAvx512Kernels() {
  static const bool avx512 = [] {
#if defined(DIFFDYN_HAVE_BLAS)
    if (openblas_get_corename == nullptr) return false;
    const char* name = openblas_get_corename();
    if (name == nullptr) return false;
    const std::string_view core(name);
    return core == "SkylakeX" || core == "Cooperlake" || core == "SapphireRapids";
#else
    return false;
#endif
  }();
  return avx512;
}
}  // namespace internal

#if DIFFDYN_LAYER_KERNEL
namespace internal {

/// Rows of C up to which Gemm runs ThinGemm (two SIMD vectors of S).
template <typename S>
inline constexpr int kThinGemmMaxRows = 2 * LayerShape<S>::kLanes;

/// Longest sum (inner size k) Gemm gives ThinGemm. BLAS sums longer ones in
/// blocks (OpenBLAS's double kernels for Zen: blocks of 256), which ThinGemm's
/// one running sum would round differently.
inline constexpr int kThinGemmMaxInner = 256;

// Output stages of ThinGemm and PanelGemm: Store(t, c, i, j) writes t = alpha
// (A op(B))(i, j) to c = &C(i, j), a vector of rows i.. or one entry; Shift(i0, j0)
// is the stage of the block of C from (i0, j0) on; Prefetch(rows, j, g, lanes) is
// called before the sums of columns [j, j + g).

// C = beta C + t (beta = 0 overwrites C without reading it).
template <typename S>
struct ScaledAddStage {
  using Vec = typename LayerVectors<S>::Vec;
  using VecU = typename LayerVectors<S>::VecU;
  S beta;
  ScaledAddStage Shift(int, int) const { return *this; }
  void Prefetch(int, int, int, int) const {}
  void Store(Vec t, S* c, int, int) const {
    VecU* out = reinterpret_cast<VecU*>(c);
    *out = beta == S(0) ? t : beta * *out + t;
  }
  void Store(S t, S* c, int, int) const { *c = beta == S(0) ? t : beta * *c + t; }
};

// C = GemmOutput's stages applied to t: (max(t + bias, 0) if relu) [mask > 0].
template <typename S>
struct OutputStage {
  using Vec = typename LayerVectors<S>::Vec;
  using VecU = typename LayerVectors<S>::VecU;
  using Mask = decltype(Vec{} < Vec{});  // the integer vector of a comparison
  const S* bias;
  bool relu;
  const S* mask;
  std::ptrdiff_t mask_ld;
  OutputStage Shift(int i0, int j0) const {
    OutputStage shifted = *this;
    if (bias) shifted.bias += i0;
    if (mask) shifted.mask += i0 + std::ptrdiff_t(j0) * mask_ld;
    return shifted;
  }
  // Asks for the mask's rows [0, rows) of columns [j, j + g) in cache: the tile's
  // sums take long enough for them to arrive, where its column-strided reads at
  // the store would wait for memory.
  void Prefetch(int rows, int j, int g, int lanes) const {
    if (!mask) return;
    for (int q = 0; q < g; ++q) {
      const S* col = mask + std::ptrdiff_t(j + q) * mask_ld;
      for (int i = 0; i < rows; i += lanes) __builtin_prefetch(col + i);
    }
  }
  // max(t, 0) as std::max(t, 0) gives it (t < 0 ? +0 : t, so NaN and -0 stay), and
  // [x > 0] as 1 or 0, both on the bits of comparison masks.
  void Store(Vec t, S* c, int i, int j) const {
    if (bias) t = *reinterpret_cast<const VecU*>(bias + i) + t;
    if (relu) t = (Vec)((Mask)t & ~(t < Vec{}));
    if (mask) {
      const Vec h = *reinterpret_cast<const VecU*>(mask + i + std::ptrdiff_t(j) * mask_ld);
      t = t * (Vec)((Mask)(Vec{} + S(1)) & (h > Vec{}));
    }
    *reinterpret_cast<VecU*>(c) = t;
  }
  void Store(S t, S* c, int i, int j) const {
    if (bias) t = bias[i] + t;
    if (relu) t = std::max(t, S(0));
    if (mask) t = t * PositiveIndicator(mask[i + std::ptrdiff_t(j) * mask_ld]);
    *c = t;
  }
};

// A's columns that a load of kWidth entries from their row 0 reads in place (the load
// stays inside A's (k - 1) lda + m entries): the first ones, their count returned; the
// others (fewer than kWidth) are copied to `tail`, kWidth entries each, zero past row m.
// The kernels read these copies instead, so no tile copies a column of its own.
template <typename S, int kWidth>
inline int PadLastColumns(int m, int k, const S* a, int lda, S* tail) {
  const std::ptrdiff_t end = std::ptrdiff_t(k - 1) * lda + m;
  int in_place = 0;
  if (end >= kWidth) {
    in_place = static_cast<int>(std::min<std::ptrdiff_t>(k, (end - kWidth) / lda + 1));
  }
  eigen_assert(k - in_place <= kWidth);  // lda >= m >= 1
  for (int j = in_place; j < k; ++j) {
    S* col = tail + std::ptrdiff_t(j - in_place) * kWidth;
    std::fill_n(col, kWidth, S(0));
    std::copy_n(a + std::ptrdiff_t(j) * lda, m, col);
  }
  return in_place;
}

// Columns [s, s + G) of C = stage(alpha A op(B)) for ThinGemm, G a compile-time
// count (g < G runs the kernel of g columns). Each column of C is V vectors of
// accumulators; per k one load of A's column and one broadcast of op(B)[j, s + q]
// per column q. A's first `in_place` columns are read in place (a V-vector load's
// entries past row m only reach lanes that are never stored), the others from
// `tail` (PadLastColumns). Not inlined: inside its callers' loops the compiler
// spilled an operand vector of the 2 x 12 tile to the stack (double 100 x 100 of 250
// terms 1.45x slower, one Zen 5 core).
template <typename S, int V, int G, bool kTransB, typename Stage>
[[gnu::noinline]] void ThinColumns(int m, int k, S alpha, const S* a, int lda, int in_place,
                                   const S* tail, const S* b, int ldb, const Stage& stage, S* c,
                                   int ldc, int s, int g) {
  if constexpr (G > 1) {
    if (g < G)
      return ThinColumns<S, V, G - 1, kTransB>(m, k, alpha, a, lda, in_place, tail, b, ldb, stage,
                                               c, ldc, s, g);
  }
  using Vec = typename LayerVectors<S>::Vec;
  using VecU = typename LayerVectors<S>::VecU;
  constexpr int kLanes = LayerShape<S>::kLanes;
  Vec acc[G][V];
  for (int q = 0; q < G; ++q) {
    for (int v = 0; v < V; ++v) acc[q][v] = Vec{};
  }
  auto step = [&](int j, const S* col) {
    Vec x[V];
    for (int v = 0; v < V; ++v) x[v] = *reinterpret_cast<const VecU*>(col + v * kLanes);
    for (int q = 0; q < G; ++q) {
      const S bj =
          kTransB ? b[(s + q) + std::ptrdiff_t(j) * ldb] : b[j + std::ptrdiff_t(s + q) * ldb];
      for (int v = 0; v < V; ++v) acc[q][v] += bj * x[v];
    }
  };
  stage.Prefetch(m, s, G, kLanes);
  for (int j = 0; j < in_place; ++j) step(j, a + std::ptrdiff_t(j) * lda);
  for (int j = in_place; j < k; ++j) step(j, tail + std::ptrdiff_t(j - in_place) * V * kLanes);
  // Whole vectors of C stored as vectors, the rows past the last one entry by entry
  // (the same operations per entry), each through the output stage.
  for (int q = 0; q < G; ++q) {
    S* col = c + std::ptrdiff_t(s + q) * ldc;
    int i = 0;
    for (int v = 0; v < V && i + kLanes <= m; ++v, i += kLanes) {
      stage.Store(Vec(alpha * acc[q][v]), col + i, i, s + q);
    }
    for (; i < m; ++i) stage.Store(S(alpha * acc[q][i / kLanes][i % kLanes]), col + i, i, s + q);
  }
}

// Vectors of N entries of S (a SIMD vector or a part of one) and the lane moves of
// PairedColumns: Splat (x in every lane), Concat (lo's lanes, then hi's).
template <typename S, int N>
struct SimdOf {
  typedef S type __attribute__((vector_size(N * sizeof(S))));
  typedef S unaligned __attribute__((vector_size(N * sizeof(S)), aligned(alignof(S)), may_alias));
};
template <typename S, int N>
using Simd = typename SimdOf<S, N>::type;

template <typename V, typename H, std::size_t... I>
inline V ConcatLanes(H lo, H hi, std::index_sequence<I...>) {
  return __builtin_shufflevector(lo, hi, static_cast<int>(I)...);
}
template <typename S, int N>
inline Simd<S, 2 * N> Concat(Simd<S, N> lo, Simd<S, N> hi) {
  return ConcatLanes<Simd<S, 2 * N>>(lo, hi, std::make_index_sequence<2 * N>{});
}
template <typename S, std::size_t... I>
inline Simd<S, sizeof...(I)> SplatLanes(S x, std::index_sequence<I...>) {
  return Simd<S, sizeof...(I)>{((void)I, x)...};
}
template <typename S, int N>
inline Simd<S, N> Splat(S x) {
  return SplatLanes<S>(x, std::make_index_sequence<N>{});
}

/// Columns of C per tile of PairedColumns in ThinGemmTo (its vectors of accumulators
/// times two).
inline constexpr int kPairedCols = 16;

// Columns [s, s + g) of C = stage(alpha A op(B)) for ThinGemm when C's rows fill at
// most half a SIMD vector (m <= H = kLanes / 2): each vector of accumulators holds two
// columns, rows of column s + 2p in lanes [0, m) and of s + 2p + 1 in [H, H + m), so
// one multiply-add serves both. Per k one load of H entries of A's column, put in
// both halves, and op(B)[j, s + 2p], op(B)[j, s + 2p + 1] broadcast to one half each.
// P vectors, g <= 2P (fewer pairs run the kernel of fewer vectors; an odd g's last
// vector repeats its column in the upper half, which is not stored). Every entry is
// summed over j = 0, 1, ... from zero with the operations of ThinColumns, so the bits
// are ThinColumns'.
template <typename S, int P, bool kTransB, typename Stage>
[[gnu::noinline]] void PairedColumns(int m, int k, S alpha, const S* a, int lda, int in_place,
                                     const S* tail, const S* b, int ldb, const Stage& stage, S* c,
                                     int ldc, int s, int g) {
  if constexpr (P > 1) {
    if (g <= 2 * (P - 1))
      return PairedColumns<S, P - 1, kTransB>(m, k, alpha, a, lda, in_place, tail, b, ldb, stage,
                                              c, ldc, s, g);
  }
  using Vec = typename LayerVectors<S>::Vec;
  constexpr int kLanes = LayerShape<S>::kLanes;
  constexpr int H = kLanes / 2;
  using Half = Simd<S, H>;
  using HalfU = typename SimdOf<S, H>::unaligned;
  // op(B)[j, column] = b[offset[column] + j step].
  std::ptrdiff_t offset[2 * P];
  for (int t = 0; t < 2 * P; ++t) {
    const std::ptrdiff_t q = s + std::min(t, g - 1);
    offset[t] = kTransB ? q : q * ldb;
  }
  const std::ptrdiff_t step = kTransB ? ldb : 1;
  Vec acc[P];
  for (int p = 0; p < P; ++p) acc[p] = Vec{};
  auto sum = [&](int j, const S* col) {
    const Half x = *reinterpret_cast<const HalfU*>(col);
    const Vec xx = Concat<S, H>(x, x);
    const S* bj = b + std::ptrdiff_t(j) * step;
    for (int p = 0; p < P; ++p) {
      const Vec bb =
          Concat<S, H>(Splat<S, H>(bj[offset[2 * p]]), Splat<S, H>(bj[offset[2 * p + 1]]));
      acc[p] += bb * xx;
    }
  };
  stage.Prefetch(m, s, g, kLanes);
  for (int j = 0; j < in_place; ++j) sum(j, a + std::ptrdiff_t(j) * lda);
  for (int j = in_place; j < k; ++j) sum(j, tail + std::ptrdiff_t(j - in_place) * H);
  // Each column's m entries through the output stage, as ThinColumns stores rows past
  // its last whole vector.
  for (int p = 0; p < P; ++p) {
    alignas(kLayerVectorBytes) S t[kLanes];
    *reinterpret_cast<Vec*>(t) = acc[p];
    for (int h = 0; h < 2 && 2 * p + h < g; ++h) {
      const int q = s + 2 * p + h;
      S* col = c + std::ptrdiff_t(q) * ldc;
      for (int i = 0; i < m; ++i) stage.Store(S(alpha * t[h * H + i]), col + i, i, q);
    }
  }
}

#if defined(__AVX512F__)
/// Whether ThinGemmTo runs a C whose rows fill less than half a vector times an
/// untransposed B on internal::TransposedColumns: AVX-512 builds.
inline constexpr bool kHaveTransposedColumns = true;

// The first `count` entries from p (0 < count <= the lanes) in a vector, zero in the
// other lanes: AVX-512's masked load, which reads nothing past them.
template <typename S>
inline typename LayerVectors<S>::Vec LoadFirst(const S* p, int count) {
  using Vec = typename LayerVectors<S>::Vec;
  const unsigned mask = (1u << count) - 1u;
  if constexpr (std::is_same_v<S, float>) {
    return (Vec)_mm512_maskz_loadu_ps(static_cast<__mmask16>(mask), p);
  } else {
    return (Vec)_mm512_maskz_loadu_pd(static_cast<__mmask8>(mask), p);
  }
}

// One stage of TransposeSquare for rows r and r + B of the square (r's bit B clear):
// lane l of the new row r (kSecond: of r + B) and where it comes from (< L: row r,
// else row r + B).
constexpr int TransposeSource(int lanes, int block, bool second, int l) {
  if (second) return (l & block) ? lanes + l : l + block;
  return (l & block) ? lanes + l - block : l;
}
template <int L, int B, bool kSecond, typename Vec, std::size_t... P>
inline Vec TransposePick(Vec x, Vec y, std::index_sequence<P...>) {
  return __builtin_shufflevector(x, y, TransposeSource(L, B, kSecond, static_cast<int>(P))...);
}

// v[r][l] to v[l][r] for the square of L vectors of L lanes: per stage B = 1, 2, ...,
// L / 2, rows r and r + B swap their off-diagonal blocks of B lanes.
template <typename Vec, int L, int B = 1>
[[gnu::always_inline]] inline void TransposeSquare(Vec* v) {
  if constexpr (B < L) {
    constexpr auto lanes = std::make_index_sequence<L>{};
    for (int r = 0; r < L; ++r) {
      if (r & B) continue;
      const Vec x = v[r], y = v[r + B];
      v[r] = TransposePick<L, B, false>(x, y, lanes);
      v[r + B] = TransposePick<L, B, true>(x, y, lanes);
    }
    TransposeSquare<Vec, L, 2 * B>(v);
  }
}

/// Column vectors of a TransposedColumns tile for C's R rows (R < 8): R x W
/// accumulators (at most 24 of AVX-512's 32 registers), W <= 4.
template <int R>
inline constexpr int kTransposedColVecs = std::min(4, 24 / R);

// Columns [s, s + g) of C = stage(alpha A B) for ThinGemm when C has R rows (fewer
// than half a vector) and B is untransposed: C^T = B^T A^T with W vectors of C's
// columns (g <= W L). First B's columns, loaded down k L terms at a time (a masked
// load past k), are transposed in registers (TransposeSquare) to the rows of op(B),
// kept in `rows` (k <= kThinGemmMaxInner); then per term j one broadcast of A(i, j)
// per row i and W R multiply-adds, the accumulators in registers throughout. Every
// entry is summed over j = 0, 1, ... from zero with the operations of ThinColumns,
// so the bits are ThinColumns'. Tile columns past g repeat column s + g - 1 and are
// not stored.
template <typename S, int R, int W, typename Stage>
[[gnu::noinline]] void TransposedColumns(int k, S alpha, const S* a, int lda, const S* b, int ldb,
                                         const Stage& stage, S* c, int ldc, int s, int g) {
  using Vec = typename LayerVectors<S>::Vec;
  using VecU = typename LayerVectors<S>::VecU;
  constexpr int L = LayerShape<S>::kLanes;
  // op(B)'s rows j < k, column vector w in rows[j][w]: W L columns of B loaded down k
  // (from `column`), L terms at a time, and transposed.
  const S* column[W * L];
  for (int q = 0; q < W * L; ++q) column[q] = b + std::ptrdiff_t(s + std::min(q, g - 1)) * ldb;
  alignas(kLayerVectorBytes) Vec rows[(kThinGemmMaxInner + L - 1) / L * L][W];
  for (int j0 = 0; j0 < k; j0 += L) {
    const int count = std::min(L, k - j0);
    for (int w = 0; w < W; ++w) {
      Vec v[L];
      for (int r = 0; r < L; ++r) {
        const S* p = column[w * L + r] + j0;
        v[r] = count == L ? Vec(*reinterpret_cast<const VecU*>(p)) : LoadFirst<S>(p, count);
      }
      TransposeSquare<Vec, L>(v);
      for (int r = 0; r < L; ++r) rows[j0 + r][w] = v[r];
    }
  }
  // C^T's tile: per term one broadcast of A(i, j) per row i.
  Vec acc[W][R];
  for (int w = 0; w < W; ++w) {
    for (int i = 0; i < R; ++i) acc[w][i] = Vec{};
  }
  for (int j = 0; j < k; ++j) {
    const S* at = a + std::ptrdiff_t(j) * lda;
    for (int i = 0; i < R; ++i) {
      const Vec x = Splat<S, L>(at[i]);
      for (int w = 0; w < W; ++w) acc[w][i] += rows[j][w] * x;
    }
  }
  // Row i of the tile's columns to C entry by entry through the output stage.
  alignas(kLayerVectorBytes) S sums[W][R][L];
  for (int w = 0; w < W; ++w) {
    for (int i = 0; i < R; ++i) *reinterpret_cast<Vec*>(sums[w][i]) = acc[w][i];
  }
  for (int q = 0; q < g; ++q) {
    S* out = c + std::ptrdiff_t(s + q) * ldc;
    for (int i = 0; i < R; ++i) {
      stage.Store(S(alpha * sums[q / L][i][q % L]), out + i, i, s + q);
    }
  }
}

// TransposedColumns over C's n columns for R = m rows (1 <= m < kLanes / 2).
template <typename S, typename Stage, int R = 1>
inline void TransposedGemmTo(int m, int n, int k, S alpha, const S* a, int lda, const S* b, int ldb,
                             const Stage& stage, S* c, int ldc) {
  if constexpr (2 * (R + 1) < LayerShape<S>::kLanes) {
    if (m > R) {
      return TransposedGemmTo<S, Stage, R + 1>(m, n, k, alpha, a, lda, b, ldb, stage, c, ldc);
    }
  }
  constexpr int W = kTransposedColVecs<R>, kCols = W * LayerShape<S>::kLanes;
  for (int s = 0; s < n; s += kCols) {
    TransposedColumns<S, R, W>(k, alpha, a, lda, b, ldb, stage, c, ldc, s, std::min(kCols, n - s));
  }
}
#else
inline constexpr bool kHaveTransposedColumns = false;
#endif

/// C = beta C + alpha A op(B) for C with few rows: A m x k (column-major,
/// leading dimension lda), op(B) k x n with op(B)[j, s] = B[j + s ldb], or
/// B[s + j ldb] if kTransB; C m x n (ldc); m <= V SIMD vectors of S. Columns of
/// C in groups of kGroup (by default 8 with one vector per column, 6 with two),
/// each entry summed over j = 0, 1, ... from zero, then alpha times the sum added
/// to beta C (beta = 0 overwrites C). With a pointer and leading dimension per
/// operand, so callers need no Eigen types.
/// ThinGemmTo stores each entry through an output stage instead (ScaledAddStage is
/// ThinGemm's beta, OutputStage a GemmOutput).
template <typename S, int V, bool kTransB, int kGroup = V == 1 ? 8 : 6, typename Stage>
inline void ThinGemmTo(int m, int n, int k, S alpha, const S* a, int lda, const S* b, int ldb,
                       const Stage& stage, S* c, int ldc) {
  // Rows in at most half a vector: C^T = B^T A^T for fewer rows and an untransposed B
  // (AVX-512; two columns per vector would leave lanes idle), else two columns per
  // vector, kPairedCols per tile.
  if constexpr (V == 1) {
    constexpr int H = LayerShape<S>::kLanes / 2;
    if constexpr (!kTransB && kHaveTransposedColumns) {
      if (m < H && k <= kThinGemmMaxInner) {
        TransposedGemmTo<S>(m, n, k, alpha, a, lda, b, ldb, stage, c, ldc);
        return;
      }
    }
    if (m <= H) {
      alignas(kLayerVectorBytes) S tail[H * H];
      const int in_place = PadLastColumns<S, H>(m, k, a, lda, tail);
      for (int s = 0; s < n; s += kPairedCols) {
        PairedColumns<S, kPairedCols / 2, kTransB>(m, k, alpha, a, lda, in_place, tail, b, ldb,
                                                   stage, c, ldc, s, std::min(kPairedCols, n - s));
      }
      return;
    }
  }
  constexpr int kWidth = V * LayerShape<S>::kLanes;
  alignas(kLayerVectorBytes) S tail[kWidth * kWidth];
  const int in_place = PadLastColumns<S, kWidth>(m, k, a, lda, tail);
  int s = 0;
  for (; s + kGroup <= n; s += kGroup) {
    ThinColumns<S, V, kGroup, kTransB>(m, k, alpha, a, lda, in_place, tail, b, ldb, stage, c, ldc,
                                       s, kGroup);
  }
  if (s < n) {
    ThinColumns<S, V, kGroup, kTransB>(m, k, alpha, a, lda, in_place, tail, b, ldb, stage, c, ldc,
                                       s, n - s);
  }
}
template <typename S, int V, bool kTransB, int kGroup = V == 1 ? 8 : 6>
inline void ThinGemm(int m, int n, int k, S alpha, const S* a, int lda, const S* b, int ldb, S beta,
                     S* c, int ldc) {
  ThinGemmTo<S, V, kTransB, kGroup>(m, n, k, alpha, a, lda, b, ldb, ScaledAddStage<S>{beta}, c,
                                    ldc);
}

#if defined(__AVX512F__)
/// Rows of a PanelGemm panel, in SIMD vectors, and columns per register tile:
/// 2 x 12 accumulators, 2 loads of A and a broadcast of op(B) fit AVX-512's 32
/// registers (2 x 12 ran 88-92 GFLOP/s in double on one Zen 5 core for C 100 x 250
/// = A 100 x 100 times B 100 x 250; 3 x 8 and 2 x 14 were no faster).
inline constexpr int kPanelVecs = 2;
inline constexpr int kPanelCols = 12;
/// Bytes of op(B) one column block of PanelGemm reads (the block stays in L2
/// while every row panel of A passes over it).
inline constexpr std::ptrdiff_t kPanelBlockBytes = 256 * 1024;
/// Shortest sum Gemm gives PanelGemm: below it OpenBLAS was as fast or faster (C
/// 100 x 250 of 6 terms with beta = 0: 4.9 us against 8.0 in float; 16 to 64 terms
/// the same time; 100: 1.7-1.9x slower).
inline constexpr int kPanelMinInner = 32;

/// C = stage(alpha A op(B)) for any m, on AVX-512: A m x k (column-major, leading
/// dimension lda), op(B) k x n as in ThinGemm, C m x n (ldc); the stage stores each
/// entry (ScaledAddStage: beta C + alpha A op(B); OutputStage: a GemmOutput's bias,
/// ReLU and mask while the tile is in registers). C is cut into column blocks whose
/// op(B) fits kPanelBlockBytes, each block into row panels of kPanelVecs vectors
/// (the last of one vector if that holds its rows), each panel into register tiles
/// of kPanelCols columns (ThinGemmTo): A's columns and op(B)'s entries are read in
/// place, nothing is packed. Each entry is summed over j = 0, 1, ... from zero,
/// then alpha times the sum goes to the stage: for k <= kThinGemmMaxInner the order
/// of OpenBLAS's kernels, and the same bits as its dgemm and sgemm with beta C
/// (Haswell and SkylakeX kernels, 2026-12-02).
template <typename S, bool kTransB, typename Stage>
inline void PanelGemm(int m, int n, int k, S alpha, const S* a, int lda, const S* b, int ldb,
                      const Stage& stage, S* c, int ldc) {
  constexpr int kLanes = LayerShape<S>::kLanes;
  constexpr int kPanelRows = kPanelVecs * kLanes;
  const std::ptrdiff_t column_bytes = std::ptrdiff_t(k) * static_cast<std::ptrdiff_t>(sizeof(S));
  const std::ptrdiff_t blocks = std::max<std::ptrdiff_t>(
      1, (column_bytes * n + kPanelBlockBytes - 1) / kPanelBlockBytes);
  const int per_block = static_cast<int>((n + blocks - 1) / blocks);
  const int width = (per_block + kPanelCols - 1) / kPanelCols * kPanelCols;
  for (int s0 = 0; s0 < n; s0 += width) {
    const int cols = std::min(width, n - s0);
    const S* bs = kTransB ? b + s0 : b + std::ptrdiff_t(s0) * ldb;
    S* cs = c + std::ptrdiff_t(s0) * ldc;
    for (int i0 = 0; i0 < m; i0 += kPanelRows) {
      const int rows = std::min(kPanelRows, m - i0);
      const Stage tile_stage = stage.Shift(i0, s0);
      if (rows <= kLanes) {
        ThinGemmTo<S, 1, kTransB, kPanelCols>(rows, cols, k, alpha, a + i0, lda, bs, ldb,
                                              tile_stage, cs + i0, ldc);
      } else {
        ThinGemmTo<S, kPanelVecs, kTransB, kPanelCols>(rows, cols, k, alpha, a + i0, lda, bs, ldb,
                                                       tile_stage, cs + i0, ldc);
      }
    }
  }
}

/// Most entries of a C that TransposedThinGemm takes (its C^T is a stack buffer).
inline constexpr int kTransposedThinMaxEntries = 4096;

/// C = beta C + alpha A B^T for a thin C (m rows, at most half a SIMD vector, so the
/// thin kernel would leave most lanes idle), as C^T = alpha B A^T on PanelGemm (B
/// n x k read in place down its columns, A m x k broadcast), then added to beta C
/// transposed. Each entry is summed over j = 0, 1, ... from zero as in ThinGemm: with
/// alpha = 1 and beta 0 or 1 (a layer's products) the bits are ThinGemm's, otherwise
/// alpha's and beta's products may round apart (the compiler may fuse either into the
/// last add). m n <= kTransposedThinMaxEntries.
template <typename S>
inline void TransposedThinGemm(int m, int n, int k, S alpha, const S* a, int lda, const S* b,
                               int ldb, S beta, S* c, int ldc) {
  alignas(kLayerVectorBytes) S ct[kTransposedThinMaxEntries];
  PanelGemm<S, true>(n, m, k, alpha, b, ldb, a, lda, ScaledAddStage<S>{S(0)}, ct, n);
  const ScaledAddStage<S> add{beta};
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < m; ++i)
      add.Store(ct[j + std::ptrdiff_t(i) * n], c + i + std::ptrdiff_t(j) * ldc, i, j);
  }
}
#endif

}  // namespace internal
#endif

/// Whether Gemm runs its own kernel (internal::PanelGemm) for products A op(B)
/// with more rows than the thin kernel takes and up to kThinGemmMaxInner terms
/// per sum (AVX-512 builds; the shortest sums it takes: internal::PanelTakes):
/// OpenBLAS picks AVX2 kernels on AVX-512 CPUs it does not know, and on AVX2 its
/// kernels were as fast as ours.
#if DIFFDYN_LAYER_KERNEL && defined(__AVX512F__)
#define DIFFDYN_PANEL_GEMM 1
#else
#define DIFFDYN_PANEL_GEMM 0
#endif
inline constexpr bool kHavePanelGemm = DIFFDYN_PANEL_GEMM != 0;

namespace internal {
// Whether Gemm runs PanelGemm for a product of more rows than ThinGemm takes: in
// double always, in float unless OpenBLAS runs its AVX-512 kernels (its sgemm was
// 10 % faster than PanelGemm there, 33 against 37 us at 100 x 100 x 250). The same
// for GemmFused: with a bias and ReLU in the store, the 6-term first-layer
// products ran faster in PanelGemm alone (8.7 against 11.0 us with OpenBLAS's
// AVX2 dgemm and the passes, one Zen 5 core) but the NeuralODE epoch slower (in 8
// of 8 interleaved pairs, 5-30 %), so those stay with BLAS. The same in float: C
// 100 x 250 of 6 terms 4.2 us alone against OpenBLAS's 4.5, the float epoch 9-10 %
// slower (3 of 3 interleaved pairs, one Zen 5 core), and no faster with C's columns
// walked 24 at a time down all its rows.
template <typename S>
inline bool PanelTakes([[maybe_unused]] Eigen::Index k) {
#if DIFFDYN_PANEL_GEMM
  return k >= kPanelMinInner && (std::is_same_v<S, double> || !BlasRunsAvx512Kernels());
#else
  return false;
#endif
}

#if defined(__AVX512F__)
// The last step of a block transpose in registers: w[L n + e] = lane L (of four
// 128-bit lanes) of x[e], x[n + e], x[2n + e], x[3n + e], for e < n; even(x, y) and
// odd(x, y) take the even (odd) lanes of x, then of y.
template <typename V, typename Even, typename Odd>
inline void GatherLanes(const V* x, int n, Even even, Odd odd, V* w) {
  for (int e = 0; e < n; ++e) {
    const V s0 = even(x[e], x[n + e]), s1 = odd(x[e], x[n + e]);
    const V s2 = even(x[2 * n + e], x[3 * n + e]), s3 = odd(x[2 * n + e], x[3 * n + e]);
    w[e] = even(s0, s2);
    w[n + e] = even(s1, s3);
    w[2 * n + e] = odd(s0, s2);
    w[3 * n + e] = odd(s1, s3);
  }
}

// The rows x cols (at most 16 x 16) float block at a (column-major, leading dimension
// lda) transposed into out (leading dimension ldo), through registers: per 128-bit
// lane, pairs of columns interleaved, then quadruples, then the lanes gathered across
// the four quadruple groups. Masked loads and stores touch only the block's entries.
// The lane moves are written as shuffles of vectors, not as the intrinsics, whose
// GCC 12 definitions warn of uninitialised values under -Wall.
inline void TransposeBlock(int rows, int cols, const float* a, std::ptrdiff_t lda, float* out,
                           std::ptrdiff_t ldo) {
  const __mmask16 row_mask = static_cast<__mmask16>((1u << rows) - 1u);
  const __mmask16 col_mask = static_cast<__mmask16>((1u << cols) - 1u);
  __m512 r[16], t[16];
  for (int q = 0; q < 16; ++q) {
    r[q] = q < cols ? _mm512_maskz_loadu_ps(row_mask, a + q * lda) : _mm512_setzero_ps();
  }
  for (int k = 0; k < 8; ++k) {
    t[2 * k] = __builtin_shufflevector(r[2 * k], r[2 * k + 1], 0, 16, 1, 17, 4, 20, 5, 21, 8, 24, 9,
                                       25, 12, 28, 13, 29);
    t[2 * k + 1] = __builtin_shufflevector(r[2 * k], r[2 * k + 1], 2, 18, 3, 19, 6, 22, 7, 23, 10,
                                           26, 11, 27, 14, 30, 15, 31);
  }
  // r[4k + e], lane L: entry 4 L + e of columns 4k .. 4k + 3.
  for (int k = 0; k < 4; ++k) {
    for (int h = 0; h < 2; ++h) {
      const __m512 x = t[4 * k + h], y = t[4 * k + h + 2];
      r[4 * k + 2 * h] =
          __builtin_shufflevector(x, y, 0, 1, 16, 17, 4, 5, 20, 21, 8, 9, 24, 25, 12, 13, 28, 29);
      r[4 * k + 2 * h + 1] =
          __builtin_shufflevector(x, y, 2, 3, 18, 19, 6, 7, 22, 23, 10, 11, 26, 27, 14, 15, 30, 31);
    }
  }
  // Row 4 L + e of the block from lane L of r[e], r[4 + e], r[8 + e], r[12 + e]; the
  // even 128-bit lanes of x then of y, or the odd ones.
  const auto even = [](__m512 x, __m512 y) -> __m512 {
    return __builtin_shufflevector(x, y, 0, 1, 2, 3, 8, 9, 10, 11, 16, 17, 18, 19, 24, 25, 26, 27);
  };
  const auto odd = [](__m512 x, __m512 y) -> __m512 {
    return __builtin_shufflevector(x, y, 4, 5, 6, 7, 12, 13, 14, 15, 20, 21, 22, 23, 28, 29, 30,
                                   31);
  };
  __m512 w[16];
  GatherLanes(r, 4, even, odd, w);
  for (int p = 0; p < rows; ++p) _mm512_mask_storeu_ps(out + p * ldo, col_mask, w[p]);
}

// The rows x cols (at most 8 x 8) double block the same way: pairs of columns
// interleaved, then the lanes gathered across the four pair groups.
inline void TransposeBlock(int rows, int cols, const double* a, std::ptrdiff_t lda, double* out,
                           std::ptrdiff_t ldo) {
  const __mmask8 row_mask = static_cast<__mmask8>((1u << rows) - 1u);
  const __mmask8 col_mask = static_cast<__mmask8>((1u << cols) - 1u);
  __m512d r[8], t[8];
  for (int q = 0; q < 8; ++q) {
    r[q] = q < cols ? _mm512_maskz_loadu_pd(row_mask, a + q * lda) : _mm512_setzero_pd();
  }
  // t[2k + e], lane L: entry 2 L + e of columns 2k, 2k + 1.
  for (int k = 0; k < 4; ++k) {
    t[2 * k] = __builtin_shufflevector(r[2 * k], r[2 * k + 1], 0, 8, 2, 10, 4, 12, 6, 14);
    t[2 * k + 1] = __builtin_shufflevector(r[2 * k], r[2 * k + 1], 1, 9, 3, 11, 5, 13, 7, 15);
  }
  // Row 2 L + e of the block from lane L of t[e], t[2 + e], t[4 + e], t[6 + e].
  const auto even = [](__m512d x, __m512d y) -> __m512d {
    return __builtin_shufflevector(x, y, 0, 1, 4, 5, 8, 9, 12, 13);
  };
  const auto odd = [](__m512d x, __m512d y) -> __m512d {
    return __builtin_shufflevector(x, y, 2, 3, 6, 7, 10, 11, 14, 15);
  };
  __m512d w[8];
  GatherLanes(t, 2, even, odd, w);
  for (int p = 0; p < rows; ++p) _mm512_mask_storeu_pd(out + p * ldo, col_mask, w[p]);
}
#endif

/// out = A^T: A is rows x cols (column-major, leading dimension lda), out cols x
/// rows (leading dimension cols); they must not overlap. On AVX-512 in blocks of
/// one SIMD vector square (the last ones partial), transposed in registers; else
/// entry by entry.
template <typename S>
void TransposeInto(int rows, int cols, const S* a, int lda, S* out) {
#if defined(__AVX512F__)
  constexpr int kB = 64 / static_cast<int>(sizeof(S));
  for (int i = 0; i < rows; i += kB) {
    for (int j = 0; j < cols; j += kB) {
      TransposeBlock(std::min(kB, rows - i), std::min(kB, cols - j),
                     a + i + std::ptrdiff_t(j) * lda, lda, out + j + std::ptrdiff_t(i) * cols,
                     cols);
    }
  }
#else
  for (int i = 0; i < rows; ++i) {
    for (int j = 0; j < cols; ++j)
      out[j + std::ptrdiff_t(i) * cols] = a[i + std::ptrdiff_t(j) * lda];
  }
#endif
}
}  // namespace internal

/// Whether Gemm calls an external BLAS (true) or Eigen's products (false).
constexpr bool GemmUsesBlas() {
#if defined(DIFFDYN_HAVE_BLAS)
  return true;
#else
  return false;
#endif
}

/// What GemmFused does with each entry t = (op(A) op(B))(i, j) before it stores
/// it: C(i, j) = r(t + bias(i)) [mask(i, j) > 0], with r(x) = max(x, 0) (as
/// std::max gives it: NaN and -0 stay) if relu, else x. A network layer's forward
/// pass is bias + relu, the cotangent of a ReLU layer's input (W^T abar) .* [h > 0]
/// the mask. Where Gemm's own kernels take the product the stages run on the
/// tile in registers, else as passes over C after the product: the same bits.
template <typename S>
struct GemmOutput {
  const S* bias = nullptr;    ///< m entries added to every column, or none
  bool relu = false;          ///< max(., 0) after the bias
  const S* mask = nullptr;    ///< m x n (leading dimension mask_ld): times [mask > 0], or none
  Eigen::Index mask_ld = 0;   ///< leading dimension of mask
};

namespace internal {

// C = stage(alpha op(A) op(B)), the stage ScaledAddStage{beta} or, when out is not
// null, OutputStage{*out}: run by ThinGemm or PanelGemm when one of them takes the
// product (A untransposed, 2 or more rows, at most kThinGemmMaxInner terms; more
// rows than ThinGemm takes only where PanelTakes). Returns whether it ran.
template <typename S, typename DA, typename DB, typename DC>
bool KernelGemm([[maybe_unused]] S alpha, [[maybe_unused]] const Eigen::MatrixBase<DA>& a,
                [[maybe_unused]] bool transpose_a, [[maybe_unused]] const Eigen::MatrixBase<DB>& b,
                [[maybe_unused]] bool transpose_b, [[maybe_unused]] S beta,
                [[maybe_unused]] const GemmOutput<S>* out,
                [[maybe_unused]] Eigen::MatrixBase<DC>& c) {
#if DIFFDYN_LAYER_KERNEL
  const Eigen::Index m = c.rows();
  const Eigen::Index k = transpose_a ? a.rows() : a.cols();
  if (transpose_a || m < 2 || k > kThinGemmMaxInner ||
      (m > kThinGemmMaxRows<S> && !PanelTakes<S>(k))) {
    return false;
  }
  const int mi = static_cast<int>(m), ni = static_cast<int>(c.cols()), ki = static_cast<int>(k);
  const int lda = static_cast<int>(std::max<Eigen::Index>(1, a.derived().outerStride()));
  const int ldb = static_cast<int>(std::max<Eigen::Index>(1, b.derived().outerStride()));
  const int ldc = static_cast<int>(std::max<Eigen::Index>(1, c.derived().outerStride()));
  const S* pa = a.derived().data();
  const S* pb = b.derived().data();
  S* pc = c.derived().data();
#if DIFFDYN_PANEL_GEMM
  // A thin C times a transposed B with more columns than a row panel: its transpose.
  if (out == nullptr && transpose_b && 2 * m <= LayerShape<S>::kLanes &&
      ni > kThinGemmMaxRows<S> && m * ni <= kTransposedThinMaxEntries &&
      PanelTakes<S>(k)) {
    TransposedThinGemm<S>(mi, ni, ki, alpha, pa, lda, pb, ldb, beta, pc, ldc);
    return true;
  }
#endif
  // The kernel for C's rows and B's layout, given the stage.
  auto run = [&](const auto& stage) {
#if DIFFDYN_PANEL_GEMM
    if (m > kThinGemmMaxRows<S>) {
      transpose_b ? PanelGemm<S, true>(mi, ni, ki, alpha, pa, lda, pb, ldb, stage, pc, ldc)
                  : PanelGemm<S, false>(mi, ni, ki, alpha, pa, lda, pb, ldb, stage, pc, ldc);
      return;
    }
#endif
    if (m <= LayerShape<S>::kLanes) {
      transpose_b ? ThinGemmTo<S, 1, true>(mi, ni, ki, alpha, pa, lda, pb, ldb, stage, pc, ldc)
                  : ThinGemmTo<S, 1, false>(mi, ni, ki, alpha, pa, lda, pb, ldb, stage, pc, ldc);
    } else {
      transpose_b ? ThinGemmTo<S, 2, true>(mi, ni, ki, alpha, pa, lda, pb, ldb, stage, pc, ldc)
                  : ThinGemmTo<S, 2, false>(mi, ni, ki, alpha, pa, lda, pb, ldb, stage, pc, ldc);
    }
  };
  if (out == nullptr) {
    run(ScaledAddStage<S>{beta});
  } else {
    run(OutputStage<S>{out->bias, out->relu, out->mask, static_cast<std::ptrdiff_t>(out->mask_ld)});
  }
  return true;
#else
  return false;
#endif
}

// a[r] *= [h[r] > 0] for r < n (1 or 0 from h's bits: see PositiveIndicator), in a
// loop the compiler vectorises; the product keeps NaN and signed zeros.
template <typename S>
inline void MultiplyByPositiveIndicator(S* __restrict a, const S* __restrict h, Eigen::Index n) {
  for (Eigen::Index r = 0; r < n; ++r) a[r] *= PositiveIndicator(h[r]);
}

}  // namespace internal

/// C = alpha op(A) op(B) + beta C, with op(X) = X^T if the flag is set, else X.
/// Sizes: op(A) is m x k, op(B) is k x n, C is m x n (checked in debug builds).
/// With beta = 0, C is overwritten (its old entries may be NaN). A, B and C are
/// column-major blocks of one scalar S (double or float) with unit inner stride;
/// C must not alias A or B. alpha and beta are given in S.
template <typename DA, typename DB, typename DC>
void Gemm(typename DC::Scalar alpha, const Eigen::MatrixBase<DA>& a, bool transpose_a,
          const Eigen::MatrixBase<DB>& b, bool transpose_b, typename DC::Scalar beta,
          const Eigen::MatrixBase<DC>& c_out) {
  using S = typename DC::Scalar;
  static_assert(std::is_same_v<S, double> || std::is_same_v<S, float>,
                "Gemm needs double or float operands");
  static_assert(std::is_same_v<typename DA::Scalar, S> && std::is_same_v<typename DB::Scalar, S>,
                "Gemm needs operands of one scalar type");
  static_assert(DA::InnerStrideAtCompileTime == 1 && DB::InnerStrideAtCompileTime == 1 &&
                    DC::InnerStrideAtCompileTime == 1,
                "Gemm needs operands with unit inner stride");
  static_assert(!DA::IsRowMajor && !DB::IsRowMajor && !DC::IsRowMajor,
                "Gemm needs column-major operands");
  Eigen::MatrixBase<DC>& c = const_cast<Eigen::MatrixBase<DC>&>(c_out);
  const Eigen::Index m = c.rows();
  const Eigen::Index n = c.cols();
  const Eigen::Index k = transpose_a ? a.rows() : a.cols();
  eigen_assert((transpose_a ? a.cols() : a.rows()) == m);
  eigen_assert((transpose_b ? b.rows() : b.cols()) == n);
  eigen_assert((transpose_b ? b.cols() : b.rows()) == k);
  if (m == 0 || n == 0) return;
  if (k == 0) {
    if (beta == S(0)) {
      c.setZero();
    } else {
      c *= beta;
    }
    return;
  }
  if (internal::KernelGemm<S>(alpha, a, transpose_a, b, transpose_b, beta, nullptr, c)) return;
#if defined(DIFFDYN_HAVE_BLAS)
  internal::UseOneBlasThread();
  // beta = 0 as a fill of our own, then beta = 1: BLAS's own beta pass took 6-9 us
  // more than the fill for a 100 x 250 C (Zen 3, float and double). BLAS scales C
  // by beta before it accumulates, so the result has the same bits.
  if (beta == S(0)) {
    c.setZero();
    beta = S(1);
  }
  const char ta = transpose_a ? 'T' : 'N';
  const char tb = transpose_b ? 'T' : 'N';
  const int mi = static_cast<int>(m), ni = static_cast<int>(n), ki = static_cast<int>(k);
  const int lda = static_cast<int>(std::max<Eigen::Index>(1, a.derived().outerStride()));
  const int ldb = static_cast<int>(std::max<Eigen::Index>(1, b.derived().outerStride()));
  const int ldc = static_cast<int>(std::max<Eigen::Index>(1, c.derived().outerStride()));
  if constexpr (std::is_same_v<S, double>) {
    dgemm_(&ta, &tb, &mi, &ni, &ki, &alpha, a.derived().data(), &lda, b.derived().data(), &ldb,
           &beta, c.derived().data(), &ldc);
  } else {
    sgemm_(&ta, &tb, &mi, &ni, &ki, &alpha, a.derived().data(), &lda, b.derived().data(), &ldb,
           &beta, c.derived().data(), &ldc);
  }
#else
  if (beta == S(0)) {
    c.setZero();
  } else if (beta != S(1)) {
    c *= beta;
  }
  if (transpose_a && transpose_b) {
    c.noalias() += alpha * a.transpose() * b.transpose();
  } else if (transpose_a) {
    c.noalias() += alpha * a.transpose() * b;
  } else if (transpose_b) {
    c.noalias() += alpha * a * b.transpose();
  } else {
    c.noalias() += alpha * a * b;
  }
#endif
}


/// C = out(op(A) op(B)): the product with a GemmOutput's bias, ReLU and mask
/// applied to each entry (sizes and operands as for Gemm; the mask may not alias
/// C). With a bias its result has the same bits as C = bias 1^T, then
/// Gemm(1, A, B, beta = 1), then the ReLU and mask passes; without, as Gemm with
/// beta = 0 and the passes.
template <typename DA, typename DB, typename DC>
void GemmFused(const Eigen::MatrixBase<DA>& a, bool transpose_a, const Eigen::MatrixBase<DB>& b,
               bool transpose_b, const GemmOutput<typename DC::Scalar>& out,
               const Eigen::MatrixBase<DC>& c_out) {
  using S = typename DC::Scalar;
  Eigen::MatrixBase<DC>& c = const_cast<Eigen::MatrixBase<DC>&>(c_out);
  const Eigen::Index m = c.rows();
  const Eigen::Index n = c.cols();
  if (m == 0 || n == 0) return;
  const Eigen::Index k = transpose_a ? a.rows() : a.cols();
  if (k > 0 && internal::KernelGemm<S>(S(1), a, transpose_a, b, transpose_b, S(0), &out, c)) {
    return;
  }
  // Elsewhere: the product, then one pass per stage, column by column.
  if (out.bias != nullptr) {
    c.colwise() = Eigen::Map<const Eigen::Matrix<S, Eigen::Dynamic, 1>>(out.bias, m);
  }
  Gemm(S(1), a, transpose_a, b, transpose_b, out.bias != nullptr ? S(1) : S(0), c);
  for (Eigen::Index j = 0; j < n; ++j) {
    S* col = c.derived().data() + j * c.derived().outerStride();
    if (out.relu) {
      Eigen::Map<Eigen::Array<S, Eigen::Dynamic, 1>> v(col, m);
      v = v.max(S(0));
    }
    if (out.mask != nullptr) internal::MultiplyByPositiveIndicator(col, out.mask + j * out.mask_ld, m);
  }
}

}  // namespace diffdyn
