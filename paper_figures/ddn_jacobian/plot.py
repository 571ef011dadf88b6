#!/usr/bin/env python3
"""Plots for the DDN Figure-2 experiment, from the CSVs of figure_ddn_jacobian.

    /usr/bin/python3 paper_figures/ddn_jacobian/plot.py OUT_DIR

Writes into OUT_DIR:
  figure_1d_<activation>.png  three stacked panels y, dy/dx, d2y/dx2 like the
                              authors' figures: truth black, noisy samples grey,
                              f+J loss red, f-only loss magenta;
  figure_2d_jacobian.png      |J error| over the 2-D grid per activation and loss.
"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read_csv(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    return {k: [float(r[k]) for r in rows] for k in rows[0]}


def activations(columns):
    acts = []
    for name in columns:
        if name.endswith("_fJ_f"):
            acts.append(name[: -len("_fJ_f")])
    return acts


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
    fig, axes = plt.subplots(2, len(acts), figsize=(3.2 * len(acts), 6), squeeze=False)
    for col, act in enumerate(acts):
        for row, loss in enumerate(["fJ", "f"]):
            err = [((a - b) ** 2 + (c - d) ** 2) ** 0.5 for a, b, c, d in zip(
                curves[f"{act}_{loss}_j1"], curves["true_j1"], curves[f"{act}_{loss}_j2"], curves["true_j2"])]
            grid = [err[i * n:(i + 1) * n] for i in range(n)]
            ax = axes[row][col]
            im = ax.imshow(grid, origin="lower", extent=[-3.1416, 3.1416, -3.1416, 3.1416], cmap="viridis")
            ax.set_title(f"{act}, loss {'y + J' if loss == 'fJ' else 'y'}", fontsize=9)
            fig.colorbar(im, ax=ax, fraction=0.046)
    fig.suptitle("|J error| of f = cos x sin y")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "figure_2d_jacobian.png"), dpi=110)
    plt.close(fig)


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else "."
    if os.path.exists(os.path.join(out, "curves_1d.csv")):
        plot_1d(out)
    if os.path.exists(os.path.join(out, "curves_2d.csv")):
        plot_2d(out)
    print("plots written to", out)


if __name__ == "__main__":
    main()
