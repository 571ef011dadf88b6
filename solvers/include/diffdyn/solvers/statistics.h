// Summary statistics of evaluation runs (costs, timings).
//
//   std::vector<double> costs = ...;
//   double median = diffdyn::Percentile(costs, 0.5);
//   double p90 = diffdyn::Percentile(costs, 0.9);
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
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

}  // namespace diffdyn
