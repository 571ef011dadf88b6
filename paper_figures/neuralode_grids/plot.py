#!/usr/bin/env python3
"""Draws the NeuralODE-Panda grid figures from the CSVs of figure_neuralode_grids.

    /usr/bin/python3 paper_figures/neuralode_grids/plot.py OUT_DIR

grid_single.csv -> fig2_3_single_step.png: validation loss over (grid points, hidden)
for each model and solver (the paper's Figs. 2 and 3), log colour scale.
grid_multi.csv  -> fig4_multi_step.png: the absolute NeuralODE's multi-step grid (rk4).
grid_compare.csv -> fig5_compare.png: the four models' single-step and average
multi-step validation losses next to the paper's Fig. 5 numbers.
"""
import csv
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.colors as mcolors  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402

PAPER_FIG5 = {"abs-nn": (1.2111e-4, 3.5197e-4), "res-nn": (7.0892e-5, 2.1715e-4),
              "abs-node": (5.6478e-5, 1.9284e-4), "res-node": (6.9874e-5, 2.3695e-4)}


def rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def heat(ax, data, title, norm):
    steps = sorted({int(r["steps"]) for r in data})
    hidden = sorted({int(r["hidden"]) for r in data})
    grid = [[math.nan] * len(steps) for _ in hidden]
    for r in data:
        v = float(r["val_loss"])
        grid[hidden.index(int(r["hidden"]))][steps.index(int(r["steps"]))] = v if r["diverged"] == "0" else math.nan
    im = ax.imshow(grid, origin="lower", norm=norm, cmap="viridis_r", aspect="auto")
    ax.set_xticks(range(len(steps)), [str(s) for s in steps])
    ax.set_yticks(range(len(hidden)), [str(h) for h in hidden])
    ax.set_xlabel("grid points (steps)")
    ax.set_ylabel("hidden width")
    ax.set_title(title, fontsize=9)
    for i, row in enumerate(grid):
        for j, v in enumerate(row):
            ax.text(j, i, "div." if math.isnan(v) else f"{v:.1e}", ha="center", va="center",
                    fontsize=7, color="w")
    return im


def finite_range(data):
    vals = [float(r["val_loss"]) for r in data if r["diverged"] == "0" and float(r["val_loss"]) > 0]
    return (min(vals), max(vals)) if vals else (1e-5, 1.0)


def main(out):
    single_path = os.path.join(out, "grid_single.csv")
    if os.path.exists(single_path):
        data = rows(single_path)
        lo, hi = finite_range(data)
        norm = mcolors.LogNorm(lo, hi)
        models = sorted({r["model"] for r in data})
        solvers = ["dopri5", "rk4"]
        fig, axes = plt.subplots(len(models), 2, figsize=(9, 3.6 * len(models)), squeeze=False)
        for i, m in enumerate(models):
            for j, s in enumerate(solvers):
                sub = [r for r in data if r["model"] == m and r["solver"] == s]
                if sub:
                    im = heat(axes[i][j], sub, f"{m}, {s}: validation single-step loss", norm)
        fig.colorbar(im, ax=axes, shrink=0.6, label="validation loss")
        fig.savefig(os.path.join(out, "fig2_3_single_step.png"), dpi=120)
    multi_path = os.path.join(out, "grid_multi.csv")
    if os.path.exists(multi_path):
        data = rows(multi_path)
        lo, hi = finite_range(data)
        fig, ax = plt.subplots(figsize=(5.5, 4.2))
        im = heat(ax, data, "abs-node, rk4: validation multi-step loss (gamma 0.9)", mcolors.LogNorm(lo, hi))
        fig.colorbar(im, ax=ax, label="validation loss")
        fig.tight_layout()
        fig.savefig(os.path.join(out, "fig4_multi_step.png"), dpi=120)
    compare_path = os.path.join(out, "grid_compare.csv")
    if os.path.exists(compare_path):
        data = rows(compare_path)
        names = [r["model"] for r in data]
        fig, axes = plt.subplots(1, 2, figsize=(10, 4))
        for k, (col, label) in enumerate([("eval_single", "single-step loss"),
                                          ("eval_avg_multi", "average multi-step loss")]):
            ax = axes[k]
            xs = range(len(names))
            ax.bar([x - 0.2 for x in xs], [float(r[col]) for r in data], 0.4, label="ours")
            ax.bar([x + 0.2 for x in xs], [PAPER_FIG5[n][k] for n in names], 0.4, label="paper (Fig. 5)")
            ax.set_xticks(list(xs), names)
            ax.set_yscale("log")
            ax.set_title(label)
            ax.legend()
        fig.tight_layout()
        fig.savefig(os.path.join(out, "fig5_compare.png"), dpi=120)


if __name__ == "__main__":
    main(sys.argv[1])
