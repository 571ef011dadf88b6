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
BM_DelanEpoch and BM_DelanEpochF32). Timed on 1 and 2 torch threads; the best is
PyTorch at its fastest. Prints the ratios to the C++ run of the same
`make bench` (delan_training.json next to --out).

    MALLOC_MMAP_THRESHOLD_=1000000000 MALLOC_TRIM_THRESHOLD_=1000000000 \
      /usr/bin/python3 bench/delan_training_torch.py --out r.json
"""
import argparse
import csv
import json
import os

import torch

from torch_common import blas_in_use, time_it

BATCH = 512
WIDTH = 64
EPS = 0.01
TEST = {"e", "q", "v"}


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


def time_epochs(threads, data, repeats, dtype):
    torch.set_num_threads(threads)
    torch.manual_seed(0)
    data = [x.to(dtype) for x in data]
    model = Delan(2, dtype)
    opt = torch.optim.Adam(model.parameters(), lr=5e-4, weight_decay=1e-5, amsgrad=True)
    gen = torch.Generator().manual_seed(1)
    return time_it(lambda: epoch(model, opt, data, gen), repeats)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default="delan_training_torch.json")
    parser.add_argument("--data", default="../shared/data/delan_characters/character_data.csv")
    parser.add_argument("--repeats", type=int, default=21)
    args = parser.parse_args()
    blas = blas_in_use()
    print("torch", torch.__version__, "BLAS in use:", ", ".join(blas) if blas else "(none found)",
          "MALLOC_MMAP_THRESHOLD_", os.environ.get("MALLOC_MMAP_THRESHOLD_"))
    data = read_characters(args.data)
    samples = data[0].shape[0]
    result = {"samples": samples, "blas": blas, "torch": torch.__version__}
    for dtype, suffix in ((torch.float64, ""), (torch.float32, "_f32")):
        for threads in (1, 2):
            wall, cpu = time_epochs(threads, data, args.repeats, dtype)
            result[f"epoch_seconds{suffix}_{threads}"] = wall
            result[f"epoch_cpu_seconds{suffix}_{threads}"] = cpu
            print(f"DeLaN epoch ({samples} samples, batch {BATCH}, {dtype}), {threads} thread(s): "
                  f"median {wall * 1e3:.1f} ms wall, {cpu * 1e3:.1f} ms CPU, "
                  f"{wall / samples * 1e6:.2f} us per sample")
    with open(args.out, "w") as f:
        json.dump(result, f)
    ours_path = os.path.join(os.path.dirname(os.path.abspath(args.out)), "delan_training.json")
    if os.path.exists(ours_path):
        report(json.load(open(ours_path))["benchmarks"], result)


def report(benchmarks, torch_result):
    """Ours (delan_training.json of the same run) next to PyTorch's best thread count, same precision."""
    for row, suffix in (("BM_DelanEpoch/", ""), ("BM_DelanEpochF32/", "_f32")):
        best = min(torch_result[f"epoch_seconds{suffix}_1"], torch_result[f"epoch_seconds{suffix}_2"])
        for b in benchmarks:
            if b.get("run_type") == "aggregate" or not b["name"].startswith(row):
                continue
            ours = b["epoch_s"]
            print(f"{b['name']}: ours {ours * 1e3:.2f} ms per epoch; PyTorch (best of 1, 2 threads) "
                  f"{best * 1e3:.2f} ms; ours / PyTorch = {ours / best:.2f}x")


if __name__ == "__main__":
    main()
