#!/usr/bin/env python3
"""PyTorch reference for bench/delan_training.cc.

One training epoch of a deep Lagrangian network in plain PyTorch, the formulation of
models/delan.h: a shared trunk on q (n-64-64, softplus) with linear heads for V, the
entries below L's diagonal and L's diagonal (softplus(d + 2) + 0.1); the trunk's
input Jacobian carried through the layers in closed form (B x width x n); H = L L^T +
0.01 I, dL/dq_k from the Jacobian, c = Hdot qd - 1/2 [qd^T dH/dq_k qd]_k, g = dV/dq,
tau = H qdd + c + g; loss mean |tau^ - tau|^2; autograd for the parameter gradient;
Adam with AMSGrad, lr 5e-4, weight decay 1e-5; batch 512 over the 2459 training
samples of the DeLaN characters (5 batches), in float64 and in float32 (the rows
BM_DelanEpoch and BM_DelanEpochF32). Runs in both two-core configurations (torch 2
threads with OpenBLAS 1, torch 1 with OpenBLAS 2), each in its own process, and keeps
the faster per precision. Prints our best row over PyTorch's best, per precision, when
the C++ run of the same `make bench` (delan_training.json) is next to --out.

    MALLOC_MMAP_THRESHOLD_=1000000000 MALLOC_TRIM_THRESHOLD_=1000000000 \
      /usr/bin/python3 bench/delan_training_torch.py --out r.json
    DIFFDYN_DELAN_CSV=path overrides the data file.
"""
import csv
import json
import os

import torch

from torch_common import (describe_torch, ours_best, reference_beside_ours, repo_path, time_it,
                          write_comparison_csv)

BATCH = 512
WIDTH = 64
EPS = 0.01
TEST = {"e", "q", "v"}
DATA = os.environ.get("DIFFDYN_DELAN_CSV", "../shared/data/delan_characters/character_data.csv")


def read_characters(path):
    """q, qd, qdd, tau (N x 2, float64) of the training characters."""
    rows = {k: [] for k in ("q", "qd", "qdd", "tau")}
    with open(path) as f:
        for row in csv.DictReader(f):
            if row["character"] in TEST:
                continue
            for k in rows:
                rows[k].append([float(row[f"{k}1"]), float(row[f"{k}2"])])
    return [torch.tensor(rows[k], dtype=torch.float64) for k in ("q", "qd", "qdd", "tau")]


