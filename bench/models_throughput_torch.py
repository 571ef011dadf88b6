#!/usr/bin/env python3
"""PyTorch reference for bench/models_throughput.cc.

Forward + backward (parameter and input gradients) of a batch of 500 through a
6-100-100-6 network with softplus or ReLU, in float64 and float32, in both
two-core configurations: torch on 2 threads with OpenBLAS on 1, and torch on 1
thread with OpenBLAS on 2 (each in its own process, since OpenBLAS reads its
thread count at start). Never both at 2, which oversubscribes the cores. Per
workload the faster configuration is PyTorch's time; if the C++ results of the
same run are next to --out (models_throughput.json), prints our best two-thread
time and the ratio ours / PyTorch (below 1: we are faster).

    /usr/bin/python3 bench/models_throughput_torch.py --out r.json
"""
import argparse
import json
import os
import subprocess
import sys

BATCH = 500
CONFIGS = {"torch2_blas1": (2, 1), "torch1_blas2": (1, 2)}


def measure(torch_threads):
    """Median wall seconds per forward+backward for each (precision, activation)."""
    import torch
    from torch_common import blas_in_use, time_it
    torch.set_num_threads(torch_threads)
    print(f"  torch {torch.__version__} threads {torch.get_num_threads()} OPENBLAS_NUM_THREADS "
          f"{os.environ.get('OPENBLAS_NUM_THREADS')}; BLAS: {', '.join(blas_in_use()) or 'none found'}",
          file=sys.stderr)
    results = {}
    for dtype, precision in ((torch.float64, "double"), (torch.float32, "float")):
        for act_name, act in (("softplus", torch.nn.functional.softplus),
                              ("relu", torch.nn.functional.relu)):
            torch.manual_seed(1)
            layers = [torch.nn.Linear(6, 100), torch.nn.Linear(100, 100), torch.nn.Linear(100, 6)]
            params = [p.detach().to(dtype).requires_grad_(True)
                      for l in layers for p in (l.weight, l.bias)]
            gen = torch.Generator().manual_seed(2)
            x = torch.randn(BATCH, 6, generator=gen, dtype=dtype).requires_grad_(True)
            gy = torch.randn(BATCH, 6, generator=gen, dtype=dtype)

            def step():
                h = x
                for i in range(3):
                    h = h @ params[2 * i].T + params[2 * i + 1]
                    if i < 2:
                        h = act(h)
                torch.autograd.grad(h, params + [x], gy)

            seconds, _ = time_it(step, repeats=200)
            results[f"{precision}/{act_name}"] = seconds
    return results


def ours_best(path):
    """Our fastest time (seconds) per 'precision/activation' over thread counts."""
    with open(path) as f:
        runs = json.load(f)["benchmarks"]
    scale = {"ms": 1e-3, "us": 1e-6, "ns": 1e-9, "s": 1.0}
    best = {}
    for run in runs:
        name = run["name"]
        if not name.startswith("BM_ForwardBackward<") or run.get("run_type") == "aggregate":
            continue
        precision = name[len("BM_ForwardBackward<"):name.index(">")]
        act = "relu" if "relu:1" in name else "softplus"
        seconds = run["real_time"] * scale[run["time_unit"]]
        key = f"{precision}/{act}"
        if key not in best or seconds < best[key][0]:
            best[key] = (seconds, name)
    return best


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default="")
    parser.add_argument("--torch-threads", type=int, default=0,
                        help="internal: measure one configuration and print JSON")
    args = parser.parse_args()
    if args.torch_threads:
        print(json.dumps(measure(args.torch_threads)))
        return
    by_config = {}
    for name, (torch_threads, blas_threads) in CONFIGS.items():
        env = dict(os.environ, OPENBLAS_NUM_THREADS=str(blas_threads))
        done = subprocess.run([sys.executable, __file__, "--torch-threads", str(torch_threads)],
                              env=env, check=True, capture_output=True, text=True,
                              cwd=os.path.dirname(os.path.abspath(__file__)))
        sys.stderr.write(done.stderr)
        by_config[name] = json.loads(done.stdout)
    best = {}
    for key in by_config["torch2_blas1"]:
        config = min(by_config, key=lambda c: by_config[c][key])
        best[key] = {"seconds": by_config[config][key], "config": config}
        print(f"PyTorch {key:16s} " + "  ".join(
            f"{c} {by_config[c][key] * 1e6:8.1f} us" for c in by_config) + f"  best {config}")
    ours = {}
    if args.out:
        ours_path = os.path.join(os.path.dirname(args.out) or ".", "models_throughput.json")
        if os.path.exists(ours_path):
            ours = ours_best(ours_path)
        for key, (seconds, name) in sorted(ours.items()):
            if key in best:
                print(f"ours {key:16s} {seconds * 1e6:8.1f} us ({name}); ours / PyTorch best = "
                      f"{seconds / best[key]['seconds']:.2f}x")
        with open(args.out, "w") as f:
            json.dump({"by_config": by_config, "best": best,
                       "ours_over_torch": {k: ours[k][0] / best[k]["seconds"]
                                           for k in ours if k in best}}, f, indent=1)


if __name__ == "__main__":
    main()
