// A saved diffdyn model inside your own controller, in your own CMake project.
//
// `diffdyn train` wrote MODEL.json (any dynamics kind: a learned model, DeLaN, an
// extended-physics file). This program, built against the installed package
// (CMakeLists.txt here: find_package(diffdyn) and one target), loads it with
// LoadTransitionModel and plans with it in a controller of its own: every model step
// (0.04 s) it tries 121 two-piece torque plans over the next second (u1 for 0.2 s,
// then u2, each of 11 values in [-2.5, 2.5] N m), rolls all of them through the
// model as one batch, scores each by the pendulum task's cost (the running cost
// integral plus 10 s of the final state cost, as `diffdyn control` weighs MPPI's
// horizon) and applies u1 of the cheapest. diffdyn's evaluator runs it on the true
// pendulum from seeded starts and compares it with doing nothing.
//
// Usage: my_controller MODEL.json [STARTS]
//   (exit 1 unless the controller lowers the task cost of doing nothing)
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>

#include "diffdyn/solvers/control.h"
#include "diffdyn/solvers/load_model.h"

namespace {

// The controller: a batch of two-piece torque plans rolled through the saved model.
class TwoPieceShooting final : public diffdyn::Controller {
 public:
  TwoPieceShooting(const diffdyn::ControlTask& task, const diffdyn::TransitionModel& model)
      : task_(task), model_(model), ws_(model.MakeWorkspace(kCandidates)) {
    const Eigen::VectorXd levels = Eigen::VectorXd::LinSpaced(kLevels, -2.5, 2.5);
    first_.resize(1, kCandidates);
    second_.resize(1, kCandidates);
    for (int c = 0; c < kCandidates; ++c) {
      first_(c) = levels[c / kLevels];
      second_(c) = levels[c % kLevels];
    }
  }
  // The model's step in control periods (0.04 s / 8 ms = 5).
  int hold() const override { return diffdyn::PeriodsPerStep(model_.time_step(), task_.period, "the model"); }
  void Reset(const Eigen::VectorXd&, std::uint64_t) override {}
  Eigen::VectorXd Command(const Eigen::VectorXd& x) override {
    Eigen::MatrixXd states = x.replicate(1, kCandidates), next(x.size(), kCandidates);
    Eigen::VectorXd cost = Eigen::VectorXd::Zero(kCandidates);
    const double dt = model_.time_step();
    const int steps = static_cast<int>(std::lround(1.0 / dt)), switch_step = static_cast<int>(std::lround(0.2 / dt));
    for (int step = 0; step < steps; ++step) {
      const Eigen::MatrixXd& u = step < switch_step ? first_ : second_;
      for (int c = 0; c < kCandidates; ++c) cost[c] += dt * task_.RunningCost(states.col(c), u.col(c));
      model_.PredictBatch(states, u, next, *ws_);
      states.swap(next);
    }
    for (int c = 0; c < kCandidates; ++c) cost[c] += 10.0 * task_.StateCost(states.col(c));
    Eigen::Index best = 0;
    cost.minCoeff(&best);
    return Eigen::VectorXd::Constant(1, first_(best));
  }

 private:
  static constexpr int kLevels = 11, kCandidates = kLevels * kLevels;
  const diffdyn::ControlTask& task_;
  const diffdyn::TransitionModel& model_;
  std::unique_ptr<diffdyn::TransitionWorkspace> ws_;
  Eigen::MatrixXd first_, second_;
};

// The controller that does nothing, for comparison.
class Zero final : public diffdyn::Controller {
 public:
  void Reset(const Eigen::VectorXd&, std::uint64_t) override {}
  Eigen::VectorXd Command(const Eigen::VectorXd&) override { return Eigen::VectorXd::Zero(1); }
};

double MeanCost(const std::vector<diffdyn::ControlRun>& runs) {
  double sum = 0.0;
  for (const auto& run : runs) sum += run.cost;
  return sum / static_cast<double>(runs.size());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s MODEL.json [STARTS]\n", argv[0]);
    return 2;
  }
  try {
    const diffdyn::ControlTask task = diffdyn::ControlTaskByName("pendulum");
    const auto model = diffdyn::LoadTransitionModel(argv[1], {.dt = 0.04});
    const diffdyn::EvaluationOptions options{.starts = argc > 2 ? std::atoi(argv[2]) : 5, .seed = 1};
    TwoPieceShooting mine(task, *model);
    Zero nothing;
    const auto runs = diffdyn::EvaluateController(task, mine, options);
    const auto idle = diffdyn::EvaluateController(task, nothing, options);
    int up = 0;
    for (const auto& run : runs) up += run.success ? 1 : 0;
    std::printf("%s: mean cost %.2f with the controller (%d of %zu swung up), %.2f doing nothing\n", argv[1],
                MeanCost(runs), up, runs.size(), MeanCost(idle));
    return MeanCost(runs) < MeanCost(idle) ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 2;
  }
}
