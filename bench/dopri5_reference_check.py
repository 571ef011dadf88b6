#!/usr/bin/env python3
"""Checks torch_common.dopri5_flow (the PyTorch reference's dopri5) against diffdyn's
batched dopri5 on the same weights: loads an abs-NODE dopri5 model file into torch,
predicts the first N transitions of the pushing data with both, and prints the largest
difference. A different sequence of accepted steps would show as a difference near the
tolerance (1e-8 here); the same sequence leaves rounding only. Exits 1 when a
difference exceeds 1e-11. Needs the Python module (build/python); `make test` runs the
same comparison (python/tests/test_dopri5_reference.py) where torch is installed.

    build/cli/diffdyn train --data ../shared/data/pybullet_pushing/collected_data.csv \\
        --model abs-node --solver dopri5 --epochs 1 --out /tmp/dopri5.json
    PYTHONPATH=build/python /usr/bin/python3 bench/dopri5_reference_check.py /tmp/dopri5.json
"""
import argparse
import os

import numpy as np
import torch

import diffdyn
from torch_common import dopri5_flow, load_mlp, read_transitions, repo_path

DATA = "../shared/data/pybullet_pushing/collected_data.csv"
# Largest difference taken as rounding: the solver tolerance is 1e-8.
TOLERANCE = 1e-11
# Transition counts compared: one sample, then batches of 50 and 200.
SAMPLES = [1, 50, 200]


def pushing_data():
    """The pushing data's path, from bench/ as repo_path sees it."""
    return os.path.join(os.path.dirname(os.path.abspath(__file__)), repo_path(DATA))


def compare(path, samples=SAMPLES, data=None):
    """(n, PyTorch's accepted steps, rejected steps, max |diffdyn - PyTorch|) for the first
    n transitions of `data` (default: the pushing data), n in `samples`, predicted by the
    dopri5 model file `path`."""
    net, spec = load_mlp(path, torch.float64)
    arch = spec["architecture"]
    if arch.get("solver") != "dopri5":
        raise SystemExit(f"error: {path}: solver is {arch.get('solver')}, not dopri5")
    model = diffdyn.load_model(path)
    x, u, _ = read_transitions(data or pushing_data(), max(samples))
    rows = []
    for n in samples:
        z, accepted, rejected = dopri5_flow(net, torch.cat([x[:n], u[:n]], dim=1), 1.0 / (arch["steps"] - 1),
                                            arch["tolerance"])
        ours = model.predict(x[:n].numpy(), u[:n].numpy(), threads=1)
        rows.append((n, accepted, rejected, float(np.abs(ours - z[:, :3].detach().numpy()).max())))
    return rows


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("model", help="an abs-NODE model file with solver dopri5")
    parser.add_argument("--samples", type=int, nargs="+", default=SAMPLES)
    args = parser.parse_args()
    worst = 0.0
    for n, accepted, rejected, diff in compare(args.model, args.samples):
        print(f"{n} samples: PyTorch {accepted} accepted + {rejected} rejected steps; "
              f"max |diffdyn - PyTorch| = {diff:.3g}")
        worst = max(worst, diff)
    if worst > TOLERANCE:
        raise SystemExit(f"error: the two dopri5 solutions differ by {worst:.3g} (more than rounding)")


if __name__ == "__main__":
    main()
