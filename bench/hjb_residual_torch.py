#!/usr/bin/env python3
"""PyTorch reference for bench/hjb_residual.cc.

One step of the pendulum's HJB residual minimisation in plain PyTorch, the formulation
of solvers/hjb.h: features z = (sin q, cos q, qd), a 3-96-96-6 tanh network giving L
(lower-triangular, row by row, diagonal softplus(y) + 1e-3), V = |L^T (z - z0)|^2 with
z0 the goal's features (q = pi); p = dV/dx by autograd with create_graph; the
control-affine pendulum (q = 0 hangs: a = (qd, -(3 g / 2 l) sin q), B = (0, 3 / (m l^2)),
m 0.75, l 2/3); state cost pi^2 sin^2((q - pi) / 2) + 0.1 qd^2; the log-cosine action
cost's conjugate g~(w) = (u_max / pi) [2 w atan(w / beta) - beta log(1 + w^2 / beta^2)];
F = rho V - q(x) - p^T a + g~(-B^T p) at rho = 0.0862; the gradient of mean F^2 in the
parameters by autograd. 256 uniform states over |theta| <= pi, |qd| <= 8, float64 (the
row BM_HjbResidualStep). Runs in both two-core configurations (torch 2 threads with
OpenBLAS 1, torch 1 with OpenBLAS 2), each in its own process, and keeps the faster.
Prints our best row over PyTorch's best when the C++ run of the same `make bench`
(hjb_residual.json) is next to --out.

    /usr/bin/python3 bench/hjb_residual_torch.py --out r.json
"""
import json
import math

import torch

from torch_common import describe_torch, ours_best, reference_beside_ours, time_it, write_comparison_csv

BATCH = 256
WIDTH = 96
RHO = 0.0862
G, LENGTH, MASS = 9.81, 2.0 / 3.0, 0.75
U_MAX = 2.5 + 1e-3
BETA = 4.0 * U_MAX * U_MAX * 0.5 / math.pi


class QuadraticValue(torch.nn.Module):
    def __init__(self):
        super().__init__()
        self.net = torch.nn.Sequential(torch.nn.Linear(3, WIDTH), torch.nn.Tanh(), torch.nn.Linear(WIDTH, WIDTH),
                                       torch.nn.Tanh(), torch.nn.Linear(WIDTH, 6)).double()
        self.rows, self.cols = torch.tril_indices(3, 3)
        self.diag = self.rows == self.cols
        self.z0 = torch.tensor([0.0, -1.0, 0.0], dtype=torch.float64)

    def forward(self, x):
        z = torch.stack([torch.sin(x[:, 0]), torch.cos(x[:, 0]), x[:, 1]], dim=1)
        y = self.net(z)
        entries = torch.where(self.diag, torch.nn.functional.softplus(y) + 1e-3, y)
        L = torch.zeros(x.shape[0], 3, 3, dtype=x.dtype)
        L[:, self.rows, self.cols] = entries
        s = torch.einsum("bij,bi->bj", L, z - self.z0)  # L^T e
        return (s * s).sum(dim=1)


def residual_step(model, x):
    """mean F^2 and its parameter gradient (autograd, second order through dV/dx)."""
    model.zero_grad()
    x = x.detach().requires_grad_(True)
    v = model(x)
    (p,) = torch.autograd.grad(v.sum(), x, create_graph=True)
    q, qd = x[:, 0], x[:, 1]
    cost = math.pi ** 2 * torch.sin((q - math.pi) / 2) ** 2 + 0.1 * qd * qd
    drift = p[:, 0] * qd - p[:, 1] * (1.5 * G / LENGTH) * torch.sin(q)
    w = -p[:, 1] * 3.0 / (MASS * LENGTH * LENGTH)
    conjugate = (U_MAX / math.pi) * (2 * w * torch.atan(w / BETA) - BETA * torch.log1p((w / BETA) ** 2))
    f = RHO * v - cost - drift + conjugate
    loss = (f * f).mean()
    loss.backward()
    return loss.item()


def measure(torch_threads):
    """Median seconds of one residual step with torch on torch_threads (the process's
    OPENBLAS_NUM_THREADS set by fastest_two_core)."""
    describe_torch(torch_threads)
    torch.manual_seed(0)
    model = QuadraticValue()
    gen = torch.Generator().manual_seed(1)
    x = torch.rand(BATCH, 2, generator=gen, dtype=torch.float64)
    x = torch.stack([2 * math.pi * x[:, 0], 16 * x[:, 1] - 8], dim=1)
    return {"float64/hjb_residual_step": time_it(lambda: residual_step(model, x), 200)[0]}


def main():
    run = reference_beside_ours(__file__, measure, "hjb_residual.json")
    if run is None or run[3] is None:
        return
    args, by_config, best, path = run
    ours = ours_best(path, lambda name: "float64" if name.startswith("BM_HjbResidualStep/") else None)
    summary, rows = {}, []
    for precision, (seconds, name) in sorted(ours.items()):
        torch_best = best[f"{precision}/hjb_residual_step"]
        rows.append(("hjb_residual_step", precision, name, seconds, torch_best["config"], torch_best["seconds"]))
        print(f"{precision}: ours {name} {seconds * 1e3:.3f} ms per step, PyTorch best "
              f"{torch_best['seconds'] * 1e3:.3f} ms ({torch_best['config']}), "
              f"ours / PyTorch = {seconds / torch_best['seconds']:.2f}x")
        summary[precision] = {"ours_seconds": seconds, "torch_seconds": torch_best["seconds"],
                              "ours_over_torch": seconds / torch_best["seconds"]}
    with open(args.out, "w") as f:
        json.dump({"by_config": by_config, "best": best, "summary": summary}, f, indent=1)
    write_comparison_csv(args.out, rows)


if __name__ == "__main__":
    main()
