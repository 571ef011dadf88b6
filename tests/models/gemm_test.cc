// Gemm (the BLAS or Eigen matrix product of the batched network paths) against
// Eigen's own products: all four transpose cases, blocks with an outer stride,
// beta = 0 over NaN, beta = 1 accumulation, and empty sizes; float operands
// (sgemm) against the double product of the same values.
#include "diffdyn/models/gemm.h"

#include <gtest/gtest.h>

#include <limits>

#include <Eigen/Dense>

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

}  // namespace
}  // namespace diffdyn
