// Seeded initialisation of MLP parameters.
//
// Each affine layer W_l (fan_out x fan_in), b_l draws its weights from one of
//
//   torch-default    W, b ~ U(-1/sqrt(fan_in), 1/sqrt(fan_in))
//                    (PyTorch's nn.Linear: kaiming_uniform with a = sqrt(5),
//                     whose bound gain * sqrt(3 / fan_in) = 1 / sqrt(fan_in))
//   xavier-uniform   W ~ U(-r, r),      r     = gain sqrt(6 / (fan_in + fan_out))
//   xavier-normal    W ~ N(0, s^2),     s     = gain sqrt(2 / (fan_in + fan_out))
//   kaiming-uniform  W ~ U(-r, r),      r     = gain sqrt(3 / fan_in)
//   kaiming-normal   W ~ N(0, s^2),     s     = gain / sqrt(fan_in)
//
// with `hidden_gain` for hidden layers and `output_gain` for the linear output
// layer; all but torch-default set the biases to the constant `bias`. The
// DDN authors' default is xavier-normal, hidden gain sqrt(2), output gain 1,
// bias 0.1.
//
// Numbers come from diffdyn::Rng through UniformUnit / StandardNormal, so the
// same seed gives the same parameters on every platform. Draw order: layer by
// layer, W column-major (the flat layout of mlp.h), then b.
//
//   Rng rng(42);
//   Eigen::VectorXd theta = InitializeParameters(arch, InitOptions{}, rng);
#pragma once

#include <cmath>
#include <string>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/mlp.h"
#include "diffdyn/models/random.h"

namespace diffdyn {

/// The initialisation schemes of init.h.
enum class InitScheme { kTorchDefault, kXavierUniform, kXavierNormal, kKaimingUniform, kKaimingNormal };

/// Scheme, gains and constant bias (bias unused by kTorchDefault).
struct InitOptions {
  /// Distribution of the weights.
  InitScheme scheme = InitScheme::kTorchDefault;
  /// Gain of the hidden layers' weights (xavier / kaiming).
  double hidden_gain = 1.0;
  /// Gain of the output layer's weights (xavier / kaiming).
  double output_gain = 1.0;
  /// Constant bias (all schemes except torch-default).
  double bias = 0.0;

  /// The DDN authors' default: xavier-normal, gains sqrt(2) / 1, bias 0.1.
  static InitOptions Ddn() { return {InitScheme::kXavierNormal, std::sqrt(2.0), 1.0, 0.1}; }
};

/// Parses "torch-default", "xavier-uniform", "xavier-normal", "kaiming-uniform",
/// "kaiming-normal"; throws diffdyn::Error naming the bad value otherwise.
inline InitScheme ParseInitScheme(const std::string& name) {
  if (name == "torch-default") return InitScheme::kTorchDefault;
  if (name == "xavier-uniform") return InitScheme::kXavierUniform;
  if (name == "xavier-normal") return InitScheme::kXavierNormal;
  if (name == "kaiming-uniform") return InitScheme::kKaimingUniform;
  if (name == "kaiming-normal") return InitScheme::kKaimingNormal;
  throw Error(StrCat("unknown initialisation '", name,
                     "' (expected torch-default, xavier-uniform, xavier-normal, "
                     "kaiming-uniform or kaiming-normal)"));
}

/// Flat parameters theta (size arch.num_parameters()) drawn from `rng`.
inline Eigen::VectorXd InitializeParameters(const MlpArchitecture& arch, const InitOptions& options,
                                            Rng& rng) {
  arch.Validate();
  Eigen::VectorXd theta(arch.num_parameters());
  for (int l = 0; l < arch.num_layers(); ++l) {
    const double fan_in = arch.sizes[l];
    const double fan_out = arch.sizes[l + 1];
    const double gain = l + 1 == arch.num_layers() ? options.output_gain : options.hidden_gain;
    const Eigen::Index w0 = arch.WeightOffset(l);
    const Eigen::Index b0 = arch.BiasOffset(l);
    const Eigen::Index nb = arch.sizes[l + 1];
    auto uniform = [&](double r) { return r * (2.0 * UniformUnit(rng) - 1.0); };
    for (Eigen::Index i = w0; i < b0; ++i) {
      switch (options.scheme) {
        case InitScheme::kTorchDefault: theta[i] = uniform(1.0 / std::sqrt(fan_in)); break;
        case InitScheme::kXavierUniform:
          theta[i] = uniform(gain * std::sqrt(6.0 / (fan_in + fan_out)));
          break;
        case InitScheme::kXavierNormal:
          theta[i] = gain * std::sqrt(2.0 / (fan_in + fan_out)) * StandardNormal(rng);
          break;
        case InitScheme::kKaimingUniform: theta[i] = uniform(gain * std::sqrt(3.0 / fan_in)); break;
        case InitScheme::kKaimingNormal: theta[i] = gain / std::sqrt(fan_in) * StandardNormal(rng); break;
      }
    }
    for (Eigen::Index i = b0; i < b0 + nb; ++i) {
      theta[i] = options.scheme == InitScheme::kTorchDefault ? uniform(1.0 / std::sqrt(fan_in))
                                                             : options.bias;
    }
  }
  return theta;
}

/// An Mlp<double> with parameters from InitializeParameters seeded by `seed`.
inline Mlp<double> MakeInitializedMlp(const MlpArchitecture& arch, const InitOptions& options,
                                      std::uint64_t seed) {
  Rng rng(seed);
  return Mlp<double>(arch, InitializeParameters(arch, options, rng));
}

}  // namespace diffdyn
