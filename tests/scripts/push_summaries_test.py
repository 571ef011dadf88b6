#!/usr/bin/env python3
"""scripts/push_summaries.py: one row per push output with its failures; a file that
is not a push output gives one error line naming it, exit 2 and no CSV."""
import json
import tempfile
from pathlib import Path

from script_check import expect, run_script


def main():
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        a, b, bad = root / "a.json", root / "b.json", root / "bad.json"
        planner = {"model": "m.json", "samples": 1000, "horizon": 20, "collision_margin": 0.02,
                   "collision_substeps": 4, "reach_weight": 100.0, "reach_steps": 1, "reach_limited": True}
        a.write_text(json.dumps({"seed": 3, "trials": 50, "successes": 48, "ci95_low": 0.865,
                                 "ci95_high": 0.989, "mean_pushes": 6.98,
                                 "outcomes": {"success": 48, "obstacle_contact": 1, "max_steps": 1}, **planner}))
        b.write_text(json.dumps({"seed": 1, "trials": 50, "successes": 50, "ci95_low": 0.929,
                                 "ci95_high": 1.0, "mean_pushes": 6.62, "outcomes": {"success": 50},
                                 **planner, "reach_limited": False}))
        bad.write_text(json.dumps({"seed": 1}))
        r = run_script("push_summaries.py", a, b)
        expect(r.returncode == 0, f"two outputs give a CSV (rc {r.returncode}: {r.stderr})")
        expect(r.stdout.splitlines() == [
            "seed,trials,successes,ci95_low,ci95_high,mean_pushes,model,samples,horizon,collision_margin,"
            "collision_substeps,reach_weight,reach_steps,reach_limited,failures",
            '3,50,48,0.865,0.989,6.98,m.json,1000,20,0.02,4,100.0,1,true,"1 max steps, 1 obstacle contact"',
            "1,50,50,0.929,1.0,6.62,m.json,1000,20,0.02,4,100.0,1,false,-"], f"rows and failures (got {r.stdout!r})")
        r = run_script("push_summaries.py", a, bad)
        lines = r.stderr.strip().split("\n")
        expect(r.returncode == 2 and r.stdout == "" and len(lines) == 1 and
               lines[0].startswith(f"error: {bad}:"), f"a bad file: one error line, exit 2 (got {r.returncode}: {r.stderr})")
    print("push_summaries: all checks passed")


if __name__ == "__main__":
    main()
