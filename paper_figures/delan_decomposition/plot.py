#!/usr/bin/env python3
"""Draws the figures of main.cc found in OUT_DIR.

decomposition.png (from timeseries.csv): for each joint, the torque and its parts
H qdd, c, g over the test characters e, q, v; ground truth, DeLaN (trained on torques
alone) and the feed-forward network's parts by the test-time trick.

cartpole_decomposition.png (from cartpole_timeseries.csv): the same for the cart-pole
swing-up, with friction, and the kinetic and potential energy and the power; DeLaN
trained with both joints excited and with only the cart pushed.

Usage: plot.py OUT_DIR"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt


def characters(out):
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


def cartpole(out):
    with open(os.path.join(out, "cartpole_timeseries.csv")) as f:
        rows = list(csv.DictReader(f))
    t = [float(r["t"]) for r in rows]
    col = lambda key: [float(r[key]) if r[key] != "" else float("nan") for r in rows]
    styles = (("true", dict(color="black", lw=2.0), "ground truth"),
              ("full", dict(color="tab:blue", lw=1.2), "DeLaN, both joints excited"),
              ("under", dict(color="tab:green", lw=1.0, ls="-."), "DeLaN, cart pushed only"),
              ("ff", dict(color="tab:orange", lw=1.0, ls="--"), "feed-forward (c holds friction)"))
    parts = [("tau", "torque tau"), ("m", "inertial H qdd"), ("c", "Coriolis, centrifugal c"),
             ("g", "gravity g"), ("f", "friction f")]
    units = ("N", "N m")
    fig, axes = plt.subplots(len(parts) + 1, 3, figsize=(14, 15), squeeze=False)
    for i, (q, title) in enumerate(parts):
        for j in (0, 1):
            ax = axes[i][j]
            for who, style, label in styles:
                key = f"{q}{j + 1}_{who}"
                if key in rows[0] and rows[0][key] != "":
                    ax.plot(t, col(key), label=label, **style)
            ax.set_title(f"{title}, {'cart' if j == 0 else 'pole'}", fontsize=9)
            ax.set_ylabel(units[j], fontsize=8)
            ax.tick_params(labelsize=7)
        axes[i][2].axis("off")
    for k, (e, title, unit) in enumerate((("T", "kinetic energy T", "J"), ("V", "potential energy V (offset-matched)", "J"),
                                          ("P", "power qd^T tau", "W"))):
        ax = axes[len(parts)][k]
        for who, style, label in styles[:3]:
            ax.plot(t, col(f"{e}_{who}"), label=label, **style)
        ax.set_title(title, fontsize=9)
        ax.set_ylabel(unit, fontsize=8)
        ax.set_xlabel("t (s)", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0][0].legend(fontsize=7)
    fig.suptitle("DeLaN with friction on the cart-pole swing-up, learned from torques alone (DDN paper Fig. 3b)")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "cartpole_decomposition.png"), dpi=100)
    print("wrote", os.path.join(out, "cartpole_decomposition.png"))


def main():
    out = sys.argv[1]
    if os.path.exists(os.path.join(out, "timeseries.csv")):
        characters(out)
    if os.path.exists(os.path.join(out, "cartpole_timeseries.csv")):
        cartpole(out)


if __name__ == "__main__":
    main()
