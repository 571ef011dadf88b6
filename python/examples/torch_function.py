"""A diffdyn model inside a PyTorch loop: gradients through an exact Jacobian.

    PYTHONPATH=build/python /usr/bin/python3 python/examples/torch_function.py [--quick]

diffdyn.torch_function.as_torch_function turns a model into a differentiable
PyTorch function (values from diffdyn, the backward pass from its Jacobian). Here
it first passes torch.autograd.gradcheck in float64, then an Adam loop optimises
50 torques (1 s) that swing the pendulum from hanging to 1 rad, through the rollout.
Exits 77 (ctest's "skipped") when PyTorch is not installed.
"""

import sys

try:
    import torch
except ImportError:
    print("skipped: PyTorch is not installed (scripts/install-deps --bench installs it)")
    sys.exit(77)

import diffdyn
from diffdyn.torch_function import as_torch_function

quick = "--quick" in sys.argv
model = diffdyn.load_model("pendulum", dt=0.02)
step = as_torch_function(model)

# Gradients against PyTorch's finite differences, in float64.
x = torch.randn(5, 2, dtype=torch.float64, requires_grad=True)
u = torch.randn(5, 1, dtype=torch.float64, requires_grad=True)
assert torch.autograd.gradcheck(step, (x, u), eps=1e-6, atol=1e-6)
print("gradcheck passed: the Jacobian's VJP matches finite differences")

# Optimise 50 torques so the pendulum ends at 1 rad, at rest, with little effort.
torques = torch.zeros(50, 1, dtype=torch.float64, requires_grad=True)
optimizer = torch.optim.Adam([torques], lr=0.05)
target = torch.tensor([1.0, 0.0], dtype=torch.float64)
for iteration in range(60 if quick else 300):
    state = torch.zeros(2, dtype=torch.float64)
    for t in range(50):
        state = step(state, torques[t])
    loss = (state - target).square().sum() + 1e-3 * torques.square().mean()
    optimizer.zero_grad()
    loss.backward()
    optimizer.step()
    if iteration % 20 == 0:
        print(f"iteration {iteration:3d}: final state {state.detach().numpy().round(3)}, loss {loss.item():.4f}")
print(f"final state {state.detach().numpy().round(3)} (target {target.numpy()}), loss {loss.item():.4f}")
