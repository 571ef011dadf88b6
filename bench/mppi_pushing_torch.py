#!/usr/bin/env python3
"""PyTorch reference for bench/mppi_pushing.cc.

A plain MPPI in PyTorch, float64, single-threaded, the algorithm of the seed's
pytorch_mppi (and of solvers/mppi.h): warm start by shifting, K x T x 3 Gaussian
noise with covariance Sigma = 0.5 I, clamp to the action bounds and recompute the
perturbation, batched rollout of the model over the K samples, running cost
(x - g)^T diag(1, 1, 0.1) (x - g) + 100 in_collision(x) summed over x_1..x_T (exact
separating-axis overlap of the rotated block with the obstacle), perturbation cost
U (lambda noise Sigma^-1), softmax weights with lambda = 0.01, U += sum_k w_k noise_k.

The models are the SAME weights as the C++ run: the model files mppi_abs_node.json
(6-100-100-6 ReLU NeuralODE, 3/8-rule RK4 on 10 grid points) and mppi_res_nn.json
(6-100-100-3 ReLU residual NN) that bench_mppi_pushing writes next to its results.
Prints the BLAS torch uses, ms per command (wall and CPU), and the ratios against the
C++ results of the same run (mppi_pushing.json next to --out), if present.

    OPENBLAS_NUM_THREADS=1 /usr/bin/python3 bench/mppi_pushing_torch.py --out r.json
"""
import argparse
import json
import math
import os

import torch

from torch_common import blas_in_use, rk4_38_flow, time_it

K = 1000
START = (0.4, 0.0, -0.2 * math.pi)
GOAL = (0.8, -0.1, 0.0)


def load_mlp(path):
    """A torch MLP (ReLU) with the flat parameters of a diffdyn model file:
    theta = [vec(W_0), b_0, vec(W_1), b_1, ...], each W_l column-major (out x in)."""
    spec = json.load(open(path))
    sizes = spec["architecture"]["mlp"]["sizes"]
    theta = torch.tensor(spec["parameters"]["values"], dtype=torch.float64)
    layers, offset = [], 0
    for n_in, n_out in zip(sizes, sizes[1:]):
        linear = torch.nn.Linear(n_in, n_out).double()
        w = theta[offset:offset + n_in * n_out].reshape(n_in, n_out).t()
        offset += n_in * n_out
        b = theta[offset:offset + n_out]
        offset += n_out
        with torch.no_grad():
            linear.weight.copy_(w)
            linear.bias.copy_(b)
        layers += [linear, torch.nn.ReLU()]
    assert offset == theta.numel()
    return torch.nn.Sequential(*layers[:-1]), spec


class AbsNode(torch.nn.Module):
    """x' = P z(1), z(0) = [x, u], dz/dt = MLP(z), 3/8-rule RK4 with steps - 1 steps."""

    def __init__(self, net, steps):
        super().__init__()
        self.net, self.steps = net, steps

    def forward(self, x, u):
        return rk4_38_flow(self.net, torch.cat([x, u], dim=1), self.steps)[:, :3]


class ResNn(torch.nn.Module):
    def __init__(self, net):
        super().__init__()
        self.net = net

    def forward(self, x, u):
        return x + self.net(torch.cat([x, u], dim=1))


def in_collision(x):
    """1 where the 0.1 m block at pose x (K x 3) overlaps the obstacle (separating axes)."""
    hb, ox, oy, hx, hy = 0.05, 0.6, 0.2, 0.05, 0.25
    c, s = torch.cos(x[:, 2]).abs(), torch.sin(x[:, 2]).abs()
    cs, sn = torch.cos(x[:, 2]), torch.sin(x[:, 2])
    dx, dy = ox - x[:, 0], oy - x[:, 1]
    apart = (dx.abs() >= hx + hb * (c + s)) | (dy.abs() >= hy + hb * (s + c)) \
        | ((cs * dx + sn * dy).abs() >= hb + hx * c + hy * s) \
        | ((-sn * dx + cs * dy).abs() >= hb + hx * s + hy * c)
    return (~apart).double()


def running_cost(x, goal):
    d = x - goal
    return d[:, 0] ** 2 + d[:, 1] ** 2 + 0.1 * d[:, 2] ** 2 + 100.0 * in_collision(x)


class Mppi:
    def __init__(self, model, horizon, gen):
        self.model, self.T, self.gen = model, horizon, gen
        self.sigma = 0.5 * torch.eye(3, dtype=torch.float64)
        self.chol = torch.linalg.cholesky(self.sigma)
        self.sigma_inv = torch.linalg.inv(self.sigma)
        self.lam = 0.01
        self.u_min = torch.tensor([-1.0, -math.pi / 2, 0.0], dtype=torch.float64)
        self.u_max = torch.tensor([1.0, math.pi / 2, 1.0], dtype=torch.float64)
        self.goal = torch.tensor(GOAL, dtype=torch.float64)
        u = torch.randn(horizon, 3, generator=gen, dtype=torch.float64) @ self.chol.t()
        self.U = torch.max(torch.min(u, self.u_max), self.u_min)

    @torch.no_grad()
    def command(self, x0):
        self.U = torch.roll(self.U, -1, dims=0)
        self.U[-1] = 0.0
        noise = torch.randn(K, self.T, 3, generator=self.gen, dtype=torch.float64) @ self.chol.t()
        perturbed = torch.max(torch.min(self.U + noise, self.u_max), self.u_min)
        noise = perturbed - self.U
        cost = torch.zeros(K, dtype=torch.float64)
        x = x0.expand(K, 3)
        for t in range(self.T):
            x = self.model(x, perturbed[:, t])
            cost += running_cost(x, self.goal)
        cost += (self.U * (self.lam * noise @ self.sigma_inv)).sum(dim=(1, 2))
        w = torch.exp(-(cost - cost.min()) / self.lam)
        w /= w.sum()
        self.U += (w[:, None, None] * noise).sum(dim=0)
        return self.U[0]


