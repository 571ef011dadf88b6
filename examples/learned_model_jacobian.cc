// The exact Jacobian of a learned dynamics model, and how close it is to the true one.
//
// A learned transition model x_{t+1} = F(x_t, u_t) (here an absolute NeuralODE on the
// pendulum: z(0) = [x; u], dz/dt = MLP(z), x_{t+1} = P z(1)) gives
//
//   J = [dF/dx, dF/du]   (n x (n + m) = 2 x 3)
//
// by Jets through the network and through every stage of its Runge-Kutta solver
// (LearnedModel::Jacobian): exact for the discrete map, one evaluation. The example
// checks it against central differences of the batched prediction, then compares
// it with the Jacobian of the true plant over the same 0.04 s (the task's pendulum,
// rk4-classic on Jets), the quantity LQR or iLQR on the learned model would use.
//
// Usage: example_learned_model_jacobian [--quick]   (exit 1 if Jets and central
// differences disagree, or the learned J misses the plant's by more than 10 %)
#include <cstring>

#include <fmt/core.h>

#include "diffdyn/physics/control_task.h"
#include "diffdyn/solvers/joint_collect.h"
#include "diffdyn/solvers/model_training.h"

namespace {

// [dF/dx, dF/du] of model at (x, u) by central differences of PredictBatch.
Eigen::MatrixXd CentralJacobian(const diffdyn::TransitionModel& model, const Eigen::VectorXd& x,
                                const Eigen::VectorXd& u, double h) {
  const int n = static_cast<int>(x.size()), m = static_cast<int>(u.size());
  Eigen::MatrixXd states = x.replicate(1, 2 * (n + m)), actions = u.replicate(1, 2 * (n + m));
  for (int j = 0; j < n + m; ++j) {
    Eigen::MatrixXd& input = j < n ? states : actions;
    const int row = j < n ? j : j - n;
    input(row, 2 * j) += h;
    input(row, 2 * j + 1) -= h;
  }
  Eigen::MatrixXd next(n, 2 * (n + m));
  model.PredictBatch(states, actions, next, *model.MakeWorkspace(2 * (n + m)));
  Eigen::MatrixXd jac(n, n + m);
  for (int j = 0; j < n + m; ++j) jac.col(j) = (next.col(2 * j) - next.col(2 * j + 1)) / (2 * h);
  return jac;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace diffdyn;
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;

  // A pendulum model learned from simulated data (see train_neuralode_joint_csv.cc).
  const ControlTask task = ControlTaskByName("pendulum");
  const Dataset data = CollectJointSpace(task.plant, {.trajectories = quick ? 40 : 100, .seed = 1, .threads = 2});
  const LearnedModel model = FitLearnedModel(data, {.type = LearnedKind::kAbsNode, .hidden = 64, .steps = 3},
                                             {.epochs = quick ? 40 : 100, .seed = 1, .progress = false})
                                 .model;
  const auto plant = TaskModel(task, 0.04, 10);

  // Jacobians at three states and torques.
  const Eigen::MatrixXd points = (Eigen::MatrixXd(3, 3) << 0.5, 2.0, -1.0,   // q
                                  1.0, -2.0, 0.5,                          // qd
                                  0.3, -1.0, 0.0)                          // u
                                     .finished();
  double worst_fd = 0.0, worst_plant = 0.0;
  for (int k = 0; k < points.cols(); ++k) {
    const Eigen::VectorXd x = points.col(k).head(2), u = points.col(k).tail(1);
    Eigen::MatrixXd jets, truth;
    model.Jacobian(x, u, &jets);
    plant->Jacobian(x, u, &truth);
    const Eigen::MatrixXd central = CentralJacobian(model, x, u, 1e-6);
    const double fd_error = (jets - central).norm() / jets.norm();
    const double plant_error = (jets - truth).norm() / truth.norm();
    worst_fd = std::max(worst_fd, fd_error);
    worst_plant = std::max(worst_plant, plant_error);
    fmt::print("x = ({:5.2f}, {:5.2f}), u = {:5.2f}\n", x[0], x[1], u[0]);
    for (int i = 0; i < 2; ++i) {
      fmt::print("  learned [{:8.5f} {:8.5f} {:8.5f}]   plant [{:8.5f} {:8.5f} {:8.5f}]\n", jets(i, 0),
                 jets(i, 1), jets(i, 2), truth(i, 0), truth(i, 1), truth(i, 2));
    }
    fmt::print("  |J_jets - J_central| / |J| = {:.1e},  |J_learned - J_plant| / |J_plant| = {:.2f} %\n",
               fd_error, 100 * plant_error);
  }
  if (!(worst_fd < 1e-6) || !(worst_plant < 0.10)) {
    fmt::print(stderr, "error: Jets vs central differences {:.1e} (< 1e-6), learned vs plant {:.1f} % (< 10 %)\n",
               worst_fd, 100 * worst_plant);
    return 1;
  }
  return 0;
}
