// diffdyn.Model: any dynamics model the library loads, over numpy batches.
//
// Batches are split into chunks of kChunk samples whose boundaries depend on N
// only, so results are the same bits at any thread count; each chunk borrows a
// workspace from the model's pool (made once, reused by later calls). The GIL is
// released while the library works, so Python threads run alongside.
#include <algorithm>
#include <chrono>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <pybind11/stl.h>

#include "arrays.h"
#include "bindings.h"
#include "diffdyn/autodiff_ode/butcher.h"
#include "diffdyn/models/parallel.h"
#include "diffdyn/solvers/load_model.h"

namespace diffdyn::python {
namespace {

constexpr int kChunk = 256;

// A loaded model, where it came from, and its reusable workspaces.
class PyModel {
 public:
  PyModel(std::string spec, std::unique_ptr<TransitionModel> model)
      : spec_(std::move(spec)), model_(std::move(model)) {}

  const std::string& spec() const { return spec_; }
  const TransitionModel& model() const { return *model_; }

  // A workspace for up to kChunk samples, from the pool or new.
  std::unique_ptr<TransitionWorkspace> Acquire() const {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!free_.empty()) {
        auto ws = std::move(free_.back());
        free_.pop_back();
        return ws;
      }
    }
    return model_->MakeWorkspace(kChunk);
  }
  void Release(std::unique_ptr<TransitionWorkspace> ws) const {
    std::lock_guard<std::mutex> lock(mutex_);
    free_.push_back(std::move(ws));
  }

 private:
  std::string spec_;
  std::unique_ptr<TransitionModel> model_;
  mutable std::mutex mutex_;
  mutable std::vector<std::unique_ptr<TransitionWorkspace>> free_;
};

// body(begin, end, workspace) over the chunks of n samples on `threads` threads.
template <typename Body>
void ForChunks(const PyModel& m, int n, int threads, Body body) {
  DIFFDYN_CHECK(threads >= 0, "threads must be >= 0, got ", threads);
  ParallelForChunks(n, kChunk, threads, [&](int, int begin, int end) {
    std::unique_ptr<TransitionWorkspace> ws = m.Acquire();
    body(begin, end, *ws);
    m.Release(std::move(ws));
  });
}

std::string Name(const PyModel& m, const char* method) { return StrCat(m.model().kind(), ".", method); }

// F(x, u) (file comment of the module for shapes); dt: per-sample intervals or None.
py::array Predict(const PyModel& m, const py::handle& x_in, const py::handle& u_in,
                  const py::object& dt_in, int threads) {
  const TransitionModel& model = m.model();
  const int n = model.state_size();
  const Batch x = ReadBatch(x_in, n, Name(m, "predict: x"));
  const Batch u = ReadBatch(u_in, model.action_size(), Name(m, "predict: u"));
  DIFFDYN_CHECK(x.samples == u.samples && x.single == u.single, Name(m, "predict"), ": x has ", x.samples,
                " samples, u has ", u.samples);
  py::array_t<double> dt;
  if (py::isinstance<py::float_>(dt_in) || py::isinstance<py::int_>(dt_in)) {
    dt = NewArray({x.samples});  // one interval for every sample
    std::fill(dt.mutable_data(), dt.mutable_data() + x.samples, dt_in.cast<double>());
  } else if (!dt_in.is_none()) {
    dt = ReadArray(dt_in, 1, Name(m, "predict: dt"));
    DIFFDYN_CHECK(dt.size() == x.samples, Name(m, "predict: dt"), " has ", dt.size(), " entries for ", x.samples,
                  " samples");
  }
  py::array_t<double> out = x.single ? NewArray({n}) : NewArray({x.samples, n});
  {
    py::gil_scoped_release release;
    const auto xs = x.matrix(), us = u.matrix();
    Eigen::Map<Eigen::MatrixXd> next(out.mutable_data(), n, x.samples);
    const double* intervals = dt.size() > 0 ? dt.data() : nullptr;
    ForChunks(m, x.samples, threads, [&](int begin, int end, TransitionWorkspace& ws) {
      const int b = end - begin;
      if (intervals) {
        const Eigen::Map<const Eigen::RowVectorXd> h(intervals + begin, b);
        model.PredictBatchOver(xs.middleCols(begin, b), us.middleCols(begin, b), h, next.middleCols(begin, b), ws);
      } else {
        model.PredictBatch(xs.middleCols(begin, b), us.middleCols(begin, b), next.middleCols(begin, b), ws);
      }
    });
  }
  CheckFiniteResult(out, Name(m, "predict"));
  return Returned(out, x.float32);
}

