#!/usr/bin/env python3
"""The HJB value function's spread over the seeds of its network, as `diffdyn sweep` grids.

Trains `diffdyn hjb --system pendulum --seed S` for S = F .. F+N-1 (the figure's settings,
`diffdyn hjb`'s defaults, or with --rollout-stages K), runs each policy with `diffdyn control --controller hjb
--starts 300 --seed 1` (the figure's starts) and compares its per-start costs with the
multiple-shooting costs stored in results/starts.csv. Writes OUT/seeds.csv:

    seed, validation_successes, validation_mean_cost (diffdyn hjb's 40 validation starts,
    apart from the evaluation's), residual (last stage, held out), successes, mean_cost,
    mean_ratio (mean J / mean J_shooting over all starts), median_ratio, p90_ratio (of
    J / J_shooting over the starts with J_shooting >= 1; nearest rank, as the figure)

    seeds.py --diffdyn build/cli/diffdyn --out OUT [--seeds 10] [--first-seed 0]
             [--rollout-stages K] [--quick]
"""
import argparse
import csv
import json
import math
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def sweep(diffdyn, out, name, spec):
    (out / name).mkdir(parents=True, exist_ok=True)
    (out / name / "spec.json").write_text(json.dumps(spec, indent=1) + "\n")
    subprocess.run([str(diffdyn), "sweep", "--spec", f"{name}/spec.json", "--out", f"{name}/sweep", "--workers", "1",
                    "--quiet"], cwd=out, check=True)
    tasks = sorted((out / name / "sweep/tasks").iterdir(), key=lambda p: int(p.name))
    results = [json.loads((t / "result.json").read_text()) for t in tasks]
    if any(r["exit_code"] != 0 for r in results):
        sys.exit(f"error: {out / name}: a task failed (see {name}/sweep/tasks)")
    return tasks


def out_of(task):
    """The --out path the sweep gave a task (relative to the sweep's working folder)."""
    args = json.loads((task / "result.json").read_text())["args"]
    return args[args.index("--out") + 1]


def nearest_rank(values, p):
    values = sorted(values)
    return values[min(len(values) - 1, max(1, math.ceil(p * len(values))) - 1)]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--diffdyn", required=True, type=lambda p: Path(p).resolve())
    parser.add_argument("--out", required=True, type=lambda p: Path(p).resolve())
    parser.add_argument("--seeds", type=int, default=10, help="how many seeds")
    parser.add_argument("--first-seed", type=int, default=0, help="the first seed")
    parser.add_argument("--rollout-stages", type=int, help="diffdyn hjb --rollout-stages (default: its own)")
    parser.add_argument("--quick", action="store_true", help="one short stage per seed (checks the pipeline)")
    args = parser.parse_args()
    shooting = {int(r["start"]): float(r["cost"]) for r in csv.DictReader(open(HERE / "results/starts.csv"))
                if r["controller"] == "shooting"}

    trained = sweep(args.diffdyn, args.out, "hjb", {
        "command": "hjb", "options": {"--system": "pendulum", "--threads": 2, "--quiet": True,
                                      **({} if args.rollout_stages is None else
                                         {"--rollout-stages": args.rollout_stages}),
                                      **({"--stages": 1, "--polish-stages": 0, "--epochs": 1, "--samples": 1000,
                                           "--rollout-starts": 2, "--rollout-epochs": 1}
                                         if args.quick else {})},
        "grid": {"--seed": list(range(args.first_seed, args.first_seed + args.seeds))}})
    models = [str(args.out / out_of(t)) for t in trained]
    run = sweep(args.diffdyn, args.out, "control", {
        "command": "control", "options": {"--system": "pendulum", "--controller": "hjb", "--starts": 300,
                                          "--seed": 1, "--threads": 2, "--quiet": True},
        "grid": {"--model": models}})

    rows = []
    for seed, (t, c) in enumerate(zip(trained, run), start=args.first_seed):
        hjb = json.loads((t / "stdout.txt").read_text())
        validation = hjb["candidates"][0]
        starts = list(csv.DictReader(open(args.out / out_of(c) / "starts.csv")))
        cost = {int(r["start"]): float(r["cost"]) for r in starts}
        ratio = [cost[i] / shooting[i] for i in shooting if shooting[i] >= 1]
        mean = sum(cost.values()) / len(cost)
        rows.append([seed, validation["successes"], f"{validation['mean_cost']:.6g}", f"{hjb['final_residual']:.6g}",
                     sum(int(r["success"]) for r in starts), f"{mean:.6g}",
                     f"{mean / (sum(shooting.values()) / len(shooting)):.6g}", f"{nearest_rank(ratio, 0.5):.6g}",
                     f"{nearest_rank(ratio, 0.9):.6g}"])
    with open(args.out / "seeds.csv", "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["seed", "validation_successes", "validation_mean_cost", "residual", "successes", "mean_cost",
                    "mean_ratio", "median_ratio", "p90_ratio"])
        w.writerows(rows)
    print(f"{len(rows)} seeds in {args.out / 'seeds.csv'}")


if __name__ == "__main__":
    main()
