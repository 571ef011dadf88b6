#include "diffdyn/physics/control_task.h"

#include "diffdyn/models/random.h"

namespace diffdyn {
namespace {

// One run of a ControlTask: TaskModel over one control period per step.
class ControlTaskRun final : public TaskRun {
 public:
  explicit ControlTaskRun(const ControlTask& task)
      : task_(task), plant_(TaskModel(task, task.period, 4)), ws_(plant_->MakeWorkspace(1)) {}

  Eigen::VectorXd Reset(const Eigen::VectorXd& x0) override {
    x_ = x0;
    left_limits_ = false;
    t_ = 0.0;
    return x_;
  }

  StepOutcome Step(const Eigen::VectorXd& u, Eigen::VectorXd* x) override {
    StepOutcome step;
    step.cost = task_.period * task_.RunningCost(x_, u);
    x->resize(x_.size());
    plant_->PredictBatch(x_, u, *x, *ws_);
    t_ += task_.period;
    if (!x->allFinite()) {
      throw NumericalError(StrCat("control: the plant's state became non-finite at t = ", t_, " s"));
    }
    x_ = *x;
    left_limits_ = left_limits_ || task_.OutOfLimits(x_);
    return step;
  }

  std::string Finish() override {
    if (left_limits_) return "left_limits";
    return task_.Succeeded(x_) ? "success" : "failed";
  }

 private:
  const ControlTask& task_;
  std::unique_ptr<TransitionModel> plant_;
  std::unique_ptr<TransitionWorkspace> ws_;
  Eigen::VectorXd x_;
  bool left_limits_ = false;
  double t_ = 0.0;
};

}  // namespace

std::vector<TaskStart> ControlTask::Starts(int count, std::uint64_t seed) const {
  Rng rng(seed);
  std::vector<TaskStart> starts;
  for (int s = 0; s < count; ++s) {
    starts.push_back({SampleStart(rng), SplitMix64Hash(SplitMix64Hash(seed) ^ static_cast<std::uint64_t>(s))});
  }
  return starts;
}

std::unique_ptr<TaskRun> ControlTask::Begin() const { return std::make_unique<ControlTaskRun>(*this); }

}  // namespace diffdyn
