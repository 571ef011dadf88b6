// Summary statistics of evaluation runs (costs, timings, success rates).
//
//   std::vector<double> costs = ...;
//   double median = diffdyn::Percentile(costs, 0.5);
//   double p90 = diffdyn::Percentile(costs, 0.9);
//   auto [low, high] = diffdyn::WilsonInterval(successes, runs);   // 95 %
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <utility>
#include <vector>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {

/// The nearest-rank percentile: the smallest value v_(k) of the sorted values with
/// k = max(1, ceil(p n)), p in [0, 1]. Throws diffdyn::Error for no values.
inline double Percentile(std::vector<double> values, double p) {
  DIFFDYN_CHECK(!values.empty(), "Percentile of no values");
  std::sort(values.begin(), values.end());
  const auto rank = static_cast<std::size_t>(std::ceil(p * static_cast<double>(values.size())));
  return values[std::min(values.size() - 1, rank == 0 ? 0 : rank - 1)];
}

/// Wilson score interval for a binomial proportion s / n (z = 1.96: 95 %):
///   (p + z^2/2n -+ z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n),  p = s / n.
/// Throws diffdyn::Error unless 0 <= successes <= trials and trials >= 1.
inline std::pair<double, double> WilsonInterval(int successes, int trials, double z = 1.96) {
  DIFFDYN_CHECK(trials >= 1 && successes >= 0 && successes <= trials,
                "WilsonInterval: need 0 <= successes <= trials and trials >= 1, got ", successes, " of ", trials);
  DIFFDYN_CHECK(std::isfinite(z) && z > 0, "WilsonInterval: z must be positive, got ", z);
  const double n = trials, p = successes / n, z2 = z * z;
  const double denom = 1 + z2 / n;
  const double centre = (p + z2 / (2 * n)) / denom;
  const double half = z * std::sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / denom;
  return {std::max(0.0, centre - half), std::min(1.0, centre + half)};
}

}  // namespace diffdyn
