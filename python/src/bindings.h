// The parts of the diffdyn Python module, each defined in its own file.
#pragma once

#include <memory>
#include <string>

#include <pybind11/pybind11.h>

#include "diffdyn/models/transition_model.h"

namespace diffdyn::python {

/// diffdyn.Model and diffdyn.load_model (model_bindings.cc).
void BindModels(pybind11::module_& m);

/// diffdyn.delan_decompose (delan_bindings.cc).
void BindDelan(pybind11::module_& m);

/// diffdyn.Mppi, diffdyn.TaskCost (mppi_bindings.cc).
void BindMppi(pybind11::module_& m);

/// diffdyn.Task and diffdyn.ground_truth (task_bindings.cc).
void BindTasks(pybind11::module_& m);

/// The model a diffdyn.Model holds; the pointer shares ownership of the Python
/// object's model. Throws pybind11::value_error naming `what` for anything else.
std::shared_ptr<const TransitionModel> SharedModel(const pybind11::handle& model, const std::string& what);

/// A new diffdyn.Model holding `model`, reported as loaded from `spec`.
pybind11::object WrapModel(std::string spec, std::unique_ptr<TransitionModel> model);

/// The path or name of `model`: a str, or the spec a diffdyn.Model was loaded from.
/// Throws pybind11::value_error for anything else (model_bindings.cc).
std::string ModelSpec(const pybind11::handle& model);

}  // namespace diffdyn::python
