#!/usr/bin/env python3
"""PyTorch reference for bench/mppi_pushing.cc.

A plain MPPI in PyTorch, in float64 and in float32, the algorithm of the seed's
pytorch_mppi (and of solvers/mppi.h): warm start by shifting, K x T x 3 Gaussian
noise with covariance Sigma = 0.5 I, clamp to the action bounds and recompute the
perturbation, batched rollout of the model over the K samples, running cost
(x - g)^T diag(1, 1, 0.1) (x - g) + 100 in_collision(x) summed over x_1..x_T (exact
separating-axis overlap of the rotated block with the obstacle), perturbation cost
U (lambda noise Sigma^-1), softmax weights with lambda = 0.01, U += sum_k w_k noise_k.

The models are the SAME weights as the C++ run: the model files mppi_abs_node.json
(6-100-100-6 ReLU NeuralODE, 3/8-rule RK4 on 10 grid points) and mppi_res_nn.json
(6-100-100-3 ReLU residual NN) that bench_mppi_pushing writes next to its results
(--models, else the folder of --out, else build/bench-results). PyTorch runs in each
two-core configuration (torch_common.TWO_CORE_CONFIGS: torch 2 threads with OpenBLAS 1,
torch 1 with OpenBLAS 2), each in its own process; the faster one per workload is
compared with our two-thread run of the same precision (mppi_pushing.json next to
--out): ms per command and ours / PyTorch.

    /usr/bin/python3 bench/mppi_pushing_torch.py --out build/bench-results/mppi_pushing_torch.json
"""
import json
import math
import os
import sys

import torch

from torch_common import (describe_torch, load_mlp, rk4_38_flow, time_it, two_core_reference,
                          write_comparison_csv)

K = 1000
START = (0.4, 0.0, -0.2 * math.pi)
GOAL = (0.8, -0.1, 0.0)


class AbsNode(torch.nn.Module):
    """x' = P z(1), z(0) = [x, u], dz/dt = MLP(z), 3/8-rule RK4 with steps - 1 steps."""

    def __init__(self, net, steps):
        super().__init__()
        self.net, self.steps = net, steps

    def forward(self, x, u):
        return rk4_38_flow(self.net, torch.cat([x, u], dim=1), self.steps)[:, :3]


class ResNn(torch.nn.Module):
    def __init__(self, net):
        super().__init__()
        self.net = net

    def forward(self, x, u):
        return x + self.net(torch.cat([x, u], dim=1))


def in_collision(x):
    """1 where the 0.1 m block at pose x (K x 3) overlaps the obstacle (separating axes)."""
    hb, ox, oy, hx, hy = 0.05, 0.6, 0.2, 0.05, 0.25
    c, s = torch.cos(x[:, 2]).abs(), torch.sin(x[:, 2]).abs()
    cs, sn = torch.cos(x[:, 2]), torch.sin(x[:, 2])
    dx, dy = ox - x[:, 0], oy - x[:, 1]
    apart = (dx.abs() >= hx + hb * (c + s)) | (dy.abs() >= hy + hb * (s + c)) \
        | ((cs * dx + sn * dy).abs() >= hb + hx * c + hy * s) \
        | ((-sn * dx + cs * dy).abs() >= hb + hx * s + hy * c)
    return (~apart).to(x.dtype)


def running_cost(x, goal):
    d = x - goal
    return d[:, 0] ** 2 + d[:, 1] ** 2 + 0.1 * d[:, 2] ** 2 + 100.0 * in_collision(x)


class Mppi:
    def __init__(self, model, horizon, gen, dtype):
        self.model, self.T, self.gen, self.dtype = model, horizon, gen, dtype
        self.sigma = 0.5 * torch.eye(3, dtype=dtype)
        self.chol = torch.linalg.cholesky(self.sigma)
        self.sigma_inv = torch.linalg.inv(self.sigma)
        self.lam = 0.01
        self.u_min = torch.tensor([-1.0, -math.pi / 2, 0.0], dtype=dtype)
        self.u_max = torch.tensor([1.0, math.pi / 2, 1.0], dtype=dtype)
        self.goal = torch.tensor(GOAL, dtype=dtype)
        u = torch.randn(horizon, 3, generator=gen, dtype=dtype) @ self.chol.t()
        self.U = torch.max(torch.min(u, self.u_max), self.u_min)

    @torch.no_grad()
    def command(self, x0):
        self.U = torch.roll(self.U, -1, dims=0)
        self.U[-1] = 0.0
        noise = torch.randn(K, self.T, 3, generator=self.gen, dtype=self.dtype) @ self.chol.t()
        perturbed = torch.max(torch.min(self.U + noise, self.u_max), self.u_min)
        noise = perturbed - self.U
        cost = torch.zeros(K, dtype=self.dtype)
        x = x0.expand(K, 3)
        for t in range(self.T):
            x = self.model(x, perturbed[:, t])
            cost += running_cost(x, self.goal)
        cost += (self.U * (self.lam * noise @ self.sigma_inv)).sum(dim=(1, 2))
        w = torch.exp(-(cost - cost.min()) / self.lam)
        w /= w.sum()
        self.U += (w[:, None, None] * noise).sum(dim=0)
        return self.U[0]


