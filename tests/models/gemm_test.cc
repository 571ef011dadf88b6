// Gemm (the BLAS or Eigen matrix product of the batched network paths) against
// Eigen's own products: all four transpose cases, blocks with an outer stride,
// beta = 0 over NaN, beta = 1 accumulation, and empty sizes; float operands
// (sgemm) against the double product of the same values.
#include "diffdyn/models/gemm.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <utility>
#include <vector>

namespace diffdyn {
namespace {

TEST(Gemm, MatchesEigenForEveryTransposeOnStridedBlocks) {
  const int m = 7, n = 5, k = 9;
  Eigen::MatrixXd big_a = Eigen::MatrixXd::Random(12, 12);
  Eigen::MatrixXd big_b = Eigen::MatrixXd::Random(11, 13);
  for (bool ta : {false, true}) {
    for (bool tb : {false, true}) {
      const auto a = big_a.block(1, 2, ta ? k : m, ta ? m : k);
      const auto b = big_b.block(2, 1, tb ? n : k, tb ? k : n);
      const Eigen::MatrixXd op_a = ta ? Eigen::MatrixXd(a.transpose()) : Eigen::MatrixXd(a);
      const Eigen::MatrixXd op_b = tb ? Eigen::MatrixXd(b.transpose()) : Eigen::MatrixXd(b);
      Eigen::MatrixXd c_big = Eigen::MatrixXd::Random(10, 8);
      const Eigen::MatrixXd c0 = c_big.topLeftCorner(m, n);
      const Eigen::MatrixXd outside = c_big.rightCols(1);
      Gemm(0.5, a, ta, b, tb, 1.0, c_big.topLeftCorner(m, n));
      const Eigen::MatrixXd expected = c0 + 0.5 * op_a * op_b;
      EXPECT_LT((c_big.topLeftCorner(m, n) - expected).cwiseAbs().maxCoeff(), 1e-13)
          << "ta " << ta << " tb " << tb << (GemmUsesBlas() ? " (BLAS)" : " (Eigen)");
      // Entries outside the block are untouched.
      EXPECT_EQ(c_big.rightCols(1), outside);
    }
  }
}

TEST(Gemm, BetaZeroOverwritesNaNAndEmptyInnerSizeScalesC) {
  const Eigen::MatrixXd a = Eigen::MatrixXd::Random(4, 3);
  const Eigen::MatrixXd b = Eigen::MatrixXd::Random(3, 2);
  Eigen::MatrixXd c = Eigen::MatrixXd::Constant(4, 2, std::numeric_limits<double>::quiet_NaN());
  Gemm(1.0, a, false, b, false, 0.0, c);
  EXPECT_TRUE(c.allFinite());
  EXPECT_LT((c - a * b).cwiseAbs().maxCoeff(), 1e-14);

  const Eigen::MatrixXd a0(4, 0), b0(0, 2);
  Eigen::MatrixXd d = Eigen::MatrixXd::Ones(4, 2);
  Gemm(1.0, a0, false, b0, false, 3.0, d);
  EXPECT_EQ(d, Eigen::MatrixXd::Constant(4, 2, 3.0));
  Gemm(1.0, a0, false, b0, false, 0.0, d);
  EXPECT_EQ(d, Eigen::MatrixXd::Zero(4, 2));

  Eigen::MatrixXd empty(0, 2);
  Gemm(1.0, Eigen::MatrixXd(0, 3), false, b, false, 0.0, empty);
  EXPECT_EQ(empty.size(), 0);
}

TEST(Gemm, FloatOperandsMatchTheDoubleProductToFloatRounding) {
  const int m = 37, n = 23, k = 101;
  const Eigen::MatrixXf big_a = Eigen::MatrixXf::Random(k + 3, k + 3);
  const Eigen::MatrixXf b = Eigen::MatrixXf::Random(k, n);
  for (bool ta : {false, true}) {
    const auto a = big_a.block(2, 1, ta ? k : m, ta ? m : k);
    const Eigen::MatrixXd op_a = ta ? Eigen::MatrixXd(a.transpose().cast<double>())
                                    : Eigen::MatrixXd(a.cast<double>());
    Eigen::MatrixXf c = Eigen::MatrixXf::Constant(m, n, std::numeric_limits<float>::quiet_NaN());
    Gemm(2.0f, a, ta, b, false, 0.0f, c);
    const Eigen::MatrixXd expected = 2.0 * op_a * b.cast<double>();
    // k terms of size <= 1, each rounded once: well under k float epsilons.
    const double gap = (c.cast<double>() - expected).cwiseAbs().maxCoeff();
    EXPECT_LT(gap, k * std::numeric_limits<float>::epsilon()) << "ta " << ta;
    EXPECT_GT(gap, 0.0) << "ta " << ta << ": the product ran in double";
  }
}

// C with rows `ms`, columns `ns` and sums of 1 to 300 terms (the thin kernel runs 2
// to two SIMD vectors' rows and at most 256 terms where it is built, the panel kernel
// more rows on AVX-512, BLAS or Eigen the others): both layouts of B, alpha and beta,
// beta = 0 over NaN, strided blocks, and A as an exactly sized buffer (its last
// columns must not be read past the end: the sanitizer build checks).
template <typename S>
void CheckProducts(std::initializer_list<int> ms, std::initializer_list<int> ns) {
  using Matrix = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;
  const S nan = std::numeric_limits<S>::quiet_NaN();
  for (int m : ms) {
    for (int n : ns) {
    for (int k : {1, 5, 100, 256, 300}) {
      for (bool tb : {false, true}) {
        std::vector<S> a_data(std::size_t(m) * k);
        Eigen::Map<Matrix> a(a_data.data(), m, k);
        a = Matrix::Random(m, k);
        Matrix big_b = Matrix::Random(k + n + 4, k + n + 4);
        const auto b = big_b.block(1, 2, tb ? n : k, tb ? k : n);
        const Eigen::MatrixXd op_b = tb ? Eigen::MatrixXd(b.transpose().template cast<double>())
                                        : Eigen::MatrixXd(b.template cast<double>());
        const Eigen::MatrixXd exact = a.template cast<double>() * op_b;
        Matrix c_big = Matrix::Random(m + 3, n + 2);
        const Eigen::MatrixXd c0 = c_big.topLeftCorner(m, n).template cast<double>();
        const Matrix outside = c_big.bottomRows(3);
        Gemm(S(0.5), a, false, b, tb, S(2), c_big.topLeftCorner(m, n));
        const double tol = 4.0 * (k + 2) * std::numeric_limits<S>::epsilon();
        EXPECT_LT((c_big.topLeftCorner(m, n).template cast<double>() - (2.0 * c0 + 0.5 * exact))
                      .cwiseAbs()
                      .maxCoeff(),
                  tol)
            << "m " << m << " k " << k << " tb " << tb;
        EXPECT_EQ(c_big.bottomRows(3), outside);
        c_big.topLeftCorner(m, n).setConstant(nan);
        Gemm(S(1), a, false, b, tb, S(0), c_big.topLeftCorner(m, n));
        EXPECT_LT((c_big.topLeftCorner(m, n).template cast<double>() - exact).cwiseAbs().maxCoeff(),
                  tol)
            << "m " << m << " k " << k << " tb " << tb;
      }
    }
    }
  }
}

TEST(Gemm, ThinProductsMatchTheExactProductInDoubleAndFloat) {
  CheckProducts<double>({1, 2, 3, 6, 8, 9, 16, 17}, {13});
  CheckProducts<float>({1, 2, 3, 6, 8, 9, 16, 17}, {13});
}

// Rows past the thin kernel's: whole and partial row panels (16 doubles or 32 floats
// on AVX-512) and column groups of 12, and n = 700, where op(B) of 256 or 300 terms
// is cut into column blocks.
TEST(Gemm, PanelProductsMatchTheExactProductInDoubleAndFloat) {
  CheckProducts<double>({18, 24, 33, 100}, {1, 12, 25, 700});
  CheckProducts<float>({33, 47, 64, 100}, {1, 12, 25, 700});
}

// The panel kernel also sums each entry over k in order from zero: splitting C's rows
// and columns into other panels, groups and blocks gives the same bits.
TEST(Gemm, PanelProductDoesNotDependOnTheSplitOfC) {
  if (!kHavePanelGemm) GTEST_SKIP() << "the panel kernel is built for AVX-512 only";
  const Eigen::MatrixXd a = Eigen::MatrixXd::Random(100, 256);
  const Eigen::MatrixXd b = Eigen::MatrixXd::Random(700, 256);
  Eigen::MatrixXd whole = Eigen::MatrixXd::Ones(100, 700), parts = whole;
  Gemm(1.0, a, false, b, true, 1.0, whole);
  for (int i = 0; i < 100; i += 37) {
    const int h = std::min(37, 100 - i);
    for (int s = 0; s < 700; s += 101) {
      const int w = std::min(101, 700 - s);
      Gemm(1.0, a.middleRows(i, h), false, b.middleRows(s, w), true, 1.0,
           parts.block(i, s, h, w));
    }
  }
  EXPECT_TRUE(whole == parts) << "largest gap " << (whole - parts).cwiseAbs().maxCoeff();
}

// The thin kernel sums each entry over k in order from zero, then adds it to C:
// the same arithmetic as one accumulator per entry, so splitting the columns of
// B (a different grouping) gives the same bits.
TEST(Gemm, ThinProductDoesNotDependOnTheColumnGrouping) {
  if (!kHaveLayerKernel) GTEST_SKIP() << "the thin kernel is built for AVX2 or AVX-512 only";
  const Eigen::MatrixXf a = Eigen::MatrixXf::Random(6, 100);
  const Eigen::MatrixXf b = Eigen::MatrixXf::Random(100, 250);
  Eigen::MatrixXf whole = Eigen::MatrixXf::Ones(6, 250), parts = whole;
  Gemm(1.0f, a, false, b, false, 1.0f, whole);
  for (int s = 0; s < 250; s += 7) {
    const int w = std::min(7, 250 - s);
    Gemm(1.0f, a, false, b.middleCols(s, w), false, 1.0f, parts.middleCols(s, w));
  }
  EXPECT_TRUE(whole == parts) << "largest gap " << (whole - parts).cwiseAbs().maxCoeff();
}

// Where C's rows fill at most half a vector the thin kernel holds two columns per
// vector (internal::PairedColumns), or, on AVX-512 with fewer rows and B
// untransposed, transposes B's columns in registers for C^T = B^T A^T
// (internal::TransposedColumns). Each entry is summed as with one vector per column,
// so the bits are those of the two-vector thin kernel (which does neither): m = 1 to
// half a vector, both layouts of B, sums of 1, 16, 100 and 256 terms (whole and
// partial vectors of k), odd and even column counts (an odd last column pairs with
// itself; a last tile of fewer columns repeats one), NaN in C with beta 0, strided C.
// With alpha = 1 and beta 0 or 1 (a layer's products) the same bits; with other alpha
// and beta within a rounding of their products (the compiler may fuse either into the
// last add). The output stages on these kernels (thin C and the panel kernel's last
// rows) are checked against BLAS and one pass per stage in CheckFusedStages.
template <typename S>
void CheckHalfVectorKernels() {
#if DIFFDYN_LAYER_KERNEL
  using Matrix = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;
  const int half = internal::LayerShape<S>::kLanes / 2;
  for (int m = 1; m <= half; ++m) {
    for (int n : {1, 2, 15, 16, 17, 250}) {
      for (bool tb : {false, true}) {
        for (int k : {1, 16, 100, 256}) {
          std::vector<S> a_data(std::size_t(m) * k);  // exactly sized: no reads past A
          Eigen::Map<Matrix> a(a_data.data(), m, k);
          a = Matrix::Random(m, k);
          const Matrix b = tb ? Matrix::Random(n, k) : Matrix::Random(k, n);
          for (S beta : {S(0), S(1), S(0.5)}) {
            Matrix one_vector = Matrix::Random(m + 2, n);
            if (beta == S(0)) one_vector(0, 0) = std::numeric_limits<S>::quiet_NaN();
            Matrix two_vectors = one_vector;
            const S alpha = beta == S(0.5) ? S(0.75) : S(1);
            auto run = [&](auto kernel, Matrix& c) {
              kernel(m, n, k, alpha, a.data(), m, b.data(), static_cast<int>(b.rows()), beta,
                     c.data(), m + 2);
            };
            if (tb) {
              run(internal::ThinGemm<S, 1, true>, one_vector);
              run(internal::ThinGemm<S, 2, true>, two_vectors);
            } else {
              run(internal::ThinGemm<S, 1, false>, one_vector);
              run(internal::ThinGemm<S, 2, false>, two_vectors);
            }
            const S gap = (one_vector - two_vectors).cwiseAbs().maxCoeff();
            if (alpha == S(1)) {
              EXPECT_TRUE(one_vector == two_vectors)
                  << "m " << m << " n " << n << " tb " << tb << " k " << k << " beta " << beta
                  << ", largest gap " << gap;
            } else {
              EXPECT_LT(gap,
                        8 * std::numeric_limits<S>::epsilon() * one_vector.cwiseAbs().maxCoeff())
                  << "m " << m << " n " << n << " tb " << tb << " k " << k;
            }
          }
        }
      }
    }
  }
#endif
}

TEST(Gemm, HalfVectorKernelsHaveTheThinKernelsBits) {
  if (!kHaveLayerKernel) GTEST_SKIP() << "the thin kernel is built for AVX2 or AVX-512 only";
  CheckHalfVectorKernels<double>();
  CheckHalfVectorKernels<float>();
}

// A thin C times a transposed B (a thin layer's weight gradient, 6 x 100 += abar
// 6 x 250 h^T) runs as its transpose on the panel kernel where C's rows fill at most
// half a vector: the same sums in the same order as the thin kernel, so with alpha = 1
// and beta 0 (NaN in C overwritten) or 1, a layer's products, the same bits; with
// other alpha and beta within a rounding of alpha's and beta's products. C is a
// strided block.
template <typename S>
void CheckTransposedThinProduct() {
#if DIFFDYN_LAYER_KERNEL
  using Matrix = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;
  struct Scales {
    S alpha, beta;
    bool same_bits;
  };
  for (int m : {2, 3, 4, 6, 8}) {
    if (m > internal::LayerShape<S>::kLanes) continue;
    const Matrix a = Matrix::Random(m, 250);
    const Matrix b = Matrix::Random(100, 250);
    for (Scales scales : {Scales{S(1), S(0), true}, Scales{S(1), S(1), true},
                          Scales{S(0.75), S(0.5), false}}) {
      Matrix big = Matrix::Random(m + 2, 100);
      if (scales.beta == S(0)) big(0, 0) = std::numeric_limits<S>::quiet_NaN();
      Matrix thin = big;
      Gemm(scales.alpha, a, false, b, true, scales.beta, big.topRows(m));
      internal::ThinGemm<S, 1, true>(m, 100, 250, scales.alpha, a.data(), m, b.data(), 100,
                                     scales.beta, thin.data(), m + 2);
      const S gap = (big - thin).cwiseAbs().maxCoeff();
      if (scales.same_bits) {
        EXPECT_TRUE(big == thin) << "m " << m << " beta " << scales.beta << ", largest gap " << gap;
      } else {
        EXPECT_LT(gap, 8 * std::numeric_limits<S>::epsilon() * big.cwiseAbs().maxCoeff())
            << "m " << m;
      }
    }
  }
#endif
}

TEST(Gemm, ThinProductWithTransposedBHasTheThinKernelsBits) {
  if (!kHaveLayerKernel) GTEST_SKIP() << "the thin kernel is built for AVX2 or AVX-512 only";
  CheckTransposedThinProduct<double>();
  CheckTransposedThinProduct<float>();
}

// Same value in x and y: equal with the same sign (so -0 against +0 differs), or
// both NaN.
template <typename S>
bool SameValue(S x, S y) {
  return (std::isnan(x) && std::isnan(y)) || (x == y && std::signbit(x) == std::signbit(y));
}

// GemmFused's stages (bias, ReLU, mask; each alone and together) give the values of
// the product followed by one pass per stage: with and without the thin and panel
// kernels (rows 1 to 100, 6 and 100 terms), both layouts of B, strided C and mask,
// NaN in B and in the mask, negative zeros and zeros in the mask.
template <typename S>
void CheckFusedStages() {
  using Matrix = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;
  using Vector = Eigen::Matrix<S, Eigen::Dynamic, 1>;
  const S nan = std::numeric_limits<S>::quiet_NaN();
  for (int m : {1, 6, 17, 33, 100}) {
    for (int n : {1, 13, 250}) {
      for (int k : {6, 100}) {
        for (bool tb : {false, true}) {
          const Matrix a = Matrix::Random(m, k);
          Matrix big_b = Matrix::Random(k + n + 2, k + n + 2);
          auto b = big_b.block(1, 1, tb ? n : k, tb ? k : n);
          b(0, 0) = nan;  // one entry of C's column 0 (tb: row 0 of every column) is NaN
          const Vector bias = Vector::Random(m);
          Matrix big_mask = Matrix::Random(m + 2, n);
          auto mask = big_mask.topRows(m);
          mask(0, n - 1) = nan;
          mask(m - 1, 0) = S(-0.0);
          mask(m / 2, n / 2) = S(0);
          for (int stages = 1; stages < 8; ++stages) {
            GemmOutput<S> out;
            if (stages & 1) out.bias = bias.data();
            out.relu = (stages & 2) != 0;
            if (stages & 4) {
              out.mask = mask.data();
              out.mask_ld = big_mask.rows();
            }
            Matrix expected(m, n);
            if (out.bias) {
              expected.colwise() = bias;
              Gemm(S(1), a, false, b, tb, S(1), expected);
            } else {
              Gemm(S(1), a, false, b, tb, S(0), expected);
            }
            for (int j = 0; j < n; ++j) {
              for (int i = 0; i < m; ++i) {
                S& t = expected(i, j);
                if (out.relu) t = std::max(t, S(0));
                if (out.mask) t = t * (mask(i, j) > S(0) ? S(1) : S(0));
              }
            }
            Matrix c_big = Matrix::Constant(m + 3, n + 1, nan);
            c_big.bottomRows(3).setOnes();
            GemmFused(a, false, b, tb, out, c_big.topLeftCorner(m, n));
            int differ = 0;
            for (int j = 0; j < n; ++j) {
              for (int i = 0; i < m; ++i) differ += !SameValue(c_big(i, j), expected(i, j));
            }
            EXPECT_EQ(differ, 0) << "m " << m << " n " << n << " k " << k << " tb " << tb
                                 << " stages " << stages;
            EXPECT_TRUE((c_big.bottomRows(3).array() == S(1)).all());
          }
        }
      }
    }
  }
}

TEST(GemmFused, StagesGiveTheValuesOfTheProductThenOnePassEachInDoubleAndFloat) {
  CheckFusedStages<double>();
  CheckFusedStages<float>();
}

// TransposeInto against Eigen's transpose, entry for entry, on shapes with whole
// SIMD blocks, partial ones on either side and neither, from a strided A; entries of
// out past A^T's (the buffer's tail) stay untouched.
template <typename S>
void CheckTransposeInto() {
  using M = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;
  for (const auto& [rows, cols] : std::vector<std::pair<int, int>>{
           {1, 1}, {3, 100}, {100, 6}, {6, 100}, {8, 8}, {16, 16}, {17, 33}, {100, 100}, {64, 9}}) {
    const int lda = rows + 5;
    const M a = M::Random(lda, cols);
    std::vector<S> out(static_cast<size_t>(rows) * cols + 7, S(-7));
    internal::TransposeInto<S>(rows, cols, a.data(), lda, out.data());
    const M expected = a.topRows(rows).transpose();
    const Eigen::Map<const M> got(out.data(), cols, rows);
    EXPECT_TRUE(got == expected) << rows << " x " << cols;
    for (size_t e = static_cast<size_t>(rows) * cols; e < out.size(); ++e) EXPECT_EQ(out[e], S(-7));
  }
}

TEST(TransposeInto, MatchesEigensTransposeOnEveryEdgeInDoubleAndFloat) {
  CheckTransposeInto<double>();
  CheckTransposeInto<float>();
}

}  // namespace
}  // namespace diffdyn
