"""Helpers shared by the PyTorch reference benchmarks (bench/<name>_torch.py)."""

import csv
import math
import os
import sys
import time

import torch


def blas_in_use():
    """Shared BLAS libraries mapped into this process (after a matmul): OpenBLAS,
    MKL or ATLAS, resolved to their real paths."""
    torch.ones(64, 64, dtype=torch.float64) @ torch.ones(64, 64, dtype=torch.float64)
    libs = set()
    with open("/proc/self/maps") as maps:
        for line in maps:
            path = line.split()[-1]
            if "blas" in path or "mkl" in path or "atlas" in path:
                libs.add(os.path.realpath(path))
    return sorted(libs)


def rk4_38_flow(f, z, steps):
    """z(1) of dz/dt = f(z) from z(0) = z by the 3/8-rule RK4 on `steps` grid points
    over [0, 1] (steps - 1 equal steps), as diffdyn's rk4 method."""
    h = 1.0 / (steps - 1)
    for _ in range(steps - 1):
        k1 = f(z)
        k2 = f(z + h * k1 / 3)
        k3 = f(z + h * (k2 - k1 / 3))
        k4 = f(z + h * (k1 - k2 + k3))
        z = z + h * (k1 + 3 * k2 + 3 * k3 + k4) / 8
    return z


# rg of the 0.1 m square block: sqrt((l^2 + w^2) / 12).
POSE_RG = math.sqrt((0.1 ** 2 + 0.1 ** 2) / 12)


def read_transitions(path, limit=None):
    """(x_t, u_t, x_{t+1}) of a pushing CSV (DESIGN.md schema) in file order, float64
    tensors of n x 3, the first `limit` only if given; exits with file:line on bad rows."""
    xs, us, ys = [], [], []
    prev = None
    with open(path) as f:
        for line, row in enumerate(csv.DictReader(f), start=2):
            try:
                state = [float(row[k]) for k in ("x", "y", "theta")]
                action = [float(row[k]) for k in ("push_location", "push_angle", "push_length")
                          ] if row["push_length"] else None
                trajectory = int(row["trajectory"])
            except (KeyError, ValueError) as e:
                sys.exit(f"error: {path}:{line}: {e}")
            if prev is not None and prev[0] == trajectory and prev[2] is not None:
                xs.append(prev[1])
                us.append(prev[2])
                ys.append(state)
                if limit is not None and len(xs) == limit:
                    break
            prev = (trajectory, state, action)
    t = lambda v: torch.tensor(v, dtype=torch.float64)
    return t(xs), t(us), t(ys)


def se2_pose_loss(pred, target):
    """MSE x + MSE y + rg MSE theta over a batch of poses (n x 3)."""
    d2 = (pred - target) ** 2
    return d2[:, 0].mean() + d2[:, 1].mean() + POSE_RG * d2[:, 2].mean()


def time_it(fn, repeats=30):
    """Median wall and process CPU seconds (CPU time is robust when other jobs share the cores)."""
    fn()
    times, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    times.sort()
    cpu.sort()
    return times[len(times) // 2], cpu[len(cpu) // 2]
