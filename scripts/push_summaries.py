#!/usr/bin/env python3
"""One CSV row per `diffdyn push --json` output, for README tables (readme_tables.py).

    push_summaries.py seed1.json seed2.json ... > summaries.csv

Columns: seed, trials, successes, ci95_low, ci95_high, mean_pushes, the planner's
settings (model, samples, horizon, collision_margin, collision_substeps, reach_weight,
reach_steps, reach_limited; the JSON's keys, DESIGN.md) and failures: the outcomes other than success with their counts
("1 max steps, 1 obstacle contact"), or "-". A file that is not such an output gives
one `error:` line naming it and exit 2, and nothing is written.
"""
import csv
import io
import json
import sys

KEYS = ("seed", "trials", "successes", "ci95_low", "ci95_high", "mean_pushes", "model", "samples", "horizon",
        "collision_margin", "collision_substeps", "reach_weight", "reach_steps", "reach_limited")


def row(path):
    try:
        with open(path) as f:
            j = json.load(f)
        fails = ", ".join(f"{n} {k.replace('_', ' ')}"
                          for k, n in sorted(j["outcomes"].items()) if k != "success")
        return [str(j[k]).lower() if isinstance(j[k], bool) else j[k] for k in KEYS] + [fails or "-"]
    except (OSError, ValueError, KeyError, AttributeError, TypeError) as e:
        raise ValueError(f"error: {path}: not a `diffdyn push --json` output ({e})") from e


def main():
    if len(sys.argv) < 2:
        print("error: usage: push_summaries.py PUSH_JSON...", file=sys.stderr)
        sys.exit(2)
    rows = []
    for path in sys.argv[1:]:
        try:
            rows.append(row(path))
        except ValueError as e:
            print(e, file=sys.stderr)
            sys.exit(2)
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow([*KEYS, "failures"])
    w.writerows(rows)
    sys.stdout.write(out.getvalue())


if __name__ == "__main__":
    main()
