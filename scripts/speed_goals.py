#!/usr/bin/env python3
"""Measure every speed goal of issue 20 on this machine, with its spread.

Runs each acceptance benchmark of issue 20 (docs/performance.md, "Where the
speed goals stand") `--rounds` times, the same commands the performance
notes quote, and prints one table: per goal the median, the fastest and
slowest round, the target, and whether it is met in every round, at the
median only, or not. `--json FILE` writes every round's figures too, with
the machine, the commit and the commands, for scripts to compare.

    python3 scripts/speed_goals.py                      # every goal, 3 rounds
    python3 scripts/speed_goals.py --only kernel,team   # some goals
    python3 scripts/speed_goals.py --quick --only team,sim,protocols
                                                        # small sizes: a smoke run

Goals and what measures them (ids for `--only` / `--skip`):

- `team`: `bite bench team --robots 100000 --threads 1,2` (the whole
  mission): real-time factor ≥ 1 on one thread, ≥ 2 on two; peak memory
  < 2 GB.
- `sim`: `bite bench sim --robots 10000 --threads 2`: real-time factor ≥ 5.
- `kernel`: `cargo bench -p bite-core --bench kernel -- decision_step`
  (divan): median decision step ≤ 2 µs.
- `graph`: `cargo bench -p bite-core --bench graph -- load_wide`: a graph of
  100,000 behaviors loaded in < 0.5 s (median).
- `compile`: `cargo bench -p bite-rtcl --bench compile -- compile_and_load`:
  a 10,000-line mission compiled and loaded in < 50 ms (median).
- `protocols`: `bite bench protocols --large 1000`: the auction, 1,000 robots
  × 1,000 tasks, in < 1 s.
- `lap`: `scripts/lap_vs_scipy.py` (SciPy in a venv, set up on first use):
  `alloc.optimal` ≤ 1.0× SciPy on every matrix up to 5,000, every total
  agreed.
- `zenoh`: `bite bench zenoh --robots 10`: each protocol's hop ≤ 1.5× a
  one-way trip (the worst of the three protocols is the figure).

A round that did not complete, or that needed a protocol deadline, is
reported as such next to its figure: it is not the figure of a clean run.

Exit status: 0 when every goal measured was met in every round, 1 when one
was not (the table says which), 2 on a setup or run error.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
VENV_PYTHON = Path.home() / ".cache" / "bite-rs" / "venv" / "bin" / "python"


class RunError(Exception):
    """A benchmark command failed or printed something unexpected."""


# ----- goals ------------------------------------------------------------

# id, group, what, unit, comparison, target (full size)
GOALS = [
    ("team_one_thread", "team", "100,000-robot team, one thread", "× real time", ">=", 1.0),
    ("team_two_threads", "team", "100,000-robot team, two threads", "× real time", ">=", 2.0),
    ("team_memory", "team", "100,000-robot team, peak memory", "GB", "<", 2.0),
    ("sim_two_threads", "sim", "10,000 physical robots, two threads", "× real time", ">=", 5.0),
    ("decision_step", "kernel", "kernel decision step (median)", "µs", "<=", 2.0),
    ("graph_load", "graph", "graph of 100,000 behaviors loaded (median)", "ms", "<", 500.0),
    ("compile_and_load", "compile", "10,000-line mission compiled and loaded (median)", "ms", "<", 50.0),
    ("auction", "protocols", "auction, 1,000 robots × 1,000 tasks", "s", "<", 1.0),
    ("lap_worst_ratio", "lap", "alloc.optimal / SciPy, worst matrix", "×", "<=", 1.0),
    ("zenoh_worst_ratio", "zenoh", "Zenoh hop / one-way trip, worst protocol, 10 processes", "×", "<=", 1.5),
]
GROUPS = sorted({g[1] for g in GOALS})


def meets(value: float, cmp: str, target: float) -> bool:
    return {
        ">=": value >= target,
        "<=": value <= target,
        "<": value < target,
    }[cmp]


def verdict(values: list[float], cmp: str, target: float) -> str:
    """`met` in every round, `met at the median`, or `not met`."""
    if not values:
        return "not measured"
    if all(meets(v, cmp, target) for v in values):
        return "met"
    if meets(statistics.median(values), cmp, target):
        return "met at the median"
    return "not met"


# ----- divan's tables ---------------------------------------------------

UNITS = {"ns": 1e-9, "µs": 1e-6, "us": 1e-6, "ms": 1e-3, "s": 1.0}
DURATION = re.compile(r"([0-9]+(?:\.[0-9]+)?)\s*(ns|µs|us|ms|s)(?![A-Za-z])")


def parse_divan(text: str) -> dict[str, dict[str, float]]:
    """Divan's table as `{"bench" or "bench/arg": {"fastest", "slowest",
    "median", "mean"}}`, in seconds."""
    out: dict[str, dict[str, float]] = {}
    parents: list[tuple[int, str]] = []
    for line in text.splitlines():
        if "│" not in line and "fastest" not in line:
            continue
        head = line.split("│")[0]
        # The tree's depth is where the name starts.
        m = re.search(r"[├╰]─\s*(\S+)", head)
        if not m:
            continue
        depth, name = m.start(), m.group(1)
        while parents and parents[-1][0] >= depth:
            parents.pop()
        full = "/".join([p for _, p in parents] + [name])
        durations = DURATION.findall(line[m.end():])
        if len(durations) >= 4:
            keys = ("fastest", "slowest", "median", "mean")
            out[full] = {k: float(v) * UNITS[u] for k, (v, u) in zip(keys, durations)}
        else:
            parents.append((depth, name))
    return out


SAMPLE_DIVAN = """\
graph         fastest       │ slowest       │ median        │ mean          │ samples │ iters
╰─ load_wide                │               │               │               │         │
   ├─ 1000    989.6 µs      │ 15.37 ms      │ 1.037 ms      │ 2.479 ms      │ 10      │ 10
   ╰─ 99999   111.5 ms      │ 336.8 ms      │ 128.5 ms      │ 150.5 ms      │ 10      │ 10
kernel                  fastest       │ slowest       │ median        │ mean          │ samples │ iters
├─ decision_step        3.634 µs      │ 8.822 µs      │ 4.17 µs       │ 4.837 µs      │ 200     │ 200
╰─ steady_tick          22.08 ns      │ 528.1 ns      │ 22.47 ns      │ 24.98 ns      │ 200     │ 25600
"""


def self_test() -> int:
    """Check the parsers on captured output (run by the test suite)."""
    t = parse_divan(SAMPLE_DIVAN)
    assert abs(t["load_wide/99999"]["median"] - 0.1285) < 1e-9, t
    assert abs(t["load_wide/1000"]["fastest"] - 989.6e-6) < 1e-12, t
    assert abs(t["decision_step"]["median"] - 4.17e-6) < 1e-12, t
    assert abs(t["steady_tick"]["slowest"] - 528.1e-9) < 1e-15, t
    assert verdict([1.2, 0.9, 1.1], ">=", 1.0) == "met at the median"
    assert verdict([1.2, 1.3], ">=", 1.0) == "met"
    assert verdict([0.3, 0.4], ">=", 1.0) == "not met"
    assert verdict([1.9, 2.1, 2.2], "<", 2.0) == "not met"
    print("self-test passed")
    return 0


# ----- running ----------------------------------------------------------

def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def run(cmd: list[str], env: dict | None = None) -> str:
    log("$ " + " ".join(cmd))
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True,
                       env={**os.environ, **(env or {})})
    if p.returncode != 0:
        raise RunError(f"{' '.join(cmd)} exited {p.returncode}:\n{p.stderr[-2000:]}")
    return p.stdout


def run_json(cmd: list[str]) -> dict:
    out = run(cmd)
    # The JSON object is the last line that parses (progress may precede it).
    for line in reversed(out.strip().splitlines()):
        line = line.strip()
        if line.startswith("{"):
            try:
                return json.loads(line)
            except json.JSONDecodeError:
                continue
    raise RunError(f"{' '.join(cmd)} printed no JSON object")


def find_bite(given: str | None, build: bool) -> str:
    if given:
        return given
    target = Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    if build:
        run(["cargo", "build", "--release", "--locked", "-p", "bite-cli"])
    bite = target / "release" / "bite"
    if not bite.exists():
        raise RunError(f"no binary at {bite}: build it or give --bite")
    return str(bite)


class Measure:
    """Every round's figures, per goal, and how each round ended."""

    def __init__(self) -> None:
        self.values: dict[str, list[float]] = {g[0]: [] for g in GOALS}
        self.remarks: dict[str, list[str]] = {g[0]: [] for g in GOALS}
        self.commands: dict[str, list[str]] = {}

    def add(self, goal: str, value: float, remark: str | None = None) -> None:
        self.values[goal].append(value)
        if remark:
            self.remarks[goal].append(remark)


def clean(row: dict, to_the_end: bool = True) -> str | None:
    """What a bench row's run needed or failed to do, if anything (its
    outcome only for a run meant to go to the mission's end)."""
    out = []
    if to_the_end and row.get("outcome") not in (None, "completed"):
        out.append(str(row.get("outcome")))
    if row.get("timeouts"):
        out.append(f"{row['timeouts']} deadlines")
    return ", ".join(out) or None


def measure_team(m: Measure, bite: str, a) -> None:
    robots, extra = (2000, ["--sim-time", "5s"]) if a.quick else (100000, [])
    cmd = [bite, "bench", "team", "--robots", str(robots), "--threads", "1,2",
           "--repeat", str(a.rounds), "--json", *extra]
    m.commands["team"] = cmd
    for row in run_json(cmd)["rows"]:
        goal = "team_one_thread" if row["threads"] == 1 else "team_two_threads"
        m.add(goal, row["real_time_factor"], clean(row, not a.quick))
        m.add("team_memory", row["peak_rss_kb"] * 1024 / 1e9)


def measure_sim(m: Measure, bite: str, a) -> None:
    robots, extra = (1000, ["--seconds", "5"]) if a.quick else (10000, [])
    cmd = [bite, "bench", "sim", "--robots", str(robots), "--threads", "2",
           "--repeat", str(a.rounds), "--json", *extra]
    m.commands["sim"] = cmd
    for row in run_json(cmd)["rows"]:
        if row.get("robots") == robots:
            # A minute of the coverage mission: not meant to complete it.
            m.add("sim_two_threads", row["real_time_factor"], clean(row, False))


def measure_divan(m: Measure, a, group: str, crate: str, bench: str, filt: str,
                  goal: str, key, scale: float, samples: int | None = None) -> None:
    """A divan bench's median, `--rounds` times (`samples`: its sample
    count, else the bench's own)."""
    samples = ["--sample-count", "5"] if a.quick else (
        ["--sample-count", str(samples)] if samples else [])
    cmd = ["cargo", "bench", "-q", "--locked", "-p", crate, "--bench", bench, "--", filt, *samples]
    m.commands[group] = cmd
    for _ in range(a.rounds):
        table = parse_divan(run(cmd))
        names = [n for n in table if key(n)]
        if not names:
            raise RunError(f"{' '.join(cmd)}: no row for {goal} in:\n{table}")
        m.add(goal, table[names[-1]]["median"] * scale)


def measure_protocols(m: Measure, bite: str, a) -> None:
    large = 100 if a.quick else 1000
    cmd = [bite, "bench", "protocols", "--robots", "3", "--large", str(large), "--json"]
    m.commands["protocols"] = cmd
    for _ in range(a.rounds):
        rows = [r for r in run_json(cmd)["large"] if r["protocol"] == "alloc.auction"]
        if not rows:
            raise RunError("bench protocols: no alloc.auction row")
        m.add("auction", rows[0]["wall_s"])


def measure_lap(m: Measure, bite: str, a) -> None:
    py = VENV_PYTHON
    if not py.exists():
        run([sys.executable, str(ROOT / "scripts" / "lap_vs_scipy.py"), "--setup-venv", "--max", "100",
             "--bite", bite])
    cmd = [str(py), str(ROOT / "scripts" / "lap_vs_scipy.py"), "--json", "--bite", bite,
           "--max", "300" if a.quick else "5000"]
    m.commands["lap"] = cmd
    for _ in range(a.rounds):
        rows = run_json(cmd)["rows"]
        worst = max(rows, key=lambda r: r["ratio"] or 0.0)
        bad = [r for r in rows if not r["agree"]]
        remark = f"worst: {worst['kind']} {worst['rows']}×{worst['cols']}"
        if bad:
            remark += f"; {len(bad)} totals disagreed"
        m.add("lap_worst_ratio", worst["ratio"], remark)


def measure_zenoh(m: Measure, bite: str, a) -> None:
    robots = 3 if a.quick else 10
    cmd = [bite, "bench", "zenoh", "--robots", str(robots), "--decisions", "5" if a.quick else "20",
           "--pings", "30" if a.quick else "300", "--json"]
    m.commands["zenoh"] = cmd
    for _ in range(a.rounds):
        r = run_json(cmd)
        rows = r["rows"]
        worst = max(rows, key=lambda x: x["per_hop_over_one_way"])
        remark = (f"worst: {worst['protocol']}, raw round trip {r['rtt_median_us']:.0f} µs"
                  + ("" if all(x["completed"] for x in rows) else "; a run did not complete"))
        m.add("zenoh_worst_ratio", worst["per_hop_over_one_way"], remark)


def machine() -> dict:
    model = platform.processor() or "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                                capture_output=True, text=True).stdout.strip()
    except OSError:
        commit = "?"
    return {"cpu": model, "cores": os.cpu_count(), "commit": commit,
            "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}


def fmt(v: float) -> str:
    return f"{v:.3g}" if abs(v) < 1000 else f"{v:,.0f}"


def table(m: Measure, quick: bool) -> tuple[str, list[dict], bool]:
    lines = ["| goal | target | median | best – worst round | rounds | status | remarks |",
             "| --- | --- | ---: | --- | ---: | --- | --- |"]
    rows, all_met = [], True
    for gid, group, what, unit, cmp, target in GOALS:
        vals = m.values[gid]
        if not vals:
            continue
        status = verdict(vals, cmp, target)
        if quick:
            status = "(quick: small sizes, no verdict)"
        else:
            all_met &= status == "met"
        lo, hi = min(vals), max(vals)
        if cmp == ">=":
            lo, hi = hi, lo  # the best first
        remarks = "; ".join(dict.fromkeys(m.remarks[gid]))
        lines.append(f"| {what} | {cmp.replace('>=', '≥').replace('<=', '≤')} {fmt(target)} {unit} "
                     f"| {fmt(statistics.median(vals))} {unit} | {fmt(lo)} – {fmt(hi)} | {len(vals)} "
                     f"| {status} | {remarks} |")
        rows.append({"goal": gid, "group": group, "what": what, "unit": unit, "comparison": cmp,
                     "target": target, "values": vals, "median": statistics.median(vals),
                     "status": status, "remarks": m.remarks[gid], "command": m.commands.get(group)})
    return "\n".join(lines), rows, all_met


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rounds", type=int, default=3, help="rounds of each benchmark (default 3)")
    p.add_argument("--only", help=f"comma-separated goal groups: {','.join(GROUPS)}")
    p.add_argument("--skip", help="comma-separated goal groups to leave out")
    p.add_argument("--quick", action="store_true", help="small sizes, for a smoke run (no verdict)")
    p.add_argument("--bite", help="the bite binary (default: build and use target/release/bite)")
    p.add_argument("--json", type=Path, help="write every round's figures to this file")
    p.add_argument("--self-test", action="store_true", help="check the parsers and stop")
    a = p.parse_args()
    if a.self_test:
        return self_test()
    if a.rounds < 1:
        p.error("--rounds must be at least 1")
    groups = set(GROUPS)
    for opt, keep in ((a.only, True), (a.skip, False)):
        if opt:
            asked = {g.strip() for g in opt.split(",") if g.strip()}
            unknown = asked - set(GROUPS)
            if unknown:
                p.error(f"unknown goal group(s) {sorted(unknown)}; known: {', '.join(GROUPS)}")
            groups = groups & asked if keep else groups - asked
    needs_bite = groups & {"team", "sim", "protocols", "lap", "zenoh"}
    m = Measure()
    started = time.monotonic()
    try:
        bite = find_bite(a.bite, build=bool(needs_bite) and not a.bite) if needs_bite else ""
        steps = [
            ("kernel", lambda: measure_divan(m, a, "kernel", "bite-core", "kernel", "decision_step",
                                             "decision_step", lambda n: n == "decision_step", 1e6,
                                             samples=300)),
            ("graph", lambda: measure_divan(m, a, "graph", "bite-core", "graph", "load_wide",
                                            "graph_load", lambda n: n.startswith("load_wide/"), 1e3)),
            ("compile", lambda: measure_divan(m, a, "compile", "bite-rtcl", "compile", "compile_and_load",
                                              "compile_and_load",
                                              lambda n: n.startswith("compile_and_load"), 1e3)),
            ("protocols", lambda: measure_protocols(m, bite, a)),
            ("zenoh", lambda: measure_zenoh(m, bite, a)),
            ("lap", lambda: measure_lap(m, bite, a)),
            ("sim", lambda: measure_sim(m, bite, a)),
            ("team", lambda: measure_team(m, bite, a)),
        ]
        for group, step in steps:
            if group in groups:
                log(f"measuring {group}")
                step()
    except (RunError, OSError, KeyError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    text, rows, all_met = table(m, a.quick)
    info = machine()
    print(f"{info['cpu']}, {info['cores']} cores, commit {info['commit']}, {info['date']}; "
          f"{a.rounds} round(s){' (quick)' if a.quick else ''}, "
          f"{time.monotonic() - started:.0f} s\n")
    print(text)
    if a.json:
        a.json.write_text(json.dumps({"machine": info, "rounds": a.rounds, "quick": a.quick,
                                      "goals": rows}, indent=1, ensure_ascii=False) + "\n")
    return 0 if all_met else 1


if __name__ == "__main__":
    sys.exit(main())
