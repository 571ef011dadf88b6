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
import json
import os

import torch

from torch_common import describe_torch, ours_best, time_it, two_core_reference

BATCH = 500


def measure(torch_threads):
    """Median wall seconds per forward+backward for each (precision, activation)."""
    describe_torch(torch_threads)
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


def workload_of(name):
    """'precision/activation' of a BM_ForwardBackward<S>/threads:T/relu:R run, else None."""
    prefix = "BM_ForwardBackward<"
    if not name.startswith(prefix):
        return None
    act = "relu" if "relu:1" in name else "softplus"
    return f"{name[len(prefix):name.index('>')]}/{act}"


def main():
    run = two_core_reference(__file__, measure)
    if run is None:
        return
    args, by_config, best = run
    ours = {}
    if args.out:
        ours_path = os.path.join(os.path.dirname(args.out) or ".", "models_throughput.json")
        if os.path.exists(ours_path):
            ours = ours_best(ours_path, workload_of)
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
