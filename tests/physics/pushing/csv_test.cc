// The pushing CSV: exact round trip, files with and without `status`, ragged
// files rejected with file and line, and the shared PyBullet data read as described.
#include "diffdyn/physics/pushing/csv.h"

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "diffdyn/models/random.h"

namespace diffdyn {
namespace {

std::filesystem::path WriteText(const std::string& name, const std::string& text) {
  const auto path = std::filesystem::path(::testing::TempDir()) / name;
  std::ofstream(path) << text;
  return path;
}

std::string ErrorOf(const std::filesystem::path& path) {
  try {
    ReadPushingCsv(path);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(PushingCsv, RoundTripIsExact) {
  Rng rng(5);
  std::vector<Trajectory> data;
  for (int t = 0; t < 3; ++t) {
    const int n = t + 1;
    std::vector<Eigen::Vector3d> poses, actions;
    for (int s = 0; s <= n; ++s) {
      poses.emplace_back(Uniform(rng, 0, 1), Uniform(rng, -1, 1), Uniform(rng, -3, 3));
      if (s < n) actions.emplace_back(Uniform(rng, -1, 1), Uniform(rng, -1.5, 1.5), UniformUnit(rng));
    }
    data.push_back(MakePushingTrajectory(poses, actions, std::to_string(t)));
  }
  data[2].status = "off_table";
  const auto path = std::filesystem::path(::testing::TempDir()) / "round_trip.csv";
  WritePushingCsvFile(path, data);
  const auto back = ReadPushingCsv(path);
  ASSERT_EQ(back.size(), data.size());
  for (size_t t = 0; t < data.size(); ++t) {
    EXPECT_EQ(back[t].status, data[t].status);
    EXPECT_EQ(back[t].label, data[t].label);
    EXPECT_EQ(back[t].t, data[t].t);
    EXPECT_EQ(back[t].states, data[t].states);
    EXPECT_EQ(back[t].actions, data[t].actions);
  }
  // Equal data, equal bytes.
  std::ostringstream a, b;
  WritePushingCsv(a, data);
  WritePushingCsv(b, back);
  EXPECT_EQ(a.str(), b.str());
}

TEST(PushingCsv, ReadsWithoutStatusColumn) {
  const auto path = WriteText("no_status.csv",
                              "trajectory,step,x,y,theta,push_location,push_angle,push_length\n"
                              "0,0,0.4,0,0.6,0.1,0.2,0.3\n0,1,0.41,0.01,0.62,,,\n"
                              "1,0,0.5,0,0,,,\n");
  const auto data = ReadPushingCsv(path);
  ASSERT_EQ(data.size(), 2u);
  EXPECT_EQ(data[0].states.cols(), 2);
  EXPECT_EQ(data[0].transitions(), 1);
  EXPECT_DOUBLE_EQ(data[0].actions(2, 0), 0.3);
  EXPECT_EQ(data[0].status, "ok");
  EXPECT_EQ(data[1].transitions(), 0);
}

TEST(PushingCsv, RaggedFilesNameFileAndLine) {
  const std::string header = "trajectory,step,x,y,theta,push_location,push_angle,push_length\n";
  const auto gap = WriteText("gap.csv", header + "0,0,0,0,0,0,0,0\n0,2,0,0,0,,,\n");
  std::string e = ErrorOf(gap);
  EXPECT_NE(e.find("gap.csv:3"), std::string::npos) << e;
  EXPECT_NE(e.find("ragged"), std::string::npos) << e;
  const auto missing = WriteText("missing.csv", header + "0,0,0,0,0,,,\n0,1,0,0,0,,,\n");
  e = ErrorOf(missing);
  EXPECT_NE(e.find("missing.csv:3"), std::string::npos) << e;
  const auto open_end = WriteText("open_end.csv", header + "0,0,0,0,0,0,0,0\n");
  e = ErrorOf(open_end);
  EXPECT_NE(e.find("open_end.csv"), std::string::npos) << e;
  const auto bad_number = WriteText("bad.csv", header + "0,0,zero,0,0,,,\n");
  e = ErrorOf(bad_number);
  EXPECT_NE(e.find("bad.csv:2"), std::string::npos) << e;
  EXPECT_NE(e.find("column x"), std::string::npos) << e;
  const auto bad_header = WriteText("header.csv", "a,b,c\n");
  e = ErrorOf(bad_header);
  EXPECT_NE(e.find("header.csv:1"), std::string::npos) << e;
  EXPECT_NE(ErrorOf("/nonexistent/pushes.csv").find("/nonexistent/pushes.csv"), std::string::npos);
}

TEST(PushingCsv, ReadsTheSharedPybulletData) {
  const auto data =
      ReadPushingCsv(std::filesystem::path(DIFFDYN_SHARED_DATA_DIR) / "pybullet_pushing/collected_data.csv");
  ASSERT_EQ(data.size(), 400u);
  for (const auto& t : data) {
    ASSERT_EQ(t.states.cols(), 11);
    ASSERT_EQ(t.transitions(), 10);
    t.Validate(3, 3, "pybullet");
  }
  EXPECT_NEAR(data[0].states(0, 0), 0.4, 1e-6);
  EXPECT_NEAR(data[0].states(2, 0), 0.2 * 3.14159265358979, 1e-6);
}

}  // namespace
}  // namespace diffdyn
