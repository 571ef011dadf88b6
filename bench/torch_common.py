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