def time_commands(model, horizon, repeats, dtype):
    """Median wall seconds of one command from START, after a warm-up."""
    mppi = Mppi(model, horizon, torch.Generator().manual_seed(1), dtype)
    x0 = torch.tensor(START, dtype=dtype)
    return time_it(lambda: mppi.command(x0), repeats)[0]


# Workloads: (name, model file, horizon, our benchmark without its precision suffix).
CASES = [("abs_node_t20", "mppi_abs_node.json", 20, "BM_MppiAbsNode/20"),
         ("abs_node_t30", "mppi_abs_node.json", 30, "BM_MppiAbsNode/30"),
         ("res_nn_t30", "mppi_res_nn.json", 30, "BM_MppiResNn/30")]
PRECISIONS = {"f64": torch.float64, "f32": torch.float32}


def models_folder():
    """Where bench_mppi_pushing wrote the model files (the --out folder of the run)."""
    out = next((a.split("=", 1)[1] for a in sys.argv if a.startswith("--out=")), None)
    if out is None and "--out" in sys.argv:
        out = sys.argv[sys.argv.index("--out") + 1]
    return os.environ.get("MPPI_MODELS") or os.path.abspath(os.path.dirname(out) if out else "build/bench-results")


def measure(torch_threads):
    """Median seconds per command of each workload and precision, keyed 'f64/abs_node_t20'."""
    describe_torch(torch_threads)
    folder = os.environ["MPPI_MODELS"]
    results = {}
    for precision, dtype in PRECISIONS.items():
        for name, file, horizon, _ in CASES:
            net, spec = load_mlp(os.path.join(folder, file), dtype)
            model = AbsNode(net, spec["architecture"]["steps"]) if name.startswith("abs") else ResNn(net)
            results[f"{precision}/{name}"] = time_commands(model, horizon, 5 if name.startswith("abs") else 20,
                                                           dtype)
    return results


def ours_two_threads(path):
    """Our two-thread wall seconds per 'precision/workload' in mppi_pushing.json."""
    with open(path) as f:
        bench = json.load(f)["benchmarks"]
    scale = {"ms": 1e-3, "us": 1e-6, "ns": 1e-9, "s": 1}
    ours = {}
    for b in bench:
        if b.get("run_type", "iteration") != "iteration":
            continue
        for name, _, _, prefix in CASES:
            for precision, suffix in (("f64", ""), ("f32", "F32")):
                family, args = prefix.split("/", 1)
                if b["name"].startswith(f"{family}{suffix}/{args}/2/"):
                    ours[f"{precision}/{name}"] = b["real_time"] * scale[b["time_unit"]]
    return ours


def main():
    os.environ["MPPI_MODELS"] = models_folder()
    run = two_core_reference(__file__, measure)
    if run is None:
        return
    args, by_config, best = run
    ours_path = os.path.join(os.path.dirname(os.path.abspath(args.out or "x")), "mppi_pushing.json")
    ours = ours_two_threads(ours_path) if os.path.exists(ours_path) else {}
    ratios, rows = {}, []
    for key, entry in best.items():
        if key in ours:
            ratios[key] = ours[key] / entry["seconds"]
            precision, workload = key.split("/")
            rows.append((workload, precision, "two threads", ours[key], entry["config"], entry["seconds"]))
            print(f"MPPI {key}, K = {K}: ours (2 threads) {ours[key] * 1e3:.1f} ms, PyTorch best "
                  f"({entry['config']}) {entry['seconds'] * 1e3:.1f} ms; ours / PyTorch = {ratios[key]:.2f}x")
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"by_config": by_config, "best": best, "ours_over_torch": ratios}, f, indent=1)
        write_comparison_csv(args.out, rows)


if __name__ == "__main__":
    main()
