#!/usr/bin/env python3
"""Float32 against float64 on the Fig. 5 protocol (README.md beside this file).

Reads the float32 sweeps' results (results/*.csv, `diffdyn sweep` output with columns
model, seed, final_val_loss, seconds_per_epoch, rejected_steps, ...) and the float64 rows of
../results/pybullet/grid_compare.csv (figure_neuralode_grids' compare grid: same data,
seeds and training). Prints one row per model with the acceptance check of issue 33:

  - the float32 median over seeds 1-3 within 15 % of the float64 median, and
  - every float32 seed within the float64 seeds' range widened by 15 %;

writes float32_vs_float64.csv and float32_vs_float64.png there, and exits 1 if a check fails.
"""
import csv
import statistics
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
MODELS = ["abs-nn", "res-nn", "abs-node", "res-node"]
TOLERANCE = 0.15


def read_rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def float32_losses(folder):
    """{model: {seed: (val_loss, seconds_per_epoch, solver_steps, rejected_steps)}}; the
    step counts are "" in results of a diffdyn that did not report them."""
    out = {}
    for path in sorted(folder.glob("*.csv")):
        for r in read_rows(path):
            if r.get("exit_code") != "0" or r.get("precision") != "f32":
                continue
            out.setdefault(r["model"], {})[int(r["seed"])] = (
                float(r["final_val_loss"]), float(r["seconds_per_epoch"]),
                r.get("solver_steps", ""), r.get("rejected_steps", ""))
    return out


def float64_losses(path):
    """{model: {seed: (val_loss, seconds_per_epoch)}} of the compare grid."""
    out = {}
    for r in read_rows(path):
        if r["diverged"] != "0":
            continue
        out.setdefault(r["model"], {})[int(r["seed"])] = (float(r["val_loss"]),
                                                          float(r["seconds_per_epoch"]))
    return out


def main():
    f32 = float32_losses(HERE / "results")
    f64 = float64_losses(HERE.parent / "results" / "pybullet" / "grid_compare.csv")
    rows, ok = [], True
    print("| model | float64 seeds 1/2/3 | float32 seeds 1/2/3 | median f32 / f64 | "
          "f32 within f64 range +-15 % | rejected steps f32 |")
    print("|---|---|---|---|---|---|")
    for model in MODELS:
        a, b = f64.get(model, {}), f32.get(model, {})
        seeds = sorted(set(a) & set(b))
        if seeds != [1, 2, 3]:
            print(f"| {model} | missing seeds (float64 {sorted(a)}, float32 {sorted(b)}) |")
            ok = False
            continue
        la, lb = [a[s][0] for s in seeds], [b[s][0] for s in seeds]
        ratio = statistics.median(lb) / statistics.median(la)
        low, high = min(la) * (1 - TOLERANCE), max(la) * (1 + TOLERANCE)
        inside = all(low <= x <= high for x in lb)
        passed = abs(ratio - 1) <= TOLERANCE and inside
        ok &= passed
        rejected = "/".join(str(b[s][3]) or "-" for s in seeds)
        print(f"| {model} | {' / '.join(f'{x:.3e}' for x in la)} | {' / '.join(f'{x:.3e}' for x in lb)} | "
              f"{ratio:.3f} | {'yes' if inside else 'NO'} | {rejected} |")
        for s in seeds:
            rows.append({"model": model, "seed": s, "val_loss_f64": la[s - 1], "val_loss_f32": lb[s - 1],
                         "in_band": int(low <= lb[s - 1] <= high),
                         "solver_steps_f32": b[s][2], "rejected_steps_f32": b[s][3]})
    with open(HERE / "float32_vs_float64.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]) if rows else ["model"])
        w.writeheader()
        w.writerows(rows)
    plot(rows)
    print("acceptance:", "passed" if ok else "FAILED")
    return 0 if ok else 1


def plot(rows):
    """Validation loss per seed, float64 and float32 side by side, with the +-15 % band."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for i, model in enumerate(MODELS):
        mine = [r for r in rows if r["model"] == model]
        if not mine:
            continue
        la = [r["val_loss_f64"] for r in mine]
        lb = [r["val_loss_f32"] for r in mine]
        ax.fill_between([i - 0.3, i + 0.3], min(la) * (1 - TOLERANCE), max(la) * (1 + TOLERANCE),
                        color="0.88", zorder=0, label="float64 range +-15 %" if i == 0 else None)
        ax.scatter([i - 0.1] * len(la), la, color="tab:blue", marker="o", label="float64" if i == 0 else None)
        ax.scatter([i + 0.1] * len(lb), lb, color="tab:orange", marker="s", label="float32" if i == 0 else None)
        ax.hlines([statistics.median(la)], i - 0.25, i + 0.05, color="tab:blue")
        ax.hlines([statistics.median(lb)], i - 0.05, i + 0.25, color="tab:orange")
    ax.set_xticks(range(len(MODELS)), MODELS)
    ax.set_yscale("log")
    ax.set_ylabel("validation single-step loss")
    ax.set_title("Fig. 5 protocol, seeds 1-3: float32 vs float64 (lines: medians)")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(HERE / "float32_vs_float64.png", dpi=120)


if __name__ == "__main__":
    sys.exit(main())
