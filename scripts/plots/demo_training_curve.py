#!/usr/bin/python3
"""Training and validation loss per epoch of the demo's NeuralODE.

usage: demo_training_curve.py training.csv out.png
"""
import csv
import math
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main(csv_path, png_path):
    epochs, train, val = [], [], []
    with open(csv_path, newline="") as f:
        for r in csv.DictReader(f):
            epochs.append(int(r["epoch"]))
            train.append(float(r["train_loss"]))
            val.append(float(r["val_loss"]))
    if not epochs:
        print(f"error: {csv_path}: no epochs", file=sys.stderr)
        sys.exit(2)
    fig, ax = plt.subplots(figsize=(6.5, 4))
    ax.semilogy(epochs, train, label="training (mean over batches)")
    if any(math.isfinite(v) for v in val):
        ax.semilogy(epochs, val, label="validation")
    ax.set_xlabel("epoch")
    ax.set_ylabel("SE(2) pose loss")
    ax.set_title("abs-node (rk4, 10 points, hidden 100)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        print("usage: demo_training_curve.py training.csv out.png", file=sys.stderr)
        sys.exit(2)
    main(sys.argv[1], sys.argv[2])
