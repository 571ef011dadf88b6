#!/usr/bin/env python3
"""The HJB policy's excess cost over multiple shooting, per start, from results/starts.csv.

Writes results/excess.csv: start, theta0, cost_hjb, cost_shooting, excess (cost_hjb -
cost_shooting) and rank (1 for the largest excess), one row per start, in start order.
The README's "Where it loses" numbers are read from it.

    /usr/bin/python3 paper_figures/hjb_pendulum/excess.py
"""
import csv
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


def main():
    with open(RESULTS / "starts.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    cost = {(r["controller"], int(r["start"])): float(r["cost"]) for r in rows}
    theta0 = {int(r["start"]): r["theta0"] for r in rows if r["controller"] == "hjb"}
    starts = sorted(theta0)
    excess = {s: cost["hjb", s] - cost["shooting", s] for s in starts}
    rank = {s: k + 1 for k, s in enumerate(sorted(starts, key=lambda s: -excess[s]))}
    with open(RESULTS / "excess.csv", "w", newline="") as f:
        out = csv.writer(f, lineterminator="\n")
        out.writerow(["start", "theta0", "cost_hjb", "cost_shooting", "excess", "rank"])
        for s in starts:
            out.writerow([s, theta0[s], f"{cost['hjb', s]:.6g}", f"{cost['shooting', s]:.6g}", f"{excess[s]:.6g}",
                          rank[s]])


if __name__ == "__main__":
    main()
