// diffdyn.Mppi: MPPI (solvers/mppi.h) over any diffdyn.Model, with a running cost
// that is either built in (diffdyn.TaskCost: a control task's cost, computed in C++)
// or a Python callable (the slow path: called once per horizon step and rollout
// chunk, with the GIL taken for the call).
//
//   model = diffdyn.load_model("pendulum", dt=0.04)
//   mppi = diffdyn.Mppi(model, diffdyn.TaskCost("pendulum"), horizon=25, seed=1)
//   u = mppi.command(x)                                    # (m,)
//
//   def cost(t, x, u, x_next):                             # (B, n), (B, m), (B, n)
//       return np.sum((x_next - goal) ** 2, axis=1)        # (B,)
//   mppi = diffdyn.Mppi(model, cost, u_min=[-2.5], u_max=[2.5])
//
// A Python cost runs one call at a time (the GIL), so MPPI's rollouts wait for it;
// the built-in costs run on all cores. Exceptions raised by a Python cost reach the
// caller of command() unchanged.
#include <memory>
#include <optional>
#include <string>

#include <pybind11/stl.h>

#include "arrays.h"
#include "bindings.h"
#include "diffdyn/physics/control_task.h"
#include "diffdyn/solvers/control.h"
#include "diffdyn/solvers/mppi.h"

namespace diffdyn::python {
namespace {

// A control task's running cost, built in C++ once the horizon is known.
struct TaskCostSpec {
  std::string task;
  double dt = 0.0;  // 0: the model's time step
  double limit_penalty = 1000.0;
  double terminal_seconds = 10.0;
};

// cost(t, x_t, u_t, x_{t+1}) -> (B,) in Python, added to the samples' costs.
class PythonCost final : public MppiCost {
 public:
  explicit PythonCost(py::object function) : function_(std::move(function)) {}
  ~PythonCost() override {
    py::gil_scoped_acquire acquire;
    function_ = py::object();
  }

  // Mppi calls the step form only.
  void Accumulate(const Eigen::Ref<const Eigen::MatrixXd>& states, Eigen::Ref<Eigen::VectorXd> costs) const override {
    AccumulateStep(-1, states, Eigen::MatrixXd(0, states.cols()), states, costs);
  }

  void AccumulateStep(int t, const Eigen::Ref<const Eigen::MatrixXd>& prev_states,
                      const Eigen::Ref<const Eigen::MatrixXd>& actions, const Eigen::Ref<const Eigen::MatrixXd>& states,
                      Eigen::Ref<Eigen::VectorXd> costs) const override {
    py::gil_scoped_acquire acquire;
    const py::object result = function_(t, FromColumns(prev_states), FromColumns(actions), FromColumns(states));
    const auto values = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(result);
    DIFFDYN_CHECK(values && values.ndim() == 1 && values.size() == costs.size(),
                  "Mppi: the cost must return one number per sample, shape (", costs.size(), ",)");
    const Eigen::Map<const Eigen::VectorXd> add(values.data(), costs.size());
    DIFFDYN_CHECK(add.allFinite(), "Mppi: the cost returned a non-finite value (use a large finite penalty)");
    costs += add;
  }

 private:
  py::object function_;
};

// Vector option from None or a sequence of m numbers.
Eigen::VectorXd Bounds(const py::object& value, int m, const char* what) {
  if (value.is_none()) return {};
  const py::array_t<double> a = ReadArray(value, 1, StrCat("Mppi: ", what));
  DIFFDYN_CHECK(a.size() == m, "Mppi: ", what, " needs ", m, " entries, got ", a.size());
  return Eigen::Map<const Eigen::VectorXd>(a.data(), m);
}

// The controller with everything it refers to.
class PyMppi {
 public:
  PyMppi(const py::object& model, const py::object& cost, int samples, int horizon, double lambda,
         double noise_variance, const py::object& noise_covariance, const py::object& u_min, const py::object& u_max,
         int threads, std::uint64_t seed)
      : model_(SharedModel(model, "Mppi: model")) {
    const int m = model_->action_size();
    MppiOptions o;
    o.samples = samples;
    o.horizon = horizon;
    o.lambda = lambda;
    o.noise_variance = noise_variance;
    o.threads = threads;
    if (!noise_covariance.is_none()) {
      const py::array_t<double> s = ReadArray(noise_covariance, 2, "Mppi: noise_covariance");
      DIFFDYN_CHECK(s.shape(0) == m && s.shape(1) == m, "Mppi: noise_covariance must be ", m, " x ", m);
      o.noise_covariance = Eigen::Map<const Eigen::MatrixXd>(s.data(), m, m);
    }
    o.u_min = Bounds(u_min, m, "u_min");
    o.u_max = Bounds(u_max, m, "u_max");
    if (py::isinstance<TaskCostSpec>(cost)) {
      UseTaskCost(cost.cast<const TaskCostSpec&>(), horizon, o);
    } else {
      DIFFDYN_CHECK(PyCallable_Check(cost.ptr()), "Mppi: cost must be a diffdyn.TaskCost or a callable "
                    "cost(t, x, u, x_next) -> (B,)");
      cost_ = std::make_unique<PythonCost>(cost);
    }
    mppi_ = std::make_unique<Mppi>(*model_, *cost_, o, seed);
  }

