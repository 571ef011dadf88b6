"""Helpers shared by the PyTorch reference benchmarks (bench/<name>_torch.py)."""

import os

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
