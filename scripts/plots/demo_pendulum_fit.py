"""Plots measured pendulum angles with the initial-guess and fitted predictions.

usage: demo_pendulum_fit.py pendulum_fit.csv out.png
"""
import csv
import sys
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main(csv_path, png_path):
    rows = defaultdict(lambda: defaultdict(list))
    with open(csv_path, newline="") as f:
        for r in csv.DictReader(f):
            traj = rows[int(r["trajectory"])]
            for key in ("t", "q_measured", "q_initial", "q_fitted"):
                traj[key].append(float(r[key]))
    n = len(rows)
    fig, axes = plt.subplots(n, 1, figsize=(8, 2.2 * n), sharex=True, squeeze=False)
    for ax, (k, traj) in zip(axes[:, 0], sorted(rows.items())):
        ax.plot(traj["t"], traj["q_measured"], ".", ms=3, color="0.4", label="measured")
        ax.plot(traj["t"], traj["q_initial"], "--", color="tab:orange", label="initial guess")
        ax.plot(traj["t"], traj["q_fitted"], "-", color="tab:blue", label="fitted")
        ax.set_ylabel(f"q [rad] (traj {k})")
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("t [s]")
    fig.suptitle("Damped pendulum: fit of g and b through dopri5 on Jets")
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)


if __name__ == "__main__":
    main(*sys.argv[1:3])
