#!/usr/bin/env bash
# Fingerprints of the shipped runs' logs: every example mission, physical
# and timed where it has both, the Table II configurations of the
# formation, on several seeds. Two builds that print the same lines made
# the same decisions (the logs are deterministic from the seed).
#
#   scripts/log-fingerprints.sh [BITE] > fingerprints.txt
#   diff <(scripts/log-fingerprints.sh old/bite) <(scripts/log-fingerprints.sh new/bite)
set -euo pipefail
BITE=${1:-bite}
cd "$(dirname "$0")/.."
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
run() { # name, args...
    local name=$1; shift
    "$BITE" run "$@" --log "$tmp/log.jsonl" --json > "$tmp/summary.json" 2>/dev/null || true
    # The events (what every robot decided and did, when), then the
    # summary line (counts and sizes, which may change without a decision
    # changing: e.g. a heartbeat's encoding).
    printf '%s %s %s\n' "$(grep -v '"event":"run_finished"' "$tmp/log.jsonl" | sha256sum | cut -c1-16)" \
        "$(grep '"event":"run_finished"' "$tmp/log.jsonl" | sha256sum | cut -c1-8)" "$name"
}
for seed in 1 2 3; do
    for g in examples/*.yaml examples/*.rtcl; do
        base=$(basename "${g%.*}")
        [[ -f examples/scenarios/$base-physics.yaml ]] && run "$base physics seed $seed" "$g" --seed "$seed"
        [[ -f examples/scenarios/$base.yaml ]] && run "$base timed seed $seed" "$g" --timed --seed "$seed"
    done
    for c in examples/configs/*.yaml; do
        run "formation $(basename "$c" .yaml) seed $seed" examples/formation.yaml --config "$c" --seed "$seed"
        run "formation $(basename "$c" .yaml) timed loss=0.2 seed $seed" examples/formation.yaml --timed \
            --config "$c" --seed "$seed" --fault loss=0.2
    done
    run "box-push hidden seed $seed" examples/box-push.yaml --scenario examples/scenarios/box-push-hidden-physics.yaml --seed "$seed"
    run "search-rescue hidden seed $seed" examples/search-rescue.rtcl \
        --scenario examples/scenarios/search-rescue-hidden-physics.yaml --seed "$seed"
    run "coverage 40 robots seed $seed" examples/coverage.yaml --robots 40 --seed "$seed"
    [[ $seed == 1 ]] && run "coverage 200 robots seed $seed" examples/coverage.yaml --robots 200 --seed "$seed"
    run "squads crash seed $seed" examples/squads.yaml --timed --seed "$seed" --fault crash=r2@20s --fault loss=0.1
done
