#!/usr/bin/env python3
"""PyTorch reference for bench/autodiff_gradient.cc.

Gradient of L = sum(w * z(1)) with respect to the weights of an MLP ODE
dz/dt = MLP(z), float64, single-threaded BLAS, by backpropagating through a
fixed-grid rk4 (3/8 rule, torchdiffeq's "rk4") with 10 steps on [0, 1] -- what
torchdiffeq's odeint does on a fixed grid without the adjoint. torchdiffeq itself
is not installed on this machine (Debian has no package), so the 3/8 step is
written here; its stage structure and autograd graph are the same.

    OPENBLAS_NUM_THREADS=1 /usr/bin/python3 bench/autodiff_gradient_torch.py [--out r.json]
"""
import argparse
import json
import statistics
import time

import torch

STEPS = 10


def make_net(sizes, seed=5):
    gen = torch.Generator().manual_seed(seed)
    params = []
    for fan_in, fan_out in zip(sizes[:-1], sizes[1:]):
        w = torch.randn(fan_out, fan_in, generator=gen, dtype=torch.float64) / fan_in ** 0.5
        b = 0.1 * torch.randn(fan_out, generator=gen, dtype=torch.float64)
        params += [w.requires_grad_(True), b.requires_grad_(True)]
    return params


def mlp(params, z):
    # z: batch x n (torch's row-per-sample layout).
    h = z
    layers = len(params) // 2
    for i in range(layers):
        h = h @ params[2 * i].T + params[2 * i + 1]
        if i + 1 < layers:
            h = torch.tanh(h)
    return h


def rk38_solve(params, z0):
    dt = 1.0 / STEPS
    z = z0
    for _ in range(STEPS):
        k1 = mlp(params, z)
        k2 = mlp(params, z + dt * k1 / 3)
        k3 = mlp(params, z + dt * (k2 - k1 / 3))
        k4 = mlp(params, z + dt * (k1 - k2 + k3))
        z = z + (k1 + 3 * (k2 + k3) + k4) * (dt / 8)
    return z


def time_gradient(sizes, batch, repeats):
    params = make_net(sizes)
    gen = torch.Generator().manual_seed(9)
    z0 = torch.randn(batch, sizes[0], generator=gen, dtype=torch.float64)
    w = torch.randn(batch, sizes[0], generator=gen, dtype=torch.float64)
    wall, cpu = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        loss = (w * rk38_solve(params, z0)).sum()
        grads = torch.autograd.grad(loss, params)
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
        del grads
    return statistics.median(wall), statistics.median(cpu), sum(p.numel() for p in params)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default=None)
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(torch.__config__.show())
    print(f"torch {torch.__version__}, threads {torch.get_num_threads()}")
    cases = [("crossover 2-2-2", [2, 2, 2], 4), ("crossover 2-20-2", [2, 20, 2], 4),
             ("crossover 2-2000-2", [2, 2000, 2], 4),
             ("train scale 3-100-100-3", [3, 100, 100, 3], 500)]
    results = []
    for name, sizes, batch in cases:
        wall, cpu, params = time_gradient(sizes, batch, args.repeats)
        print(f"{name:<26} params {params:>6}  batch {batch:>4}  rk4 x{STEPS} backprop "
              f"wall {wall * 1e3:9.3f} ms  cpu {cpu * 1e3:9.3f} ms")
        results.append({"name": name, "params": params, "batch": batch,
                         "wall_ms": wall * 1e3, "cpu_ms": cpu * 1e3})
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"benchmarks": results}, f, indent=1)


if __name__ == "__main__":
    main()
