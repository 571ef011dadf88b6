// The compiled part of the `diffdyn` Python package (diffdyn/__init__.py re-exports
// it): models over numpy batches (model_bindings.cc), DeLaN's torque parts
// (delan_bindings.cc), control tasks and MPPI
// (task_bindings.cc, mppi_bindings.cc), the training, evaluation and diagnosis whose
// summaries `diffdyn train / eval / diagnose --json` print, the library's version,
// and its errors as Python exceptions:
// diffdyn::Error (bad input) becomes ValueError with the command line's message,
// diffdyn::NumericalError (a runtime failure) RuntimeError.
#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "arrays.h"
#include "bindings.h"
#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/solvers/model_diagnosis.h"
#include "diffdyn/solvers/model_evaluation.h"
#include "diffdyn/solvers/model_training.h"
#include "diffdyn/solvers/version.h"

namespace diffdyn::python {
namespace {

// The `eval --json` summary as a dict (through JSON text, so numbers are the same bits).
py::object Evaluate(const py::handle& model, const std::string& data, const std::string& solver, int steps,
                    int substeps, int threads, const std::string& precision) {
  EvalRequest request{.model = ModelSpec(model), .data = data, .solver = solver, .steps = steps,
                      .substeps = substeps, .threads = threads, .precision = precision};
  std::string text;
  {
    py::gil_scoped_release release;
    text = EvaluateFiles(request).dump();
  }
  return py::module_::import("json").attr("loads")(text);
}

// 1-based joints from a list.
std::vector<int> Joints(const py::handle& value, const char* option) {
  try {
    return value.cast<std::vector<int>>();
  } catch (const py::cast_error&) {
    throw py::value_error(StrCat(option, ": expected a list of 1-based joint numbers"));
  }
}

void SetActuated(TrainRequest& r, const py::handle& value) {
  const bool text = py::isinstance<py::str>(value);
  if (text && value.cast<std::string>() == "all") {
    r.layout.all_actuated = true;
  } else if (!text || value.cast<std::string>() != "auto") {
    r.layout.actuated = Joints(value, "actuated");
  }
}

void SetAngleFeatures(TrainRequest& r, const py::handle& value) {
  const std::string features = value.cast<std::string>();
  if (features != "sincos" && features != "raw") {
    throw py::value_error("angle_features: expected 'sincos' or 'raw', got '" + features + "'");
  }
  r.layout.angle_features = features == "raw" ? AngleFeatures::kRaw : AngleFeatures::kSinCos;
  r.angle_features_given = true;
}

// The keyword options of train, each setting its field of the request.
using Setter = std::function<void(TrainRequest&, const py::handle&)>;
const std::map<std::string, Setter>& TrainSetters() {
  static const std::map<std::string, Setter> setters = {
      {"solver", [](TrainRequest& r, const py::handle& v) { r.solver = v.cast<std::string>(); }},
      {"steps", [](TrainRequest& r, const py::handle& v) { r.steps = v.cast<int>(); }},
      {"loss", [](TrainRequest& r, const py::handle& v) { r.loss = v.cast<std::string>(); }},
      {"gamma", [](TrainRequest& r, const py::handle& v) { r.gamma = v.cast<double>(); }},
      {"val_fraction", [](TrainRequest& r, const py::handle& v) { r.val_fraction = v.cast<double>(); }},
      {"threads", [](TrainRequest& r, const py::handle& v) { r.threads = v.cast<int>(); }},
      {"patience", [](TrainRequest& r, const py::handle& v) { r.patience = v.cast<int>(); }},
      {"normalize", [](TrainRequest& r, const py::handle& v) { r.normalize = v.cast<std::string>(); }},
      {"seed", [](TrainRequest& r, const py::handle& v) { r.seed = v.cast<std::uint64_t>(); }},
      {"precision", [](TrainRequest& r, const py::handle& v) { r.precision = v.cast<std::string>(); }},
      {"progress", [](TrainRequest& r, const py::handle& v) { r.progress = v.cast<bool>(); }},
      {"epochs", [](TrainRequest& r, const py::handle& v) { r.epochs = v.cast<int>(); }},
      {"batch", [](TrainRequest& r, const py::handle& v) { r.batch = v.cast<int>(); }},
      {"hidden", [](TrainRequest& r, const py::handle& v) { r.hidden = v.cast<int>(); }},
      {"lr", [](TrainRequest& r, const py::handle& v) { r.lr = v.cast<double>(); }},
      {"mass_epsilon", [](TrainRequest& r, const py::handle& v) { r.mass_epsilon = v.cast<double>(); }},
      {"diagonal_floor", [](TrainRequest& r, const py::handle& v) { r.diagonal_floor = v.cast<double>(); }},
      {"prismatic", [](TrainRequest& r, const py::handle& v) { r.layout.prismatic = Joints(v, "prismatic"); }},
      {"actuated", SetActuated},
      {"angle_features", SetAngleFeatures}};
  return setters;
}

// The `train --json` summary; the model file is written to `out`.
py::object Train(const std::string& data, const std::string& model, const std::string& out, const py::kwargs& kw) {
  TrainRequest r{.data = data, .model = model, .out = out};
  for (const auto& [key_handle, value] : kw) {
    const std::string key = key_handle.cast<std::string>();
    const auto setter = TrainSetters().find(key);
    if (setter == TrainSetters().end()) throw py::value_error("train: unknown option '" + key + "'");
    try {
      setter->second(r, value);
    } catch (const py::cast_error&) {
      throw py::type_error(StrCat("train: option '", key, "' got a ", py::str(value.get_type()).cast<std::string>()));
    }
  }
  std::string text;
  {
    py::gil_scoped_release release;
    text = TrainFiles(r).dump();
  }
  return py::module_::import("json").attr("loads")(text);
}

// The `diagnose --json` summary; report.md, extended_model.json and residuals.csv go to `out`.
py::object Diagnose(const py::handle& model, const std::string& measured, const std::string& out,
                    const std::vector<std::string>& params, const std::string& params_file,
                    const std::vector<std::string>& fit_params, const std::vector<std::string>& scale_params,
                    double cutoff_hz, double holdout, double phase_period, double rollout_horizon,
                    double min_effect_to_noise, double alpha, std::uint64_t seed) {
  DiagnoseRequest r{.model = ModelSpec(model), .measured = measured, .out = out, .params = params,
                    .params_file = params_file, .fit_params = fit_params, .scale_params = scale_params};
  r.pipeline.cutoff_hz = cutoff_hz;
  r.pipeline.holdout_fraction = holdout;
  r.pipeline.phase_period = phase_period;
  r.pipeline.rollout_horizon = rollout_horizon;
  r.pipeline.min_effect_to_noise = min_effect_to_noise;
  r.pipeline.alpha = alpha;
  r.pipeline.seed = seed;
  std::string text;
  {
    py::gil_scoped_release release;
    text = DiagnoseFiles(r).dump();
  }
  return py::module_::import("json").attr("loads")(text);
}

void TranslateErrors() {
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const NumericalError& e) {
      PyErr_SetString(PyExc_RuntimeError, e.what());
    } catch (const Error& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    }
  });
}

}  // namespace
}  // namespace diffdyn::python

