// diffdyn.Task: a control task (physics/control_task.h) from Python, and
// diffdyn.ground_truth: the force components of a joint-space system's equation
// along a trajectory (solvers/joint_collect.h).
//
//   task = diffdyn.Task("pendulum")
//   x0 = task.sample_starts(20, seed=1)      # the starts `diffdyn control --seed 1` uses
//   plant = task.plant()                     # a diffdyn.Model over one control period
//   c = task.running_cost(x, u)              # c(x, u) per sample
//   parts = diffdyn.ground_truth("pendulum", states, actions)   # {"m": ..., "g": ..., ...}
#include <string>
#include <vector>

#include <pybind11/stl.h>

#include "arrays.h"
#include "bindings.h"
#include "diffdyn/physics/control_task.h"
#include "diffdyn/solvers/control.h"
#include "diffdyn/solvers/joint_collect.h"

namespace diffdyn::python {
namespace {

// The evaluator's starts (Task::Starts): (count, n).
py::array_t<double> SampleStarts(const ControlTask& task, int count, std::uint64_t seed) {
  DIFFDYN_CHECK(count >= 1 && count <= 100000, "sample_starts: count must be in [1, 100000], got ", count);
  const std::vector<TaskStart> starts = task.Starts(count, seed);
  Eigen::MatrixXd columns(task.state_size(), count);
  for (int s = 0; s < count; ++s) columns.col(s) = starts[static_cast<std::size_t>(s)].x0;
  return FromColumns(columns);
}

// c(x, u) per sample: x (N, n), u (N, m) -> (N,); one sample -> a float.
py::object RunningCost(const ControlTask& task, const py::handle& x_in, const py::handle& u_in) {
  const Batch x = ReadBatch(x_in, task.state_size(), "running_cost: x");
  const Batch u = ReadBatch(u_in, task.action_size(), "running_cost: u");
  DIFFDYN_CHECK(x.samples == u.samples, "running_cost: x has ", x.samples, " samples, u has ", u.samples);
  Eigen::VectorXd costs(x.samples);
  for (int b = 0; b < x.samples; ++b) costs[b] = task.RunningCost(x.matrix().col(b), task.Clip(u.matrix().col(b)));
  if (x.single) return py::float_(costs[0]);
  return FromVector(costs);
}

// The success test per sample: x (N, n) -> list of bool; one sample -> bool.
py::object Succeeded(const ControlTask& task, const py::handle& x_in) {
  const Batch x = ReadBatch(x_in, task.state_size(), "succeeded: x");
  std::vector<bool> ok;
  for (int b = 0; b < x.samples; ++b) ok.push_back(task.Succeeded(x.matrix().col(b)));
  if (x.single) return py::bool_(ok[0]);
  return py::cast(ok);
}

// The plant over `dt` seconds (default: one control period) in `substeps` rk4 steps.
py::object Plant(const ControlTask& task, double dt, int substeps) {
  if (dt == 0.0) dt = task.period;
  DIFFDYN_CHECK(dt > 0 && dt <= 10 && substeps >= 1 && substeps <= 10000, "plant: dt must be in (0, 10] s and "
                "substeps in [1, 10000], got ", dt, " and ", substeps);
  return WrapModel(StrCat(task.plant.name, " task plant"), TaskModel(task, dt, substeps));
}

// The channels of AddGroundTruth as (K + 1, rows) arrays: states (K + 1, 2n), actions (K, a).
py::dict GroundTruth(const std::string& system, const py::handle& states_in, const py::handle& actions_in) {
  const JointTask task = JointTaskByName(system);
  const int n = task.Model()->dof(), a = static_cast<int>(task.actuated.size());
  const Batch states = ReadBatch(states_in, 2 * n, "ground_truth: states");
  const Batch actions = ReadBatch(actions_in, a, "ground_truth: actions");
  DIFFDYN_CHECK(!states.single && !actions.single && actions.samples == states.samples - 1,
                "ground_truth: expected states (K + 1, ", 2 * n, ") and actions (K, ", a, ") with K >= 1, got ",
                states.samples, " states and ", actions.samples, " actions");
  Trajectory trajectory;
  trajectory.states = states.matrix();
  trajectory.actions = actions.matrix();
  {
    py::gil_scoped_release release;
    AddGroundTruth(task, &trajectory);
  }
  py::dict out;
  for (const auto& [name, channel] : trajectory.channels) {
    out[py::str(name)] = FromColumns(channel);
  }
  return out;
}

}  // namespace

void BindTasks(py::module_& m) {
  py::class_<ControlTask>(m, "Task", R"doc(
A control task (DESIGN.md, "Control tasks"): the plant, the running cost
c(x, u) = sum_i w_i e_i(x)^2 + g(u), the success test, the start distribution, the
torque bounds and the control period. Task("pendulum") or Task("cartpole").)doc")
      .def(py::init(&ControlTaskByName), py::arg("name"))
      .def_property_readonly("name", [](const ControlTask& t) { return t.plant.name; })
      .def_readonly("period", &ControlTask::period, "Control period (s).")
      .def_readonly("duration", &ControlTask::duration, "Run length (s).")
      .def_property_readonly("state_size", &ControlTask::state_size)
      .def_property_readonly("action_size", &ControlTask::action_size)
      .def_property_readonly("bound", [](const ControlTask& t) { return FromVector(t.plant.bound); },
                             "|u_j| bound per action (m,).")
      .def_property_readonly("goal", [](const ControlTask& t) { return FromVector(t.goal); })
      .def("sample_starts", &SampleStarts, py::arg("count"), py::arg("seed") = 0,
           "(count, n) start states: the ones `diffdyn control --starts COUNT --seed SEED` runs from.")
      .def("running_cost", &RunningCost, py::arg("x"), py::arg("u"),
           "c(x, clip(u)): x (N, n), u (N, m) -> (N,); one sample -> float.")
      .def("succeeded", &Succeeded, py::arg("x"), "The success test on final states: (N, n) -> [bool] or bool.")
      .def("plant", &Plant, py::arg("dt") = 0.0, py::arg("substeps") = 4,
           "The plant as a diffdyn.Model over dt seconds (default: the control period), rk4 in `substeps` steps.")
      .def("__repr__", [](const ControlTask& t) { return StrCat("<diffdyn.Task ", t.plant.name, ">"); });

  m.def("ground_truth", &GroundTruth, py::arg("system"), py::arg("states"), py::arg("actions"),
        R"doc(The ground-truth components of a joint-space system's equation along a trajectory of its
task plant, as `diffdyn collect --system SYSTEM` records them: states (K + 1, 2n) = (q, qd),
actions (K, a) the actuated torques, each held from its sample. Returns a dict of (K + 1, rows)
arrays: tau, qdd, m = H(q) qdd, c = C(q, qd) qd, g = g(q), f (what the effects take away),
kinetic, potential. SYSTEM: pendulum, cartpole, double-pendulum, arm2, panda.)doc");
}

}  // namespace diffdyn::python
