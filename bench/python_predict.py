"""The cost of the Python layer: model.predict on a batch against the same call in C++.

    PYTHONPATH=build/python /usr/bin/python3 bench/python_predict.py [--diffdyn build/cli/diffdyn] [--out F.json]

For each model (the analytic pendulum at 20 ms, and an abs-node of hidden width 100
trained for one epoch on pendulum data: the weights do not change the cost) and a
batch of 1000 samples, one thread: the median seconds of `model.predict(x, u,
threads=1)` from Python, and of the library's PredictBatch on the same arrays
timed inside C++ (`diffdyn._diffdyn._native_predict_seconds`: no Python, one workspace made
beforehand). The ratio Python / C++ is the layer's overhead (array checks, chunking
into 256-sample blocks, the GIL hand-over).
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


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--diffdyn", default="build/cli/diffdyn")
    parser.add_argument("--samples", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=200)
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
    if args.out:
        with open(args.out, "w") as f:
            json.dump(rows, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