// [dF/dx, dF/du] per sample: (N, n, n + m), or (n, n + m) for one sample.
py::array Jacobian(const PyModel& m, const py::handle& x_in, const py::handle& u_in, int threads) {
  const TransitionModel& model = m.model();
  DIFFDYN_CHECK(model.differentiable(), Name(m, "jacobian"), ": this model has no derivatives");
  const int n = model.state_size(), k = n + model.action_size();
  const Batch x = ReadBatch(x_in, n, Name(m, "jacobian: x"));
  const Batch u = ReadBatch(u_in, model.action_size(), Name(m, "jacobian: u"));
  DIFFDYN_CHECK(x.samples == u.samples && x.single == u.single, Name(m, "jacobian"), ": x has ", x.samples,
                " samples, u has ", u.samples);
  py::array_t<double> out = x.single ? NewArray({n, k}) : NewArray({x.samples, n, k});
  {
    py::gil_scoped_release release;
    const auto xs = x.matrix(), us = u.matrix();
    double* data = out.mutable_data();
    using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
    ParallelForChunks(x.samples, kChunk, threads, [&](int, int begin, int end) {
      Eigen::MatrixXd jac;
      for (int b = begin; b < end; ++b) {
        model.Jacobian(xs.col(b), us.col(b), &jac);
        Eigen::Map<RowMajor>(data + Eigen::Index(b) * n * k, n, k) = jac;
      }
    });
  }
  CheckFiniteResult(out, Name(m, "jacobian"));
  return Returned(out, x.float32);
}

// States x_0 .. x_T under actions u_0 .. u_{T-1}: x0 (N, n), actions (N, T, m) ->
// (N, T + 1, n); one sample: x0 (n,), actions (T, m) -> (T + 1, n).
py::array Rollout(const PyModel& m, const py::handle& x0_in, const py::handle& actions_in, int threads) {
  const TransitionModel& model = m.model();
  const int n = model.state_size(), a = model.action_size();
  const Batch x0 = ReadBatch(x0_in, n, Name(m, "rollout: x0"));
  const py::array_t<double> actions = ReadArray(actions_in, x0.single ? 2 : 3, Name(m, "rollout: actions"));
  const int samples = x0.samples;
  const int steps = static_cast<int>(actions.shape(x0.single ? 0 : 1));
  const bool fits = actions.shape(actions.ndim() - 1) == a && (x0.single || actions.shape(0) == samples);
  DIFFDYN_CHECK(fits && steps >= 1, Name(m, "rollout: actions"), ": expected shape ",
                x0.single ? StrCat("(T, ", a, ")") : StrCat("(", samples, ", T, ", a, ")"), " with T >= 1");
  py::array_t<double> out = x0.single ? NewArray({steps + 1, n}) : NewArray({samples, steps + 1, n});
  {
    py::gil_scoped_release release;
    const auto start = x0.matrix();
    const double* u = actions.data();
    double* states = out.mutable_data();
    ForChunks(m, samples, threads, [&](int begin, int end, TransitionWorkspace& ws) {
      const int b = end - begin;
      Eigen::MatrixXd x = start.middleCols(begin, b), next(n, b), act(a, b);
      for (int t = 0; t <= steps; ++t) {
        for (int j = 0; j < b; ++j) {
          const Eigen::Index sample = begin + j;
          Eigen::Map<Eigen::VectorXd>(states + (sample * (steps + 1) + t) * n, n) = x.col(j);
          if (t < steps) act.col(j) = Eigen::Map<const Eigen::VectorXd>(u + (sample * steps + t) * a, a);
        }
        if (t == steps) break;
        model.PredictBatch(x, act, next, ws);
        x.swap(next);
      }
    });
  }
  CheckFiniteResult(out, Name(m, "rollout"));
  return Returned(out, x0.float32);
}

// Median seconds of `repeats` PredictBatch calls on the whole batch in C++ (one
// thread, one workspace made beforehand): the reference of bench/python_predict.py.
double NativePredictSeconds(const PyModel& m, const py::handle& x_in, const py::handle& u_in, int repeats) {
  const TransitionModel& model = m.model();
  const Batch x = ReadBatch(x_in, model.state_size(), "x"), u = ReadBatch(u_in, model.action_size(), "u");
  DIFFDYN_CHECK(repeats >= 1 && x.samples == u.samples, "repeats must be >= 1 and x, u the same samples");
  py::gil_scoped_release release;
  const auto ws = model.MakeWorkspace(x.samples);
  Eigen::MatrixXd next(model.state_size(), x.samples);
  std::vector<double> seconds;
  for (int r = 0; r < repeats; ++r) {
    const auto start = std::chrono::steady_clock::now();
    model.PredictBatch(x.matrix(), u.matrix(), next, *ws);
    seconds.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  }
  std::nth_element(seconds.begin(), seconds.begin() + repeats / 2, seconds.end());
  return seconds[static_cast<std::size_t>(repeats / 2)];
}

