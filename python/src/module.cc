// The compiled part of the `diffdyn` Python package (diffdyn/__init__.py re-exports
// it): models over numpy batches (model_bindings.cc), the evaluation `diffdyn eval
// --json` prints, the library's version, and its errors as Python exceptions:
// diffdyn::Error (bad input) becomes ValueError with the command line's message,
// diffdyn::NumericalError (a runtime failure) RuntimeError.
#include <string>

#include <pybind11/pybind11.h>

#include "arrays.h"
#include "bindings.h"
#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/solvers/model_evaluation.h"
#include "diffdyn/solvers/version.h"

namespace diffdyn::python {
namespace {

// The `eval --json` summary as a dict (through JSON text, so numbers are the same bits).
py::object Evaluate(const py::handle& model, const std::string& data, const std::string& solver, int steps,
                    int substeps, int threads) {
  EvalRequest request{.model = ModelSpec(model), .data = data, .solver = solver, .steps = steps,
                      .substeps = substeps, .threads = threads};
  std::string text;
  {
    py::gil_scoped_release release;
    text = EvaluateFiles(request).dump();
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
  m.def("evaluate", &Evaluate, py::arg("model"), py::arg("data"), py::arg("solver") = "", py::arg("steps") = 0,
        py::arg("substeps") = 4, py::arg("threads") = 0,
        R"doc(The dictionary `diffdyn eval --model MODEL --data DATA --json` prints, from the same
computation: MODEL is a path or name, or a diffdyn.Model (its spec is evaluated; continuous-time
models take the data's median interval). solver / steps / substeps as the command's options.)doc");
  m.def("_input_copies", [] { return InputCopies().load(); },
        "How many input arrays were converted (copied) instead of read in place (for tests).");
}
