#!/usr/bin/env python3
"""Checks torch_common.dopri5_flow (the PyTorch reference's dopri5) against diffdyn's
batched dopri5 on the same weights: loads an abs-NODE dopri5 model file into torch in
the file's precision, predicts the first N transitions of the pushing data with both,
and prints the largest difference. In float64 a different sequence of accepted steps
would show as a difference near the tolerance (1e-8 here); the same sequence leaves
rounding only; exits 1 when a difference exceeds 1e-11. In float32 the rounding
(~1e-6) would hide a step sequence chosen at 1e-8, and after one epoch the field is
too gentle for the steps to matter: `stiffened` writes a copy with the output layer
scaled 30x and the tolerance 1e-4, where both take 7 steps; exits 1 above 2e-4 there
(measured 2.3e-6; a 1 % error in one of the reference's stage coefficients gives
9.6e-4 to 2.5e-3). Needs the Python module (build/python);
`make test` runs the same comparison (python/tests/test_dopri5_reference.py) where
torch is installed.

    build/cli/diffdyn train --data ../shared/data/pybullet_pushing/collected_data.csv \\
        --model abs-node --solver dopri5 --epochs 1 --out /tmp/dopri5.json
    PYTHONPATH=build/python /usr/bin/python3 bench/dopri5_reference_check.py /tmp/dopri5.json
    (float32: add --precision f32 to the training command)
"""
import argparse
import json
import os
import tempfile

import numpy as np
import torch

import diffdyn
from torch_common import dopri5_flow, load_mlp, read_transitions, repo_path

DATA = "../shared/data/pybullet_pushing/collected_data.csv"
# Largest difference taken as rounding, by the model file's precision: in float64 at
# the solver tolerance 1e-8; in float32 on a `stiffened` file (tolerance 1e-4).
TOLERANCE = {"f64": 1e-11, "f32": 2e-4}
# What `stiffened` does to a float32 file: output layer gain, solver tolerance.
F32_GAIN = 30.0
F32_SOLVER_TOLERANCE = 1e-4
# Transition counts compared: one sample, then batches of 50 and 200.
SAMPLES = [1, 50, 200]


def pushing_data():
    """The pushing data's path, from bench/ as repo_path sees it."""
    return os.path.join(os.path.dirname(os.path.abspath(__file__)), repo_path(DATA))


def precision_of(path):
    """The precision a diffdyn model file records ("f64" or "f32")."""
    with open(path) as f:
        return json.load(f).get("precision", "f64")


def stiffened(path, out, gain=F32_GAIN, tolerance=F32_SOLVER_TOLERANCE):
    """Writes to `out` the model file `path` with its last layer (weights and bias) times
    `gain`, so the field is `gain` times stronger, and the solver tolerance `tolerance`."""
    with open(path) as f:
        spec = json.load(f)
    sizes = spec["architecture"]["mlp"]["sizes"]
    last = sizes[-2] * sizes[-1] + sizes[-1]
    values = spec["parameters"]["values"]
    spec["parameters"]["values"] = values[:-last] + [gain * v for v in values[-last:]]
    spec["architecture"]["tolerance"] = tolerance
    with open(out, "w") as f:
        json.dump(spec, f)


def compare(path, samples=SAMPLES, data=None):
    """(n, PyTorch's accepted steps, rejected steps, max |diffdyn - PyTorch|) for the first
    n transitions of `data` (default: the pushing data), n in `samples`, predicted by the
    dopri5 model file `path`, both in the file's precision."""
    dtype = torch.float32 if precision_of(path) == "f32" else torch.float64
    net, spec = load_mlp(path, dtype)
    arch = spec["architecture"]
    if arch.get("solver") != "dopri5":
        raise SystemExit(f"error: {path}: solver is {arch.get('solver')}, not dopri5")
    model = diffdyn.load_model(path)
    x, u, _ = read_transitions(data or pushing_data(), max(samples))
    rows = []
    for n in samples:
        z, accepted, rejected = dopri5_flow(net, torch.cat([x[:n], u[:n]], dim=1).to(dtype),
                                            1.0 / (arch["steps"] - 1), arch["tolerance"])
        ours = model.predict(x[:n].numpy(), u[:n].numpy(), threads=1)
        rows.append((n, accepted, rejected, float(np.abs(ours - z[:, :3].detach().double().numpy()).max())))
    return rows


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("model", help="an abs-NODE model file with solver dopri5")
    parser.add_argument("--samples", type=int, nargs="+", default=SAMPLES)
    args = parser.parse_args()
    precision = precision_of(args.model)
    path = args.model
    if precision == "f32":
        path = os.path.join(tempfile.mkdtemp(), "stiffened.json")
        stiffened(args.model, path)
        print(f"float32: output layer x {F32_GAIN:g}, tolerance {F32_SOLVER_TOLERANCE:g}")
    worst = 0.0
    for n, accepted, rejected, diff in compare(path, args.samples):
        print(f"{n} samples: PyTorch {accepted} accepted + {rejected} rejected steps; "
              f"max |diffdyn - PyTorch| = {diff:.3g}")
        worst = max(worst, diff)
    if worst > TOLERANCE[precision]:
        raise SystemExit(f"error: the two dopri5 solutions differ by {worst:.3g} (more than rounding)")


if __name__ == "__main__":
    main()
