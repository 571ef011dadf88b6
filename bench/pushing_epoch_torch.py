#!/usr/bin/env python3
"""PyTorch reference for bench/pushing_epoch.cc.

One training epoch of the absolute NeuralODE of the NeuralODE-Panda paper in plain
PyTorch, float64 and float32: z0 = [x, u] (6), dz/dt = MLP(z) (6-100-100-6, ReLU),
Kutta's 3/8-rule RK4 over 9 equal steps on [0, 1] written out in torch (what
torchdiffeq's "rk4" does, without its bookkeeping), autograd back through the
solver; and in both precisions the same with adaptive dopri5 (tolerance 1e-8, first
trial step 1/9, one step size per batch; torch_common.dopri5_flow); SE(2) pose loss, Adam
lr 1e-3, 1000 transitions of the shared data in shuffled batches of 500. Runs in
both two-core configurations (torch 2 threads with OpenBLAS 1, torch 1 with OpenBLAS
2), each in its own process, and keeps the faster per workload. If the C++ results
of the same run are next to --out (pushing_epoch.json), prints ours (the default
chunk of 250, best thread count) over PyTorch's best, and for rk4 ours in GFLOP/s
against the same-precision two-thread peak (OpenBLAS's, the best of its own kernel set and,
on AVX-512 CPUs, its AVX-512 kernels). dopri5 picks its own steps on each side (ours per chunk of 250,
PyTorch per batch of 500), and each side's model (its own initial weights, trained
for its own number of epochs) asks for its own count: both are printed (stderr,
benchmark counters), and the dopri5 ratio also per step of one sample.

    /usr/bin/python3 bench/pushing_epoch_torch.py --out r.json
    DIFFDYN_PUSHING_CSV=path overrides the data file.
"""
import json
import os
import re
import sys

import torch

from torch_common import (describe_torch, dopri5_flow, write_comparison_csv, ours_best, read_transitions,
                          reference_beside_ours, repo_path, rk4_38_flow, se2_pose_loss, time_it)

TRANSITIONS = 1000
BATCH = 500
CHUNK = 250  # our samples per thread task in the runs compared (workload_of)
DOPRI5_TOLERANCE = 1e-8
TIMED_EPOCHS = 7
DATA = os.environ.get("DIFFDYN_PUSHING_CSV", "../shared/data/pybullet_pushing/collected_data.csv")


class AbsNode(torch.nn.Module):
    def __init__(self, dtype, hidden=100, steps=10, method="rk4"):
        super().__init__()
        self.net = torch.nn.Sequential(
            torch.nn.Linear(6, hidden), torch.nn.ReLU(),
            torch.nn.Linear(hidden, hidden), torch.nn.ReLU(),
            torch.nn.Linear(hidden, 6)).to(dtype)
        self.steps = steps
        self.method = method
        self.accepted = self.rejected = 0

    def forward(self, x, u):
        z = torch.cat([x, u], dim=1)
        if self.method == "rk4":
            return rk4_38_flow(self.net, z, self.steps)[:, :3]
        z, accepted, rejected = dopri5_flow(self.net, z, 1.0 / (self.steps - 1), DOPRI5_TOLERANCE)
        self.accepted += accepted
        self.rejected += rejected
        return z[:, :3]


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
    for name, dtype, method in (("float64", torch.float64, "rk4"), ("float32", torch.float32, "rk4"),
                                ("float64", torch.float64, "dopri5"), ("float32", torch.float32, "dopri5")):
        x, u, y = (v.to(dtype) for v in data)
        torch.manual_seed(1)
        model = AbsNode(dtype, method=method)
        opt = torch.optim.Adam(model.parameters(), lr=1e-3)
        gen = torch.Generator().manual_seed(2)
        result[f"{name}/epoch_abs_node_{method}"] = time_it(lambda: epoch(model, opt, x, u, y, gen),
                                                            TIMED_EPOCHS)[0]
        if method == "dopri5":
            epochs = TIMED_EPOCHS + 1  # time_it's warm-up too
            steps = (model.accepted + model.rejected) / epochs
            # dopri5's work is its steps: seconds per step of one sample, for a ratio
            # that does not depend on how many steps each side's model asked for.
            result[f"{name}/sample_step_abs_node_dopri5"] = result[f"{name}/epoch_abs_node_dopri5"] / (steps * BATCH)
            print(f"  {name} dopri5: {model.accepted / epochs:.1f} accepted and {model.rejected / epochs:.1f} "
                  f"rejected steps per epoch (batches of {BATCH}: {steps * BATCH:.0f} sample-steps)", file=sys.stderr)
    return result


