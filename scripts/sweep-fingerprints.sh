#!/usr/bin/env bash
# The shipped sweeps, every run's outcome kept: the formation's fault
# matrix under Table II on seeds 1 to 60, the same with 8 robots on seeds
# 1 to 4, and every other example mission on seeds 1 to 20 (15,624 runs;
# about 10 minutes on two cores with a release build). Two builds whose
# outputs `scripts/sweep-compare.py` finds identical made the same
# outcomes, task times and message counts, run for run.
#
#   scripts/sweep-fingerprints.sh BITE OUTDIR
#   scripts/sweep-compare.py OLD_OUTDIR NEW_OUTDIR
set -euo pipefail
BITE=$(realpath "${1:?usage: $0 BITE OUTDIR}")
OUT=${2:?usage: $0 BITE OUTDIR}
mkdir -p "$OUT"
OUT=$(realpath "$OUT")
cd "$(dirname "$0")/.."
sweep() { # name, args...
    local name=$1; shift
    echo "== $name" >&2
    "$BITE" sweep "$@" --out "$OUT/$name.jsonl" --json > "$OUT/$name.totals.json"
}
sweep formation --seeds 1..60
sweep formation-8 --seeds 1..4 --robots 8
for g in examples/*.yaml examples/*.rtcl; do
    base=$(basename "${g%.*}")
    [[ $base == formation ]] && continue
    sweep "$base" --graph "$g" --seeds 1..20
done
python3 scripts/sweep-compare.py "$OUT"
