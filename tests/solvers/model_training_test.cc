// FitLearnedModel (the learned-model training behind `diffdyn train`) and TrainFiles.
#include "diffdyn/solvers/model_training.h"

#include <filesystem>

#include <gtest/gtest.h>

#include "diffdyn/solvers/joint_collect.h"

namespace diffdyn {
namespace {

Dataset SmallPendulumData(std::uint64_t seed) {
  return CollectJointSpace(JointTaskByName("pendulum"), {.trajectories = 6, .seconds = 2.0, .seed = seed});
}

TEST(FitLearnedModel, ScalesTrainsAndTakesTheDataTimeStep) {
  const Dataset data = SmallPendulumData(1);
  const LearnedModelConfig config{.type = LearnedKind::kAbsNn, .hidden = 16, .system = SystemDescription::Unnamed(3, 3)};
  const FittedModel fit = FitLearnedModel(data, config, {.epochs = 20, .seed = 3, .progress = false});
  EXPECT_EQ(fit.model.state_size(), 2);
  EXPECT_EQ(fit.model.action_size(), 1);
  EXPECT_NEAR(fit.model.time_step(), 0.04, 1e-12);
  EXPECT_EQ(fit.result.epochs.size(), 20u);
  EXPECT_LT(fit.result.final_val_loss, fit.result.epochs.front().val_loss);
  // Scaled: the training split's inputs have unit moments, so a raw-unit model differs.
  EXPECT_TRUE(fit.model.config().scaling.has_input());
  const FittedModel raw = FitLearnedModel(data, config, {.epochs = 20, .seed = 3, .progress = false}, 1, false);
  EXPECT_FALSE(raw.model.config().scaling.has_input());
  EXPECT_NE(raw.result.final_val_loss, fit.result.final_val_loss);
}

TEST(FitLearnedModel, IsWhatTrainFilesSaves) {
  const auto dir = std::filesystem::temp_directory_path() / "diffdyn_model_training_test";
  std::filesystem::create_directories(dir);
  const Dataset data = SmallPendulumData(2);
  WriteDataset((dir / "data.csv").string(), data);
  TrainRequest request{.data = (dir / "data.csv").string(), .model = "res-nn", .out = (dir / "m.json").string()};
  request.epochs = 5;
  request.hidden = 8;
  request.seed = 4;
  request.threads = 1;
  TrainFiles(request);
  const FittedModel fit = FitLearnedModel(ReadDataset(request.data), {.type = LearnedKind::kResNn, .hidden = 8},
                                          {.epochs = 5, .seed = 4, .threads = 1, .progress = false});
  const LearnedModel saved = LoadLearnedModel(request.out);
  EXPECT_EQ(saved.parameters(), fit.model.parameters());
  EXPECT_EQ(saved.time_step(), fit.model.time_step());
  std::filesystem::remove_all(dir);
}

TEST(FitLearnedModel, RefusesASplitWithoutTrainingData) {
  EXPECT_THROW(FitLearnedModel(SmallPendulumData(1), {.hidden = 8}, {.epochs = 1, .val_fraction = 0.999999}),
               Error);
}

}  // namespace
}  // namespace diffdyn
