#!/usr/bin/env bash
# Sweep scaling: the same CPU-bound sweep of 8 single-threaded training tasks
# (abs-NODE on pendulum data, --threads 1) under `mpirun -np 1` and `mpirun -np 2`,
# and with --workers 1 and 2; prints the wall times and the speed-ups.
#   bench/sweep_scaling.sh [BUILD_DIR] [EPOCHS]
# Root in containers: export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1.
set -euo pipefail
build="${1:-build}"
epochs="${2:-30}"
diffdyn="$(cd "$build" && pwd)/cli/diffdyn"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
export OMPI_MCA_btl_vader_single_copy_mechanism=none

"$diffdyn" collect --system pendulum --trajectories 40 --seconds 2 --seed 1 --quiet --out "$work/data.csv"
cat >"$work/spec.json" <<SPEC
{"command": "train",
 "options": {"--data": "$work/data.csv", "--model": "abs-node", "--epochs": $epochs, "--threads": 1, "--quiet": true},
 "grid": {"--seed": [1, 2, 3, 4, 5, 6, 7, 8]}}
SPEC

# Wall seconds of one sweep into a fresh folder (the sweep's own JSON "seconds"):
#   run LAUNCHER... -- SWEEP_OPTIONS...
run() {
  local launcher=() out="$work/out-$RANDOM"
  while [[ "$1" != "--" ]]; do launcher+=("$1"); shift; done
  shift
  "${launcher[@]}" "$diffdyn" sweep --spec "$work/spec.json" --out "$out" --json --quiet "$@" |
    /usr/bin/python3 -c 'import json, sys; j = json.load(sys.stdin); assert j["failed"] == 0, j; print(j["seconds"])'
}

mpi1=$(run mpirun -np 1 --)
mpi2=$(run mpirun -np 2 --)
w1=$(run env -- --workers 1)
w2=$(run env -- --workers 2)
/usr/bin/python3 - "$mpi1" "$mpi2" "$w1" "$w2" <<'PY'
import sys
mpi1, mpi2, w1, w2 = map(float, sys.argv[1:])
print(f"8 training tasks (1 thread each), {open('/proc/cpuinfo').read().count('processor')} cores")
print(f"mpirun -np 1: {mpi1:7.1f} s   mpirun -np 2: {mpi2:7.1f} s   speed-up {mpi1 / mpi2:.2f}x")
print(f"--workers 1:  {w1:7.1f} s   --workers 2:  {w2:7.1f} s   speed-up {w1 / w2:.2f}x")
PY
