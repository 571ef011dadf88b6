#!/usr/bin/python3
"""Runs `diffdyn diagnose` on blind cases from generate.py and scores it.

Usage:
  /usr/bin/python3 score.py --cases DIR --diffdyn build/cli/diffdyn
      --out RESULTS_DIR [--extra-args "..."] [--timeout S]

Writes RESULTS_DIR/summary.md, summary.json and per_case.csv; each case's
diagnose output folder is RESULTS_DIR/case_XXX (with stdout.json and
stderr.txt). Exits 0 whatever the scores, 2 on bad arguments.
"""

import argparse
import csv
import json
import os
import shlex
import subprocess
import sys
import time

TOLERANCE = 0.15                 # relative magnitude tolerance
SYSTEM_WIDE = ("gain", "delay", "payload")
VELOCITY_KINDS = ("viscous", "coulomb", "stribeck")
RELATED = {("stribeck", "coulomb"), ("coulomb", "stribeck")}
NONNEGATIVE = ("viscous", "coulomb", "armature", "payload")


def run_diagnose(diffdyn, case_dir, system, out_dir, extra, timeout):
  """Runs one diagnose; returns (exit code, parsed JSON or None, seconds)."""
  os.makedirs(out_dir, exist_ok=True)
  cmd = (["nice", "-n", "10", diffdyn, "diagnose", "--model", system,
          "--measured", os.path.join(case_dir, "measured.csv"),
          "--out", out_dir, "--json", "--quiet"] + extra)
  start = time.time()
  try:
    proc = subprocess.run(cmd, capture_output=True, text=True,
                          timeout=timeout, check=False)
    code, stdout, stderr = proc.returncode, proc.stdout, proc.stderr
  except subprocess.TimeoutExpired as exc:
    code, stdout, stderr = "timeout", exc.stdout or "", exc.stderr or ""
    stdout = stdout.decode() if isinstance(stdout, bytes) else stdout
    stderr = stderr.decode() if isinstance(stderr, bytes) else stderr
  seconds = time.time() - start
  with open(os.path.join(out_dir, "stdout.json"), "w") as f:
    f.write(stdout)
  with open(os.path.join(out_dir, "stderr.txt"), "w") as f:
    f.write(stderr)
  lines = [l for l in stdout.strip().splitlines() if l.startswith("{")]
  try:
    result = json.loads(lines[-1]) if lines else None
  except json.JSONDecodeError:
    result = None
  return code, result, seconds


def relative_error(got, want):
  """|got - want| / |want| (inf when want is 0 and got is not)."""
  if want == 0:
    return 0.0 if got == 0 else float("inf")
  return abs(got - want) / abs(want)


def candidates(truth, effect, named):
  """(index, true value) of named effects that count as the true effect."""
  out = []
  equivalent = truth.get("equivalent")
  for i, eff in enumerate(named):
    same_joint = (effect["kind"] in SYSTEM_WIDE or
                  eff.get("joint") == effect["joint"])
    if eff.get("kind") == effect["kind"] and same_joint:
      out.append((i, effect["value"]))
    elif equivalent and eff.get("kind") == equivalent["kind"]:
      out.append((i, equivalent["value"]))
  return out


def match(truth, named):
  """Scores the named effects against the truth of one case.

  Returns:
    dict with found, magnitude_ok, rel_err, related, extras (indices).
  """
  used = set()
  res = {"found": False, "magnitude_ok": False, "rel_err": None,
         "related": False}
  for effect in truth["effects"]:
    cands = candidates(truth, effect, named)
    if cands:
      errs = [(relative_error(float(named[i]["value"]), v), i)
              for i, v in cands]
      err, best = min(errs)
      used.add(best)
      res.update(found=True, magnitude_ok=err <= TOLERANCE, rel_err=err)
      continue
    for i, eff in enumerate(named):
      if ((effect["kind"], eff.get("kind")) in RELATED and
          eff.get("joint") == effect["joint"]):
        used.add(i)
        res["related"] = True
  res["extras"] = [i for i in range(len(named)) if i not in used]
  return res


