#!/usr/bin/env python3
"""PyTorch reference for bench/control_mppi.cc.

One MPPI command on the pendulum swing-up task, float64, written as a PyTorch user
would (pytorch_mppi's algorithm, batched over the K samples): warm start by shifting,
K x T Gaussian noise with standard deviation 0.5 u_max, clamp to |u| <= 2.5 N m and
keep the surviving perturbation, the perturbation cost U lambda Sigma^-1 eps, a batched
rollout of the task's analytic pendulum (q'' = (u - m g l sin q) / (m l^2), m = 0.75,
l = 2/3, g = 9.81; classic RK4, one 40-ms step per model step, T = 25 steps = 1 s), the
task's running cost dt (q(x_{t+1}) + g(u_t)) with q = pi^2 sin^2((q - pi) / 2) + 0.1 qd^2
and the log-cosine action cost, the terminal cost 10 q(x_T), softmax weights with
lambda = 0.1 and U += sum_k w_k eps_k. The same arithmetic as MppiController over
TaskModel(task, 0.04, 1) (solvers/control.h).

Prints ms per command (wall and CPU) on 1 and 2 threads and, when control_mppi.json
(the C++ run's --benchmark_out) is next to --out, the ratios against it.

    build/bench/bench_control_mppi --benchmark_repetitions=5 \
        --benchmark_out=build/bench-results/control_mppi.json --benchmark_out_format=json
    /usr/bin/python3 bench/control_mppi_torch.py --out build/bench-results/control_mppi_torch.json
"""
import argparse
import json
import math
import os

import torch

from torch_common import blas_in_use, time_it

K, T, DT = 1000, 25, 0.04
M, L, G = 0.75, 2.0 / 3.0, 9.81
U_BOUND = 2.5
U_MAX = 2.5 + 1e-3  # the log-cosine cost's asymptote, just beyond the bound
BETA = 4.0 * U_MAX ** 2 * 0.5 / math.pi
LAMBDA, NOISE_SD, TERMINAL = 0.1, 0.5 * U_BOUND, 10.0


def dynamics(x, u):
    """dx/dt (K x 2) of the pendulum at x (K x 2), u (K)."""
    q, qd = x[:, 0], x[:, 1]
    qdd = (u - M * G * L * torch.sin(q)) / (M * L * L)
    return torch.stack([qd, qdd], dim=1)


def step(x, u):
    k1 = dynamics(x, u)
    k2 = dynamics(x + 0.5 * DT * k1, u)
    k3 = dynamics(x + 0.5 * DT * k2, u)
    k4 = dynamics(x + DT * k3, u)
    return x + DT / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


def state_cost(x):
    e = math.pi * torch.sin(0.5 * (x[:, 0] - math.pi))
    return e * e + 0.1 * x[:, 1] ** 2


def action_cost(u):
    return -(2.0 * BETA * U_MAX / math.pi) * torch.log(torch.cos(math.pi * u / (2.0 * U_MAX)))


class Mppi:
    def __init__(self, gen):
        self.gen = gen
        self.U = torch.zeros(T, dtype=torch.float64)

    @torch.no_grad()
    def command(self, x0):
        self.U = torch.roll(self.U, -1)
        self.U[-1] = 0.0
        noise = NOISE_SD * torch.randn(K, T, generator=self.gen, dtype=torch.float64)
        perturbed = (self.U + noise).clamp(-U_BOUND, U_BOUND)
        eps = perturbed - self.U
        cost = (LAMBDA / NOISE_SD ** 2) * (eps * self.U).sum(dim=1)
        x = x0.expand(K, 2)
        for t in range(T):
            x = step(x, perturbed[:, t])
            cost += DT * (state_cost(x) + action_cost(perturbed[:, t]))
        cost += TERMINAL * state_cost(x)
        w = torch.exp(-(cost - cost.min()) / LAMBDA)
        w /= w.sum()
        self.U = (self.U + (w[:, None] * eps).sum(dim=0)).clamp(-U_BOUND, U_BOUND)
        return self.U[0]


def time_commands(repeats):
    """Median (wall, CPU) seconds of one command from x0 = (0.3, 0), after a warm-up."""
    mppi = Mppi(torch.Generator().manual_seed(1))
    x0 = torch.tensor([0.3, 0.0], dtype=torch.float64)
    return time_it(lambda: mppi.command(x0), repeats)


def ours(bench, threads):
    """(wall, cpu) seconds of the C++ benchmark's median on `threads` threads."""
    name = f"BM_MppiPendulumCommand/threads:{threads}"
    rows = [b for b in bench if b["name"].startswith(name)]
    median = [b for b in rows if b.get("aggregate_name") == "median"]
    for b in median or rows:
        scale = {"ms": 1e-3, "us": 1e-6, "ns": 1e-9, "s": 1}[b["time_unit"]]
        return b["real_time"] * scale, b["cpu_time"] * scale
    return None


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default="control_mppi_torch.json")
    parser.add_argument("--repeats", type=int, default=41)
    args = parser.parse_args()
    blas = blas_in_use()
    print("torch", torch.__version__, "BLAS in use:", ", ".join(blas) if blas else "(none found)")
    result = {"blas": blas, "torch": torch.__version__}
    timings = {}
    for threads in (1, 2):
        torch.set_num_threads(threads)
        wall, cpu = time_commands(args.repeats)
        timings[threads] = wall
        result[f"threads_{threads}_seconds"], result[f"threads_{threads}_cpu_seconds"] = wall, cpu
        print(f"PyTorch MPPI pendulum, K = {K}, T = {T}, float64, {threads} thread(s): median "
              f"{wall * 1e3:.2f} ms wall, {cpu * 1e3:.2f} ms CPU per command over {args.repeats}")
    with open(args.out, "w") as f:
        json.dump(result, f)

    ours_path = os.path.join(os.path.dirname(os.path.abspath(args.out)), "control_mppi.json")
    if not os.path.exists(ours_path):
        return
    bench = json.load(open(ours_path))["benchmarks"]
    for threads in (1, 2):
        r = ours(bench, threads)
        if r is None:
            continue
        print(f"{threads} thread(s): ours {r[0] * 1e3:.2f} ms, PyTorch {timings[threads] * 1e3:.2f} ms: "
              f"{timings[threads] / r[0]:.1f}x faster")


if __name__ == "__main__":
    main()
