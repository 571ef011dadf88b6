// The float32 engine of the four learned kinds against their float64 engine: the
// same model (double master parameters) and inputs, prediction, parameter gradient
// and state gradient within a tolerance from float's epsilon, through sin/cos
// features, scalings, fixed-step and adaptive solvers; the precision in model files.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>

#include "diffdyn/models/learned_model.h"
#include "diffdyn/models/random.h"

namespace diffdyn {
namespace {

constexpr double kFloatEps = std::numeric_limits<float>::epsilon();

struct PrecisionCase {
  LearnedKind type;
  Method method;
};

std::string PrecisionCaseName(const ::testing::TestParamInfo<PrecisionCase>& info) {
  std::string name = LearnedKindName(info.param.type) + "_" + MethodName(info.param.method);
  for (char& c : name) c = c == '-' ? '_' : c;
  return name;
}

// A pendulum-like system (its angle seen as sin/cos) with input and output scalings.
LearnedModelConfig FloatCaseConfig(const PrecisionCase& c) {
  LearnedModelConfig config;
  config.type = c.type;
  config.method = c.method;
  config.hidden = 16;
  config.steps = 5;
  config.activation = Activation::Tanh();
  config.tolerance = 1e-6;
  config.system.name = "pendulum-like";
  config.system.state_names = {"q1", "qd1"};
  config.system.action_names = {"tau1"};
  config.system.angles = {0};
  config.system.angle_features = DefaultAngleFeatures(c.type);
  const MlpArchitecture arch = config.Architecture();
  const int f = arch.sizes.front(), o = arch.sizes.back();
  config.scaling = {Eigen::VectorXd::Constant(f, 0.1), Eigen::VectorXd::Constant(f, 1.5),
                    Eigen::VectorXd::Constant(o, -0.05), Eigen::VectorXd::Constant(o, 0.7)};
  return config;
}

Eigen::MatrixXd NormalMatrix(int rows, int cols, Rng& rng) {
  Eigen::MatrixXd m(rows, cols);
  for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = StandardNormal(rng);
  return m;
}

// max |a - b| / (1 + max |b|): the normwise relative difference.
double RelativeDifference(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return (a - b).cwiseAbs().maxCoeff() / (1.0 + b.cwiseAbs().maxCoeff());
}

// Forward, then Backward of dL/dnext = w, in the model's precision.
struct ForwardBackward {
  Eigen::MatrixXd next, dl_dstates;
  Eigen::VectorXd grad;
};

ForwardBackward ForwardAndBackward(const LearnedModel& model, const Eigen::MatrixXd& x,
                                   const Eigen::MatrixXd& u, const Eigen::MatrixXd& w) {
  ForwardBackward r;
  r.next.resize(x.rows(), x.cols());
  r.grad = Eigen::VectorXd::Zero(model.num_parameters());
  auto ws = model.MakeWorkspace(static_cast<int>(x.cols()));
  model.Forward(x, u, r.next, *ws);
  model.Backward(w, *ws, &r.grad, &r.dl_dstates);
  return r;
}

class LearnedModelPrecision : public ::testing::TestWithParam<PrecisionCase> {};

TEST_P(LearnedModelPrecision, Float32MatchesFloat64WithinFloatRounding) {
  LearnedModel model = LearnedModel::Initialized(FloatCaseConfig(GetParam()), 5);
  Rng rng(21);
  const int b = 300;
  const Eigen::MatrixXd x = NormalMatrix(2, b, rng), u = NormalMatrix(1, b, rng),
                        w = NormalMatrix(2, b, rng);
  ASSERT_EQ(model.precision(), Precision::kF64);
  const ForwardBackward d = ForwardAndBackward(model, x, u, w);
  ASSERT_TRUE(model.SetPrecision(Precision::kF32));
  const ForwardBackward f = ForwardAndBackward(model, x, u, w);

  // Each path rounds every operation to float: differences of a few hundred float
  // epsilons over the network's and the solver's operations, not more.
  EXPECT_LT(RelativeDifference(f.next, d.next), 64 * kFloatEps);
  EXPECT_LT(RelativeDifference(f.dl_dstates, d.dl_dstates), 256 * kFloatEps);
  EXPECT_LT(RelativeDifference(f.grad, d.grad), 1024 * kFloatEps);
  // ... and float was really used: the results are not the double ones.
  EXPECT_GT((f.next - d.next).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_GT((f.grad - d.grad).cwiseAbs().maxCoeff(), 0.0);

  // PredictBatch (no tape) gives Forward's values, one workspace serving both precisions.
  auto ws = model.MakeWorkspace(b);
  Eigen::MatrixXd next(2, b);
  model.PredictBatch(x, u, next, *ws);
  EXPECT_LT(RelativeDifference(next, f.next), 8 * kFloatEps);
  ASSERT_TRUE(model.SetPrecision(Precision::kF64));
  model.PredictBatch(x, u, next, *ws);
  EXPECT_LT(RelativeDifference(next, d.next), 1e-12);
}

TEST_P(LearnedModelPrecision, Float32FollowsParameterUpdates) {
  LearnedModel model = LearnedModel::Initialized(FloatCaseConfig(GetParam()), 6);
  ASSERT_TRUE(model.SetPrecision(Precision::kF32));
  Rng rng(22);
  const Eigen::MatrixXd x = NormalMatrix(2, 40, rng), u = NormalMatrix(1, 40, rng);
  auto ws = model.MakeWorkspace(40);
  Eigen::MatrixXd before(2, 40), after(2, 40);
  model.PredictBatch(x, u, before, *ws);
  // An optimiser's step on the double master copy reaches the float engine.
  model.mutable_parameters() *= 1.1;
  model.PredictBatch(x, u, after, *ws);
  EXPECT_GT((after - before).cwiseAbs().maxCoeff(), 1e-4);
  Eigen::MatrixXd fresh(2, 40);
  auto ws2 = model.MakeWorkspace(40);
  model.PredictBatch(x, u, fresh, *ws2);
  EXPECT_EQ(after, fresh);
}

INSTANTIATE_TEST_SUITE_P(Kinds, LearnedModelPrecision,
                         ::testing::Values(PrecisionCase{LearnedKind::kAbsNn, Method::kRk4},
                                           PrecisionCase{LearnedKind::kResNn, Method::kRk4},
                                           PrecisionCase{LearnedKind::kAbsNode, Method::kRk4},
                                           PrecisionCase{LearnedKind::kResNode, Method::kRk4},
                                           PrecisionCase{LearnedKind::kAbsNode, Method::kDopri5},
                                           PrecisionCase{LearnedKind::kResNode, Method::kEuler}),
                         PrecisionCaseName);

TEST(LearnedModelPrecisionFile, RecordsAndRestoresThePrecision) {
  LearnedModel model =
      LearnedModel::Initialized(FloatCaseConfig({LearnedKind::kResNode, Method::kRk4}), 7);
  ASSERT_TRUE(model.SetPrecision(Precision::kF32));
  const std::filesystem::path path = ::testing::TempDir() + "/learned_f32.json";
  SaveLearnedModel(path, model);
  std::ifstream in(path);
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j["precision"], "f32");
  const LearnedModel back = LoadLearnedModel(path);
  EXPECT_EQ(back.precision(), Precision::kF32);
  EXPECT_EQ(back.parameters(), model.parameters());  // the double master copy, bit for bit
}

TEST(LearnedModelPrecisionFile, RejectsAnUnknownPrecisionNamingTheFile) {
  LearnedModel model =
      LearnedModel::Initialized(FloatCaseConfig({LearnedKind::kAbsNn, Method::kRk4}), 8);
  const std::filesystem::path path = ::testing::TempDir() + "/learned_f16.json";
  SaveLearnedModel(path, model);
  nlohmann::json j;
  {
    std::ifstream in(path);
    j = nlohmann::json::parse(in);
  }
  EXPECT_EQ(j["precision"], "f64");
  j["precision"] = "f16";
  std::ofstream(path) << j.dump();
  try {
    LoadLearnedModel(path);
    FAIL() << "f16 was accepted";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(path.string()), std::string::npos) << what;
    EXPECT_NE(what.find("f16"), std::string::npos) << what;
  }
  EXPECT_EQ(ParsePrecision("f32"), Precision::kF32);
  EXPECT_THROW(ParsePrecision("double"), Error);
}

}  // namespace
}  // namespace diffdyn
