#!/usr/bin/env python3
"""The planner's design measurements (README "Design measurements"), as `diffdyn sweep` grids.

Models (each collected and trained here, in OUT/models/):
  acceptance     1000 x 10 pushes, task starts, no obstacle in the data world, collect
                 seed 11, abs-NODE 150 epochs, seed 0 (the README's acceptance model)
  free500        the same collection with 500 trajectories, 40 epochs
  obstacle500    500 x 10 pushes with the obstacle in the data world, 40 epochs
Sweeps of `diffdyn push --obstacle --json` (OUT/<sweep>/):
  reach_blind    acceptance, 50 trials, seeds 1-3, reach-blind planner
                 (--reach-limited false --reach-weight 0)
  reach_default  acceptance, 50 trials, seed 3, the default planner (README's acceptance run)
  reach_charged  acceptance, 50 trials, seed 3, reach weight 100 on the first 1 or 20
                 planned pushes, rollouts not reach-limited
  margins        obstacle500, 20 trials, seed 1, reach-blind, collision margin
                 {0, 0.01, 0.02, 0.03} x swept substeps {0, 4}
  data_world     free500 and acceptance, 20 trials, seed 1, reach-blind, margin 0.02, 4 substeps
  oracle         (--oracle) the ODE world as the model, K 100, T 5: 10 trials at margin 0.01,
                 4 substeps, and 5 trials with the seed's cost (margin 0, no substeps)
Writes OUT/design.csv (scripts/push_summaries.py over every task, plus the sweep's
name) and OUT/design_model_error.csv: the xy error of the model's prediction of every
executed push of reach_blind seeds 1 and 2 (pushes, median, p90, max in mm).

    design.py --diffdyn build/cli/diffdyn --out OUT [--oracle]
"""
import argparse
import csv
import io
import json
import math
import statistics
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
BLIND = {"--reach-limited": "false", "--reach-weight": 0}


def run(cmd, cwd):
    print("+", " ".join(map(str, cmd)), flush=True)
    subprocess.run(list(map(str, cmd)), cwd=cwd, check=True)


def model(diffdyn, out, name, trajectories, obstacle, epochs):
    """Collects and trains one abs-NODE into OUT/models/<name>.json (kept if present)."""
    path = Path("models") / f"{name}.json"
    if (out / path).exists():
        return path
    (out / "models").mkdir(exist_ok=True)
    data = Path("models") / f"{name}.csv"
    run([diffdyn, "collect", "--trajectories", trajectories, "--length", 10, "--starts", "task", "--obstacle",
         obstacle, "--seed", 11, "--threads", 2, "--quiet", "--out", data], out)
    run([diffdyn, "train", "--data", data, "--model", "abs-node", "--solver", "rk4", "--steps", 10, "--hidden", 100,
         "--epochs", epochs, "--seed", 0, "--threads", 2, "--quiet", "--out", path], out)
    return path


def sweep(diffdyn, out, name, options, grid):
    """One sweep of `push --obstacle` tasks, one after another on both cores (kept when
    OUT/<name> holds a finished sweep of the same spec)."""
    spec = {"command": "push", "options": {"--obstacle": True, "--threads": 2, "--quiet": True, **options},
            "grid": grid}
    text = json.dumps(spec, indent=1, default=str) + "\n"
    (out / name).mkdir(exist_ok=True)
    done = out / name / "sweep/results.csv"
    if not (done.exists() and (out / name / "spec.json").read_text() == text):
        (out / name / "spec.json").write_text(text)
        run([diffdyn, "sweep", "--spec", f"{name}/spec.json", "--out", f"{name}/sweep", "--workers", 1, "--quiet"],
            out)
    rows = list(csv.DictReader(open(out / name / "sweep/results.csv")))
    if any(r["exit_code"] != "0" for r in rows):
        sys.exit(f"error: {out / name}: a task failed (see {name}/sweep/tasks)")
    return [out / name / "sweep/tasks" / str(i) for i in range(len(rows))]