  py::array_t<double> Command(const py::handle& x_in) {
    const Batch x = ReadBatch(x_in, model_->state_size(), "Mppi.command: x");
    DIFFDYN_CHECK(x.single, "Mppi.command: x is one state (n,)");
    Eigen::VectorXd u;
    {
      py::gil_scoped_release release;
      u = mppi_->Command(x.matrix().col(0));
    }
    return FromVector(u);
  }

  void Reset() { mppi_->Reset(); }
  py::array_t<double> Nominal() const { return FromColumns(mppi_->nominal()); }
  py::array_t<double> SampleCosts() const { return FromVector(mppi_->sample_costs()); }
  py::array_t<double> PredictNominal(const py::handle& x_in) const {
    const Batch x = ReadBatch(x_in, model_->state_size(), "Mppi.predict_nominal: x");
    DIFFDYN_CHECK(x.single, "Mppi.predict_nominal: x is one state (n,)");
    return FromColumns(mppi_->PredictNominal(x.matrix().col(0)));
  }

 private:
  // The task's cost over the model's steps; the task's bounds unless given.
  void UseTaskCost(const TaskCostSpec& spec, int horizon, MppiOptions& o) {
    task_ = std::make_unique<ControlTask>(ControlTaskByName(spec.task));
    DIFFDYN_CHECK(model_->state_size() == task_->state_size() && model_->action_size() == task_->action_size(),
                  "Mppi: the model has ", model_->state_size(), " states and ", model_->action_size(),
                  " actions, the ", spec.task, " task ", task_->state_size(), " and ", task_->action_size());
    const double dt = spec.dt > 0 ? spec.dt : model_->time_step();
    DIFFDYN_CHECK(dt > 0, "Mppi: TaskCost needs dt (the model does not record its time step)");
    if (o.u_min.size() == 0) o.u_min = -task_->plant.bound;
    if (o.u_max.size() == 0) o.u_max = task_->plant.bound;
    cost_ = std::make_unique<TaskMppiCost>(*task_, dt, spec.limit_penalty, horizon, spec.terminal_seconds);
  }

  std::shared_ptr<const TransitionModel> model_;
  std::unique_ptr<ControlTask> task_;  // referenced by a TaskMppiCost
  std::unique_ptr<MppiCost> cost_;
  std::unique_ptr<Mppi> mppi_;
};

}  // namespace

void BindMppi(py::module_& m) {
  py::class_<TaskCostSpec>(m, "TaskCost", R"doc(
The running cost of a control task for diffdyn.Mppi, computed in C++ on all cores:
dt * c(x_{t+1}, u_t) per model step of dt seconds, plus `limit_penalty` per step outside
the task's state limits, plus `terminal_seconds` * q(x_T) at the horizon's end (as
`diffdyn control --controller mppi` plans). dt = 0 takes the model's time step.)doc")
      .def(py::init([](const std::string& task, double dt, double limit_penalty, double terminal_seconds) {
             ControlTaskByName(task);  // checks the name
             DIFFDYN_CHECK(dt >= 0 && limit_penalty >= 0 && terminal_seconds >= 0,
                           "TaskCost: dt, limit_penalty and terminal_seconds must be >= 0");
             return TaskCostSpec{task, dt, limit_penalty, terminal_seconds};
           }),
           py::arg("task"), py::arg("dt") = 0.0, py::arg("limit_penalty") = 1000.0, py::arg("terminal_seconds") = 10.0)
      .def_readonly("task", &TaskCostSpec::task)
      .def_readonly("dt", &TaskCostSpec::dt);

  py::class_<PyMppi>(m, "Mppi", R"doc(
MPPI over a diffdyn.Model (solvers/mppi.h): K sampled action sequences of T steps, noise
N(0, Sigma), temperature lambda. `cost` is a diffdyn.TaskCost (built in, fast; the task's
bounds are used unless u_min / u_max are given) or a callable cost(t, x, u, x_next) -> (B,)
over a batch of B rollouts at horizon step t (x, x_next: (B, n), u: (B, m)), called with the
GIL held (slow path). Sigma = noise_variance * I unless noise_covariance (m, m) is given.
The same seed gives the same commands at any thread count.)doc")
      .def(py::init<const py::object&, const py::object&, int, int, double, double, const py::object&,
                    const py::object&, const py::object&, int, std::uint64_t>(),
           py::arg("model"), py::arg("cost"), py::arg("samples") = 1000, py::arg("horizon") = 20,
           py::arg("lambda_") = 0.01, py::arg("noise_variance") = 0.5, py::arg("noise_covariance") = py::none(),
           py::arg("u_min") = py::none(), py::arg("u_max") = py::none(), py::arg("threads") = 0,
           py::arg("seed") = 0)
      .def("command", &PyMppi::Command, py::arg("x"), "One MPPI iteration from state x (n,): the action u_0 (m,).")
      .def("reset", &PyMppi::Reset, "A fresh nominal sequence drawn from N(0, Sigma), clamped.")
      .def_property_readonly("nominal", &PyMppi::Nominal, "The nominal sequence U after the last command (T, m).")
      .def_property_readonly("sample_costs", &PyMppi::SampleCosts, "The last command's sample costs S_k (K,).")
      .def("predict_nominal", &PyMppi::PredictNominal, py::arg("x"),
           "The model's state path under the nominal sequence from x: (T + 1, n).");
}

}  // namespace diffdyn::python
