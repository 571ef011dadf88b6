#!/usr/bin/python3
"""Pictures of the ODE-engine pushing world (matplotlib, Agg backend).

  plot_pushing.py episode --poses P.csv --tip T.csv --arm A.csv --top top.png --side arm.png
      Top view of an episode (table, obstacle, goal, block poses, tip path) and a
      picture of the arm's configuration during a push (side and top projections).
  plot_pushing.py compare --ode ode.csv --pybullet pybullet.csv --out dist.png
      Overlays per-push |dx|, |dy|, |dtheta| distributions of two pushing CSVs, for all
      pushes and for the four classes push_length </>= 0.5 x |push_angle| </>= 0.75,
      and prints the ratios of means, medians and 90th percentiles.
Inputs are CSV files written by diffdyn; exit code 2 with one line on a bad input.
"""
import argparse
import csv
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Polygon, Rectangle  # noqa: E402

TABLE = (-0.25, -0.5, 1.5, 1.0)  # x0, y0, width, height of the table top
OBSTACLE = (0.55, -0.05, 0.1, 0.5)
BLOCK = 0.1


def fail(message):
    print(f"error: {message}", file=sys.stderr)
    sys.exit(2)


def read_rows(path, columns):
    if not os.path.isfile(path):
        fail(f"{path}: no such file")
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        missing = [c for c in columns if c not in (reader.fieldnames or [])]
        if missing:
            fail(f"{path}: missing columns {', '.join(missing)}")
        return list(reader)


def block_corners(x, y, theta):
    c, s, h = math.cos(theta), math.sin(theta), BLOCK / 2
    return [(x + c * px - s * py, y + s * px + c * py) for px, py in ((-h, -h), (h, -h), (h, h), (-h, h))]


def atomic_save(fig, path):
    tmp = os.path.join(os.path.dirname(os.path.abspath(path)), "." + os.path.basename(path) + ".tmp.png")
    fig.savefig(tmp, dpi=120, bbox_inches="tight")
    os.replace(tmp, path)
    plt.close(fig)


def episode(args):
    poses = read_rows(args.poses, ["step", "x", "y", "theta"])
    tip = read_rows(args.tip, ["step", "x", "y", "z"])
    arm = read_rows(args.arm, ["point", "x", "y", "z"])
    obstacle = args.obstacle == "on"

    fig, ax = plt.subplots(figsize=(7, 5))
    ax.add_patch(Rectangle(TABLE[:2], TABLE[2], TABLE[3], color="#e8dcc8", zorder=0, label="table"))
    if obstacle:
        ax.add_patch(Rectangle(OBSTACLE[:2], OBSTACLE[2], OBSTACLE[3], color="#555555", label="obstacle"))
    gx, gy = args.goal
    ax.add_patch(Polygon(block_corners(gx, gy, 0.0), fill=False, ls="--", ec="green", lw=1.5, label="goal"))
    n = len(poses)
    for i, r in enumerate(poses):
        x, y, t = float(r["x"]), float(r["y"]), float(r["theta"])
        ax.add_patch(Polygon(block_corners(x, y, t), alpha=0.25 + 0.6 * i / max(n - 1, 1), fc="tab:blue",
                             ec="navy", label="block" if i == 0 else None))
        ax.text(x, y, str(i), ha="center", va="center", fontsize=7, color="white")
    steps = sorted({int(r["step"]) for r in tip})
    for k in steps:
        pts = [(float(r["x"]), float(r["y"])) for r in tip if int(r["step"]) == k]
        ax.plot([p[0] for p in pts], [p[1] for p in pts], color="tab:red", lw=1.2,
                label="tip path" if k == steps[0] else None)
        ax.plot(pts[0][0], pts[0][1], "o", color="tab:red", ms=3)
    ax.plot(0, 0, "ks", ms=8, label="arm base")
    ax.set_xlim(-0.1, 1.1)
    ax.set_ylim(-0.5, 0.55)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("ODE-engine pushing episode, top view")
    ax.legend(loc="upper left", fontsize=7)
    atomic_save(fig, args.top)

    fig, (side, top) = plt.subplots(1, 2, figsize=(10, 4.5))
    xs, ys, zs = ([float(r[c]) for r in arm] for c in ("x", "y", "z"))
    for a, h, v, name in ((side, xs, zs, "z"), (top, xs, ys, "y")):
        a.plot(h, v, "-o", color="tab:orange", lw=3, ms=5, label="Panda joints (frames 1..7, flange, tip)")
        a.plot(h[-1], v[-1], "o", color="tab:red", ms=9, label="pusher tip")
        a.set_xlabel("x (m)")
        a.set_ylabel(f"{name} (m)")
        a.set_aspect("equal")
        a.grid(alpha=0.3)
    bx, by, bt = (float(poses[args.arm_step][c]) for c in ("x", "y", "theta"))
    side.add_patch(Rectangle((-0.3, -0.075), 1.5, 0.05, color="#e8dcc8", label="table"))
    side.add_patch(Rectangle((bx - 0.05, -0.025), 0.1, 0.05, color="tab:blue", alpha=0.6, label="block (x extent)"))
    top.add_patch(Polygon(block_corners(bx, by, bt), fc="tab:blue", alpha=0.6))
    if obstacle:
        top.add_patch(Rectangle(OBSTACLE[:2], OBSTACLE[2], OBSTACLE[3], color="#555555"))
    side.set_title("arm during a push (side, x-z)")
    top.set_title("arm during a push (top, x-y)")
    side.legend(loc="upper right", fontsize=7)
    atomic_save(fig, args.side)


