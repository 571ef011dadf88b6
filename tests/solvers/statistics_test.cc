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

}  // namespace
}  // namespace diffdyn
