#!/usr/bin/env python3
"""Draws the NeuralODE-Panda grid figures from the CSVs of figure_neuralode_grids and
prints the README's tables (Markdown) and trend checks to stdout.

    /usr/bin/python3 paper_figures/neuralode_grids/plot.py OUT_DIR [PART_DIR ...]

With PART_DIRs (separate figure_neuralode_grids runs, e.g. one grid or seed each,
as `diffdyn figures` runs them), their grid CSVs are first merged into OUT_DIR:
the rows of each grid_*.csv in the order the parts are given, headers checked.

grid_single.csv  -> fig2_3_single_step.png: validation loss over (grid points, hidden)
                    for each model and solver (the paper's Figs. 2 and 3), log colours.
grid_multi.csv   -> fig4_multi_step.png: the absolute NeuralODE's multi-step grid (rk4).
grid_compare.csv -> fig5_compare.png: the four models' single-step and average
grid_accept.csv     multi-step validation losses (median over seeds, bars from the
                    smallest to the largest seed) next to the paper's Fig. 5 numbers.
Missing CSVs and missing configurations (an unfinished, resumable sweep) are skipped.
"""
import csv
import math
import os
import statistics
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.colors as mcolors  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402

PAPER_FIG5 = {"abs-nn": (1.2111e-4, 3.5197e-4), "res-nn": (7.0892e-5, 2.1715e-4),
              "abs-node": (5.6478e-5, 1.9284e-4), "res-node": (6.9874e-5, 2.3695e-4)}
MODELS = ["abs-nn", "res-nn", "abs-node", "res-node"]


def rows(path):
    if not os.path.exists(path):
        return []
    with open(path) as f:
        return list(csv.DictReader(f))


def merge(out, parts):
    """Writes OUT/grid_<name>.csv from the parts' rows of that grid, in turn."""
    os.makedirs(out, exist_ok=True)
    for grid in ("accept", "compare", "single", "multi"):
        name = f"grid_{grid}.csv"
        header, body = None, []
        for part in parts:
            path = os.path.join(part, name)
            if not os.path.exists(path):
                continue
            with open(path) as f:
                lines = f.read().splitlines()
            if not lines:
                sys.exit(f"error: {path}: empty (no header)")
            if header is not None and lines[:1] != [header]:
                sys.exit(f"error: {path}: header differs from the first part's")
            header = lines[0]
            body += [line for line in lines[1:] if line]
        if header is not None:
            tmp = os.path.join(out, name + ".tmp")
            with open(tmp, "w") as f:
                f.write("\n".join([header] + body) + "\n")
            os.replace(tmp, os.path.join(out, name))


def val(r):
    return math.nan if r["diverged"] != "0" else float(r["val_loss"])


def lookup(data, **key):
    for r in data:
        if all(str(r[k]) == str(v) for k, v in key.items()):
            return r
    return None


def heat(ax, data, title, norm):
    steps = sorted({int(r["steps"]) for r in data})
    hidden = sorted({int(r["hidden"]) for r in data})
    grid = [[math.nan] * len(steps) for _ in hidden]
    for r in data:
        grid[hidden.index(int(r["hidden"]))][steps.index(int(r["steps"]))] = val(r)
    im = ax.imshow(grid, origin="lower", norm=norm, cmap="viridis_r", aspect="auto")
    ax.set_xticks(range(len(steps)), [str(s) for s in steps])
    ax.set_yticks(range(len(hidden)), [str(h) for h in hidden])
    ax.set_xlabel("grid points (steps)")
    ax.set_ylabel("hidden width")
    ax.set_title(title, fontsize=9)
    for i, row in enumerate(grid):
        for j, v in enumerate(row):
            ax.text(j, i, "n/a" if math.isnan(v) else f"{v:.2e}", ha="center", va="center",
                    fontsize=7, color="w")
    return im


def log_norm(data):
    vals = [val(r) for r in data if val(r) > 0]
    return mcolors.LogNorm(min(vals), max(vals)) if vals else mcolors.LogNorm(1e-5, 1.0)


