// The parts of the diffdyn Python module, each defined in its own file.
#pragma once

#include <string>

#include <pybind11/pybind11.h>

namespace diffdyn::python {

/// diffdyn.Model and diffdyn.load_model (model_bindings.cc).
void BindModels(pybind11::module_& m);

/// The path or name of `model`: a str, or the spec a diffdyn.Model was loaded from.
/// Throws pybind11::value_error for anything else (model_bindings.cc).
std::string ModelSpec(const pybind11::handle& model);

}  // namespace diffdyn::python
