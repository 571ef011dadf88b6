#!/usr/bin/env python3
"""Independent PyTorch training of the absolute / residual NN with the facts' protocol.

A cross-check of `diffdyn train --model abs-nn|res-nn`: the same 80/20 sample-level
split rule, batch 500 with a fresh shuffle per epoch, Adam lr 1e-3, PyTorch's default
Linear initialisation, no normalisation, SE(2) pose loss, float64. Its seeds drive
PyTorch's own generators, so per-seed numbers differ from diffdyn's; the spread over
seeds is what compares.

  /usr/bin/python3 paper_figures/neuralode_grids/torch_nn_check.py \
      --data ../shared/data/pybullet_pushing/collected_data.csv --model abs --epochs 100 \
      --seeds 1-10 --out paper_figures/neuralode_grids/results/pybullet/torch_nn_check.csv
"""
import argparse
import csv
import os
import statistics
import sys

import torch

# One transition reader and one SE(2) loss for every PyTorch script (bench/torch_common.py).
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "bench"))
from torch_common import read_transitions, se2_pose_loss  # noqa: E402


def train(x, u, y, residual, epochs, seed):
    g = torch.Generator().manual_seed(seed)
    perm = torch.randperm(len(x), generator=g)
    n_val = int(round(0.2 * len(x)))
    val, tr = perm[:n_val], perm[n_val:]
    torch.manual_seed(seed)
    net = torch.nn.Sequential(torch.nn.Linear(6, 100), torch.nn.ReLU(), torch.nn.Linear(100, 100),
                              torch.nn.ReLU(), torch.nn.Linear(100, 3)).double()

    def predict(idx):
        out = net(torch.cat([x[idx], u[idx]], 1))
        return x[idx] + out if residual else out

    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    for _ in range(epochs):
        order = tr[torch.randperm(len(tr), generator=g)]
        for b in range(0, len(order), 500):
            idx = order[b:b + 500]
            opt.zero_grad()
            se2_pose_loss(predict(idx), y[idx]).backward()
            opt.step()
    with torch.no_grad():
        return float(se2_pose_loss(predict(val), y[val]))


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True)
    p.add_argument("--model", choices=["abs", "res"], default="abs")
    p.add_argument("--epochs", type=int, default=100)
    p.add_argument("--seeds", default="1-10", help="first-last")
    p.add_argument("--out", help="CSV of seed, val_loss")
    a = p.parse_args()
    torch.set_num_threads(1)
    first, last = (int(s) for s in a.seeds.split("-"))
    x, u, y = read_transitions(a.data)
    rows = []
    for seed in range(first, last + 1):
        v = train(x, u, y, a.model == "res", a.epochs, seed)
        rows.append((seed, v))
        print(f"{a.model}-nn epochs {a.epochs} seed {seed}: val {v:.4g}", flush=True)
    print(f"median over seeds {first}-{last}: {statistics.median(v for _, v in rows):.4g}")
    if a.out:
        with open(a.out, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["model", "epochs", "seed", "val_loss"])
            for s, v in rows:
                w.writerow([f"{a.model}-nn", a.epochs, s, repr(v)])


if __name__ == "__main__":
    main()
