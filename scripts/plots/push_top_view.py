#!/usr/bin/python3
"""Top view of one pushing trial written by `diffdyn push --out DIR`.

usage: push_top_view.py trials.csv out.png --trial I --goal GX GY [--tolerance R] [--obstacle 0|1]

Draws the table area, the obstacle rectangle, the goal circle of radius R, the block
as a rotated square at each step (light to dark), the centre path, and labels the
start and the end. Exit code 2 with one line on a bad input.
"""
import argparse
import csv
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Circle, Polygon, Rectangle  # noqa: E402

TABLE = (-0.25, -0.5, 1.5, 1.0)  # x0, y0, width, height of the table top
OBSTACLE = (0.55, -0.05, 0.1, 0.5)  # x0, y0, width, height
BLOCK = 0.1


def fail(message):
    print(f"error: {message}", file=sys.stderr)
    sys.exit(2)


def read_trial(path, trial):
    if not os.path.isfile(path):
        fail(f"{path}: no such file")
    poses, outcome = [], ""
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        need = ["trial", "step", "x", "y", "theta", "outcome"]
        missing = [c for c in need if c not in (reader.fieldnames or [])]
        if missing:
            fail(f"{path}: missing columns {', '.join(missing)}")
        for line, row in enumerate(reader, start=2):
            try:
                if int(row["trial"]) != trial:
                    continue
                poses.append((float(row["x"]), float(row["y"]), float(row["theta"])))
            except ValueError:
                fail(f"{path}:{line}: not a number")
            outcome = row["outcome"]
    if not poses:
        fail(f"{path}: no rows of trial {trial}")
    return poses, outcome


def block_corners(x, y, theta):
    c, s = math.cos(theta), math.sin(theta)
    h = BLOCK / 2
    return [(x + c * dx - s * dy, y + s * dx + c * dy) for dx, dy in ((-h, -h), (h, -h), (h, h), (-h, h))]


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("csv")
    parser.add_argument("png")
    parser.add_argument("--trial", type=int, default=0)
    parser.add_argument("--goal", type=float, nargs=2, required=True)
    parser.add_argument("--tolerance", type=float, default=0.1)
    parser.add_argument("--obstacle", type=int, default=1)
    args = parser.parse_args()
    poses, outcome = read_trial(args.csv, args.trial)

    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    ax.add_patch(Rectangle(TABLE[:2], TABLE[2], TABLE[3], color="0.93", zorder=0, label="table"))
    if args.obstacle:
        ax.add_patch(Rectangle(OBSTACLE[:2], OBSTACLE[2], OBSTACLE[3], color="tab:red", alpha=0.6,
                               label="obstacle"))
    ax.add_patch(Circle(args.goal, args.tolerance, fill=False, ls="--", lw=1.5, color="tab:green",
                        label=f"goal ({args.tolerance:g} m)"))
    ax.plot(*args.goal, "+", color="tab:green", ms=10)
    n = len(poses)
    for k, (x, y, th) in enumerate(poses):
        shade = 0.25 + 0.75 * k / max(1, n - 1)
        ax.add_patch(Polygon(block_corners(x, y, th), closed=True, fill=False,
                             ec=plt.cm.Blues(shade), lw=1.2))
    xs, ys = [p[0] for p in poses], [p[1] for p in poses]
    ax.plot(xs, ys, ".-", color="tab:blue", lw=1, ms=4, label="block centre")
    ax.annotate("start", (xs[0], ys[0]), xytext=(-10, -22), textcoords="offset points")
    ax.annotate(f"end ({n - 1} pushes)", (xs[-1], ys[-1]), xytext=(8, 12), textcoords="offset points")
    ax.set_xlim(0.2, 1.05)
    ax.set_ylim(-0.4, 0.35)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"trial {args.trial}: {outcome}")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(args.png, dpi=110)


if __name__ == "__main__":
    main()
