#!/usr/bin/env python3
"""PyTorch reference for bench/models_jacobian.cc.

1000 input Jacobians (3 x 6) of a 6-100-100-3 softplus network in float64 and
float32: autograd (3 backward passes), functorch vmap(jacrev), vmap(jacfwd),
and the DDN-style closed-form forward chain written in torch; in both two-core
configurations (torch 2 threads with OpenBLAS 1, torch 1 with OpenBLAS 2), each
in its own process, keeping the faster per method. Prints the BLAS torch uses
and, if the C++ results of the same run are next to --out (models_jacobian.json),
the ratio of our best (any thread count) to PyTorch's best, per precision.

    /usr/bin/python3 bench/models_jacobian_torch.py --out r.json
"""
import json
import os
import sys

import torch

from torch_common import describe_torch, ours_best, time_it, two_core_reference, write_comparison_csv

BATCH = 1000


def make_net(dtype):
    torch.manual_seed(1)
    layers = [torch.nn.Linear(6, 100), torch.nn.Linear(100, 100), torch.nn.Linear(100, 3)]
    return [(l.weight.detach().to(dtype), l.bias.detach().to(dtype)) for l in layers]


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


def measure(torch_threads):
    """Median wall seconds of each method per precision, keyed 'precision/method'."""
    describe_torch(torch_threads)
    results = {}
    for dtype, precision in ((torch.float64, "double"), (torch.float32, "float")):
        params = make_net(dtype)
        gen = torch.Generator().manual_seed(2)
        x = torch.randn(BATCH, 6, generator=gen, dtype=torch.float64).to(dtype)
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
            print("functorch unavailable:", e, file=sys.stderr)
        reference = autograd_jacobian(params, x)
        for name, fn in methods.items():
            err = (fn() - reference).abs().max().item()
            assert err < (1e-10 if dtype == torch.float64 else 1e-4), (precision, name, err)
            results[f"{precision}/{name}"], _ = time_it(fn)
    return results


def precision_of(name):
    """'double' or 'float' for our batched benchmarks (BM_...<S>/...), else None."""
    return name[name.index("<") + 1:name.index(">")] if "<" in name else None


def main():
    run = two_core_reference(__file__, measure)
    if run is None:
        return
    args, by_config, best = run
    torch_best = {}
    for key, entry in best.items():
        precision = key.split("/")[0]
        if precision not in torch_best or entry["seconds"] < torch_best[precision][0]:
            torch_best[precision] = (entry["seconds"], key, entry["config"])
    for precision, (seconds, key, config) in torch_best.items():
        print(f"PyTorch best, {precision}: {key} {seconds * 1e6:.1f} us ({config})")
    if not args.out:
        return
    ours_path = os.path.join(os.path.dirname(args.out) or ".", "models_jacobian.json")
    ours = ours_best(ours_path, precision_of) if os.path.exists(ours_path) else {}
    for precision, (seconds, name) in sorted(ours.items()):
        if precision in torch_best:
            print(f"ours best, {precision}: {name} {seconds * 1e6:.1f} us; ours / PyTorch best = "
                  f"{seconds / torch_best[precision][0]:.2f}x")
    with open(args.out, "w") as f:
        json.dump({"by_config": by_config, "best": best,
                   "ours_over_torch": {p: ours[p][0] / torch_best[p][0]
                                       for p in ours if p in torch_best}}, f, indent=1)
    write_comparison_csv(args.out, [("input_jacobians_1000", p, ours[p][1], ours[p][0], torch_best[p][2],
                                     torch_best[p][0]) for p in sorted(ours) if p in torch_best])


if __name__ == "__main__":
    main()
