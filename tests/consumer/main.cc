// Uses diffdyn's installed headers and libraries from another project: fixed-size
// Eigen types, Jets and heap-allocated matrices cross the library boundary both ways
// (made here and filled there, made there and freed here), compiled with or without
// -march=native, and the answers must still be right.
#include <cmath>
#include <cstdio>
#include <fstream>

#include <Eigen/Core>
#include <ceres/jet.h>

#include "diffdyn/models/parallel.h"
#include "diffdyn/models/random.h"
#include "diffdyn/physics/pushing/ode_engine.h"
#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/load_model.h"
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

  // Matrices allocated by the library and freed here, and the other way round.
  const char* csv = "consumer_joint.csv";
  std::ofstream(csv) << "t,q1,qd1,tau1\n0,0.1,0,0\n0.01,0.1,0,0\n0.02,0.1,0,0\n";
  const diffdyn::Dataset data = diffdyn::ReadDataset(csv);
  ok = ok && data.samples() == 3 && data.trajectories[0].states(0, 2) == 0.1;
  const auto pendulum = diffdyn::LoadTransitionModel("pendulum", {.dt = 0.01});
  auto ws = pendulum->MakeWorkspace(2);
  Eigen::MatrixXd states(2, 2), torques = Eigen::MatrixXd::Zero(1, 2), next(2, 2);
  states << 0.0, 0.3, 0.0, 0.0;
  pendulum->PredictBatch(states, torques, next, *ws);
  // At rest at the bottom it stays; at q = 0.3 gravity pulls it back (qd < 0).
  ok = ok && next.col(0).norm() == 0.0 && next(1, 1) < 0.0;
  std::printf("diffdyn %s consumer: %s\n", diffdyn::Version().c_str(), ok ? "ok" : "FAILED");
  return ok ? 0 : 1;
}
