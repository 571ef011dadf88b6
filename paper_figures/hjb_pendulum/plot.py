#!/usr/bin/env python3
"""Draws hjb_pendulum.png from the CSVs of main.cc: the value function V and the policy
u* over (theta, theta_dot) at three stages of the discount homotopy; phase-plane
trajectories of the HJB policy, multiple shooting and the clipped LQR from the same
starts; the residual per stage; the cost distributions; and the HJB cost against the
shooting cost per start. Usage: plot.py OUT_DIR"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

COLORS = {"hjb": "tab:blue", "shooting": "tab:green", "lqr": "tab:red"}


def read(out, name):
    with open(os.path.join(out, name)) as f:
        return list(csv.DictReader(f))


def grid_of(rows, stage, key):
    sel = [r for r in rows if int(r["stage"]) == stage]
    th = sorted({float(r["theta"]) for r in sel})
    td = sorted({float(r["theta_dot"]) for r in sel})
    z = np.zeros((len(td), len(th)))
    for r in sel:
        z[td.index(float(r["theta_dot"])), th.index(float(r["theta"]))] = float(r[key])
    return np.array(th), np.array(td), z, float(sel[0]["rho"])


def main():
    out = sys.argv[1]
    grid, stages = read(out, "grid.csv"), read(out, "stages.csv")
    starts, traj, summary = read(out, "starts.csv"), read(out, "trajectories.csv"), read(out, "summary.csv")
    n = len(stages)
    shown = sorted({1, (n + 1) // 2, n})
    fig, axes = plt.subplots(3, 4, figsize=(17, 11.5))
    for col, stage in enumerate(shown[:3]):
        for row, (key, cmap, label) in enumerate((("value", "viridis", "V"), ("action", "coolwarm", "u* (N m)"))):
            th, td, z, rho = grid_of(grid, stage, key)
            ax = axes[row][col]
            kw = dict(vmin=-2.5, vmax=2.5) if key == "action" else {}
            im = ax.pcolormesh(th, td, z, cmap=cmap, shading="auto", **kw)
            fig.colorbar(im, ax=ax, label=label)
            ax.set_title(f"{label} after stage {stage}/{n}, rho = {rho:.3g} 1/s", fontsize=9)
            ax.set_xlabel("theta (rad, 0 upright)")
            ax.set_ylabel("theta_dot (rad/s)")
    for col, name in enumerate(("hjb", "shooting", "lqr")):
        ax = axes[2][col]
        for s in sorted({r["start"] for r in traj if r["controller"] == name}, key=int):
            pts = [r for r in traj if r["controller"] == name and r["start"] == s]
            th = np.unwrap([float(r["theta"]) for r in pts])
            ax.plot(th, [float(r["theta_dot"]) for r in pts], lw=0.8, color=COLORS[name], alpha=0.8)
            ax.plot(th[0], float(pts[0]["theta_dot"]), "k.", ms=3)
        row = next(r for r in summary if r["controller"] == name)
        ax.set_title(f"{name}: {row['successes']}/{row['starts']} swung up, mean cost "
                     f"{float(row['mean_cost']):.2f} (every 10th start)", fontsize=9)
        ax.set_xlabel("theta (rad, unwrapped)")
        ax.set_ylabel("theta_dot (rad/s)")
    ax = axes[0][3]
    ax.semilogy([int(r["stage"]) for r in stages], [float(r["residual"]) for r in stages], "o-")
    for r in stages:
        ax.annotate(f"{float(r['rho']):.3g}", (int(r["stage"]), float(r["residual"])), fontsize=7)
    ax.set_xlabel("stage (labels: rho)")
    ax.set_ylabel("mean squared HJB residual (held out)")
    ax.set_title("residual along the homotopy", fontsize=9)
    ax = axes[1][3]
    names = [s for s in ("hjb", "shooting", "lqr") if any(r["controller"] == s for r in starts)]
    data = [[float(r["cost"]) for r in starts if r["controller"] == s] for s in names]
    ax.boxplot(data, labels=names, showmeans=True)
    ax.set_yscale("log")
    ax.set_ylabel("cost over 5 s")
    ax.set_title("cost per start (triangle: mean)", fontsize=9)
    ax = axes[2][3]
    cost = {s: [float(r["cost"]) for r in starts if r["controller"] == s] for s in names}
    if "shooting" in cost and "hjb" in cost:
        ax.loglog(cost["shooting"], cost["hjb"], ".", color=COLORS["hjb"], ms=4)
        lim = [min(cost["shooting"] + cost["hjb"]), max(cost["shooting"] + cost["hjb"])]
        ax.plot(lim, lim, "k--", lw=0.8, label="equal")
        ax.plot(lim, [1.05 * v for v in lim], "k:", lw=0.8, label="+5 %")
        ax.legend(fontsize=8)
        row = next(r for r in summary if r["controller"] == "hjb")
        ax.set_title(f"J_hjb / J_shooting: mean {float(row['mean_ratio']):.3f}, median "
                     f"{float(row['median_ratio']):.3f}, p90 {float(row['p90_ratio']):.3f}", fontsize=9)
    ax.set_xlabel("shooting cost")
    ax.set_ylabel("HJB policy cost")
    fig.suptitle("Pendulum swing-up: HJB value function by residual minimisation with a discount homotopy "
                 "(DDN paper Fig. 4)")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "hjb_pendulum.png"), dpi=100)
    print("wrote", os.path.join(out, "hjb_pendulum.png"))


if __name__ == "__main__":
    main()
