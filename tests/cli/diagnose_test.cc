// diffdyn diagnose end to end: the JSON contract (noise_std, not_identifiable),
// an extended model fed back through --model, which has nothing missing, and an
// unactuated joint that must not carry a system-wide effect through the gate.
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "run_diffdyn.h"

namespace diffdyn {
namespace {

using testing::RunDiffdyn;
using testing::SummaryJson;
using testing::TempPath;

// A pendulum with hidden viscous friction: diagnose names it; fed back on a
// fresh record of the same plant, the extended model has nothing missing.
TEST(Diagnose, AnExtendedModelFedBackHasNothingMissing) {
  const std::string a = TempPath("diag_fed_a.csv"), b = TempPath("diag_fed_b.csv");
  for (const auto& [file, seed] : {std::pair{a, 5}, std::pair{b, 6}}) {
    ASSERT_EQ(RunDiffdyn("collect --system pendulum --effect viscous:1=0.2 --trajectories 20 --quiet --seed " +
                         std::to_string(seed) + " --out " + file)
                  .exit_code,
              0);
  }
  const std::string first = TempPath("diag_fed_first"), second = TempPath("diag_fed_second");
  const auto j = SummaryJson(
      RunDiffdyn("diagnose --model pendulum --measured " + a + " --json --out " + first));
  bool viscous = false;
  for (const auto& e : j.at("named_effects")) {
    if (e.at("kind") == "viscous") viscous = std::abs(e.at("value").get<double>() - 0.2) < 0.03;
    if (e.at("value").is_number()) {
      EXPECT_GE(e.at("value").get<double>(), 0.0) << e.dump();
    }
  }
  EXPECT_TRUE(viscous) << j.at("named_effects").dump();
  ASSERT_EQ(j.at("noise_std").size(), 1u);
  EXPECT_GT(j.at("noise_std")[0].get<double>(), 0.0);
  EXPECT_TRUE(j.at("not_identifiable").is_array());

  const auto k =
      SummaryJson(RunDiffdyn("diagnose --model " + first + "/extended_model.json --measured " + b +
                             " --json --out " + second));
  EXPECT_TRUE(k.at("no_significant_discrepancy").get<bool>()) << k.at("named_effects").dump();
  EXPECT_TRUE(k.at("named_effects").empty());
  EXPECT_LT(k.at("heldout_sse_removed").get<double>(), 0.05);
}

// The cart-pole task drives the cart only: the pole's torque is zero throughout,
// so its noise sigma is 0. A system-wide effect (gain, payload, delay) is sized on
// the joints with a torque signal; counting the pole (size infinite) named a gain
// of 1.006 on this record.
TEST(Diagnose, AnUnactuatedJointDoesNotPassASystemWideEffect) {
  const std::string data = TempPath("diag_cartpole_task.csv");
  ASSERT_EQ(RunDiffdyn("collect --system cartpole --seed 3 --trajectories 20 --quiet --out " + data).exit_code, 0);
  const auto j = SummaryJson(RunDiffdyn("diagnose --model cartpole --measured " + data +
                                        " --json --out " + TempPath("diag_cartpole_task")));
  EXPECT_EQ(j.at("noise_std")[1].get<double>(), 0.0);
  for (const auto& e : j.at("named_effects")) EXPECT_NE(e.at("joint").get<int>(), 0) << e.dump();
}

TEST(Diagnose, RefusesAModelThatIsNeitherANameNorAFile) {
  const auto r = RunDiffdyn("diagnose --model robot --measured " + std::string(DIFFDYN_SHARED_DATA_DIR) +
                            "/panda_gaz2019_traj1 --out " + TempPath("diag_refused"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--model"), std::string::npos) << r.err;
}

// The first `count` trajectories of the seed's PyBullet pushing data, as a CSV.
std::string PyBulletSubset(const std::string& name, int count) {
  std::ifstream in(std::string(DIFFDYN_SHARED_DATA_DIR) + "/pybullet_pushing/collected_data.csv");
  const std::string path = TempPath(name);
  std::ofstream out(path);
  std::string line;
  for (int row = 0; row < 1 + 11 * count && std::getline(in, line); ++row) out << line << '\n';
  return path;
}

// The pusher against PyBullet's pushes, end to end on six trajectories: the
// calibrated world is written and collect and push take it; bad input is refused.
TEST(Diagnose, CalibratesThePusherAndItsWorldIsTakenByCollectAndPush) {
  const std::string data = PyBulletSubset("diag_pybullet6.csv", 6), out = TempPath("diag_pusher");
  const auto j = SummaryJson(
      RunDiffdyn("diagnose --model pushing --measured " + data + " --out " + out +
                 " --fit-param block_table_friction --fit-transitions 12 --max-iterations 2"
                 " --holdout 0.2 --threads 2 --quiet --json"));
  EXPECT_EQ(j.at("model"), "pushing");
  EXPECT_EQ(j.at("n_samples").get<int>(), 20);  // two held-out trajectories of ten pushes
  ASSERT_EQ(j.at("nominal_rmse").size(), 3u);
  ASSERT_EQ(j.at("parameters").size(), 1u);
  EXPECT_EQ(j.at("parameters")[0].at("name"), "block_table_friction");
  EXPECT_GT(j.at("nominal_loss").get<double>(), 0.0);
  EXPECT_LT(j.at("nominal_loss").get<double>(), j.at("identity_loss").get<double>());
  for (const char* file : {"report.md", "calibrated_pusher.json", "replays.csv", "rollouts.csv"}) {
    EXPECT_TRUE(std::filesystem::exists(std::filesystem::path(out) / file)) << file;
  }
  const std::string world = out + "/calibrated_pusher.json";
  EXPECT_EQ(RunDiffdyn("collect --world " + world + " --trajectories 1 --length 1 --quiet --out " +
                       TempPath("diag_pusher_collect.csv"))
                .exit_code,
            0);
  EXPECT_EQ(RunDiffdyn("eval --model " + world + " --data " + data + " --quiet").exit_code, 0);

  // Bad input: one line naming the option, exit 2, nothing written.
  const std::string refused = TempPath("diag_pusher_refused");
  const std::string joint_space = TempPath("diag_pusher_joint_space.csv");
  std::ofstream(joint_space) << "t,q1,qd1,tau1\n0,0,0,0\n0.1,0,0,0\n";
  for (const std::string& args :
       {"--measured " + joint_space, "--measured " + data + " --fit-param table_colour",
        "--measured " + data + " --fit-param tip_pad_x",
        "--measured " + data + " --param block_mass=-3"}) {
    const auto r = RunDiffdyn("diagnose --model pushing " + args + " --out " + refused);
    EXPECT_EQ(r.exit_code, 2) << args << "\n" << r.err;
    EXPECT_EQ(r.err.find("error: "), 0u) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(std::filesystem::exists(refused)) << args;
  }
  const auto r =
      RunDiffdyn("collect --world " + data + " --trajectories 1 --out " + TempPath("diag_no.csv"));
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("--world"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace diffdyn
