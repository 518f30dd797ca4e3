#!/usr/bin/env python3
"""A run log (JSON lines, `bite run --log`, `--log-messages` for the
messages too) as a timeline to read: one line per record, time, robot,
event, then the rest of the record compact.

    scripts/timeline.py LOG [--robot r1,r3] [--event interaction,split]
                            [--from 20] [--to 40] [--grep 'b3#2'] [--width 200]

Filters combine (all must hold); --event and --grep match substrings.
"""
import argparse
import json
import sys


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("log")
    p.add_argument("--robot", help="robots, comma-separated")
    p.add_argument("--event", help="event name substrings, comma-separated")
    p.add_argument("--from", dest="start", type=float, default=float("-inf"))
    p.add_argument("--to", dest="end", type=float, default=float("inf"))
    p.add_argument("--grep", help="a substring of the record's JSON")
    p.add_argument("--width", type=int, default=240, help="cut lines to this many characters (0: never)")
    a = p.parse_args()
    robots = set(a.robot.split(",")) if a.robot else None
    events = a.event.split(",") if a.event else None
    with open(a.log, encoding="utf-8") as f:
        for n, line in enumerate(f, 1):
            try:
                r = json.loads(line)
            except json.JSONDecodeError as e:
                print(f"{a.log}:{n}:{e.colno}: not a record: {e.msg}", file=sys.stderr)
                continue
            t = r.get("t", 0.0)
            if not (a.start <= t <= a.end):
                continue
            robot = str(r.get("robot", r.get("from", "-")))
            event = str(r.get("event", "?"))
            if robots is not None and robot not in robots:
                continue
            if events is not None and not any(e in event for e in events):
                continue
            rest = {k: v for k, v in r.items() if k not in ("t", "robot", "event")}
            text = json.dumps(rest, separators=(",", ":"))
            if a.grep and a.grep not in text:
                continue
            out = f"{t:10.3f} {robot:>4} {event:<22} {text}"
            print(out if a.width <= 0 else out[: a.width])


if __name__ == "__main__":
    try:
        main()
    except BrokenPipeError:
        sys.exit(0)
