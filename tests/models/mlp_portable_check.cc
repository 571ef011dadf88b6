// Compile-only check, built with AVX-512 and AVX2 switched off (tests/models/CMakeLists.txt):
// mlp.h must build where the layer kernel is not available, with Mlp::Evaluate
// falling back to Forward's products.
#include "diffdyn/models/mlp.h"

static_assert(!diffdyn::kHaveLayerKernel, "this file must be compiled without AVX-512 and AVX2");

namespace diffdyn {

void EvaluateWithoutLayerKernel(const Mlp<double>& net, const Eigen::MatrixXd& x,
                                Eigen::MatrixXd* y, MlpWorkspace* ws) {
  net.Evaluate(x, *y, ws, 1);
}

}  // namespace diffdyn
