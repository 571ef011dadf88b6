// Uses diffdyn's installed headers and libraries from another project: fixed-size
// Eigen types and Jets cross the library boundary, compiled with or without
// -march=native, and the answers must still be right.
#include <cmath>
#include <cstdio>

#include <Eigen/Core>
#include <ceres/jet.h>

#include "diffdyn/autodiff_ode/parallel.h"
#include "diffdyn/autodiff_ode/random.h"
#include "diffdyn/physics/ode_engine.h"
#include "diffdyn/solvers/version.h"

int main() {
  using Jet = ceres::Jet<double, 4>;
  Eigen::Matrix<Jet, 4, 1> x;
  for (int i = 0; i < 4; ++i) x[i] = Jet(0.5 * i, i);
  const Jet f = x.squaredNorm();  // df/dx_i = 2 x_i
  bool ok = true;
  for (int i = 0; i < 4; ++i) ok = ok && std::abs(f.v[i] - 2.0 * 0.5 * i) < 1e-15;

  diffdyn::Rng rng(7);
  std::vector<double> parts(diffdyn::NumChunks(1000, 100));
  diffdyn::ParallelForChunks(1000, 100, 2, [&](int c, int begin, int end) {
    for (int i = begin; i < end; ++i) parts[c] += i;
  });
  double sum = 0;
  for (double p : parts) sum += p;
  ok = ok && sum == 999.0 * 1000.0 / 2.0 && diffdyn::UniformUnit(rng) < 1.0;
  ok = ok && diffdyn::OdeEngine::IsDoublePrecision() && !diffdyn::Version().empty();
  std::printf("diffdyn %s consumer: %s\n", diffdyn::Version().c_str(), ok ? "ok" : "FAILED");
  return ok ? 0 : 1;
}
