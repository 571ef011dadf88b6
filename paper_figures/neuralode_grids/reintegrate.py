#!/usr/bin/env python3
"""Re-integrates trained NeuralODE fields with other solvers and grids.

Trains the grid's NeuralODE cells (seed 1, 100 epochs, rk4) with `diffdyn train`
and evaluates each trained field with `diffdyn eval --solver S [--steps N]` over
every transition of the file it was trained on, both steps as `diffdyn sweep`
grids. Writes OUT/reintegration.csv:

    data, model, hidden, train_steps, train_val_loss,
    eval_solver, eval_steps, single_step_loss

(`eval_steps` is empty for dopri5, which chooses its own steps). Models:
abs-NODE (lr 1e-3) h 100 and res-NODE (lr 1e-2) h 32 and 100, each trained
on 2 and 10 grid points, on the shared PyBullet file; and the 10-point h 100
abs- and res-NODE on `ode400.csv`, collected by the README's command unless
--ode-data names it.

    reintegrate.py --diffdyn build/cli/diffdyn --out OUT [--ode-data ode400.csv]
"""
import argparse
import csv
import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PYBULLET = REPO.parent / "shared/data/pybullet_pushing/collected_data.csv"

# (data name, model kind, learning rate, hidden widths, training grid points)
TRAINED = [
    ("pybullet", "abs-node", 1e-3, [100], [2, 10]),
    ("pybullet", "res-node", 1e-2, [32, 100], [2, 10]),
    ("ode400", "abs-node", 1e-3, [100], [10]),
    ("ode400", "res-node", 1e-2, [100], [10]),
]
# Re-integration: fixed-step solvers at these grid points, then dopri5.
FIXED_SOLVERS = ["rk4", "euler"]
EVAL_STEPS = [2, 6, 10, 100]


def sweep(diffdyn, spec, folder):
    """Runs one `diffdyn sweep` and returns its results.csv rows."""
    folder.mkdir(parents=True, exist_ok=True)
    spec_path = folder / "spec.json"
    spec_path.write_text(json.dumps(spec, indent=1) + "\n")
    subprocess.run([diffdyn, "sweep", "--spec", str(spec_path), "--out", str(folder / "sweep"),
                    "--workers", "2", "--quiet"], check=True)
    rows = list(csv.DictReader(open(folder / "sweep/results.csv")))
    failed = [r for r in rows if r["exit_code"] != "0"]
    if failed:
        sys.exit(f"error: {folder}: {len(failed)} tasks failed (see {folder}/sweep/tasks)")
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--diffdyn", required=True)
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--ode-data", type=Path)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    ode = args.ode_data or args.out / "ode400.csv"
    if not ode.exists():
        subprocess.run([args.diffdyn, "collect", "--trajectories", "400", "--length", "10", "--starts", "seed",
                        "--seed", "7", "--threads", "2", "--quiet", "--out", str(ode)], check=True)
    data = {"pybullet": str(PYBULLET), "ode400": str(ode.resolve())}

    rows = []
    for name, kind, lr, hidden, steps in TRAINED:
        tag = f"{name}_{kind}"
        trained = sweep(args.diffdyn, {
            "command": "train",
            "options": {"--data": data[name], "--model": kind, "--solver": "rk4", "--lr": lr, "--epochs": 100,
                        "--seed": 1, "--threads": 1, "--quiet": True},
            "grid": {"--hidden": hidden, "--steps": steps}}, args.out / f"train_{tag}")
        for t in trained:
            evals = sweep(args.diffdyn, {
                "command": "eval",
                "options": {"--model": t["model_path"], "--data": data[name], "--threads": 1, "--quiet": True},
                "grid": {"--solver": FIXED_SOLVERS, "--steps": EVAL_STEPS}},
                args.out / f"eval_{tag}_h{t['hidden']}_p{t['steps']}")
            evals += sweep(args.diffdyn, {
                "command": "eval",
                "options": {"--model": t["model_path"], "--data": data[name], "--solver": "dopri5", "--threads": 1,
                            "--quiet": True},
                "grid": {"--seed": [0]}},
                args.out / f"eval_{tag}_h{t['hidden']}_p{t['steps']}_dopri5")
            for e in evals:
                solver = e.get("solver") or "dopri5"
                rows.append([name, kind, t["hidden"], t["steps"], t["final_val_loss"], solver,
                             "" if solver == "dopri5" else e["steps"], e["single_step_loss"]])

    with open(args.out / "reintegration.csv", "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["data", "model", "hidden", "train_steps", "train_val_loss", "eval_solver", "eval_steps",
                    "single_step_loss"])
        w.writerows(rows)
    print(f"{len(rows)} evaluations in {args.out / 'reintegration.csv'}")


if __name__ == "__main__":
    main()
