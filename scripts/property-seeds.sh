#!/usr/bin/env bash
# Explore the simulator's property `no_waiting_across_levels` on fresh RNG
# seeds: one proptest run per seed (PROPTEST_CASES cases each, default
# 1000), two at a time, one line per seed: `SEED pass` or `SEED fail`
# with the failure's first lines (graph seed, team, what the run's
# summary said). A failing case's graph and scenario are saved under
# target/proptest-failures/ with the command that replays it.
#
#   cargo test --release -p bite-sim --test properties --no-run   # prints the binary
#   scripts/property-seeds.sh PROPERTIES_BINARY 8201 8600 > seeds.txt
set -euo pipefail
BIN=$(realpath "${1:?usage: $0 PROPERTIES_BINARY FROM TO}")
FROM=${2:?usage: $0 PROPERTIES_BINARY FROM TO}
TO=${3:?usage: $0 PROPERTIES_BINARY FROM TO}
export PROPTEST_CASES=${PROPTEST_CASES:-1000}
export BIN
one() {
    local out
    if out=$(PROPTEST_RNG_SEED=$1 "$BIN" --exact no_waiting_across_levels 2>&1); then
        echo "$1 pass"
    else
        echo "$1 fail $(grep -m3 -E 'Test failed|outcome|invariants' <<<"$out" | sed 's/  */ /g' | tr '\n' ' ')"
    fi
}
export -f one
seq "$FROM" "$TO" | xargs -P "${JOBS:-2}" -I{} bash -c 'one {}'
