#!/usr/bin/env python3
"""Plots for the DDN Figure-2 experiment, from the CSVs of figure_ddn_jacobian.

    /usr/bin/python3 paper_figures/ddn_jacobian/plot.py OUT_DIR [RUN_DIR ...]

With RUN_DIRs (outputs of separate figure_ddn_jacobian runs, e.g. one
activation each, run in parallel), their results.csv and curves_{1,2}d.csv
are first merged into OUT_DIR: results rows are concatenated (in the order
relu, softplus, tanh, cos), curve columns joined after checking that every
run used the same test grid and the same samples.

Writes into OUT_DIR:
  figure_1d_<activation>.png  three stacked panels y, dy/dx, d2y/dx2 like the
                              authors' figures: truth black, noisy samples grey,
                              f+J loss red, f-only loss magenta;
  figure_2d_jacobian.png      |J error| over the 2-D grid per activation (columns)
                              and loss (rows), one shared log colour scale;
  figure_2d_slice.png         f, df/dx and d2f/dx2 along the grid row nearest
                              y = pi/2 (where f = cos x sin y ~ cos x), coloured
                              like the 1-D figures.
"""
import csv
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402

ORDER = ["relu", "softplus", "tanh", "cos"]


def read_rows(path):
    with open(path) as f:
        reader = csv.reader(f)
        header = next(reader)
        return header, [row for row in reader]