def fmt(v):
    return "n/a" if v is None or math.isnan(v) else f"{v:.2e}"


def single_step(out):
    data = rows(os.path.join(out, "grid_single.csv"))
    if not data:
        return
    models = [m for m in ["abs-node", "res-node"] if any(r["model"] == m for r in data)]
    fig, axes = plt.subplots(len(models), 2, figsize=(10, 3.8 * len(models)), squeeze=False)
    for i, m in enumerate(models):
        sub_m = [r for r in data if r["model"] == m]
        norm = log_norm(sub_m)
        for j, s in enumerate(["dopri5", "rk4"]):
            sub = [r for r in sub_m if r["solver"] == s]
            if sub:
                im = heat(axes[i][j], sub, f"{m}, {s}: validation single-step loss", norm)
                fig.colorbar(im, ax=axes[i][j], label="validation loss")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "fig2_3_single_step.png"), dpi=120)

    hidden = sorted({int(r["hidden"]) for r in data})
    steps = sorted({int(r["steps"]) for r in data})
    for m in models:
        print(f"\n### {m}, single-step grid (train / validation, lr {data[0]['lr'] if m == 'abs-node' else ''})\n"
              .replace(", lr )", ")"))
        print("| solver | points | " + " | ".join(f"h = {h}" for h in hidden) + " |")
        print("|---|---|" + "---|" * len(hidden))
        for s in ["dopri5", "rk4"]:
            for n in steps:
                cells = []
                for h in hidden:
                    r = lookup(data, model=m, solver=s, steps=n, hidden=h)
                    cells.append("n/a" if r is None else
                                 ("diverged" if r["diverged"] != "0" else
                                  f"{float(r['train_loss']):.2e} / {float(r['val_loss']):.2e}"))
                print(f"| {s} | {n} | " + " | ".join(cells) + " |")

    def v(m, s, n, h):
        r = lookup(data, model=m, solver=s, steps=n, hidden=h)
        return math.nan if r is None else val(r)

    print("\n### Trend checks (validation loss)\n")
    for m in models:
        falls = total = 0
        for s in ["dopri5", "rk4"]:
            for n in steps:
                seq = [v(m, s, n, h) for h in hidden]
                if not any(math.isnan(x) for x in seq):
                    total += 1
                    falls += all(a > b for a, b in zip(seq, seq[1:]))
        print(f"- {m}: loss falls monotonically with hidden width in {falls} of {total} (solver, points) rows")
        worse = []
        for h in hidden:
            a, b, c = v(m, "rk4", steps[0], h), v(m, "rk4", steps[1], h), v(m, "rk4", steps[-1], h)
            worse.append(f"h {h}: {fmt(a)} vs {fmt(b)} / {fmt(c)}")
        print(f"- {m}: rk4 with {steps[0]} points vs {steps[1]} / {steps[-1]}: " + "; ".join(worse))
        flat = []
        for h in hidden:
            seq = [v(m, "dopri5", n, h) for n in steps]
            if not any(math.isnan(x) for x in seq):
                flat.append(f"h {h}: max/min {max(seq) / min(seq):.2f}")
        print(f"- {m}: dopri5 spread over points: " + "; ".join(flat))
        close = []
        for h in hidden:
            a, b = v(m, "rk4", steps[-1], h), v(m, "dopri5", steps[-1], h)
            if not (math.isnan(a) or math.isnan(b)):
                close.append(f"h {h}: {a / b:.2f}")
        print(f"- {m}: rk4 / dopri5 at {steps[-1]} points: " + "; ".join(close))
    ratios = []
    for m in models:
        for h in hidden:
            for n in steps:
                a = lookup(data, model=m, solver="dopri5", steps=n, hidden=h)
                b = lookup(data, model=m, solver="rk4", steps=n, hidden=h)
                if a and b and float(b["seconds_per_epoch"]) > 0:
                    ratios.append((m, n, h, float(a["seconds_per_epoch"]) / float(b["seconds_per_epoch"])))
    if ratios:
        print("\n### Training time per epoch, dopri5 / rk4 (same model, points, width)\n")
        for m, n, h, q in ratios:
            print(f"- {m} points {n} h {h}: {q:.2f}x")
        print(f"- median {statistics.median(q for *_, q in ratios):.2f}x over {len(ratios)} pairs")


