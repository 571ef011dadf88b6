#!/usr/bin/env python3
"""PyTorch reference for bench/pushing_epoch.cc.

One training epoch of the absolute NeuralODE of the NeuralODE-Panda paper in plain
PyTorch, float64 and float32: z0 = [x, u] (6), dz/dt = MLP(z) (6-100-100-6, ReLU),
Kutta's 3/8-rule RK4 over 9 equal steps on [0, 1] written out in torch (what
torchdiffeq's "rk4" does, without its bookkeeping), autograd back through the
solver, SE(2) pose loss, Adam lr 1e-3, 1000 transitions of the shared data in
shuffled batches of 500. Runs in both two-core configurations (torch 2 threads with
OpenBLAS 1, torch 1 with OpenBLAS 2), each in its own process, and keeps the faster
per precision. If the C++ results of the same run are next to --out
(pushing_epoch.json), prints ours (the default chunk of 250, best thread count)
over PyTorch's best, and ours in GFLOP/s against the same-precision two-thread peak.

    /usr/bin/python3 bench/pushing_epoch_torch.py --out r.json
    DIFFDYN_PUSHING_CSV=path overrides the data file.
"""
import json
import os
import re

import torch

from torch_common import (describe_torch, write_comparison_csv, ours_best, read_transitions, reference_beside_ours,
                          repo_path, rk4_38_flow, se2_pose_loss, time_it)

TRANSITIONS = 1000
BATCH = 500
DATA = os.environ.get("DIFFDYN_PUSHING_CSV", "../shared/data/pybullet_pushing/collected_data.csv")


class AbsNode(torch.nn.Module):
    def __init__(self, dtype, hidden=100, steps=10):
        super().__init__()
        self.net = torch.nn.Sequential(
            torch.nn.Linear(6, hidden), torch.nn.ReLU(),
            torch.nn.Linear(hidden, hidden), torch.nn.ReLU(),
            torch.nn.Linear(hidden, 6)).to(dtype)
        self.steps = steps

    def forward(self, x, u):
        return rk4_38_flow(self.net, torch.cat([x, u], dim=1), self.steps)[:, :3]


def epoch(model, opt, x, u, y, gen):
    order = torch.randperm(x.shape[0], generator=gen)
    for i in range(0, x.shape[0], BATCH):
        idx = order[i:i + BATCH]
        opt.zero_grad()
        loss = se2_pose_loss(model(x[idx], u[idx]), y[idx])
        loss.backward()
        opt.step()
    return loss.item()


def measure(torch_threads):
    """Median wall seconds of one epoch per precision, with torch on torch_threads."""
    describe_torch(torch_threads)
    path = repo_path(DATA)
    data = read_transitions(path, TRANSITIONS)
    result = {}
    for name, dtype in (("float64", torch.float64), ("float32", torch.float32)):
        x, u, y = (v.to(dtype) for v in data)
        torch.manual_seed(1)
        model = AbsNode(dtype)
        opt = torch.optim.Adam(model.parameters(), lr=1e-3)
        gen = torch.Generator().manual_seed(2)
        result[f"{name}/epoch_abs_node_rk4"] = time_it(lambda: epoch(model, opt, x, u, y, gen), 7)[0]
    return result


def precision_of(name):
    """Our rk4 epoch runs at the default chunk (250) by precision; None for the others."""
    if re.match(r"BM_EpochAbsNodeRk4/threads:\d+/chunk:250/", name):
        return "float64"
    if re.match(r"BM_EpochAbsNodeRk4F32/threads:\d+/chunk:250/", name):
        return "float32"
    return None


def peak_of(runs, name):
    run = next((r for r in runs if r["name"].startswith(name + "/")), None)
    return run["GFLOP/s"] if run and "GFLOP/s" in run else None


def main():
    run = reference_beside_ours(__file__, measure, "pushing_epoch.json")
    if run is None or run[3] is None:
        return
    args, by_config, best, path = run
    ours = ours_best(path, precision_of)
    with open(path) as f:
        runs = json.load(f)["benchmarks"]
    peaks = {"float64": peak_of(runs, "BM_PeakDgemmOpenBlas2Threads"),
             "float32": peak_of(runs, "BM_PeakSgemmOpenBlas2Threads")}
    summary, rows = {}, []
    for precision, (seconds, name) in sorted(ours.items()):
        torch_s = best[f"{precision}/epoch_abs_node_rk4"]["seconds"]
        rows.append(("epoch_abs_node_rk4", precision, name, seconds,
                     best[f"{precision}/epoch_abs_node_rk4"]["config"], torch_s))
        run = next(r for r in runs if r["name"] == name)
        rate = run.get("epoch_flops_G", 0.0) / seconds
        peak = peaks[precision]
        line = (f"{precision}: ours {name} {seconds * 1e3:.1f} ms, PyTorch best "
                f"{torch_s * 1e3:.1f} ms, ours / PyTorch = {seconds / torch_s:.2f}x; "
                f"ours {rate:.1f} GFLOP/s")
        if peak:
            line += f" = {100 * rate / peak:.0f}% of the two-thread peak {peak:.1f} GFLOP/s"
        print(line)
        summary[precision] = {"ours_seconds": seconds, "torch_seconds": torch_s,
                              "ours_over_torch": seconds / torch_s, "ours_gflops": rate,
                              "peak_gflops": peak}
    with open(args.out, "w") as f:
        json.dump({"by_config": by_config, "best": best, "summary": summary}, f, indent=1)
    write_comparison_csv(args.out, rows)


if __name__ == "__main__":
    main()
