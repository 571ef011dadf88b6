"""A diffdyn model as a PyTorch function: values from diffdyn, gradients by its Jacobian.

    import torch
    from diffdyn.torch_function import as_torch_function

    step = as_torch_function(diffdyn.load_model("pendulum", dt=0.02))
    x = torch.zeros(64, 2, dtype=torch.float64, requires_grad=True)
    u = torch.ones(64, 1, dtype=torch.float64, requires_grad=True)
    loss = step(x, u).square().sum()
    loss.backward()          # x.grad, u.grad through the model's exact Jacobian

The backward pass is the vector-Jacobian product g^T [dF/dx, dF/du] with the
Jacobians diffdyn computes by forward-mode Jets, so gradients are exact to
rounding (torch.autograd.gradcheck passes in float64). Tensors move through
numpy on the CPU; the result keeps the input's dtype.
"""

import numpy as np
import torch


class _ModelStep(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x, u, model):
        xn = x.detach().cpu().numpy()
        un = u.detach().cpu().numpy()
        ctx.model = model
        ctx.save_for_backward(x, u)
        return torch.from_numpy(np.asarray(model.predict(xn, un))).to(x.dtype)

    @staticmethod
    def backward(ctx, grad_next):
        x, u = ctx.saved_tensors
        n = x.shape[-1]
        jac = torch.from_numpy(np.asarray(
            ctx.model.jacobian(x.detach().cpu().numpy(), u.detach().cpu().numpy()))).to(grad_next.dtype)
        # (.., n) x (.., n, n + m) -> (.., n + m)
        grad_z = torch.einsum("...i,...ij->...j", grad_next, jac)
        return grad_z[..., :n], grad_z[..., n:], None


def as_torch_function(model):
    """f(x, u) = model.predict(x, u) on torch tensors ((N, n), (N, m) or one sample), differentiable."""
    if not model.differentiable:
        raise ValueError(f"{model.kind}: this model has no derivatives")

    def step(x, u):
        return _ModelStep.apply(x, u, model)

    return step
