#!/usr/bin/env python3
"""Totals of the shipped sweeps (scripts/sweep-fingerprints.sh), and with
two output folders, every run whose outcome, task time, deadline count,
message count or violations differ between them.

    scripts/sweep-compare.py OUTDIR            # totals
    scripts/sweep-compare.py OLD NEW           # totals of both, then differences

Exit status 1 when two folders differ in any run (or in which runs they
hold), 0 otherwise.
"""
import json
import pathlib
import sys

FIELDS = ("outcome", "task_time", "timeouts", "messages", "violations", "panicked")


def load(folder):
    runs = {}
    for f in sorted(pathlib.Path(folder).glob("*.jsonl")):
        for n, line in enumerate(f.read_text().splitlines(), 1):
            if not line.strip():
                continue
            r = json.loads(line)
            key = (f.stem, r["case"], r["class"], r["seed"])
            runs[key] = r
    return runs


def totals(name, runs):
    with_deadline = sum(1 for r in runs.values() if r.get("timeouts", 0) > 0)
    deadlines = sum(r.get("timeouts", 0) for r in runs.values())
    violations = sum(r.get("violations", 0) for r in runs.values())
    panicked = sum(1 for r in runs.values() if r.get("panicked"))
    outcomes = {}
    for r in runs.values():
        outcomes[r["outcome"]] = outcomes.get(r["outcome"], 0) + 1
    shown = ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items()))
    print(
        f"{name}: {len(runs)} runs ({shown}); {with_deadline} with a deadline, "
        f"{deadlines} deadlines, {violations} violations, {panicked} panicked"
    )


def main():
    if len(sys.argv) not in (2, 3):
        print(__doc__, file=sys.stderr)
        return 2
    folders = sys.argv[1:]
    sets = [load(f) for f in folders]
    for f, runs in zip(folders, sets):
        totals(f, runs)
    if len(sets) == 1:
        return 0
    old, new = sets
    differ = 0
    for key in sorted(set(old) | set(new), key=str):
        a, b = old.get(key), new.get(key)
        if a is None or b is None:
            differ += 1
            print(f"only in {'new' if a is None else 'old'}: {key}")
            continue
        moved = [f for f in FIELDS if a.get(f) != b.get(f)]
        if moved:
            differ += 1
            what = ", ".join(f"{f} {a.get(f)} -> {b.get(f)}" for f in moved)
            print(f"{key[0]} {b['replay']}: {what}")
    print(f"{differ} runs differ" if differ else "identical, run for run")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