def multi_step(out):
    data = rows(os.path.join(out, "grid_multi.csv"))
    if not data:
        return
    fig, ax = plt.subplots(figsize=(6.5, 4.6))
    im = heat(ax, data, "abs-node, rk4: validation multi-step loss (gamma 0.9)", log_norm(data))
    fig.colorbar(im, ax=ax, label="validation loss")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "fig4_multi_step.png"), dpi=120)
    hidden = sorted({int(r["hidden"]) for r in data})
    steps = sorted({int(r["steps"]) for r in data})
    print("\n### abs-node, rk4, 4-step loss (gamma 0.9), validation\n")
    print("| points | " + " | ".join(f"h = {h}" for h in hidden) + " |")
    print("|---|" + "---|" * len(hidden))
    for n in steps:
        cells = [lookup(data, steps=n, hidden=h) for h in hidden]
        print(f"| {n} | " + " | ".join("n/a" if r is None else fmt(val(r)) for r in cells) + " |")


def comparison(out, grid, title):
    data = rows(os.path.join(out, f"grid_{grid}.csv"))
    if not data:
        return
    # One group per (model, epochs): median, min and max over the seeds.
    groups = {}
    for r in data:
        groups.setdefault((r["model"], int(r["epochs"]), r["solver"], float(r["lr"])), []).append(r)
    keys = sorted(groups, key=lambda k: (MODELS.index(k[0]), k[1]))
    print(f"\n### {title}\n")
    print("| model | solver | epochs | lr | seeds | single-step, per seed | median | median / paper |"
          " avg multi-step median | median / paper |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    stats = []
    for k in keys:
        g = sorted(groups[k], key=lambda r: int(r["seed"]))
        ok = [r for r in g if r["diverged"] == "0"]
        single = [float(r["eval_single"]) for r in ok]
        multi = [float(r["eval_avg_multi"]) for r in ok]
        ms = statistics.median(single) if single else math.nan
        mm = statistics.median(multi) if multi else math.nan
        paper = PAPER_FIG5[k[0]]
        solver = k[2] if "node" in k[0] else "-"
        per_seed = " / ".join("diverged" if r["diverged"] != "0" else f"{float(r['eval_single']):.2e}" for r in g)
        print(f"| {k[0]} | {solver} | {k[1]} | {k[3]:g} | {','.join(r['seed'] for r in g)} | {per_seed} | "
              f"{fmt(ms)} | {ms / paper[0]:.2f}x | {fmt(mm)} | {mm / paper[1]:.2f}x |")
        stats.append((f"{k[0]}\n{k[1]} ep", k[0], single, multi))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for j, label in enumerate(["validation single-step loss", "validation average 4-step loss"]):
        ax = axes[j]
        for x, (name, model, single, multi) in enumerate(stats):
            vals = single if j == 0 else multi
            if vals:
                med = statistics.median(vals)
                ax.bar(x - 0.2, med, 0.4, color="C0", label="ours (median)" if x == 0 else None,
                       yerr=[[med - min(vals)], [max(vals) - med]], capsize=3)
            ax.bar(x + 0.2, PAPER_FIG5[model][j], 0.4, color="C1", label="paper Fig. 5" if x == 0 else None)
        ax.set_xticks(range(len(stats)), [s[0] for s in stats], fontsize=8)
        ax.set_yscale("log")
        ax.set_title(label, fontsize=10)
        ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(os.path.join(out, f"fig5_{grid}.png"), dpi=120)


def main(out):
    comparison(out, "accept", "Issue #7 acceptance: diffdyn train defaults (rk4, 10 points, h 100)")
    comparison(out, "compare", "Fig. 5 protocol: NODEs dopri5, 10 points, h 100, 200 epochs")
    single_step(out)
    multi_step(out)


if __name__ == "__main__":
    if len(sys.argv) > 2:
        merge(sys.argv[1], sys.argv[2:])
    main(sys.argv[1])