def summaries(tasks_by_sweep, out):
    """design.csv: push_summaries.py's row of every task's push --json line, and its sweep."""
    table = []
    for name, tasks in tasks_by_sweep.items():
        done = subprocess.run([sys.executable, REPO / "scripts/push_summaries.py",
                               *[t / "stdout.txt" for t in tasks]], check=True, capture_output=True, text=True)
        rows = list(csv.reader(io.StringIO(done.stdout)))
        if not table:
            table.append(["sweep"] + rows[0])
        table += [[name] + r for r in rows[1:]]
    with open(out / "design.csv", "w", newline="") as f:
        csv.writer(f, lineterminator="\n").writerows(table)


def model_error(tasks, out):
    """design_model_error.csv: per executed push, the xy distance between the pose reached (a row's
    x, y) and the model's prediction of it (the row's pred_x, pred_y, made one push before)."""
    errors = []
    for t in tasks:
        for r in csv.DictReader(open(next(t.glob("*/trials.csv")))):
            if r.get("pred_x", "") not in ("", "nan"):
                errors.append(1e3 * math.hypot(float(r["pred_x"]) - float(r["x"]), float(r["pred_y"]) - float(r["y"])))
    errors.sort()
    with open(out / "design_model_error.csv", "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["pushes", "median_mm", "p90_mm", "max_mm"])
        w.writerow([len(errors), f"{statistics.median(errors):.4g}",
                    f"{statistics.quantiles(errors, n=10, method='inclusive')[-1]:.4g}", f"{errors[-1]:.4g}"])


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--diffdyn", required=True, type=lambda p: Path(p).resolve())
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--oracle", action="store_true")
    args = parser.parse_args()
    out, d = args.out.resolve(), args.diffdyn
    out.mkdir(parents=True, exist_ok=True)
    acceptance = model(d, out, "acceptance", 1000, "off", 150)
    free500 = model(d, out, "free500", 500, "off", 40)
    obstacle500 = model(d, out, "obstacle500", 500, "on", 40)

    tasks = {
        "reach_blind": sweep(d, out, "reach_blind", {"--model": acceptance, "--trials": 50, **BLIND},
                             {"--seed": [1, 2, 3]}),
        "reach_default": sweep(d, out, "reach_default", {"--model": acceptance, "--trials": 50}, {"--seed": [3]}),
        "reach_charged": sweep(d, out, "reach_charged", {"--model": acceptance, "--trials": 50, "--seed": 3,
                                                         "--reach-limited": "false", "--reach-weight": 100},
                               {"--reach-steps": [1, 20]}),
        "margins": sweep(d, out, "margins", {"--model": obstacle500, "--trials": 20, "--seed": 1, **BLIND},
                         {"--collision-margin": [0, 0.01, 0.02, 0.03], "--collision-substeps": [0, 4]}),
        "data_world": sweep(d, out, "data_world", {"--trials": 20, "--seed": 1, **BLIND},
                            {"--model": [free500, acceptance]}),
    }
    if args.oracle:
        tasks["oracle_margin"] = sweep(d, out, "oracle_margin", {"--model": "oracle", "--samples": 100, "--horizon": 5,
                                                                  "--trials": 10, "--seed": 1},
                                       {"--collision-margin": [0.01]})
        tasks["oracle_seed_cost"] = sweep(d, out, "oracle_seed_cost", {"--model": "oracle", "--samples": 100,
                                                                       "--horizon": 5, "--trials": 5, "--seed": 1,
                                                                       "--collision-substeps": 0},
                                          {"--collision-margin": [0]})
    summaries(tasks, out)
    model_error(tasks["reach_blind"][:2], out)
    print(f"{out / 'design.csv'}, {out / 'design_model_error.csv'}")


if __name__ == "__main__":
    main()