class Delan(torch.nn.Module):
    def __init__(self, n, dtype):
        super().__init__()
        self.n = n
        self.m = 1 + n * (n + 1) // 2
        self.layers = torch.nn.ModuleList([torch.nn.Linear(n, WIDTH), torch.nn.Linear(WIDTH, WIDTH),
                                           torch.nn.Linear(WIDTH, self.m)]).to(dtype)
        self.low = torch.tril_indices(n, n, -1)

    def trunk(self, q):
        """y (B x m) and dy/dq (B x m x n) in one pass."""
        h = q
        dh = torch.eye(self.n, dtype=q.dtype).expand(q.shape[0], self.n, self.n)
        for layer in self.layers[:-1]:
            a = layer(h)
            da = torch.matmul(layer.weight, dh)  # B x w x n
            h = torch.nn.functional.softplus(a)
            dh = torch.sigmoid(a).unsqueeze(2) * da
        out = self.layers[-1]
        return out(h), torch.matmul(out.weight, dh)

    def forward(self, q, qd, qdd):
        n, b = self.n, q.shape[0]
        y, dy = self.trunk(q)
        off, d = y[:, 1:1 + n * (n - 1) // 2], y[:, 1 + n * (n - 1) // 2:]
        doff, dd = dy[:, 1:1 + n * (n - 1) // 2, :], dy[:, 1 + n * (n - 1) // 2:, :]
        L = torch.zeros(b, n, n, dtype=q.dtype)
        L[:, self.low[0], self.low[1]] = off
        diag = torch.nn.functional.softplus(d + 2.0) + 0.1
        L = L + torch.diag_embed(diag)
        # dL/dq_k: B x n x n x n (last index k).
        dL = torch.zeros(b, n, n, n, dtype=q.dtype)
        dL[:, self.low[0], self.low[1], :] = doff
        idx = torch.arange(n)
        dL[:, idx, idx, :] = torch.sigmoid(d + 2.0).unsqueeze(2) * dd
        H = L @ L.transpose(1, 2) + EPS * torch.eye(n, dtype=q.dtype)
        Ldot = torch.einsum("bijk,bk->bij", dL, qd)
        Hdot = Ldot @ L.transpose(1, 2) + L @ Ldot.transpose(1, 2)
        dH = torch.einsum("bijk,blj->bilk", dL, L)  # dL_k L^T
        dH = dH + dH.transpose(1, 2)
        quad = torch.einsum("bi,bijk,bj->bk", qd, dH, qd)
        c = torch.einsum("bij,bj->bi", Hdot, qd) - 0.5 * quad
        g = dy[:, 0, :]
        return torch.einsum("bij,bj->bi", H, qdd) + c + g


def epoch(model, opt, data, gen):
    q, qd, qdd, tau = data
    order = torch.randperm(q.shape[0], generator=gen)
    for i in range(0, q.shape[0], BATCH):
        idx = order[i:i + BATCH]
        opt.zero_grad()
        loss = ((model(q[idx], qd[idx], qdd[idx]) - tau[idx]) ** 2).sum(dim=1).mean()
        loss.backward()
        opt.step()
    return loss.item()


def time_epochs(data, dtype, repeats=21):
    """Median wall seconds of one epoch in dtype."""
    torch.manual_seed(0)
    data = [x.to(dtype) for x in data]
    model = Delan(2, dtype)
    opt = torch.optim.Adam(model.parameters(), lr=5e-4, weight_decay=1e-5, amsgrad=True)
    gen = torch.Generator().manual_seed(1)
    return time_it(lambda: epoch(model, opt, data, gen), repeats)[0]


def measure(torch_threads):
    """Median epoch seconds per precision with torch on torch_threads (the process's
    OPENBLAS_NUM_THREADS set by fastest_two_core)."""
    describe_torch(torch_threads)
    path = repo_path(DATA)
    data = read_characters(path)
    return {f"{name}/delan_epoch": time_epochs(data, dtype)
            for name, dtype in (("float64", torch.float64), ("float32", torch.float32))}


def precision_of(name):
    """Our epoch rows by precision (BM_DelanEpoch, BM_DelanEpochF32); None for the others."""
    if name.startswith("BM_DelanEpochF32/"):
        return "float32"
    if name.startswith("BM_DelanEpoch/"):
        return "float64"
    return None


def main():
    run = reference_beside_ours(__file__, measure, "delan_training.json")
    if run is None or run[3] is None:
        return
    args, by_config, best, path = run
    # One iteration of ours is 50 epochs: its counter epoch_s is the time per epoch.
    ours = ours_best(path, precision_of, lambda r: r["epoch_s"])
    summary, rows = {}, []
    for precision, (seconds, name) in sorted(ours.items()):
        torch_s = best[f"{precision}/delan_epoch"]["seconds"]
        rows.append(("delan_epoch", precision, name, seconds, best[f"{precision}/delan_epoch"]["config"], torch_s))
        print(f"{precision}: ours {name} {seconds * 1e3:.2f} ms per epoch, PyTorch best "
              f"{torch_s * 1e3:.2f} ms ({best[f'{precision}/delan_epoch']['config']}), "
              f"ours / PyTorch = {seconds / torch_s:.2f}x")
        summary[precision] = {"ours_seconds": seconds, "torch_seconds": torch_s,
                              "ours_over_torch": seconds / torch_s}
    with open(args.out, "w") as f:
        json.dump({"by_config": by_config, "best": best, "summary": summary}, f, indent=1)
    write_comparison_csv(args.out, rows)


if __name__ == "__main__":
    main()
