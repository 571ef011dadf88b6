#!/bin/sh
# The ODE-engine pusher against the seed's PyBullet pushes, end to end:
#   1. diffdyn diagnose --model pushing (calibration, report, plots) into DIAG;
#   2. the nominal and the calibrated pusher each collect the seed's dataset shape
#      (400 trajectories of 10 pushes from the seed's start pose, collect seed 1);
#   3. an abs-NODE (rk4, 10 grid points, 100 epochs) is trained on each, seeds 1-3,
#      and scored by diffdyn eval on the PyBullet data: all 400 trajectories, and
#      the 120 the calibration held out (the trajectories of DIAG/replays.csv);
#   4. OUT/abs_node_on_pybullet.csv: world, seed, then single-step and average
#      multi-step loss on all trajectories and on the held-out ones.
# usage: run.sh BUILD_DIR OUT [DIAG]   (an existing diagnosis folder DIAG skips step 1)
set -eu
build=$1
out=$2
data=$(dirname "$0")/../../../shared/data/pybullet_pushing/collected_data.csv
diffdyn=$build/cli/diffdyn
python=/usr/bin/python3
mkdir -p "$out"
diag=${3:-$out/diagnose}
if [ -z "${3:-}" ]; then
  "$diffdyn" diagnose --model pushing --measured "$data" --out "$diag" --json > "$out/diagnose.json"
fi
# The held-out trajectories' rows of the PyBullet file.
$python - "$diag/replays.csv" "$data" "$out/heldout.csv" <<'PY'
import csv, sys
held = {r["trajectory"] for r in csv.DictReader(open(sys.argv[1]))}
rows = list(csv.reader(open(sys.argv[2])))
with open(sys.argv[3], "w", newline="") as f:
    w = csv.writer(f)
    w.writerows([rows[0]] + [r for r in rows[1:] if r[0] in held])
PY
"$diffdyn" collect --trajectories 400 --length 10 --threads 2 --seed 1 --quiet --out "$out/nominal.csv"
"$diffdyn" collect --world "$diag/calibrated_pusher.json" --trajectories 400 --length 10 --threads 2 --seed 1 \
  --quiet --out "$out/calibrated.csv"
losses() {
  "$diffdyn" eval --model "$1" --data "$2" --json |
    $python -c "import json, sys; j = json.load(sys.stdin); print('%.9g,%.9g' % (j['single_step_loss'], j['avg_multi_step_loss']), end='')"
}
echo "world,seed,single_step_loss,avg_multi_step_loss,heldout_single_step_loss,heldout_avg_multi_step_loss" \
  > "$out/abs_node_on_pybullet.csv"
for w in nominal calibrated; do
  for seed in 1 2 3; do
    model=$out/${w}_abs_node_$seed.json
    "$diffdyn" train --model abs-node --data "$out/$w.csv" --seed $seed --quiet --out "$model"
    echo "$w,$seed,$(losses "$model" "$data"),$(losses "$model" "$out/heldout.csv")" >> "$out/abs_node_on_pybullet.csv"
  done
done
cat "$out/abs_node_on_pybullet.csv"
