"""The cost of the Python layer: model.predict and Mppi.command against the same calls in C++.

    PYTHONPATH=build/python /usr/bin/python3 bench/python_predict.py [--diffdyn build/cli/diffdyn]
        [--mppi-bench build/bench/bench_control_mppi] [--out F.json]

For each model (the analytic pendulum at 20 ms, and an abs-node of hidden width 100
trained for one epoch on pendulum data: the weights do not change the cost) and a
batch of 1000 samples, one thread: the median seconds of `model.predict(x, u,
threads=1)` from Python, and of the library's PredictBatch on the same arrays
timed inside C++ (`diffdyn._diffdyn._native_predict_seconds`: no Python, one workspace made
beforehand). The ratio Python / C++ is the layer's overhead (array checks, chunking
into 256-sample blocks, the GIL hand-over).

MPPI: the median seconds of `Mppi.command(x)` with diffdyn.TaskCost("pendulum") in
the setting of bench/control_mppi.cc (K = 1000, 25 steps of 40 ms over the task's
analytic pendulum, x = (0.3, 0), one and two threads), against that benchmark's
median, run by this script right after (when its binary is there).
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

import diffdyn


def python_seconds(model, x, u, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        model.predict(x, u, threads=1)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def learned_model(binary, folder):
    data, path = os.path.join(folder, "pendulum.csv"), os.path.join(folder, "abs-node.json")
    for args in (["collect", "--system", "pendulum", "--trajectories", "20", "--seconds", "2", "--out", data],
                 ["train", "--data", data, "--model", "abs-node", "--epochs", "1", "--hidden", "100",
                  "--out", path]):
        subprocess.run([binary, *args, "--quiet"], check=True, capture_output=True)
    return path


def mppi_rows(bench_binary, repeats):
    """Mppi.command from Python against BM_MppiPendulumCommand, per thread count."""
    task = diffdyn.Task("pendulum")
    model = task.plant(dt=0.04, substeps=1)
    x = np.array([0.3, 0.0])
    python = {}
    for threads in (1, 2):
        mppi = diffdyn.Mppi(model, diffdyn.TaskCost("pendulum"), samples=1000, horizon=25, lambda_=0.1,
                            noise_variance=(0.5 * task.bound[0]) ** 2, threads=threads, seed=1)
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            mppi.command(x)
            times.append(time.perf_counter() - start)
        python[threads] = statistics.median(times)
    native = {}
    if os.path.exists(bench_binary):
        out = subprocess.run([bench_binary, "--benchmark_repetitions=5", "--benchmark_report_aggregates_only=true",
                              "--benchmark_format=json"], check=True, capture_output=True, text=True).stdout
        for b in json.loads(out)["benchmarks"]:
            if b.get("aggregate_name") == "median":
                native[int(b["run_name"].split("threads:")[1].split("/")[0])] = b["real_time"] * 1e-3  # ms -> s
    rows = []
    for threads, seconds in python.items():
        row = {"model": f"Mppi.command, pendulum, {threads} thread(s)", "python_seconds": seconds}
        if threads in native:
            row.update({"cpp_seconds": native[threads], "ratio": seconds / native[threads]})
        rows.append(row)
        cpp = f"C++ {native[threads] * 1e6:9.1f} us" if threads in native else "C++ (no benchmark binary)"
        ratio = f"ratio {seconds / native[threads]:.3f}" if threads in native else ""
        print(f"{row['model']:38s} {cpp}   Python {seconds * 1e6:9.1f} us   {ratio}")
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--diffdyn", default="build/cli/diffdyn")
    parser.add_argument("--samples", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=200)
    parser.add_argument("--mppi-bench", default="build/bench/bench_control_mppi")
    parser.add_argument("--out")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        models = {"pendulum (rk4-classic, 4 substeps)": diffdyn.load_model("pendulum", dt=0.02),
                  "abs-node 100 (rk4, 10 points)": diffdyn.load_model(learned_model(args.diffdyn, folder))}
        for name, model in models.items():
            x = rng.standard_normal((args.samples, model.state_size))
            u = rng.standard_normal((args.samples, model.action_size))
            python_seconds(model, x, u, 5)  # warm up: workspaces, caches
            native = diffdyn._diffdyn._native_predict_seconds(model, x, u, args.repeats)
            wrapped = python_seconds(model, x, u, args.repeats)
            rows.append({"model": name, "samples": args.samples, "cpp_seconds": native,
                         "python_seconds": wrapped, "ratio": wrapped / native})
            print(f"{name:38s} C++ {native * 1e6:9.1f} us   Python {wrapped * 1e6:9.1f} us   "
                  f"ratio {wrapped / native:.3f}")
    rows += mppi_rows(args.mppi_bench, 100)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(rows, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
