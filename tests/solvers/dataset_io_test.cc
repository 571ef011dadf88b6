// Datasets: the joint-space CSV with a trajectory column and ground-truth channels
// read into trajectories and written back exactly; the actuated joints found from
// the data; a model's actions taken by name; errors naming the file and line; the
// real data folders read into the same type.
#include "diffdyn/solvers/dataset_io.h"

#include <filesystem>
#include <fstream>
#include <limits>
#include <string>

#include <gtest/gtest.h>

#include "diffdyn/models/random.h"

namespace diffdyn {
namespace {

std::string WriteText(const std::string& name, const std::string& text) {
  const std::string path = ::testing::TempDir() + "/" + name;
  std::ofstream(path) << text;
  return path;
}

std::string ErrorOf(const std::string& path) {
  try {
    ReadDataset(path);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

// Two labelled trajectories of a 2-joint robot, joint 2 never driven, with
// ground truth; columns in a shuffled order.
const char* kTwoRuns =
    "tau2,t,q2,trajectory,q1,qd1,qd2,tau1,g1,g2,kinetic\n"
    "0,0,0.1,a,0.2,1,2,0.5,3,4,7\n"
    "0,0.1,0.2,a,0.3,1.5,2.5,0.6,3.1,4.1,7.1\n"
    "0,0.25,0.3,a,0.4,1.6,2.6,0.7,3.2,4.2,7.2\n"
    "0,0,-0.1,b,-0.2,-1,-2,-0.5,-3,-4,1\n"
    "0,0.1,-0.2,b,-0.3,-1.5,-2.5,-0.6,-3.1,-4.1,1.1\n"
    "0,0.2,-0.3,b,-0.4,-1.6,-2.6,-0.7,-3.2,-4.2,1.2\n";

TEST(ReadDataset, JointCsvWithTrajectoriesChannelsAndActuatedJointsFromTheData) {
  const Dataset d = ReadDataset(WriteText("two_runs.csv", kTwoRuns));
  EXPECT_EQ(d.format, "joint-csv");
  ASSERT_EQ(d.trajectories.size(), 2u);
  EXPECT_EQ(d.system.state_names, (std::vector<std::string>{"q1", "q2", "qd1", "qd2"}));
  // tau2 is zero throughout: joint 2 is not actuated.
  EXPECT_EQ(d.system.action_names, std::vector<std::string>{"tau1"});
  EXPECT_EQ(d.system.angles, (std::vector<int>{0, 1}));
  const Trajectory& a = d.trajectories[0];
  EXPECT_EQ(a.label, "a");
  EXPECT_EQ(a.transitions(), 2);
  EXPECT_DOUBLE_EQ(a.states(0, 1), 0.3);   // q1
  EXPECT_DOUBLE_EQ(a.states(3, 2), 2.6);   // qd2
  EXPECT_DOUBLE_EQ(a.actions(0, 1), 0.6);  // tau1 of sample 1
  EXPECT_DOUBLE_EQ(a.channels.at("tau")(0, 2), 0.7);
  EXPECT_DOUBLE_EQ(a.channels.at("g")(1, 0), 4.0);
  EXPECT_DOUBLE_EQ(d.trajectories[1].channels.at("kinetic")(0, 2), 1.2);
  const SampleIntervals dt = d.Intervals();
  EXPECT_NEAR(dt.min, 0.1, 1e-12);
  EXPECT_NEAR(dt.max, 0.15, 1e-12);
  EXPECT_NEAR(dt.median, 0.1, 1e-12);
  // Every joint actuated, the first prismatic, on request.
  const Dataset all = ReadDataset(WriteText("two_runs.csv", kTwoRuns), {.all_actuated = true, .prismatic = {1}});
  EXPECT_EQ(all.system.action_names, (std::vector<std::string>{"tau1", "tau2"}));
  EXPECT_EQ(all.system.angles, std::vector<int>{1});
  EXPECT_THROW(ReadDataset(WriteText("two_runs.csv", kTwoRuns), {.prismatic = {3}}), Error);
}

TEST(WriteDataset, JointCsvRoundTripIsExact) {
  Dataset d = ReadDataset(WriteText("two_runs_rt.csv", kTwoRuns));
  Rng rng(4);
  for (Trajectory& t : d.trajectories) {
    for (Eigen::Index i = 0; i < t.states.size(); ++i) t.states.data()[i] = StandardNormal(rng);
  }
  // The actions come from the channel "tau" on writing; keep them consistent.
  const std::string path = ::testing::TempDir() + "/two_runs_written.csv";
  WriteDataset(path, d);
  const Dataset back = ReadDataset(path);
  ASSERT_EQ(back.trajectories.size(), d.trajectories.size());
  for (std::size_t i = 0; i < d.trajectories.size(); ++i) {
    EXPECT_EQ(back.trajectories[i].label, d.trajectories[i].label);
    EXPECT_EQ(back.trajectories[i].t, d.trajectories[i].t);
    EXPECT_EQ(back.trajectories[i].states, d.trajectories[i].states);
    EXPECT_EQ(back.trajectories[i].actions, d.trajectories[i].actions);
    EXPECT_EQ(back.trajectories[i].channels, d.trajectories[i].channels);
  }
}

TEST(ReadDataset, BadJointCsvNamesFileAndLine) {
  const std::string header = "trajectory,t,q1,qd1,tau1\n";
  std::string e = ErrorOf(WriteText("resumed.csv", header + "a,0,0,0,0\na,1,0,0,0\na,2,0,0,0\n"
                                                            "b,0,0,0,0\nb,1,0,0,0\nb,2,0,0,0\na,3,0,0,0\n"));
  EXPECT_NE(e.find("resumed.csv:8"), std::string::npos) << e;
  EXPECT_NE(e.find("continues after another"), std::string::npos) << e;
  e = ErrorOf(WriteText("back.csv", header + "a,0,0,0,0\na,1,0,0,0\na,0.5,0,0,0\n"));
  EXPECT_NE(e.find("back.csv:4"), std::string::npos) << e;
  e = ErrorOf(WriteText("nan.csv", header + "a,0,0,0,0\na,1,nan,0,0\na,2,0,0,0\n"));
  EXPECT_NE(e.find("nan.csv:3"), std::string::npos) << e;
  e = ErrorOf(WriteText("partial.csv", "t,q1,q2,qd1,qd2,tau1,tau2,m1\n0,0,0,0,0,0,0,0\n"));
  EXPECT_NE(e.find("partial.csv:1"), std::string::npos) << e;
  EXPECT_NE(e.find("m2"), std::string::npos) << e;
}

// A model's actions by name: tau1 only from data of every joint (the channel "tau").
TEST(DatasetForModel, TakesTheModelsActionsByName) {
  const Dataset all = ReadDataset(WriteText("two_runs_fm.csv", kTwoRuns), {.all_actuated = true});
  SystemDescription model = JointSpaceSystem(2, {.actuated = {1}, .prismatic = {1}});
  const Dataset seen = DatasetForModel(all, model, "--model m");
  EXPECT_EQ(seen.system.action_names, std::vector<std::string>{"tau1"});
  EXPECT_EQ(seen.system.angles, std::vector<int>{1});
  EXPECT_EQ(seen.trajectories[1].actions.row(0), all.trajectories[1].actions.row(0));
  model.action_names = {"push"};
  EXPECT_THROW(DatasetForModel(all, model, "--model m"), Error);
  // Other state names: only the sizes must agree.
  EXPECT_THROW(DatasetForModel(all, SystemDescription::Unnamed(4, 1), "--model m"), Error);
  EXPECT_NO_THROW(DatasetForModel(all, SystemDescription::Unnamed(4, 2), "--model m"));
}

// The real data read into the same type: the Panda log's irregular sampling.
TEST(ReadDataset, RealPandaLogIsIrregular) {
  const Dataset d = ReadDataset(std::string(DIFFDYN_SHARED_DATA_DIR) + "/panda_gaz2019_traj1");
  EXPECT_EQ(d.format, "panda-gaz2019");
  EXPECT_EQ(d.system.state_size(), 14);
  EXPECT_EQ(d.system.action_size(), 7);
  EXPECT_EQ(d.transitions(), 20543);
  const SampleIntervals dt = d.Intervals();
  EXPECT_NEAR(dt.median, 1e-3, 1e-6);
  EXPECT_NEAR(dt.min, 0.0007, 1e-6);
  EXPECT_NEAR(dt.max, 0.00881, 1e-6);
}

// Columns are found by name; a missing one, a non-number and a time going back
// are named with file and line; a missing file names the path.
TEST(ReadDataset, JointCsvColumnsByNameAndErrors) {
  const Dataset b = ReadDataset(WriteText("by_name.csv", "tau1,qd1,t,q1\n1,2,0,3\n1,2,0.1,3\n1,2,0.2,3\n"));
  EXPECT_DOUBLE_EQ(b.trajectories[0].states(0, 1), 3.0);
  EXPECT_DOUBLE_EQ(b.trajectories[0].states(1, 1), 2.0);
  std::string e = ErrorOf(WriteText("no_tau.csv", "t,q1,qd1\n0,1,2\n"));
  EXPECT_NE(e.find("no_tau.csv:1: no column 'tau1'"), std::string::npos) << e;
  e = ErrorOf(WriteText("word.csv", "t,q1,qd1,tau1\n0,1,2,3\n0.1,x,2,3\n0.2,1,2,3\n"));
  EXPECT_NE(e.find("word.csv:3"), std::string::npos) << e;
  e = ErrorOf(WriteText("earlier.csv", "t,q1,qd1,tau1\n0,1,2,3\n0.1,1,2,3\n0.05,1,2,3\n"));
  EXPECT_NE(e.find("earlier.csv:4"), std::string::npos) << e;
  e = ErrorOf(::testing::TempDir() + "/no_such_dir_xyz/missing.csv");
  EXPECT_NE(e.find("missing.csv: no such file"), std::string::npos) << e;
}

// Without qd columns qd is the central difference of q, and listed as unmeasured.
TEST(ReadDataset, JointCsvWithoutVelocitiesDifferentiatesPositions) {
  const Dataset d = ReadDataset(WriteText("no_qd.csv", "t,q1,tau1\n0,0,1\n0.1,0.2,1\n0.2,0.6,1\n0.3,1.2,1\n"));
  EXPECT_FALSE(d.IsMeasured("qd1"));
  EXPECT_TRUE(d.IsMeasured("q1"));
  EXPECT_TRUE(d.IsMeasured("tau"));
  EXPECT_NEAR(d.trajectories[0].states(1, 1), 3.0, 1e-12);  // (0.6 - 0) / 0.2
  EXPECT_NEAR(d.trajectories[0].states(1, 0), 2.0, 1e-12);  // one-sided at the start
}

// One run made in memory: the layout applies, and bad sizes or times are refused.
TEST(JointSpaceDataset, MakesOneTrajectoryOfTheRun) {
  const Eigen::VectorXd t = Eigen::VectorXd::LinSpaced(5, 0.0, 0.4);
  const Eigen::MatrixXd q = Eigen::MatrixXd::Random(2, 5), qd = Eigen::MatrixXd::Random(2, 5);
  Eigen::MatrixXd tau = Eigen::MatrixXd::Random(2, 5);
  const Dataset d = JointSpaceDataset("run", t, q, qd, tau, {.actuated = {2}, .prismatic = {1}});
  ASSERT_EQ(d.trajectories.size(), 1u);
  EXPECT_EQ(d.samples(), 5);
  EXPECT_EQ(JointCount(d), 2);
  EXPECT_EQ(d.system.action_names, std::vector<std::string>{"tau2"});
  EXPECT_EQ(d.trajectories[0].actions, tau.row(1).head(4));
  EXPECT_EQ(d.trajectories[0].channels.at("tau"), tau);
  EXPECT_EQ(d.trajectories[0].states.bottomRows(2), qd);
  EXPECT_THROW(JointSpaceDataset("run", t, q, qd, tau.leftCols(4)), Error);
  Eigen::VectorXd back = t;
  back[3] = 0.1;
  EXPECT_THROW(JointSpaceDataset("run", back, q, qd, tau), Error);
  tau(0, 0) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(JointSpaceDataset("run", t, q, qd, tau), Error);
}

// The IBM double pendulum (free motion from camera markers) and the DeLaN characters.
TEST(ReadDataset, RealDoublePendulumAndCharacters) {
  const std::string shared = DIFFDYN_SHARED_DATA_DIR;
  const Dataset ibm = ReadDataset(shared + "/ibm_double_pendulum");
  EXPECT_EQ(ibm.format, "ibm-double-pendulum");
  EXPECT_EQ(JointCount(ibm), 2);
  EXPECT_FALSE(ibm.IsMeasured("qd1"));
  EXPECT_FALSE(ibm.IsMeasured("tau"));
  EXPECT_NEAR(ibm.properties.at("link1_px"), 602.1, 3.0);
  EXPECT_NEAR(ibm.properties.at("link2_px"), 460.8, 3.0);
  EXPECT_NEAR(ibm.Intervals().median, 1.0 / 400.0, 1e-12);
  const Dataset delan = ReadDataset(shared + "/delan_characters");
  EXPECT_EQ(delan.format, "delan-characters");
  ASSERT_EQ(delan.trajectories.size(), 20u);
  EXPECT_EQ(delan.trajectories.front().label, "b");
  EXPECT_EQ(delan.samples(), 2913);
  EXPECT_TRUE(delan.trajectories[0].channels.count("qdd"));
}

}  // namespace
}  // namespace diffdyn
