#!/usr/bin/env python3
"""PyTorch reference for bench/pushing_epoch.cc.

One training epoch of the absolute NeuralODE of the NeuralODE-Panda paper in plain
PyTorch, float64 and float32, single-threaded: z0 = [x, u] (6), dz/dt = MLP(z) (6-100-100-6,
ReLU), Kutta's 3/8-rule RK4 over 9 equal steps on [0, 1] written out in torch (what
torchdiffeq's "rk4" does, without its bookkeeping), autograd back through the
solver, SE(2) pose loss, Adam lr 1e-3, 1000 transitions of the shared data in
shuffled batches of 500. Prints the BLAS torch uses and, if the C++ results of the
same run are next to --out (pushing_epoch.json), the ratios.

    OPENBLAS_NUM_THREADS=1 /usr/bin/python3 bench/pushing_epoch_torch.py --out r.json
"""
import argparse
import json
import os
import time

import torch

from torch_common import blas_in_use, read_transitions, rk4_38_flow, se2_pose_loss

TRANSITIONS = 1000
BATCH = 500
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


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default="pushing_epoch_torch.json")
    parser.add_argument("--data", default=os.environ.get(
        "DIFFDYN_PUSHING_CSV", "../shared/data/pybullet_pushing/collected_data.csv"))
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(1)
    blas = blas_in_use()
    print("torch", torch.__version__, "threads", torch.get_num_threads(),
          "OPENBLAS_NUM_THREADS", os.environ.get("OPENBLAS_NUM_THREADS"))
    print("BLAS in use:", ", ".join(blas) if blas else "(none found in /proc/self/maps)")
    data = read_transitions(args.data, TRANSITIONS)
    result = {"blas": blas, "torch": torch.__version__}
    medians = {}
    for name, dtype in (("", torch.float64), ("_f32", torch.float32)):
        median, median_cpu = time_epochs(dtype, [v.to(dtype) for v in data], args.repeats)
        print(f"abs-NODE rk4 (10 grid points) epoch, {TRANSITIONS} transitions, batch {BATCH}, "
              f"{dtype}: median {median * 1e3:.1f} ms wall, {median_cpu * 1e3:.1f} ms CPU over {args.repeats}")
        result[f"epoch_abs_node_rk4{name}_seconds"] = median
        result[f"epoch_abs_node_rk4{name}_cpu_seconds"] = median_cpu
        medians[name] = (median, median_cpu)
    with open(args.out, "w") as f:
        json.dump(result, f)
    # Side by side with the C++ run written next to --out.
    ours_path = os.path.join(os.path.dirname(os.path.abspath(args.out)), "pushing_epoch.json")
    if os.path.exists(ours_path):
        report(json.load(open(ours_path))["benchmarks"], *medians[""])
        report_f32(json.load(open(ours_path))["benchmarks"], *medians["_f32"])


def time_epochs(dtype, data, repeats):
    """Median wall and process-CPU seconds of `repeats` epochs in `dtype`, after a warm-up."""
    x, u, y = data
    torch.manual_seed(1)
    model = AbsNode(dtype)
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    gen = torch.Generator().manual_seed(2)
    epoch(model, opt, x, u, y, gen)  # warm-up
    # Wall time, and process CPU time (robust when other jobs share the cores).
    times, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        epoch(model, opt, x, u, y, gen)
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    times.sort()
    cpu.sort()
    return times[len(times) // 2], cpu[len(cpu) // 2]


def find_run(benchmarks, prefix):
    """The first non-aggregate run named prefix/..., or None."""
    for b in benchmarks:
        if b["name"].startswith(prefix + "/") and b.get("run_type") != "aggregate":
            return b
    return None


def seconds(b, key="real_time"):
    unit = {"ms": 1e-3, "us": 1e-6, "ns": 1e-9, "s": 1}
    return None if b is None else b[key] * unit[b["time_unit"]]


def report_f32(benchmarks, median, median_cpu):
    """float32: ours (BM_EpochAbsNodeRk4F32) next to PyTorch float32, and against our float64."""
    one, two = find_run(benchmarks, "BM_EpochAbsNodeRk4F32/threads:1"), find_run(benchmarks, "BM_EpochAbsNodeRk4F32/threads:2")
    f64 = find_run(benchmarks, "BM_EpochAbsNodeRk4/threads:1")
    if not (one and two):
        return
    print(f"float32: ours {seconds(one) * 1e3:.1f} ms (1 thread), {seconds(two) * 1e3:.1f} ms (2 threads) wall; "
          f"PyTorch float32 / ours = {median / seconds(one):.2f}x (1 thread), {median / seconds(two):.2f}x "
          f"(2 threads); CPU PyTorch / ours (1 thread) = {median_cpu / seconds(one, 'cpu_time'):.2f}x")
    if f64:
        print(f"ours float64 / float32 (1 thread): {seconds(f64) / seconds(one):.2f}x")


def report(benchmarks, median, median_cpu):
    """Ours (pushing_epoch.json of the same run) next to PyTorch: wall and CPU."""
    find = lambda prefix: find_run(benchmarks, prefix)
    sec = seconds
    one, two = find("BM_EpochAbsNodeRk4/threads:1"), find("BM_EpochAbsNodeRk4/threads:2")
    dopri = find("BM_EpochAbsNodeDopri5/threads:2")
    peaks = [b for b in (find("BM_PeakDgemm2Threads"), find("BM_PeakDgemmOpenBlas2Threads"))
             if b is not None and "GFLOP/s" in b]
    peak = max(peaks, key=lambda b: b["GFLOP/s"]) if peaks else None
    if one and two:
        print(f"ours: {sec(one) * 1e3:.1f} ms (1 thread), {sec(two) * 1e3:.1f} ms (2 threads) wall; "
              f"PyTorch / ours = {median / sec(one):.2f}x (1 thread), {median / sec(two):.2f}x (2 threads)")
        print(f"CPU time (all threads): ours {sec(one, 'cpu_time') * 1e3:.1f} ms (1 thread), "
              f"{sec(two, 'cpu_time') * 1e3:.1f} ms (2 threads), PyTorch {median_cpu * 1e3:.1f} ms; "
              f"PyTorch / ours = {median_cpu / sec(one, 'cpu_time'):.2f}x (1 thread), "
              f"{median_cpu / sec(two, 'cpu_time'):.2f}x (2 threads)")
        flops = two.get("epoch_flops_G")
        if peak and flops:
            print(f"2 threads: {flops / sec(two):.1f} GFLOP/s = {100 * flops / sec(two) / peak['GFLOP/s']:.0f}% "
                  f"of the measured peak {peak['GFLOP/s']:.1f} GFLOP/s ({peak['name'].split('/')[0]}); "
                  f"PyTorch {flops / median:.1f} GFLOP/s")
    if dopri and two:
        print(f"dopri5 / rk4 epoch time (2 threads): {sec(dopri) / sec(two):.1f}x wall, "
              f"{sec(dopri, 'cpu_time') / sec(two, 'cpu_time'):.1f}x CPU")

if __name__ == "__main__":
    main()
