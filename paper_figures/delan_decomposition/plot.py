#!/usr/bin/env python3
"""Draws decomposition.png from timeseries.csv (main.cc): for each joint, the torque
and its parts H qdd, c, g over the test characters e, q, v; ground truth, DeLaN
(trained on torques alone) and the feed-forward network's parts by the test-time
trick. Usage: plot.py OUT_DIR"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt


def main():
    out = sys.argv[1]
    with open(os.path.join(out, "timeseries.csv")) as f:
        rows = list(csv.DictReader(f))
    x = [int(r["sample"]) for r in rows]
    quantities = [("tau", "torque tau"), ("m", "inertial H qdd"), ("c", "Coriolis, centrifugal c"),
                  ("g", "gravity g")]
    joints = sorted({int(k.split("_")[0][3:]) for k in rows[0] if k.startswith("tau")})
    fig, axes = plt.subplots(len(quantities), len(joints), figsize=(11, 9), sharex=True, squeeze=False)
    for i, (q, title) in enumerate(quantities):
        for j, joint in enumerate(joints):
            ax = axes[i][j]
            for who, style, label in (("true", dict(color="black", lw=2.0), "ground truth"),
                                      ("delan", dict(color="tab:blue", lw=1.2), "DeLaN"),
                                      ("ff", dict(color="tab:orange", lw=1.0, ls="--"), "feed-forward")):
                ax.plot(x, [float(r[f"{q}{joint}_{who}"]) for r in rows], label=label, **style)
            ax.set_title(f"{title}, joint {joint}", fontsize=9)
            ax.set_ylabel("N m", fontsize=8)
            ax.tick_params(labelsize=7)
    axes[-1][0].set_xlabel("test sample (characters e, q, v, 0.04 s apart)")
    axes[-1][-1].set_xlabel("test sample (characters e, q, v, 0.04 s apart)")
    axes[0][0].legend(fontsize=8)
    fig.suptitle("DeLaN force decomposition learned from torques alone (DDN paper Fig. 3a, 2-link characters)")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "decomposition.png"), dpi=110)
    print("wrote", os.path.join(out, "decomposition.png"))


if __name__ == "__main__":
    main()
