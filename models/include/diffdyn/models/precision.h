// The floating-point precision a model computes in.
//
// A model's parameters are always stored and optimised in double (the master copy);
// with Precision::kF32 its heavy batched work (network products, the NeuralODE's
// solver and adjoint) runs on float copies, as PyTorch's float32 does. Sums that
// need double (losses, Adam's moments, adaptive solvers' error estimates) stay in
// double either way. Model files record the precision ("precision": "f32" or "f64");
// a command's --precision converts a loaded model.
//
//   const Precision p = ParsePrecision("f32", "--precision");  // Precision::kF32
//   PrecisionName(p);                                          // "f32"
#pragma once

#include <string>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {

/// float64 (the default) or float32.
enum class Precision { kF64, kF32 };

/// "f64" or "f32".
inline std::string PrecisionName(Precision p) { return p == Precision::kF32 ? "f32" : "f64"; }

/// Parses "f64" or "f32"; throws diffdyn::Error naming `option` and the value otherwise.
inline Precision ParsePrecision(const std::string& name,
                                const std::string& option = "--precision") {
  if (name == "f64") return Precision::kF64;
  if (name == "f32") return Precision::kF32;
  throw Error(StrCat(option, ": unknown precision '", name, "' (expected f32 or f64)"));
}

}  // namespace diffdyn
