"""Plots of `diffdyn diagnose --model pushing`: the held-out one-step error per
state channel binned by push angle and by push location (nominal and calibrated
pusher), and the open-loop rollouts of held-out trajectories.

usage: diagnose_pushing.py replays.csv rollouts.csv OUT_DIR
writes OUT_DIR/error_by_push.png and OUT_DIR/rollouts.png
"""
import math
import os
import sys

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

CHANNELS = (("x", "x (mm)", 1000.0), ("y", "y (mm)", 1000.0), ("theta", "θ (mrad)", 1000.0))
COLORS = {"nominal": "tab:red", "calibrated": "tab:blue", "measured": "k"}


def read(path):
    data = np.genfromtxt(path, delimiter=",", names=True)
    return np.atleast_1d(data)


def binned_rmse(u, err, edges):
    out = []
    for k in range(len(edges) - 1):
        last = k == len(edges) - 2
        sel = (u >= edges[k]) & ((u <= edges[k + 1]) if last else (u < edges[k + 1]))
        out.append(math.sqrt(np.mean(err[sel] ** 2)) if sel.any() else float("nan"))
    return np.array(out)


def error_by_push(r, out_dir):
    bins = (("push_angle", "push angle (rad)", np.linspace(-math.pi / 2, math.pi / 2, 7)),
            ("push_location", "push location", np.linspace(-1, 1, 7)))
    fig, axes = plt.subplots(2, 3, figsize=(11, 6))
    for row, (key, label, edges) in enumerate(bins):
        centres = 0.5 * (edges[:-1] + edges[1:])
        width = 0.35 * (edges[1] - edges[0])
        for col, (ch, title, scale) in enumerate(CHANNELS):
            ax = axes[row, col]
            for off, model in ((-0.5, "nominal"), (0.5, "calibrated")):
                err = (r[f"{model}_{ch}"] - r[f"measured_{ch}"]) * scale
                ax.bar(centres + off * width, binned_rmse(r[key], err, edges), width, color=COLORS[model],
                       label=model)
            ax.set_xlabel(label)
            ax.set_ylabel(f"RMSE {title}")
            if row == 0 and col == 0:
                ax.legend(fontsize=8)
    fig.suptitle(f"One-step error of the pusher on {len(r)} held-out measured pushes")
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "error_by_push.png"), dpi=110)
    plt.close(fig)


def rollouts(ro, out_dir):
    ids = np.unique(ro["rollout"]).astype(int)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8))
    ax = axes[0]
    for n, k in enumerate(ids[:6]):
        sel = ro["rollout"] == k
        for model in ("measured", "nominal", "calibrated"):
            ax.plot(ro[f"{model}_x"][sel], ro[f"{model}_y"][sel], ".-", ms=3, lw=1, color=COLORS[model],
                    label=model if n == 0 else None)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("held-out trajectories, open loop from the first pose")
    ax.legend(fontsize=8)
    ax = axes[1]
    steps = np.unique(ro["step"]).astype(int)
    for model in ("nominal", "calibrated"):
        err = np.hypot(ro[f"{model}_x"] - ro["measured_x"], ro[f"{model}_y"] - ro["measured_y"]) * 1000
        ax.plot(steps, [err[ro["step"] == s].mean() for s in steps], "o-", color=COLORS[model], label=model)
    ax.set_xlabel("push")
    ax.set_ylabel("mean position error (mm)")
    ax.set_title(f"rollout error over {len(ids)} held-out trajectories")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "rollouts.png"), dpi=110)
    plt.close(fig)


def main(replays_path, rollouts_path, out_dir):
    error_by_push(read(replays_path), out_dir)
    rollouts(read(rollouts_path), out_dir)


if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    main(*sys.argv[1:])