def workload_of(name):
    """(precision, method) of our epoch runs at the default chunk (250); None for the others."""
    for pattern, key in ((r"BM_EpochAbsNodeRk4/", ("float64", "rk4")), (r"BM_EpochAbsNodeRk4F32/", ("float32", "rk4")),
                         (r"BM_EpochAbsNodeDopri5/", ("float64", "dopri5")),
                         (r"BM_EpochAbsNodeDopri5F32/", ("float32", "dopri5"))):
        if re.match(pattern + rf"threads:\d+/chunk:{CHUNK}/", name):
            return key
    return None


def peak_of(runs, names):
    """The best GFLOP/s of the peak rows named (rows skipped or missing count as none)."""
    rates = [r["GFLOP/s"] for r in runs for name in names
             if r["name"].startswith(name + "/") and "GFLOP/s" in r]
    return max(rates) if rates else None


def main():
    run = reference_beside_ours(__file__, measure, "pushing_epoch.json")
    if run is None or run[3] is None:
        return
    args, by_config, best, path = run
    ours = ours_best(path, workload_of)
    with open(path) as f:
        runs = json.load(f)["benchmarks"]
    # OpenBLAS with its own kernel set and, on AVX-512 CPUs, with its AVX-512 kernels.
    peaks = {"float64": peak_of(runs, ["BM_PeakDgemmOpenBlas2Threads", "BM_PeakDgemmOpenBlasAvx512Kernels2Threads"]),
             "float32": peak_of(runs, ["BM_PeakSgemmOpenBlas2Threads", "BM_PeakSgemmOpenBlasAvx512Kernels2Threads"])}
    summary, rows = {}, []
    for (precision, method), (seconds, name) in sorted(ours.items()):
        workload = f"epoch_abs_node_{method}"
        torch_s = best[f"{precision}/{workload}"]["seconds"]
        rows.append((workload, precision, name, seconds, best[f"{precision}/{workload}"]["config"], torch_s))
        run = next(r for r in runs if r["name"] == name)
        line = (f"{precision} {method}: ours {name} {seconds * 1e3:.1f} ms, PyTorch best "
                f"{torch_s * 1e3:.1f} ms, ours / PyTorch = {seconds / torch_s:.2f}x")
        entry = {"ours_seconds": seconds, "torch_seconds": torch_s, "ours_over_torch": seconds / torch_s}
        if method == "rk4":
            rate = run.get("epoch_flops_G", 0.0) / seconds
            peak = peaks[precision]
            line += f"; ours {rate:.1f} GFLOP/s"
            if peak:
                line += f" = {100 * rate / peak:.0f}% of the two-thread peak {peak:.1f} GFLOP/s"
            entry.update({"ours_gflops": rate, "peak_gflops": peak})
        else:
            accepted, rejected = run.get("steps", 0), run.get("rejected", 0)
            tried = accepted + rejected
            line += (f" (ours {accepted:.0f} accepted and {rejected:.0f} rejected steps "
                     f"over the epoch's chunks of {CHUNK}: {tried * CHUNK:.0f} sample-steps)")
            per_step = seconds / (tried * CHUNK)
            torch_per_step = best[f"{precision}/sample_step_abs_node_dopri5"]["seconds"]
            line += (f"; per sample-step ours {per_step * 1e6:.2f} us, PyTorch {torch_per_step * 1e6:.2f} us, "
                     f"ours / PyTorch = {per_step / torch_per_step:.2f}x")
            entry.update({"ours_steps": accepted, "ours_rejected": rejected,
                          "ours_sample_step_seconds": per_step, "torch_sample_step_seconds": torch_per_step,
                          "sample_step_ours_over_torch": per_step / torch_per_step})
        print(line)
        summary[f"{precision}/{method}"] = entry
    with open(args.out, "w") as f:
        json.dump({"by_config": by_config, "best": best, "summary": summary}, f, indent=1)
    write_comparison_csv(args.out, rows)


if __name__ == "__main__":
    main()
