"""Helpers shared by the PyTorch reference benchmarks (bench/<name>_torch.py)."""

import csv
import ctypes
import json
import math
import os
import subprocess
import sys
import time

import torch


def blas_in_use():
    """Shared BLAS libraries mapped into this process (after a matmul): OpenBLAS,
    MKL or ATLAS, resolved to their real paths."""
    torch.ones(64, 64, dtype=torch.float64) @ torch.ones(64, 64, dtype=torch.float64)
    libs = set()
    with open("/proc/self/maps") as maps:
        for line in maps:
            path = line.split()[-1]
            if "blas" in path or "mkl" in path or "atlas" in path:
                libs.add(os.path.realpath(path))
    return sorted(libs)


def openblas_core(libs):
    """The kernel set the OpenBLAS among `libs` (blas_in_use()) chose for this CPU
    (openblas_get_corename: "Haswell" is AVX2, "SkylakeX" AVX-512; OPENBLAS_CORETYPE
    overrides it), or "" when no OpenBLAS is mapped."""
    for path in libs:
        if "openblas" in os.path.basename(path):
            lib = ctypes.CDLL(path)
            lib.openblas_get_corename.restype = ctypes.c_char_p
            return lib.openblas_get_corename().decode()
    return ""


def rk4_38_flow(f, z, steps):
    """z(1) of dz/dt = f(z) from z(0) = z by the 3/8-rule RK4 on `steps` grid points
    over [0, 1] (steps - 1 equal steps), as diffdyn's rk4 method."""
    h = 1.0 / (steps - 1)
    for _ in range(steps - 1):
        k1 = f(z)
        k2 = f(z + h * k1 / 3)
        k3 = f(z + h * (k2 - k1 / 3))
        k4 = f(z + h * (k1 - k2 + k3))
        z = z + h * (k1 + 3 * k2 + 3 * k3 + k4) / 8
    return z


def load_mlp(path, dtype):
    """A torch MLP (ReLU) in `dtype` with the flat parameters of a diffdyn model file:
    theta = [vec(W_0), b_0, vec(W_1), b_1, ...], each W_l column-major (out x in)."""
    spec = json.load(open(path))
    sizes = spec["architecture"]["mlp"]["sizes"]
    theta = torch.tensor(spec["parameters"]["values"], dtype=torch.float64).to(dtype)
    layers, offset = [], 0
    for n_in, n_out in zip(sizes, sizes[1:]):
        linear = torch.nn.Linear(n_in, n_out).to(dtype)
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


# Dormand & Prince (1980) 5(4) pair: stage rows a, 5th-order weights b (= the last
# row of a, FSAL) and the 4th-order embedded weights b_hat.
DOPRI5_A = [[],
            [1 / 5],
            [3 / 40, 9 / 40],
            [44 / 45, -56 / 15, 32 / 9],
            [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729],
            [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656],
            [35 / 384, 0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84]]
DOPRI5_B = DOPRI5_A[6]
DOPRI5_B_HAT = [5179 / 57600, 0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40]


def dopri5_flow(f, z, first_step, tol):
    """z(1) of dz/dt = f(z) from z(0) = z by adaptive dopri5 with one step size for the
    batch, as diffdyn's batched solver: error ratio the RMS over all entries of
    err / (tol + tol max(|z|, |z_new|)), accepted when <= 1, next step
    h min(10, max(0.2, 0.9 ratio^(-1/5))) (the retry after a rejection at most h),
    the first trial step `first_step`, the last stage reused (FSAL). The error control
    runs outside autograd; backward goes through the accepted steps, as backprop
    through torchdiffeq's solver does. Returns (z(1), accepted, rejected)."""
    t, dt, accepted, rejected = 0.0, first_step, 0, 0
    k_first = f(z)
    while t < 1.0:
        clipped = dt >= 1.0 - t
        h = 1.0 - t if clipped else dt
        k = [k_first]
        for row in DOPRI5_A[1:]:
            k.append(f(z + h * sum(a * ki for a, ki in zip(row, k) if a != 0)))
        z_new = z + h * sum(b * ki for b, ki in zip(DOPRI5_B, k) if b != 0)
        with torch.no_grad():
            err = h * sum((b - bh) * ki for b, bh, ki in zip(DOPRI5_B + [0.0], DOPRI5_B_HAT, k))
            scale = tol + tol * torch.maximum(z.abs(), z_new.abs())
            ratio = (err / scale).double().square().mean().sqrt().item()
        factor = 10.0 if ratio == 0 else min(10.0, max(0.2, 0.9 * ratio ** -0.2))
        if ratio <= 1.0:
            z, k_first = z_new, k[6]
            accepted += 1
            t = 1.0 if clipped else t + h
            dt = max(dt, h * factor) if clipped else h * factor
        else:
            rejected += 1
            dt = h * min(1.0, factor)
    return z, accepted, rejected