PYBIND11_MODULE(_diffdyn, m) {
  namespace py = pybind11;
  using namespace diffdyn::python;
  m.doc() = "diffdyn: robot dynamics with differential equations as the model prior (numpy in and out).";
  m.attr("__version__") = diffdyn::Version();
  TranslateErrors();
  BindModels(m);
  BindTasks(m);
  BindDelan(m);
  BindMppi(m);
  m.def("evaluate", &Evaluate, py::arg("model"), py::arg("data"), py::arg("solver") = "", py::arg("steps") = 0,
        py::arg("substeps") = 4, py::arg("threads") = 0, py::arg("precision") = "",
        R"doc(The dictionary `diffdyn eval --model MODEL --data DATA --json` prints, from the same
computation: MODEL is a path or name, or a diffdyn.Model (its spec is evaluated; continuous-time
models take the data's median interval). solver / steps / substeps / precision as the command's
options (precision "": the model file's own).)doc");
  m.def("train", &Train, py::arg("data"), py::arg("model") = "abs-nn", py::arg("out") = "model.json",
        R"doc(Trains a model on the dataset file `data`, writes it to `out` and returns the dictionary
`diffdyn train --json` prints, from the same function. Keyword options are the command's, in
snake case: solver, steps, hidden, loss, epochs, lr, batch, val_fraction, gamma, threads,
patience, normalize, seed, precision ("f32" or "f64"), mass_epsilon, diagonal_floor, actuated ("auto", "all" or a list of
1-based joints), prismatic (a list), angle_features ("sincos" or "raw"), progress (a bar on stderr).)doc");
  const diffdyn::DiagnosisOptions d;
  m.def("_diagnose", &Diagnose, py::arg("model"), py::arg("measured"), py::arg("out"),
        py::arg("params") = std::vector<std::string>{}, py::arg("params_file") = "",
        py::arg("fit_params") = std::vector<std::string>{}, py::arg("scale_params") = std::vector<std::string>{},
        py::arg("cutoff_hz") = d.cutoff_hz, py::arg("holdout") = d.holdout_fraction,
        py::arg("phase_period") = d.phase_period, py::arg("rollout_horizon") = d.rollout_horizon,
        py::arg("min_effect_to_noise") = d.min_effect_to_noise, py::arg("alpha") = d.alpha, py::arg("seed") = 0,
        "The diagnosis of diffdyn.diagnose without the plots (see there).");
  m.def("_plots_dir", [] { return diffdyn::PlotScriptsDir().string(); },
        "The folder of the plot scripts the command line runs.");
  m.def("_input_copies", [] { return InputCopies().load(); },
        "How many input arrays were converted (copied) instead of read in place (for tests).");
}
