#!/usr/bin/env python3
"""Plots of paper_figures/mppi_obstacle: reads results.csv and trials.csv of one or
more output folders (rows are merged in the order given) and writes, into the first:

  success_rates.png   success rate per model with its Wilson 95 % interval
  pushes_<model>.png  top view of one successful trial per model (table, obstacle,
                      goal circle, the block's square after every push)

    /usr/bin/python3 paper_figures/mppi_obstacle/plot.py OUT [MORE_OUT ...]
"""
import csv
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Circle, Polygon, Rectangle  # noqa: E402

BLOCK = 0.1
OBSTACLE = (0.6, 0.2, 0.05, 0.25)  # centre x, y, half sizes
GOAL_TOLERANCE = 0.1


def read(folders, name):
    rows = []
    for folder in folders:
        path = os.path.join(folder, name)
        if os.path.exists(path):
            rows += list(csv.DictReader(open(path)))
    return rows


def bar_chart(results, out):
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    names = [r["model"] for r in results]
    rate = [100 * float(r["rate"]) for r in results]
    low = [100 * (float(r["rate"]) - float(r["ci95_low"])) for r in results]
    high = [100 * (float(r["ci95_high"]) - float(r["rate"])) for r in results]
    colors = ["tab:gray" if n == "oracle" else "tab:blue" for n in names]
    ax.bar(names, rate, yerr=[low, high], capsize=5, color=colors)
    for i, r in enumerate(results):
        ax.text(i, 2, f"{r['successes']}/{r['trials']}", ha="center", color="white", fontsize=9)
    ax.axhline(95, color="tab:red", lw=1, ls="--", label="paper: abs-NODE 95+%")
    ax.set_ylim(0, 105)
    ax.set_ylabel("success rate (%)")
    ax.set_title("Obstacle task: MPPI success, Wilson 95 % intervals")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)


def block_polygon(x, y, theta, **kw):
    h = BLOCK / 2
    c, s = math.cos(theta), math.sin(theta)
    corners = [(x + c * a - s * b, y + s * a + c * b) for a, b in ((-h, -h), (h, -h), (h, h), (-h, h))]
    return Polygon(corners, closed=True, **kw)


def top_view(model, trial_rows, out):
    fig, ax = plt.subplots(figsize=(5, 5))
    ax.add_patch(Rectangle((0.2, -0.5), 0.8, 1.0, color="wheat", alpha=0.4, label="table (part)"))
    ox, oy, hx, hy = OBSTACLE
    ax.add_patch(Rectangle((ox - hx, oy - hy), 2 * hx, 2 * hy, color="dimgray", label="obstacle"))
    gx, gy = float(trial_rows[0]["goal_x"]), float(trial_rows[0]["goal_y"])
    ax.add_patch(Circle((gx, gy), GOAL_TOLERANCE, fill=False, color="tab:green", lw=2, label="goal"))
    n = len(trial_rows)
    for k, r in enumerate(trial_rows):
        color = plt.cm.viridis(k / max(n - 1, 1))
        ax.add_patch(block_polygon(float(r["x"]), float(r["y"]), float(r["theta"]),
                                   fill=False, ec=color, lw=1.5))
    ax.plot([float(r["x"]) for r in trial_rows], [float(r["y"]) for r in trial_rows], "k.:", lw=1)
    ax.set_xlim(0.2, 1.0)
    ax.set_ylim(-0.4, 0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{model}: {n - 1} pushes, {trial_rows[0]['outcome']}")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)


def main():
    folders = sys.argv[1:]
    if not folders:
        sys.exit("usage: plot.py OUT [MORE_OUT ...]")
    results = read(folders, "results.csv")
    if not results:
        sys.exit(f"error: no results.csv in {', '.join(folders)}")
    bar_chart(results, os.path.join(folders[0], "success_rates.png"))
    trials = read(folders, "trials.csv")
    for model in [r["model"] for r in results]:
        runs = {}
        for r in trials:
            if r["model"] == model:
                runs.setdefault(r["trial"], []).append(r)
        chosen = next((rows for rows in runs.values() if rows[0]["outcome"] == "success"), None)
        if chosen is None and runs:
            chosen = next(iter(runs.values()))  # no success: show the first trial
        if chosen:
            top_view(model, chosen, os.path.join(folders[0], f"pushes_{model}.png"))


if __name__ == "__main__":
    main()