# rg of the 0.1 m square block: sqrt((l^2 + w^2) / 12).
POSE_RG = math.sqrt((0.1 ** 2 + 0.1 ** 2) / 12)


def read_transitions(path, limit=None):
    """(x_t, u_t, x_{t+1}) of a pushing CSV (DESIGN.md schema) in file order, float64
    tensors of n x 3, the first `limit` only if given; exits with file:line on bad rows."""
    xs, us, ys = [], [], []
    prev = None
    with open(path) as f:
        for line, row in enumerate(csv.DictReader(f), start=2):
            try:
                state = [float(row[k]) for k in ("x", "y", "theta")]
                action = [float(row[k]) for k in ("push_location", "push_angle", "push_length")
                          ] if row["push_length"] else None
                trajectory = int(row["trajectory"])
            except (KeyError, ValueError) as e:
                sys.exit(f"error: {path}:{line}: {e}")
            if prev is not None and prev[0] == trajectory and prev[2] is not None:
                xs.append(prev[1])
                us.append(prev[2])
                ys.append(state)
                if limit is not None and len(xs) == limit:
                    break
            prev = (trajectory, state, action)
    t = lambda v: torch.tensor(v, dtype=torch.float64)
    return t(xs), t(us), t(ys)


def se2_pose_loss(pred, target):
    """MSE x + MSE y + rg MSE theta over a batch of poses (n x 3)."""
    d2 = (pred - target) ** 2
    return d2[:, 0].mean() + d2[:, 1].mean() + POSE_RG * d2[:, 2].mean()


def time_it(fn, repeats=30):
    """Median wall and process CPU seconds (CPU time is robust when other jobs share the cores)."""
    fn()
    times, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    times.sort()
    cpu.sort()
    return times[len(times) // 2], cpu[len(cpu) // 2]


# The two ways to use both cores without oversubscribing them: (torch threads, OpenBLAS threads).
TWO_CORE_CONFIGS = {"torch2_blas1": (2, 1), "torch1_blas2": (1, 2)}


def fastest_two_core(script):
    """Runs `script --torch-threads N` (which prints a JSON object of median seconds per
    workload) once per configuration of TWO_CORE_CONFIGS, each in its own process since
    OpenBLAS reads its thread count at start. Returns (seconds per configuration,
    {workload: {"seconds", "config"}} of the faster configuration) and prints both."""
    by_config = {}
    for name, (torch_threads, blas_threads) in TWO_CORE_CONFIGS.items():
        env = dict(os.environ, OPENBLAS_NUM_THREADS=str(blas_threads))
        done = subprocess.run([sys.executable, script, "--torch-threads", str(torch_threads)],
                              env=env, check=True, capture_output=True, text=True,
                              cwd=os.path.dirname(os.path.abspath(script)))
        sys.stderr.write(done.stderr)
        by_config[name] = json.loads(done.stdout)
    best = {}
    for key in next(iter(by_config.values())):
        config = min(by_config, key=lambda c: by_config[c][key])
        best[key] = {"seconds": by_config[config][key], "config": config}
        print(f"PyTorch {key:36s} " + "  ".join(
            f"{c} {by_config[c][key] * 1e6:8.1f} us" for c in by_config) + f"  best {config}")
    return by_config, best


def describe_torch(torch_threads):
    """One line on stderr: torch version, its threads, OpenBLAS's, the BLAS mapped and
    OpenBLAS's kernel set."""
    torch.set_num_threads(torch_threads)
    libs = blas_in_use()
    print(f"  torch {torch.__version__} threads {torch.get_num_threads()} OPENBLAS_NUM_THREADS "
          f"{os.environ.get('OPENBLAS_NUM_THREADS')}; BLAS: {', '.join(libs) or 'none found'}"
          f"; OpenBLAS core {openblas_core(libs) or '-'}",
          file=sys.stderr)


def wall_seconds(run):
    """A Google Benchmark run's wall time per iteration in seconds."""
    return run["real_time"] * {"ms": 1e-3, "us": 1e-6, "ns": 1e-9, "s": 1.0}[run["time_unit"]]


def ours_best(path, key_of, seconds_of=wall_seconds):
    """Our fastest time per workload in a Google Benchmark JSON file: {key: (seconds,
    benchmark name)}, where key_of(name) names a run's workload (None skips the run) and
    seconds_of(run) reads its time (default: wall time per iteration)."""
    with open(path) as f:
        runs = json.load(f)["benchmarks"]
    best = {}
    for run in runs:
        key = key_of(run["name"])
        if key is None or run.get("run_type") == "aggregate":
            continue
        seconds = seconds_of(run)
        if key not in best or seconds < best[key][0]:
            best[key] = (seconds, run["name"])
    return best


def two_core_reference(script, measure):
    """The command line of a two-core PyTorch reference: with --torch-threads N (the
    internal mode fastest_two_core uses) prints measure(N) as JSON and returns None;
    otherwise returns (args, by_config, best) of fastest_two_core(script), args.out being
    the JSON file to write (empty: none)."""
    import argparse
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default="")
    parser.add_argument("--torch-threads", type=int, default=0,
                        help="internal: measure one configuration and print JSON")
    args = parser.parse_args()
    if args.torch_threads:
        print(json.dumps(measure(args.torch_threads)))
        return None
    return (args, *fastest_two_core(script))


