"""diffdyn.torch_function: gradients through the model's Jacobian against PyTorch's
own finite differences (gradcheck, float64), for an analytic and a learned model;
float32 tensors stay float32."""

import pytest

torch = pytest.importorskip("torch")

import diffdyn  # noqa: E402
from diffdyn.torch_function import as_torch_function  # noqa: E402


def test_gradcheck_analytic_and_learned(pendulum_files):
    _, path = pendulum_files
    for model in (diffdyn.load_model("cartpole", dt=0.05), diffdyn.load_model(path)):
        step = as_torch_function(model)
        generator = torch.Generator().manual_seed(3)
        x = torch.randn(4, model.state_size, dtype=torch.float64, generator=generator, requires_grad=True)
        u = torch.randn(4, model.action_size, dtype=torch.float64, generator=generator, requires_grad=True)
        assert torch.autograd.gradcheck(step, (x, u), eps=1e-6, atol=1e-6, rtol=1e-5)


def test_float32_in_float32_out_and_refuses_the_oracle():
    step = as_torch_function(diffdyn.load_model("pendulum", dt=0.02))
    x = torch.zeros(3, 2, dtype=torch.float32, requires_grad=True)
    y = step(x, torch.ones(3, 1, dtype=torch.float32))
    assert y.dtype == torch.float32
    y.sum().backward()
    assert x.grad.dtype == torch.float32 and torch.isfinite(x.grad).all()
    with pytest.raises(ValueError, match="no derivatives"):
        as_torch_function(diffdyn.load_model("oracle"))