def inadmissible(eff):
  """True when a named value is physically inadmissible."""
  kind = eff.get("kind")
  value = eff.get("value")
  params = eff.get("params") or [value]
  if value is None or kind == "residual":
    return False
  if kind in NONNEGATIVE:
    return value < 0
  if kind == "stribeck":
    return any(p < 0 for p in params[:2])
  if kind == "gain":
    return not 0.5 <= value <= 2.0
  if kind == "delay":
    return not 0.0 <= value <= 0.1
  return False


def noise_ratios(result, truth):
  """Estimated / true torque noise std per joint, if diagnose reports it."""
  est = result.get("noise_std") if result else None
  if est is None:
    return None
  true = truth["noise"]["tau_std"]
  est = est if isinstance(est, list) else [est] * len(true)
  return [e / t for e, t in zip(est, true)]


def describe(effects):
  """Short text for a list of effects."""
  parts = []
  for eff in effects:
    value = eff.get("value")
    text = f"{eff.get('kind')}:{eff.get('joint')}"
    if isinstance(value, (int, float)):
      text += f"={value:.4g}"
    params = eff.get("params")
    params = list(params.values()) if isinstance(params, dict) else params
    if params and len(params) > 1:
      text += "(" + ",".join(f"{p:.3g}" for p in params) + ")"
    parts.append(text)
  return " ".join(parts) or "-"


def score_case(entry, cases_dir, args, extra):
  """Runs and scores one case; returns its row."""
  case_dir = os.path.join(cases_dir, entry["name"])
  with open(os.path.join(case_dir, "truth.json")) as f:
    truth = json.load(f)
  code, result, seconds = run_diagnose(
      args.diffdyn, case_dir, truth["system"],
      os.path.join(args.out, entry["name"]), extra, args.timeout)
  failed = code != 0 or result is None
  named = [] if failed else list(result.get("named_effects") or [])
  scored = match(truth, named)
  extras = [named[i] for i in scored["extras"]]
  true_eff = truth["effects"][0] if truth["effects"] else {}
  return {
      "case": entry["name"], "system": truth["system"],
      "control": truth["control"], "static": truth["static"],
      "truth": describe(truth["effects"]) if truth["effects"] else "control",
      "true_kind": true_eff.get("kind", ""),
      "true_value": true_eff.get("value"),
      "effect_rms_to_noise": truth.get("effect_rms_to_noise"),
      "named": describe(named), "n_named": len(named),
      "found": scored["found"], "magnitude_ok": scored["magnitude_ok"],
      "rel_err": scored["rel_err"], "related": scored["related"],
      "n_extra": len(extras),
      "n_residual": sum(e.get("kind") == "residual" for e in named),
      "n_inadmissible": sum(inadmissible(e) for e in named),
      "velocity_named": any(e.get("kind") in VELOCITY_KINDS for e in named),
      "no_significant_discrepancy": (None if failed else
                                     result.get("no_significant_discrepancy")),
      "not_identifiable": (None if failed else
                           result.get("not_identifiable")),
      "noise_ratio": noise_ratios(result, truth),
      "exit": code, "failed": failed, "seconds": round(seconds, 2),
  }


def pct(num, den):
  """Percentage or None for an empty denominator."""
  return None if den == 0 else round(100.0 * num / den, 1)


def breakdown(rows, key):
  """Recall % per value of a row key over effect cases."""
  out = {}
  for row in rows:
    out.setdefault(row[key], []).append(row["found"])
  return {k: f"{sum(v)}/{len(v)}" for k, v in sorted(out.items())}