def ours_next_to(out, name):
    """The path of our Google Benchmark JSON `name` written next to the reference's --out
    file `out` in the same run, or None (no --out, or no such file)."""
    if not out:
        return None
    path = os.path.join(os.path.dirname(out) or ".", name)
    return path if os.path.exists(path) else None


def reference_beside_ours(script, measure, ours_name):
    """two_core_reference(script, measure) plus the path of our results `ours_name` of the
    same run (ours_next_to): None in the internal mode, else (args, by_config, best,
    path or None)."""
    run = two_core_reference(script, measure)
    return None if run is None else (*run, ours_next_to(run[0].out, ours_name))


def repo_path(path):
    """A path given relative to the repository root, as seen from bench/ (where
    fastest_two_core runs the references); absolute paths are kept."""
    return path if os.path.isabs(path) else os.path.join("..", path)


def describe_machine():
    """'<CPU model> (N cores, AVX-512|AVX2|baseline ISA)', as diffdyn figures writes it."""
    model, isa = "unknown CPU", "baseline ISA"
    with open("/proc/cpuinfo") as f:
        for line in f:
            key, _, value = line.partition(":")
            key, value = key.strip(), value.strip()
            if key == "model name" and model == "unknown CPU":
                model = value
            if key == "flags" and isa == "baseline ISA":
                flags = set(value.split())
                isa = "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "baseline ISA"
    return f"{model} ({os.cpu_count()} cores, {isa})"


COMPARISON_COLUMNS = ["workload", "precision", "ours_benchmark", "ours_ms", "torch_config", "torch_ms",
                      "ours_over_torch", "machine", "date"]


def write_comparison_csv(out, rows):
    """Writes the run's comparisons next to the reference's JSON `out` (same name,
    .csv): one row per (workload, precision: f64 or f32) with our time, PyTorch's best
    two-core time and configuration, their ratio, the machine and the UTC date.
    `rows` holds (workload, precision, ours benchmark name, ours seconds, torch
    config, torch seconds). The figures page (paper_figures/figures.json) cites
    these CSVs as stored under bench/results/."""
    if not out:
        return None
    path = os.path.splitext(out)[0] + ".csv"
    machine = describe_machine()
    short = {"float64": "f64", "double": "f64", "float32": "f32", "float": "f32"}
    date = time.strftime("%Y-%m-%d", time.gmtime())
    with open(path, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(COMPARISON_COLUMNS)
        for workload, precision, name, ours_s, config, torch_s in rows:
            w.writerow([workload, short.get(precision, precision), name, f"{ours_s * 1e3:.6g}", config, f"{torch_s * 1e3:.6g}",
                        f"{ours_s / torch_s:.4g}", machine, date])
    print(f"comparison written to {path}")
    return path
