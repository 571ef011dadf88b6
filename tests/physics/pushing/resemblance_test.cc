// The ODE-engine data resemble the seed's PyBullet data under the same action
// distribution: per-push |dx|, |dy|, |dtheta| means within a factor of 2, and
// medians and 90th percentiles within a factor of 2 in each of the four classes
// push_length < / >= 0.5 x |push_angle| < / >= 0.75.
#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <vector>

#include <gtest/gtest.h>

#include "diffdyn/physics/pushing/collect.h"
#include "diffdyn/physics/pushing/csv.h"

namespace diffdyn {
namespace {

struct Push {
  std::array<double, 3> change;  // |dx|, |dy|, |dtheta|
  double length, angle;
};

std::vector<Push> Pushes(const std::vector<Trajectory>& data) {
  std::vector<Push> pushes;
  for (const auto& t : data) {
    for (int s = 0; s < t.transitions(); ++s) {
      const Eigen::Vector3d d = (t.states.col(s + 1) - t.states.col(s)).cwiseAbs();
      pushes.push_back({{d.x(), d.y(), d.z()}, t.actions(2, s), std::abs(t.actions(1, s))});
    }
  }
  return pushes;
}

double Quantile(std::vector<double> v, double p) {
  std::sort(v.begin(), v.end());
  const double i = p * (v.size() - 1);
  const size_t lo = static_cast<size_t>(i);
  const size_t hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (v[hi] - v[lo]) * (i - lo);
}

TEST(PushingResemblance, OdeDataMatchPybulletWithinFactorTwo) {
  const auto pybullet = Pushes(ReadPushingCsv(std::filesystem::path(DIFFDYN_SHARED_DATA_DIR) /
                                              "pybullet_pushing/collected_data.csv"));
  CollectOptions options;
  options.trajectories = 100;
  options.length = 10;
  options.seed = 2024;
  options.threads = 2;
  options.world.obstacle = false;  // the seed collected its data without the obstacle
  const auto ode = Pushes(CollectPushingData(options));
  ASSERT_GE(ode.size(), 900u);

  const char* names[3] = {"|dx|", "|dy|", "|dtheta|"};
  for (int k = 0; k < 3; ++k) {
    double mo = 0, mp = 0;
    for (const auto& p : ode) mo += p.change[k] / ode.size();
    for (const auto& p : pybullet) mp += p.change[k] / pybullet.size();
    EXPECT_GT(mo / mp, 0.5) << names[k] << " mean ode " << mo << " pybullet " << mp;
    EXPECT_LT(mo / mp, 2.0) << names[k] << " mean ode " << mo << " pybullet " << mp;
  }
  for (const bool short_push : {true, false}) {
    for (const bool small_angle : {true, false}) {
      auto select = [&](const std::vector<Push>& all, int k) {
        std::vector<double> v;
        for (const auto& p : all) {
          if ((p.length < 0.5) == short_push && (p.angle < 0.75) == small_angle) v.push_back(p.change[k]);
        }
        return v;
      };
      for (int k = 0; k < 3; ++k) {
        const auto o = select(ode, k), p = select(pybullet, k);
        ASSERT_GE(o.size(), 100u);
        for (const double q : {0.5, 0.9}) {
          const double ratio = Quantile(o, q) / Quantile(p, q);
          EXPECT_GT(ratio, 0.5) << names[k] << " q" << q << " length<0.5=" << short_push
                                << " |angle|<0.75=" << small_angle;
          EXPECT_LT(ratio, 2.0) << names[k] << " q" << q << " length<0.5=" << short_push
                                << " |angle|<0.75=" << small_angle;
        }
      }
    }
  }
}

}  // namespace
}  // namespace diffdyn
