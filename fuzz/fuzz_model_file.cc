// Fuzz target: the model-file loader of every kind (learned, extended-physics, delan),
// then one batched prediction from the rest state, as every command that loads
// a model does next; and the value-file loader (kind value, solvers/hjb.h), then V,
// dV/dx and the policy at the goal and at the rest state, as control --controller hjb. Bad files throw diffdyn::Error (exit 2); a prediction that
// overflows throws diffdyn::NumericalError (exit 1); anything else is a finding.
#include <cstddef>
#include <cstdint>
#include <memory>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/solvers/hjb.h"
#include "diffdyn/solvers/load_model.h"
#include "fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = diffdyn::fuzz::WriteBytes(diffdyn::fuzz::ScratchFolder() / "model.json", data, size);
  try {
    const std::unique_ptr<diffdyn::TransitionModel> model =
        diffdyn::LoadTransitionModel(path, {.dt = 0.01, .substeps = 1});
    const Eigen::MatrixXd states = Eigen::MatrixXd::Zero(model->state_size(), 2);
    const Eigen::MatrixXd actions = Eigen::MatrixXd::Zero(model->action_size(), 2);
    Eigen::MatrixXd next(model->state_size(), 2);
    auto workspace = model->MakeWorkspace(2);
    model->PredictBatch(states, actions, next, *workspace);
  } catch (const diffdyn::Error&) {
  } catch (const diffdyn::NumericalError&) {
    // Finite weights whose prediction overflows: a runtime failure (exit 1), not a crash.
  }
  try {
    std::string task_name;
    const diffdyn::ValueFunction value = diffdyn::LoadValueFunction(path, &task_name);
    const diffdyn::ControlTask task = diffdyn::ControlTaskByName(task_name);
    if (value.state_size() != task.state_size()) return 0;  // refused by control (exit 2)
    Eigen::MatrixXd x = Eigen::MatrixXd::Zero(task.state_size(), 2);
    x.col(0) = task.goal;
    Eigen::VectorXd v;
    Eigen::MatrixXd p;
    value.Evaluate(x, &v, &p);
    diffdyn::HjbController controller(task, value);
    controller.Command(x.col(1));
  } catch (const diffdyn::Error&) {
  }
  return 0;
}