std::shared_ptr<PyModel> Load(const std::string& spec, double dt, const std::string& solver, int substeps,
                              const std::string& precision) {
  LoadModelOptions options;
  options.dt = dt;
  options.method = ParseMethod(solver, "solver");
  options.substeps = substeps;
  if (!precision.empty()) options.precision = ParsePrecision(precision, "precision");
  DIFFDYN_CHECK(substeps >= 1, "substeps must be >= 1, got ", substeps);
  return std::make_shared<PyModel>(spec, LoadTransitionModel(spec, options));
}

}  // namespace

std::shared_ptr<const TransitionModel> SharedModel(const py::handle& model, const std::string& what) {
  if (!py::isinstance<PyModel>(model)) throw py::value_error(what + ": expected a diffdyn.Model");
  const auto holder = model.cast<std::shared_ptr<PyModel>>();
  return {holder, &holder->model()};  // shares ownership of the diffdyn.Model
}

py::object WrapModel(std::string spec, std::unique_ptr<TransitionModel> model) {
  return py::cast(std::make_shared<PyModel>(std::move(spec), std::move(model)));
}

std::string ModelSpec(const py::handle& model) {
  if (py::isinstance<py::str>(model)) return model.cast<std::string>();
  if (py::isinstance<PyModel>(model)) return model.cast<const PyModel&>().spec();
  throw py::value_error("model: expected a diffdyn.Model or a model path / name");
}

void BindModels(py::module_& m) {
  py::class_<PyModel, std::shared_ptr<PyModel>>(m, "Model", R"doc(
A dynamics model x_{t+1} = F(x_t, u_t): learned (abs-nn, res-nn, abs-node, res-node),
analytic (pendulum, cartpole, double-pendulum, arm2, panda), extended-physics, DeLaN
or the ODE-engine pusher ("oracle"). Made by diffdyn.load_model.)doc")
      .def_property_readonly("kind", [](const PyModel& p) { return p.model().kind(); })
      .def_property_readonly("spec", &PyModel::spec, "The path or name it was loaded from.")
      .def_property_readonly("state_size", [](const PyModel& p) { return p.model().state_size(); })
      .def_property_readonly("action_size", [](const PyModel& p) { return p.model().action_size(); })
      .def_property_readonly("time_step", [](const PyModel& p) { return p.model().time_step(); },
                             "Seconds one transition spans (0: not recorded).")
      .def_property_readonly("state_names", [](const PyModel& p) { return p.model().description().state_names; })
      .def_property_readonly("action_names", [](const PyModel& p) { return p.model().description().action_names; })
      .def_property_readonly("differentiable", [](const PyModel& p) { return p.model().differentiable(); })
      .def_property_readonly("precision", [](const PyModel& p) { return PrecisionName(p.model().precision()); },
                             "\"f32\" or \"f64\": what predict and rollout compute in.")
      .def("predict", &Predict, py::arg("x"), py::arg("u"), py::arg("dt") = py::none(), py::arg("threads") = 0,
           R"doc(Next states F(x, u): x (N, n), u (N, m) -> (N, n); one sample x (n,), u (m,) -> (n,).
dt: seconds per transition, (N,) or one number, for continuous-time models (others ignore it).
float64 C-contiguous inputs are read in place; float32 in gives float32 out. The model computes in its
own precision (Model.precision, set by load_model's precision).)doc")
      .def("jacobian", &Jacobian, py::arg("x"), py::arg("u"), py::arg("threads") = 0,
           R"doc([dF/dx, dF/du] per sample, exact (forward-mode Jets): (N, n, n + m), or (n, n + m) for one sample.)doc")
      .def("rollout", &Rollout, py::arg("x0"), py::arg("actions"), py::arg("threads") = 0,
           R"doc(States x_0 .. x_T: x0 (N, n), actions (N, T, m) -> (N, T + 1, n); x0 (n,), actions (T, m) -> (T + 1, n).)doc")
      .def("__repr__", [](const PyModel& p) {
        return StrCat("<diffdyn.Model ", p.model().kind(), " '", p.spec(), "': ", p.model().state_size(),
                      " states, ", p.model().action_size(), " actions>");
      });

  m.def("_native_predict_seconds", &NativePredictSeconds, py::arg("model"), py::arg("x"), py::arg("u"),
        py::arg("repeats"), "Median seconds of the same predict in C++ (one thread), for benchmarks.");
  m.def("load_model", &Load, py::arg("spec"), py::arg("dt") = 0.0, py::arg("solver") = "rk4-classic",
        py::arg("substeps") = 4, py::arg("precision") = "",
        R"doc(The model `spec` names: a model file (learned, extended-physics, delan), an analytic model
name (pendulum, cartpole, double-pendulum, arm2, panda) or "oracle". Continuous-time models
need dt (seconds per transition) and integrate with `solver` in `substeps` steps. precision:
"f32" or "f64" converts a learned model (as the commands' --precision); "" keeps the file's own.)doc");
}

}  // namespace diffdyn::python