def write_rows(path, header, rows):
    tmp = path + ".tmp"
    with open(tmp, "w", newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(header)
        writer.writerows(rows)
    os.replace(tmp, path)


def order_key(name):
    return ORDER.index(name) if name in ORDER else len(ORDER)


def merge(out, runs):
    """Merges results.csv and curves_{1,2}d.csv of several runs into out."""
    os.makedirs(out, exist_ok=True)
    header, rows = None, []
    for run in runs:
        h, r = read_rows(os.path.join(run, "results.csv"))
        if header is not None and h != header:
            sys.exit(f"error: {run}/results.csv: header differs from the first run's")
        header = h
        rows += r
    rows.sort(key=lambda r: (int(r[0]), order_key(r[1]), r[2] != "f+J"))
    write_rows(os.path.join(out, "results.csv"), header, rows)
    for dim in (1, 2):
        name = f"curves_{dim}d.csv"
        parts = [read_rows(os.path.join(run, name)) for run in runs if os.path.exists(os.path.join(run, name))]
        if not parts:
            continue
        n_fixed = dim + 1 + dim + dim * dim  # inputs and the truth
        header, rows = parts[0]
        for (h, r), run in zip(parts[1:], runs[1:]):
            if h[:n_fixed] != header[:n_fixed] or [x[:dim] for x in r] != [x[:dim] for x in rows]:
                sys.exit(f"error: {run}/{name}: a different test grid from the first run's")
            header = header + h[n_fixed:]
            rows = [a + b[n_fixed:] for a, b in zip(rows, r)]
        write_rows(os.path.join(out, name), header, rows)
        samples = f"samples_{dim}d.csv"
        sample_runs = [run for run in runs if os.path.exists(os.path.join(run, samples))]
        first = read_rows(os.path.join(sample_runs[0], samples))
        for run in sample_runs[1:]:
            if read_rows(os.path.join(run, samples)) != first:
                sys.exit(f"error: {run}/{samples}: different training samples (another seed?)")
        write_rows(os.path.join(out, samples), *first)


def read_csv(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    return {k: [float(r[k]) for r in rows] for k in rows[0]}


def activations(columns):
    acts = []
    for name in columns:
        if name.endswith("_fJ_f"):
            acts.append(name[: -len("_fJ_f")])
    return sorted(acts, key=order_key)


def plot_1d(out):
    curves = read_csv(os.path.join(out, "curves_1d.csv"))
    samples = read_csv(os.path.join(out, "samples_1d.csv"))
    x = curves["x"]
    for act in activations(curves):
        fig, axes = plt.subplots(3, 1, figsize=(6, 7), sharex=True)
        for ax, key, label in zip(axes, ["f", "j1", "h1"], ["y", "dy/dx", "d²y/dx²"]):
            if key in ("f", "j1"):
                ax.plot(samples["x"], samples[key], ".", color="0.7", ms=2, label="noisy samples")
            ax.plot(x, curves["true_" + key], "k-", lw=2, label="ground truth")
            ax.plot(x, curves[f"{act}_fJ_{key}"], "r-", lw=1.2, label="loss on y + dy/dx")
            ax.plot(x, curves[f"{act}_f_{key}"], "m--", lw=1.2, label="loss on y only")
            ax.set_ylabel(label)
        axes[0].set_title(f"DDN, {act}: f(x) = sin x")
        axes[0].legend(fontsize=7, loc="upper left")
        axes[-1].set_xlabel("x")
        fig.tight_layout()
        fig.savefig(os.path.join(out, f"figure_1d_{act}.png"), dpi=120)
        plt.close(fig)


def plot_2d(out):
    curves = read_csv(os.path.join(out, "curves_2d.csv"))
    acts = activations(curves)
    n = int(round(len(curves["x"]) ** 0.5))
    errors = {}
    for act in acts:
        for loss in ["fJ", "f"]:
            errors[act, loss] = [math.hypot(a - b, c - d) for a, b, c, d in zip(
                curves[f"{act}_{loss}_j1"], curves["true_j1"], curves[f"{act}_{loss}_j2"], curves["true_j2"])]
    everything = [e for errs in errors.values() for e in errs if e > 0]
    norm = LogNorm(vmin=max(min(everything), 1e-5), vmax=max(everything))
    fig, axes = plt.subplots(2, len(acts), figsize=(3.0 * len(acts) + 1.0, 6.2), squeeze=False,
                             layout="constrained")
    for col, act in enumerate(acts):
        for row, loss in enumerate(["fJ", "f"]):
            err = errors[act, loss]
            grid = [[max(e, norm.vmin) for e in err[i * n:(i + 1) * n]] for i in range(n)]
            mse = sum(e * e for e in err) / (2 * len(err))
            ax = axes[row][col]
            im = ax.imshow(grid, origin="lower", extent=[-math.pi, math.pi, -math.pi, math.pi],
                           cmap="viridis", norm=norm)
            ax.set_title(f"{act}, loss {'y + J' if loss == 'fJ' else 'y'}\nJ MSE {mse:.1e}", fontsize=9)
            ax.set_xticks([-3, 0, 3])
            ax.set_yticks([-3, 0, 3])
    fig.colorbar(im, ax=axes, fraction=0.025, label="|J error|")
    fig.suptitle("|J error| of f = cos x sin y on the 50 x 50 test grid")
    fig.savefig(os.path.join(out, "figure_2d_jacobian.png"), dpi=110)
    plt.close(fig)

    # f, df/dx and d2f/dx2 along the grid row nearest y = pi / 2.
    ys = curves["y"][::n]
    j = min(range(n), key=lambda k: abs(ys[k] - math.pi / 2))
    row = slice(j * n, (j + 1) * n)
    x = curves["x"][row]
    fig, axes = plt.subplots(3, len(acts), figsize=(3.4 * len(acts), 7), sharex=True, squeeze=False)
    for col, act in enumerate(acts):
        for r, (key, label) in enumerate(zip(["f", "j1", "h1"], ["f", "df/dx", "d²f/dx²"])):
            ax = axes[r][col]
            ax.plot(x, curves["true_" + key][row], "k-", lw=2, label="ground truth")
            ax.plot(x, curves[f"{act}_fJ_{key}"][row], "r-", lw=1.2, label="loss on f + J")
            ax.plot(x, curves[f"{act}_f_{key}"][row], "m--", lw=1.2, label="loss on f only")
            if col == 0:
                ax.set_ylabel(label)
        axes[0][col].set_title(act)
        axes[-1][col].set_xlabel("x")
    axes[0][0].legend(fontsize=7, loc="upper left")
    fig.suptitle(f"f = cos x sin y along y = {ys[j]:.3f}")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "figure_2d_slice.png"), dpi=110)
    plt.close(fig)


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else "."
    if len(sys.argv) > 2:
        merge(out, sys.argv[2:])
    if os.path.exists(os.path.join(out, "curves_1d.csv")):
        plot_1d(out)
    if os.path.exists(os.path.join(out, "curves_2d.csv")):
        plot_2d(out)
    print("plots written to", out)


if __name__ == "__main__":
    main()