def totals(rows):
  """Summary numbers over all rows."""
  dyn = [r for r in rows if not r["control"] and not r["static"]]
  ctrl = [r for r in rows if r["control"]]
  static = [r for r in rows if r["static"]]
  found = [r for r in dyn if r["found"]]
  ratios = [x for r in rows if r["noise_ratio"] for x in r["noise_ratio"]]
  return {
      "n_cases": len(rows), "n_effect_cases": len(dyn),
      "n_controls": len(ctrl), "n_static": len(static),
      "cli_failures": [r["case"] for r in rows if r["failed"]],
      "recall_pct": pct(len(found), len(dyn)),
      "magnitude_within_15pct_of_found_pct": pct(
          sum(r["magnitude_ok"] for r in found), len(found)),
      "related_named_instead": sum(r["related"] for r in dyn),
      "recall_by_kind": breakdown(dyn, "true_kind"),
      "recall_by_system": breakdown(dyn, "system"),
      "extras_total": sum(r["n_extra"] for r in rows),
      "residual_named_total": sum(r["n_residual"] for r in rows),
      "cases_with_more_than_1_extra": sum(r["n_extra"] > 1 for r in rows),
      "max_extras": max((r["n_extra"] for r in rows), default=0),
      "controls_clean_pct": pct(sum(r["n_named"] == 0 for r in ctrl),
                                len(ctrl)),
      "inadmissible_values": sum(r["n_inadmissible"] for r in rows),
      "static_payload_found": sum(r["found"] for r in static),
      "static_payload_error_pct": [
          None if r["rel_err"] is None else round(100 * r["rel_err"], 1)
          for r in static],
      "static_velocity_dependent_named": sum(r["velocity_named"]
                                             for r in static),
      "noise_ratio_min_max": ([round(min(ratios), 3), round(max(ratios), 3)]
                              if ratios else None),
      "seconds_total": round(sum(r["seconds"] for r in rows), 1),
      "seconds_max": max((r["seconds"] for r in rows), default=0),
  }


def markdown(rows, tot, command):
  """summary.md text."""
  lines = ["# diagnose blind scores", "", f"Command: `{command}`", "",
           "| case | system | truth | RMS/noise | named | ok | extra | s |",
           "|---|---|---|---|---|---|---|---|"]
  for r in rows:
    if r["failed"]:
      ok = f"FAIL(exit {r['exit']})"
    elif r["control"]:
      ok = "clean" if r["n_named"] == 0 else "not clean"
    elif r["found"]:
      ok = "found" + ("" if r["magnitude_ok"] else
                      f" (mag {100 * r['rel_err']:.0f}% off)")
    else:
      ok = "related" if r["related"] else "missed"
    ratio = r["effect_rms_to_noise"]
    lines.append(f"| {r['case']} | {r['system']} | {r['truth']} | "
                 f"{'' if ratio is None else f'{ratio:.1f}'} | {r['named']} | "
                 f"{ok} | {r['n_extra']} | {r['seconds']} |")
  lines += ["", "## Totals", ""]
  lines += [f"- {k}: {v}" for k, v in tot.items()]
  return "\n".join(lines) + "\n"


def write_outputs(out, rows, tot, command):
  """Writes per_case.csv, summary.json and summary.md; returns the md."""
  with open(os.path.join(out, "per_case.csv"), "w", newline="") as f:
    writer = csv.DictWriter(f, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
  with open(os.path.join(out, "summary.json"), "w") as f:
    json.dump({"command": command, "totals": tot}, f, indent=1)
  text = markdown(rows, tot, command)
  with open(os.path.join(out, "summary.md"), "w") as f:
    f.write(text)
  return text


def main():
  """Command line."""
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument("--cases", required=True)
  parser.add_argument("--diffdyn", required=True)
  parser.add_argument("--out", required=True)
  parser.add_argument("--extra-args", default="")
  parser.add_argument("--timeout", type=float, default=1800.0,
                      help="seconds per diagnose run (then a failure row)")
  args = parser.parse_args()
  listing = os.path.join(args.cases, "cases.json")
  if not os.path.isfile(listing):
    parser.error(f"no cases.json in {args.cases}")
  if not (os.path.isfile(args.diffdyn) and os.access(args.diffdyn, os.X_OK)):
    parser.error(f"not an executable: {args.diffdyn}")
  with open(listing) as f:
    entries = json.load(f)["cases"]
  if not entries:
    parser.error("cases.json lists no cases")
  os.makedirs(args.out, exist_ok=True)
  extra = shlex.split(args.extra_args)
  rows = []
  for entry in entries:
    rows.append(score_case(entry, args.cases, args, extra))
    r = rows[-1]
    print(f"{r['case']} {r['system']:8s} truth {r['truth']:28s} named "
          f"{r['named']} ({r['seconds']} s, exit {r['exit']})",
          file=sys.stderr, flush=True)
  command = " ".join([os.path.basename(sys.argv[0])] + sys.argv[1:])
  print(write_outputs(args.out, rows, totals(rows), command))


if __name__ == "__main__":
  main()
