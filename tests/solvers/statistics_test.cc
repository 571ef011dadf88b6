// Percentile: nearest rank on unsorted values, the ends, and no values refused.
#include "diffdyn/solvers/statistics.h"

#include <vector>

#include <gtest/gtest.h>

namespace diffdyn {
namespace {

TEST(Percentile, NearestRankOfUnsortedValues) {
  const std::vector<double> v = {5, 1, 4, 2, 3, 10, 9, 8, 7, 6};
  EXPECT_EQ(Percentile(v, 0.5), 5);   // k = 5
  EXPECT_EQ(Percentile(v, 0.9), 9);   // k = 9
  EXPECT_EQ(Percentile(v, 0.91), 10);  // k = ceil(9.1) = 10
  EXPECT_EQ(Percentile(v, 0.0), 1);
  EXPECT_EQ(Percentile(v, 1.0), 10);
  EXPECT_EQ(Percentile({3.5}, 0.5), 3.5);
}

TEST(Percentile, NoValuesIsAnError) { EXPECT_THROW((void)Percentile({}, 0.5), Error); }

TEST(WilsonInterval, MatchesClosedFormValues) {
  // 0 of n: (0, z^2 / (n + z^2)); n of n: (n / (n + z^2), 1).
  const double z2 = 1.96 * 1.96;
  auto [lo0, hi0] = WilsonInterval(0, 10);
  EXPECT_NEAR(lo0, 0.0, 1e-12);
  EXPECT_NEAR(hi0, z2 / (10 + z2), 1e-12);
  EXPECT_NEAR(hi0, 0.27754, 1e-5);
  auto [lo1, hi1] = WilsonInterval(10, 10);
  EXPECT_NEAR(lo1, 10 / (10 + z2), 1e-12);
  EXPECT_NEAR(hi1, 1.0, 1e-12);
  // 5 of 10: the textbook 0.2366 .. 0.7634.
  auto [lo, hi] = WilsonInterval(5, 10);
  EXPECT_NEAR(lo, 0.23659, 1e-5);
  EXPECT_NEAR(hi, 0.76341, 1e-5);
  // Symmetry s <-> n - s, and the interval narrows with n.
  auto [a, b] = WilsonInterval(3, 20);
  auto [c, d] = WilsonInterval(17, 20);
  EXPECT_NEAR(a, 1 - d, 1e-12);
  EXPECT_NEAR(b, 1 - c, 1e-12);
  auto [e, f] = WilsonInterval(30, 200);
  EXPECT_LT(f - e, b - a);
  EXPECT_LT(e, 0.15);
  EXPECT_GT(f, 0.15);
}

TEST(WilsonInterval, RejectsImpossibleCounts) {
  EXPECT_THROW(WilsonInterval(0, 0), Error);
  EXPECT_THROW(WilsonInterval(-1, 5), Error);
  EXPECT_THROW(WilsonInterval(6, 5), Error);
}

}  // namespace
}  // namespace diffdyn
