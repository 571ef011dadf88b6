// The four learned kinds on systems other than pushing: a pendulum-like system
// (n = 2, m = 1, its angle seen as sin/cos) and a 5-state, 2-action system without
// angles. Batched = training = templated paths; parameter and state gradients =
// Jets = central differences (through the sin/cos features); periodicity in the
// encoded angle; the system recorded in model files.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>
#include <vector>

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "diffdyn/models/learned_model.h"
#include "diffdyn/models/random.h"

namespace diffdyn {
namespace {

using Jet = ceres::Jet<double, 2>;

SystemDescription PendulumLike() {
  SystemDescription s;
  s.name = "pendulum-like";
  s.state_names = {"q1", "qd1"};
  s.action_names = {"tau1"};
  s.angles = {0};
  s.angle_features = AngleFeatures::kSinCos;
  return s;
}

struct Case {
  LearnedKind type;
  bool pendulum;        // else 5 states, 2 actions, no angles
  bool scaled = false;  // with input and output scalings (Scaling)
};

std::string CaseName(const ::testing::TestParamInfo<Case>& info) {
  std::string name = LearnedKindName(info.param.type);
  for (char& c : name) c = c == '-' ? '_' : c;
  name.append(info.param.pendulum ? "_pendulum" : "_wide");
  return name.append(info.param.scaled ? "_scaled" : "");
}

// Shifts in [-1, 1] and scales in [0.5, 2] for every network input and output.
Scaling SomeScaling(const LearnedModelConfig& config, std::uint64_t seed) {
  const MlpArchitecture arch = config.Architecture();
  Rng rng(seed);
  const auto draw = [&](int size, double low, double high) {
    Eigen::VectorXd v(size);
    for (int i = 0; i < size; ++i) v[i] = low + (high - low) * UniformUnit(rng);
    return v;
  };
  const int f = arch.sizes.front(), o = arch.sizes.back();
  return {draw(f, -1, 1), draw(f, 0.5, 2), draw(o, -1, 1), draw(o, 0.5, 2)};
}

// A smooth (tanh) field, so that central differences see no kink.
LearnedModelConfig ConfigOf(const Case& c) {
  LearnedModelConfig config;
  config.type = c.type;
  config.method = Method::kRk4;
  config.steps = 4;
  config.hidden = 9;
  config.activation = Activation::Tanh();
  config.system = c.pendulum ? PendulumLike() : SystemDescription::Unnamed(5, 2);
  config.system.angle_features = DefaultAngleFeatures(c.type);
  if (c.scaled) config.scaling = SomeScaling(config, 11);
  return config;
}

Eigen::MatrixXd Normal(int rows, int cols, Rng& rng) {
  Eigen::MatrixXd m(rows, cols);
  for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = StandardNormal(rng);
  return m;
}

class AnySystem : public ::testing::TestWithParam<Case> {};

TEST_P(AnySystem, BatchedTrainingAndTemplatedPathsAgree) {
  const LearnedModel model = LearnedModel::Initialized(ConfigOf(GetParam()), 5);
  const int n = model.state_size(), m = model.action_size(), b = 7;
  EXPECT_EQ(model.net().num_inputs(), model.system().feature_size());
  Rng rng(3);
  const Eigen::MatrixXd x = 2.0 * Normal(n, b, rng), u = Normal(m, b, rng);
  Eigen::MatrixXd batched(n, b), taped(n, b);
  auto ws = model.MakeWorkspace(b);
  model.PredictBatch(x, u, batched, *ws);
  model.Forward(x, u, taped, *ws);
  for (int j = 0; j < b; ++j) {
    const Eigen::VectorXd one = model.Predict(x.col(j), u.col(j));
    EXPECT_LT((batched.col(j) - one).cwiseAbs().maxCoeff(), 1e-12) << "sample " << j;
    EXPECT_LT((taped.col(j) - one).cwiseAbs().maxCoeff(), 1e-12) << "sample " << j;
  }
}

// L = <C, F(x, u)>: Backward's dL/dtheta against central differences along random
// directions, and dL/dx against Jets seeded in the state.
TEST_P(AnySystem, GradientsMatchJetsAndFiniteDifferences) {
  LearnedModel model = LearnedModel::Initialized(ConfigOf(GetParam()), 6);
  const int n = model.state_size(), m = model.action_size(), b = 5;
  Rng rng(4);
  const Eigen::MatrixXd x = 2.0 * Normal(n, b, rng), u = Normal(m, b, rng), c = Normal(n, b, rng);
  auto ws = model.MakeWorkspace(b);
  Eigen::MatrixXd next(n, b), dl_dx;
  model.Forward(x, u, next, *ws);
  Eigen::VectorXd grad = Eigen::VectorXd::Zero(model.num_parameters());
  model.Backward(c, *ws, &grad, &dl_dx);
  const auto loss = [&](const LearnedModel& mm) {
    Eigen::MatrixXd out(n, b);
    auto w = mm.MakeWorkspace(b);
    mm.PredictBatch(x, u, out, *w);
    return c.cwiseProduct(out).sum();
  };
  const double eps = 1e-6;
  for (int k = 0; k < 3; ++k) {
    const Eigen::VectorXd v = Normal(static_cast<int>(model.num_parameters()), 1, rng);
    LearnedModel plus = model, minus = model;
    plus.mutable_parameters() += eps * v;
    minus.mutable_parameters() -= eps * v;
    const double fd = (loss(plus) - loss(minus)) / (2 * eps);
    EXPECT_NEAR(grad.dot(v), fd, 1e-6 * std::max(1.0, std::abs(fd))) << "direction " << k;
  }
  for (int j = 0; j < b; ++j) {
    for (int i0 = 0; i0 < n; i0 += 2) {  // two state directions per Jet
      VectorX<Jet> xj(n), uj(m);
      for (int i = 0; i < n; ++i) xj[i] = Jet(x(i, j));
      for (int i = 0; i < m; ++i) uj[i] = Jet(u(i, j));
      for (int d = 0; d < 2 && i0 + d < n; ++d) xj[i0 + d].v[d] = 1.0;
      const VectorX<Jet> f = model.Predict(xj, uj);
      for (int d = 0; d < 2 && i0 + d < n; ++d) {
        double expected = 0.0;
        for (int r = 0; r < n; ++r) expected += c(r, j) * f[r].v[d];
        EXPECT_NEAR(dl_dx(i0 + d, j), expected, 1e-9 * std::max(1.0, std::abs(expected)))
            << "sample " << j << " state " << i0 + d;
      }
    }
  }
}

// TransitionModel::Jacobian [dF/dx, dF/du] against central differences of the
// batched path (every column) and against reverse mode (Backward: c^T dF/dx).
TEST_P(AnySystem, JacobianMatchesDifferencesAndReverseMode) {
  const LearnedModel model = LearnedModel::Initialized(ConfigOf(GetParam()), 8);
  const TransitionModel& any = model;
  ASSERT_TRUE(any.differentiable());
  const int n = model.state_size(), m = model.action_size();
  Rng rng(9);
  const Eigen::VectorXd x = 2.0 * Normal(n, 1, rng), u = Normal(m, 1, rng), c = Normal(n, 1, rng);
  Eigen::MatrixXd jac;
  const Eigen::VectorXd value = any.Jacobian(x, u, &jac);
  ASSERT_EQ(jac.rows(), n);
  ASSERT_EQ(jac.cols(), n + m);
  auto ws = model.MakeWorkspace(1);
  Eigen::MatrixXd next(n, 1);
  model.PredictBatch(x, u, next, *ws);
  EXPECT_LT((value - next.col(0)).cwiseAbs().maxCoeff(), 1e-12);
  const double eps = 1e-6;
  for (int k = 0; k < n + m; ++k) {
    Eigen::VectorXd xp = x, xm = x, up = u, um = u;
    (k < n ? xp[k] : up[k - n]) += eps;
    (k < n ? xm[k] : um[k - n]) -= eps;
    Eigen::MatrixXd fp(n, 1), fm(n, 1);
    model.PredictBatch(xp, up, fp, *ws);
    model.PredictBatch(xm, um, fm, *ws);
    const Eigen::VectorXd fd = (fp - fm) / (2 * eps);
    EXPECT_LT((jac.col(k) - fd).cwiseAbs().maxCoeff(), 1e-6 * std::max(1.0, fd.norm())) << "column " << k;
  }
  Eigen::MatrixXd dl_dx;
  model.Forward(x, u, next, *ws);
  model.Backward(c, *ws, nullptr, &dl_dx);
  const Eigen::VectorXd expected = jac.leftCols(n).transpose() * c;
  EXPECT_LT((dl_dx.col(0) - expected).cwiseAbs().maxCoeff(), 1e-9 * std::max(1.0, expected.norm()));
  EXPECT_THROW(any.Jacobian(Eigen::VectorXd::Zero(n + 1), u, &jac), Error);
}

// With the angle seen as (sin, cos), or (res-node) the flow started from the wrapped
// angle, shifting it by 2 pi changes no prediction but the angle itself, and that by
// a whole turn (0 for abs-nn, 2 pi for the others).
TEST_P(AnySystem, PeriodicInTheEncodedAngle) {
  if (!GetParam().pendulum) GTEST_SKIP() << "no encoded angle";
  const LearnedModel model = LearnedModel::Initialized(ConfigOf(GetParam()), 7);
  const Eigen::Vector2d x(0.7, -1.3);
  const Eigen::Matrix<double, 1, 1> u(0.4);
  const Eigen::VectorXd a = model.Predict(x, u);
  const Eigen::VectorXd b = model.Predict(Eigen::Vector2d(x[0] + 2 * std::numbers::pi, x[1]), u);
  const double turns = (b[0] - a[0]) / (2 * std::numbers::pi);
  EXPECT_NEAR(turns, std::round(turns), 1e-9);
  EXPECT_NEAR(b[1], a[1], 1e-9);
}

// res-node starts its flow from the wrapped angle: ten turns out, the batched and
// templated paths both give the prediction at the wrapped angle plus ten turns, and
// a periodic (sin, cos) field is refused.
TEST(ResNode, StartsFromTheWrappedAngle) {
  const LearnedModel model = LearnedModel::Initialized(ConfigOf({LearnedKind::kResNode, true}), 3);
  const double turns = 20 * std::numbers::pi;
  const Eigen::Vector2d near(0.7, -1.3), far(0.7 + turns, -1.3);
  const Eigen::Matrix<double, 1, 1> u(0.4);
  const Eigen::VectorXd expected = model.Predict(near, u) + Eigen::Vector2d(turns, 0.0);
  auto ws = model.MakeWorkspace(1);
  Eigen::MatrixXd batched(2, 1);
  model.PredictBatch(far, u, batched, *ws);
  EXPECT_LT((model.Predict(far, u) - expected).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((batched.col(0) - expected).cwiseAbs().maxCoeff(), 1e-12);
  LearnedModelConfig periodic = ConfigOf({LearnedKind::kResNode, true});
  periodic.system.angle_features = AngleFeatures::kSinCos;
  EXPECT_THROW(periodic.Validate(), Error);
  EXPECT_EQ(DefaultAngleFeatures(LearnedKind::kAbsNode), AngleFeatures::kSinCos);
}

INSTANTIATE_TEST_SUITE_P(
    Kinds, AnySystem,
    ::testing::Values(Case{LearnedKind::kAbsNn, true}, Case{LearnedKind::kResNn, true},
                      Case{LearnedKind::kAbsNode, true}, Case{LearnedKind::kResNode, true},
                      Case{LearnedKind::kAbsNn, false}, Case{LearnedKind::kResNode, false},
                      Case{LearnedKind::kAbsNn, true, true}, Case{LearnedKind::kResNn, false, true},
                      Case{LearnedKind::kAbsNode, true, true}, Case{LearnedKind::kResNode, true, true}),
    CaseName);

TEST(LearnedModelFile, RecordsTheSystemAndReadsFilesWithoutOne) {
  const std::filesystem::path dir = ::testing::TempDir();
  const LearnedModel model =
      LearnedModel::Initialized(ConfigOf({LearnedKind::kResNode, /*pendulum=*/true}), 8);
  SaveLearnedModel(dir / "pendulum_res_node.json", model);
  const LearnedModel back = LoadLearnedModel(dir / "pendulum_res_node.json");
  EXPECT_TRUE(back.system().SameLayout(model.system()));
  EXPECT_EQ(back.system().name, "pendulum-like");
  EXPECT_TRUE(back.parameters() == model.parameters());
  const Eigen::Vector2d x(0.2, 0.1);
  const Eigen::Matrix<double, 1, 1> u(-0.5);
  EXPECT_EQ(back.Predict(x, u), model.Predict(x, u));

  // A file without "system" (as written before systems were recorded): 3 x 3, raw.
  LearnedModelConfig old;
  old.type = LearnedKind::kAbsNn;
  old.hidden = 4;
  const LearnedModel three = LearnedModel::Initialized(old, 9);
  SaveLearnedModel(dir / "old.json", three);
  std::ifstream in(dir / "old.json");
  nlohmann::json j = nlohmann::json::parse(in);
  j.erase("system");
  std::ofstream(dir / "old.json") << j.dump();
  const LearnedModel loaded = LoadLearnedModel(dir / "old.json");
  EXPECT_EQ(loaded.state_size(), 3);
  EXPECT_EQ(loaded.action_size(), 3);
  EXPECT_TRUE(loaded.system().angles.empty());

  // A system that does not fit the network is refused, naming the file.
  j["system"] = SystemToJson(PendulumLike());
  std::ofstream(dir / "mismatch.json") << j.dump();
  try {
    LoadLearnedModel(dir / "mismatch.json");
    FAIL() << "a 2-state system was accepted for a 3-state network";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("mismatch.json"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("2 states and 1 actions"), std::string::npos) << e.what();
  }
}

// A scaled model's file keeps the scalings (same predictions to the bit); scalings of
// the wrong size or with a scale <= 0 are refused, naming the file.
TEST(LearnedModelFile, KeepsScalingsAndRefusesBadOnes) {
  const std::filesystem::path dir = ::testing::TempDir();
  const LearnedModel model =
      LearnedModel::Initialized(ConfigOf({LearnedKind::kAbsNode, /*pendulum=*/true, /*scaled=*/true}), 8);
  SaveLearnedModel(dir / "scaled.json", model);
  const LearnedModel back = LoadLearnedModel(dir / "scaled.json");
  const Eigen::Vector2d x(0.3, -2.0);
  const Eigen::Matrix<double, 1, 1> u(0.8);
  EXPECT_EQ(back.Predict(x, u), model.Predict(x, u));
  EXPECT_FALSE(back.features().identity());
  EXPECT_FALSE(back.output_map().identity());

  std::ifstream in(dir / "scaled.json");
  const nlohmann::json good = nlohmann::json::parse(in);
  for (const auto& [key, value] : {std::pair<std::string, double>{"input_scale", -1.0},
                                   std::pair<std::string, double>{"output_scale", 0.0}}) {
    nlohmann::json j = good;
    j["architecture"]["scaling"][key][0] = value;
    std::ofstream(dir / "bad_scale.json") << j.dump();
    try {
      LoadLearnedModel(dir / "bad_scale.json");
      FAIL() << key << " " << value << " was accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("bad_scale.json"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("scales positive"), std::string::npos) << e.what();
    }
  }
  nlohmann::json j = good;
  j["architecture"]["scaling"]["input_shift"].erase(0);
  std::ofstream(dir / "short_shift.json") << j.dump();
  EXPECT_THROW(LoadLearnedModel(dir / "short_shift.json"), Error);
}

// FitScaling's input map takes the features of the fitting data to mean 0 and
// standard deviation 1; its output map is the moments of the network's target.
TEST(FitScaling, MakesTheDataUnitScale) {
  LearnedModelConfig config = ConfigOf({LearnedKind::kResNn, /*pendulum=*/true});
  Rng rng(12);
  const int count = 400;
  Eigen::MatrixXd x = Normal(2, count, rng), u = 5.0 * Normal(1, count, rng);
  x.row(1) = 10.0 * x.row(1).array() + 3.0;
  Eigen::MatrixXd next = x;
  next.row(1).array() += 0.2 * Normal(1, count, rng).row(0).array() + 0.05;
  config.scaling = FitScaling(config, x, u, next);
  const LearnedModel model = LearnedModel::Initialized(config, 1);
  Eigen::MatrixXd z(3, count), features;
  z << x, u;
  model.features().Apply(z, features);
  const Eigen::VectorXd mean = features.rowwise().mean();
  const Eigen::VectorXd var =
      (features.colwise() - mean).array().square().rowwise().sum() / static_cast<double>(count);
  EXPECT_LT(mean.cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((var.array() - 1.0).abs().maxCoeff(), 1e-9);
  // res-nn's target x_{t+1} - x_t: row 0 is constant 0 (scale 1), row 1 ~ 0.05 + 0.2 N(0, 1).
  EXPECT_EQ(config.scaling.output_scale[0], 1.0);
  EXPECT_NEAR(config.scaling.output_shift[1], 0.05, 0.03);
  EXPECT_NEAR(config.scaling.output_scale[1], 0.2, 0.03);
  // res-node's field carries z from wrap(x_t) to x_{t+1} - x_t: row 1's target is
  // 0.05 + 0.2 N(0, 1) - (3 + 10 N(0, 1)) (x's row 1 is no angle, so not wrapped).
  config.type = LearnedKind::kResNode;
  config.system.angle_features = AngleFeatures::kRaw;
  const Scaling res_node = FitScaling(config, x, u, next);
  ASSERT_EQ(res_node.output_scale.size(), 3);
  EXPECT_NEAR(res_node.output_shift[1], 0.05 - 3.0, 0.5);
  EXPECT_NEAR(res_node.output_scale[1], 10.0, 1.0);
  EXPECT_EQ(res_node.output_scale[2], 1.0);  // the action rides along
  // Its input and output moments are those of the wrapped angle: three turns out
  // changes nothing.
  Eigen::MatrixXd turned = x, turned_next = next;
  turned.row(0).array() += 6 * std::numbers::pi;
  turned_next.row(0).array() += 6 * std::numbers::pi;
  const Scaling turned_scaling = FitScaling(config, turned, u, turned_next);
  EXPECT_LT((turned_scaling.input_shift - res_node.input_shift).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((turned_scaling.input_scale - res_node.input_scale).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((turned_scaling.output_shift - res_node.output_shift).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT((turned_scaling.output_scale - res_node.output_scale).cwiseAbs().maxCoeff(), 1e-9);
}

TEST(SystemDescription, ValidatesAndRoundTripsThroughJson) {
  SystemDescription s = PendulumLike();
  s.action_low = Eigen::VectorXd::Constant(1, -2.5);
  s.action_high = Eigen::VectorXd::Constant(1, 2.5);
  EXPECT_EQ(s.feature_size(), 4);
  const SystemDescription back = SystemFromJson(SystemToJson(s));
  EXPECT_TRUE(back.SameLayout(s));
  SystemDescription bad = s;
  bad.angles = {2};
  EXPECT_THROW(bad.Validate(), Error);
  bad = s;
  bad.action_low[0] = 3.0;
  EXPECT_THROW(bad.Validate(), Error);
  nlohmann::json j = SystemToJson(s);
  j["angle_features"] = "polar";
  EXPECT_THROW(SystemFromJson(j), Error);
}

}  // namespace
}  // namespace diffdyn
