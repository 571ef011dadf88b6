// --precision f32|f64 on train, eval, push and control: the model file records the
// precision, loading converts, float32 results stay within float32's rounding of the
// float64 ones, the bytes do not depend on the thread count, and the models or
// options that have no float32 path are one-line errors.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>

#include "run_diffdyn.h"

namespace diffdyn {
namespace {

using testing::ReadAll;
using testing::RunDiffdyn;
using testing::SummaryJson;
using testing::TempPath;

// The header and the first `trajectories` trajectories (11 rows each) of the shared
// pushing data, as a temporary file.
std::string PushingHead(int trajectories) {
  std::ifstream in(std::string(DIFFDYN_SHARED_DATA_DIR) + "/pybullet_pushing/collected_data.csv");
  std::string line, out;
  for (int i = 0; i < 1 + 11 * trajectories && std::getline(in, line); ++i) out += line + "\n";
  const std::string path = TempPath("precision_pushing_" + std::to_string(trajectories) + ".csv");
  std::ofstream(path) << out;
  return path;
}

// `train ... --json` of a small NeuralODE in `precision` with `threads` threads.
nlohmann::json TrainSmallNode(const std::string& csv, const std::string& precision,
                              const std::string& solver, int threads, const std::string& out) {
  return SummaryJson(RunDiffdyn("train --data " + csv +
                                " --model abs-node --hidden 16 --epochs 3 --seed 2" + " --solver " +
                                solver + " --precision " + precision + " --threads " +
                                std::to_string(threads) + " --quiet --json --out " + out));
}

// The float32 run's losses are the float64 ones up to float32's rounding carried
// through a few Adam updates, and not the same bits.
void ExpectLossesFollowFloat64(const nlohmann::json& f64, const nlohmann::json& f32) {
  for (const char* key : {"final_train_loss", "final_val_loss"}) {
    const double x = f64[key].get<double>(), y = f32[key].get<double>();
    EXPECT_NEAR(y, x, 1e-4 * x) << key;
    EXPECT_NE(y, x) << key << ": the float32 run computed in float64";
  }
}

TEST(Precision, Float32TrainingFollowsFloat64AndIsRecorded) {
  const std::string csv = PushingHead(20);
  const std::string f64 = TempPath("precision_f64.json"), f32 = TempPath("precision_f32.json");
  const nlohmann::json a = TrainSmallNode(csv, "f64", "rk4", 1, f64);
  const nlohmann::json b = TrainSmallNode(csv, "f32", "rk4", 1, f32);
  EXPECT_EQ(a["precision"], "f64");
  EXPECT_EQ(b["precision"], "f32");
  // Three epochs of Adam from the same start (3 x 4 parameter updates).
  ExpectLossesFollowFloat64(a, b);
  // rk4 with 10 grid points: 9 steps per batch call, none rejected.
  EXPECT_EQ(b["solver_steps"], a["solver_steps"]);
  EXPECT_GT(b["solver_steps"].get<long>(), 0);
  EXPECT_EQ(b["rejected_steps"], 0);
  EXPECT_EQ(nlohmann::json::parse(ReadAll(f32))["precision"], "f32");
  EXPECT_EQ(nlohmann::json::parse(ReadAll(f64))["precision"], "f64");

  // eval reads the model's own precision; --precision converts.
  const auto eval = [&](const std::string& model, const std::string& extra) {
    return SummaryJson(RunDiffdyn("eval --model " + model + " --data " + csv + " --json " +
                                  extra))["single_step_loss"]
        .get<double>();
  };
  const double own = eval(f32, ""), as_f32 = eval(f32, "--precision f32"),
               as_f64 = eval(f32, "--precision f64");
  EXPECT_EQ(own, as_f32);
  EXPECT_NE(own, as_f64);
  EXPECT_NEAR(own, as_f64, 1e-4 * as_f64);
}

TEST(Precision, BytesDoNotDependOnTheThreadCount) {
  // 480 training windows: two chunks of the batch, one per thread.
  const std::string csv = PushingHead(60);
  for (const char* precision : {"f32", "f64"}) {
    const std::string one = TempPath(std::string("precision_t1_") + precision + ".json");
    const std::string two = TempPath(std::string("precision_t2_") + precision + ".json");
    const nlohmann::json a = TrainSmallNode(csv, precision, "dopri5", 1, one);
    const nlohmann::json b = TrainSmallNode(csv, precision, "dopri5", 2, two);
    EXPECT_EQ(a["final_val_loss"], b["final_val_loss"]) << precision;
    EXPECT_EQ(a["solver_steps"], b["solver_steps"]) << precision;
    EXPECT_EQ(a["rejected_steps"], b["rejected_steps"]) << precision;
    nlohmann::json ja = nlohmann::json::parse(ReadAll(one)),
                   jb = nlohmann::json::parse(ReadAll(two));
    EXPECT_EQ(ja["parameters"], jb["parameters"]) << precision;
  }
}

// DeLaN in float32: the losses follow float64 to float32's rounding, the file records
// the precision, the bytes do not depend on the thread count, and eval converts.
TEST(Precision, DelanTrainsInFloat32AtAnyThreadCount) {
  const std::string csv = TempPath("precision_arm2.csv");
  ASSERT_EQ(RunDiffdyn("collect --system arm2 --trajectories 4 --seconds 2 --seed 3 --quiet --out " + csv).exit_code,
            0);
  const auto train = [&](const std::string& precision, int threads) {
    const std::string out = TempPath("precision_delan_" + precision + "_" + std::to_string(threads) + ".json");
    const nlohmann::json summary =
        SummaryJson(RunDiffdyn("train --data " + csv + " --model delan-friction --hidden 16 --epochs 5 --seed 1" +
                               " --precision " + precision + " --threads " + std::to_string(threads) +
                               " --quiet --json --out " + out));
    return std::make_pair(summary, nlohmann::json::parse(ReadAll(out)));
  };
  const auto [a, file_a] = train("f64", 1);
  const auto [b, file_b] = train("f32", 1);
  const auto [c, file_c] = train("f32", 2);
  EXPECT_EQ(b["precision"], "f32");
  EXPECT_EQ(file_b["precision"], "f32");
  EXPECT_EQ(file_a["precision"], "f64");
  ExpectLossesFollowFloat64(a, b);
  EXPECT_EQ(b["final_val_loss"], c["final_val_loss"]);
  EXPECT_EQ(file_b["parameters"], file_c["parameters"]);
  const std::string model = TempPath("precision_delan_f32_1.json");
  const nlohmann::json own = SummaryJson(RunDiffdyn("eval --model " + model + " --data " + csv + " --json"));
  const nlohmann::json as_f64 =
      SummaryJson(RunDiffdyn("eval --model " + model + " --data " + csv + " --precision f64 --json"));
  EXPECT_EQ(own["precision"], "f32");
  EXPECT_EQ(as_f64["precision"], "f64");
  EXPECT_NEAR(own["torque_mse"].get<double>(), as_f64["torque_mse"].get<double>(),
              1e-4 * as_f64["torque_mse"].get<double>());
}

TEST(Precision, WithoutAFloat32PathIsAOneLineError) {
  const std::string csv = PushingHead(20);
  const std::string model = TempPath("precision_refused.json");
  for (const std::string& args :
       {"train --data " + csv + " --epochs 1 --precision f16 --out " + model,
        "train --data " + csv + " --epochs 1 --precision F32 --out " + model,
        "eval --model pendulum --data " + csv + " --precision f32",
        std::string("control --system pendulum --model pendulum --starts 1 --precision f32")}) {
    const auto r = RunDiffdyn(args);
    EXPECT_EQ(r.exit_code, 2) << args << "\n" << r.err;
    EXPECT_EQ(r.err.rfind("error: ", 0), 0u) << args << "\n" << r.err;
    EXPECT_EQ(testing::CountLines(r.err), 1) << args << "\n" << r.err;
    EXPECT_NE(r.err.find("precision"), std::string::npos) << args << "\n" << r.err;
    EXPECT_EQ(r.out, "") << args;
  }
  EXPECT_FALSE(std::ifstream(model).good());
}

}  // namespace
}  // namespace diffdyn