def pushes(path):
    rows = read_rows(path, ["trajectory", "step", "x", "y", "theta", "push_length", "push_angle"])
    out = []
    for a, b in zip(rows, rows[1:]):
        if a["trajectory"] != b["trajectory"] or a["push_length"] == "":
            continue
        d = [abs(float(b[c]) - float(a[c])) for c in ("x", "y", "theta")]
        out.append((d, float(a["push_length"]), abs(float(a["push_angle"]))))
    if not out:
        fail(f"{path}: no pushes")
    return out


def quantile(v, p):
    v = sorted(v)
    i = p * (len(v) - 1)
    lo = int(i)
    hi = min(lo + 1, len(v) - 1)
    return v[lo] + (v[hi] - v[lo]) * (i - lo)


def compare(args):
    ode, pb = pushes(args.ode), pushes(args.pybullet)
    classes = [("all pushes", lambda L, A: True)]
    for short in (True, False):
        for small in (True, False):
            name = f"len{'<' if short else '>='}0.5, |ang|{'<' if small else '>='}0.75"
            classes.append((name, lambda L, A, s=short, m=small: (L < 0.5) == s and (A < 0.75) == m))
    names = ["|dx| (m)", "|dy| (m)", "|dtheta| (rad)"]
    fig, axes = plt.subplots(3, len(classes), figsize=(3.2 * len(classes), 8))
    print(f"{'class':<28}{'quantity':<16}{'ode':>10}{'pybullet':>10}{'ratio':>8}")
    for c, (cname, keep) in enumerate(classes):
        so = [p for p in ode if keep(p[1], p[2])]
        sp = [p for p in pb if keep(p[1], p[2])]
        for k in range(3):
            vo, vp = [p[0][k] for p in so], [p[0][k] for p in sp]
            ax = axes[k][c]
            top = quantile(vo + vp, 0.98)
            bins = [top * i / 30 for i in range(31)]
            ax.hist(vp, bins=bins, density=True, alpha=0.5, label=f"PyBullet (n={len(vp)})")
            ax.hist(vo, bins=bins, density=True, alpha=0.5, label=f"ODE (n={len(vo)})")
            if k == 0:
                ax.set_title(cname, fontsize=9)
            if c == 0:
                ax.set_ylabel(names[k])
            ax.tick_params(labelsize=7)
            stats = [("mean", sum(vo) / len(vo), sum(vp) / len(vp))] if c == 0 else []
            stats += [("median", quantile(vo, 0.5), quantile(vp, 0.5)), ("p90", quantile(vo, 0.9), quantile(vp, 0.9))]
            for sname, a, b in stats:
                print(f"{cname:<28}{names[k].split()[0] + ' ' + sname:<16}{a:>10.4f}{b:>10.4f}{a / b:>8.2f}")
            ax.legend(fontsize=6)
    fig.suptitle("Per-push block motion: ODE engine vs PyBullet (same uniform actions)")
    atomic_save(fig, args.out)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    e = sub.add_parser("episode")
    e.add_argument("--poses", required=True)
    e.add_argument("--tip", required=True)
    e.add_argument("--arm", required=True)
    e.add_argument("--arm-step", type=int, default=0, help="pose row the arm picture belongs to")
    e.add_argument("--obstacle", choices=["on", "off"], default="on")
    e.add_argument("--goal", type=float, nargs=2, default=[0.8, -0.1])
    e.add_argument("--top", required=True)
    e.add_argument("--side", required=True)
    c = sub.add_parser("compare")
    c.add_argument("--ode", required=True)
    c.add_argument("--pybullet", required=True)
    c.add_argument("--out", required=True)
    args = parser.parse_args()
    for out in [getattr(args, n) for n in ("top", "side", "out") if hasattr(args, n)]:
        if not os.path.isdir(os.path.dirname(os.path.abspath(out))):
            fail(f"{out}: directory does not exist")
    episode(args) if args.command == "episode" else compare(args)


if __name__ == "__main__":
    main()
