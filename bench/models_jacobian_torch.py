#!/usr/bin/env python3
"""PyTorch reference for bench/models_jacobian.cc.

1000 input Jacobians (3 x 6) of a 6-100-100-3 softplus network in float64,
single-threaded: autograd (3 backward passes), functorch vmap(jacrev),
vmap(jacfwd), and the DDN-style closed-form forward chain written in torch.
Prints the BLAS torch uses and, if the C++ results of the same run are next to
--out (models_jacobian.json), the ratio of our best to PyTorch's best.

    OPENBLAS_NUM_THREADS=1 /usr/bin/python3 bench/models_jacobian_torch.py --out r.json
"""
import argparse
import json
import os

import torch

from torch_common import blas_in_use, time_it

BATCH = 1000


def make_net():
    torch.manual_seed(1)
    layers = [torch.nn.Linear(6, 100), torch.nn.Linear(100, 100), torch.nn.Linear(100, 3)]
    return [(l.weight.detach().double(), l.bias.detach().double()) for l in layers]


def forward(params, x):
    h = x
    for i, (w, b) in enumerate(params):
        h = h @ w.T + b
        if i + 1 < len(params):
            h = torch.nn.functional.softplus(h)
    return h


def autograd_jacobian(params, x):
    x = x.clone().requires_grad_(True)
    y = forward(params, x)
    rows = [torch.autograd.grad(y[:, k].sum(), x, retain_graph=k < 2)[0] for k in range(3)]
    return torch.stack(rows, dim=1)


def closed_form_chain(params, x):
    # DDN: J <- diag(g'(a)) W J, starting from J = I.
    h = x
    jac = None
    for i, (w, b) in enumerate(params):
        a = h @ w.T + b
        u = w.expand(x.shape[0], -1, -1) if jac is None else torch.matmul(w, jac)
        if i + 1 < len(params):
            d = torch.sigmoid(a)
            h = torch.nn.functional.softplus(a)
            jac = d.unsqueeze(2) * u
        else:
            jac = u
    return jac


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default="")
    args = parser.parse_args()
    torch.set_num_threads(1)
    print("torch", torch.__version__, "threads", torch.get_num_threads(),
          "OPENBLAS_NUM_THREADS", os.environ.get("OPENBLAS_NUM_THREADS"))
    print("BLAS libraries mapped:", ", ".join(blas_in_use()) or "none found")
    params = make_net()
    gen = torch.Generator().manual_seed(2)
    x = torch.randn(BATCH, 6, generator=gen, dtype=torch.float64)

    methods = {"autograd_3_backward": lambda: autograd_jacobian(params, x),
               "closed_form_chain": lambda: closed_form_chain(params, x)}
    try:
        import functorch
        f1 = lambda v: forward(params, v.unsqueeze(0)).squeeze(0)
        jr = functorch.vmap(functorch.jacrev(f1))
        jf = functorch.vmap(functorch.jacfwd(f1))
        methods["functorch_vmap_jacrev"] = lambda: jr(x)
        methods["functorch_vmap_jacfwd"] = lambda: jf(x)
    except Exception as e:  # functorch missing or failing: say so, keep going
        print("functorch unavailable:", e)

    reference = autograd_jacobian(params, x)
    results, results_cpu = {}, {}
    for name, fn in methods.items():
        err = (fn() - reference).abs().max().item()
        seconds, cpu = time_it(fn)
        results[name], results_cpu[name] = seconds, cpu
        print(f"{name:24s} {seconds * 1e6:10.1f} us wall {cpu * 1e6:10.1f} us CPU   "
              f"max|J - autograd| = {err:.1e}")
    best = min(results, key=results.get)
    best_cpu = min(results_cpu, key=results_cpu.get)
    print(f"PyTorch best: {best} {results[best] * 1e6:.1f} us wall; "
          f"{best_cpu} {results_cpu[best_cpu] * 1e6:.1f} us CPU")

    if args.out:
        with open(args.out, "w") as f:
            json.dump({"median_seconds": results, "median_cpu_seconds": results_cpu, "best": best}, f,
                      indent=1)
        ours_path = os.path.join(os.path.dirname(args.out) or ".", "models_jacobian.json")
        if os.path.exists(ours_path):
            with open(ours_path) as f:
                ours = json.load(f)["benchmarks"]
            # One thread each (our /2/ runs use two).
            scale = {"ms": 1e-3, "us": 1e-6, "ns": 1e-9, "s": 1.0}
            single = [b for b in ours if "/2/" not in b["name"] and b.get("run_type") != "aggregate"]
            wall = {b["name"]: b["real_time"] * scale[b["time_unit"]] for b in single}
            cpu = {b["name"]: b["cpu_time"] * scale[b["time_unit"]] for b in single}
            our_best = min(wall, key=wall.get)
            our_best_cpu = min(cpu, key=cpu.get)
            print(f"ours best (1 thread): {our_best} {wall[our_best] * 1e6:.1f} us wall; "
                  f"speed-up over PyTorch best: {results[best] / wall[our_best]:.2f}x wall")
            print(f"ours best CPU (1 thread): {our_best_cpu} {cpu[our_best_cpu] * 1e6:.1f} us CPU; "
                  f"speed-up over PyTorch best: {results_cpu[best_cpu] / cpu[our_best_cpu]:.2f}x CPU")


if __name__ == "__main__":
    main()
