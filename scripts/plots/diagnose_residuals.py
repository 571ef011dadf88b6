"""Residual plots of `diffdyn diagnose`: torque residual against velocity per
joint (nominal and extended model) and the residual in time.

usage: diagnose_residuals.py residuals.csv OUT_DIR N_JOINTS
"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main(csv_path, out_dir, n):
    n = int(n)
    cols = {}
    with open(csv_path, newline="") as f:
        reader = csv.DictReader(f)
        for key in reader.fieldnames:
            cols[key] = []
        for row in reader:
            for key, value in row.items():
                cols[key].append(float(value))
    held = [h > 0.5 for h in cols["heldout"]]

    fig, axes = plt.subplots(n, 2, figsize=(9, 2.3 * n), squeeze=False, sharex="row")
    for j in range(1, n + 1):
        qd = cols[f"qd{j}"]
        for c, (key, title) in enumerate(((f"res_nominal{j}", "nominal"), (f"res_extended{j}", "extended"))):
            ax = axes[j - 1, c]
            r = cols[key]
            ax.plot([v for v, h in zip(qd, held) if not h], [x for x, h in zip(r, held) if not h], ".",
                    ms=2, color="0.6", label="train")
            ax.plot([v for v, h in zip(qd, held) if h], [x for x, h in zip(r, held) if h], ".",
                    ms=2, color="tab:red", label="held out")
            ax.axhline(0, color="k", lw=0.5)
            ax.set_ylabel(f"residual {j}")
            if j == 1:
                ax.set_title(f"{title} model")
            if j == n:
                ax.set_xlabel("velocity qd")
    axes[0, 0].legend(loc="best", fontsize=7)
    fig.suptitle("Torque residual (measured - model) against joint velocity")
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "residual_vs_velocity.png"), dpi=100)
    plt.close(fig)

    fig, axes = plt.subplots(n, 1, figsize=(9, 1.8 * n), squeeze=False, sharex=True)
    for j in range(1, n + 1):
        ax = axes[j - 1, 0]
        ax.plot(cols["t"], cols[f"res_nominal{j}"], lw=0.6, color="tab:orange", label="nominal")
        ax.plot(cols["t"], cols[f"res_extended{j}"], lw=0.6, color="tab:blue", label="extended")
        ax.set_ylabel(f"r{j}")
    axes[0, 0].legend(loc="upper right", fontsize=7)
    axes[-1, 0].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "residual_time.png"), dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    main(*sys.argv[1:4])