def time_commands(model, horizon, repeats):
    """Median (wall, CPU) seconds of one command from START, after a warm-up."""
    mppi = Mppi(model, horizon, torch.Generator().manual_seed(1))
    x0 = torch.tensor(START, dtype=torch.float64)
    return time_it(lambda: mppi.command(x0), repeats)


def ours(bench, prefix):
    """(wall, cpu) seconds of the C++ benchmark whose name starts with `prefix`."""
    for b in bench:
        if b.get("run_type", "iteration") == "iteration" and b["name"].startswith(prefix + "/"):
            scale = {"ms": 1e-3, "us": 1e-6, "ns": 1e-9, "s": 1}[b["time_unit"]]
            return b["real_time"] * scale, b["cpu_time"] * scale, b
    return None


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default="mppi_pushing_torch.json")
    parser.add_argument("--models", default=None,
                        help="folder of mppi_abs_node.json / mppi_res_nn.json (default: that of --out)")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    folder = args.models or os.path.dirname(os.path.abspath(args.out))
    torch.set_num_threads(1)
    blas = blas_in_use()
    print("torch", torch.__version__, "threads", torch.get_num_threads(),
          "OPENBLAS_NUM_THREADS", os.environ.get("OPENBLAS_NUM_THREADS"))
    print("BLAS in use:", ", ".join(blas) if blas else "(none found in /proc/self/maps)")
    net, spec = load_mlp(os.path.join(folder, "mppi_abs_node.json"))
    node = AbsNode(net, spec["architecture"]["steps"])
    res_net, _ = load_mlp(os.path.join(folder, "mppi_res_nn.json"))
    res = ResNn(res_net)

    cases = [("abs_node_t20", node, 20, "BM_MppiAbsNode/20"),
             ("abs_node_t30", node, 30, "BM_MppiAbsNode/30"),
             ("res_nn_t30", res, 30, "BM_MppiResNn/30")]
    result = {"blas": blas, "torch": torch.__version__}
    timings = {}
    for name, model, horizon, _ in cases:
        repeats = args.repeats if name.startswith("abs") else 4 * args.repeats
        wall, cpu = time_commands(model, horizon, repeats)
        timings[name] = (wall, cpu)
        result[name + "_seconds"], result[name + "_cpu_seconds"] = wall, cpu
        print(f"PyTorch MPPI {name}, K = {K}, T = {horizon}, float64: median "
              f"{wall * 1e3:.1f} ms wall, {cpu * 1e3:.1f} ms CPU per command over {repeats}")
    with open(args.out, "w") as f:
        json.dump(result, f)

    # Side by side with the C++ run written next to --out.
    ours_path = os.path.join(os.path.dirname(os.path.abspath(args.out)), "mppi_pushing.json")
    if not os.path.exists(ours_path):
        return
    bench = json.load(open(ours_path))["benchmarks"]
    peak = None  # the best two-thread dgemm, Eigen or OpenBLAS
    for b in bench:
        if b["name"].startswith(("BM_PeakDgemm2Threads", "BM_PeakDgemmOpenBlas2Threads")):
            if b.get("GFLOP/s") and (peak is None or b["GFLOP/s"] > peak):
                peak = b["GFLOP/s"]
    for name, _, horizon, prefix in cases:
        wall, cpu = timings[name]
        for threads in (1, 2):
            r = ours(bench, f"{prefix}/{threads}")
            if r is None:
                continue
            our_wall, our_cpu, b = r
            line = (f"{name}, {threads} thread(s): ours {our_wall * 1e3:.1f} ms wall "
                    f"({our_cpu * 1e3:.1f} ms CPU); PyTorch / ours = {wall / our_wall:.2f}x wall")
            if threads == 1:
                line += f", {cpu / our_cpu:.2f}x CPU"
            flops = b.get("command_flops_G")
            if flops:
                # Dense-equivalent: ours skips ReLU units that are zero for a whole
                # block of samples, so the rate can pass the dgemm peak.
                line += f"; {flops / our_wall:.1f} dense-equivalent GFLOP/s"
                if peak and threads == 2:
                    line += f" = {100 * flops / our_wall / peak:.0f}% of the 2-thread dgemm peak {peak:.1f}"
                line += f" (PyTorch {flops / wall:.1f})"
            print(line)


if __name__ == "__main__":
    main()
