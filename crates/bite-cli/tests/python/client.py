"""A BITE team client written from docs/zenoh-interface.md alone.

Usage: client.py ENDPOINT TEAM KEY_FILE GRAPH_FILE SCENARIO_FILE ROBOTS TIMEOUT_S

Connects to a robot's endpoint, waits for every robot's status, submits the
graph (with the scenario) as a signed mission, waits until every robot's
status says `completed`, queries the team's membership, and prints a JSON
report on standard output. Exit status 0 on success.
"""

import hashlib
import hmac
import json
import sys
import threading
import time

import zenoh


def main():
    endpoint, team, key_file, graph_file, scenario_file, robots, timeout = sys.argv[1:8]
    robots = robots.split(",")
    timeout = float(timeout)
    key = bytes.fromhex(open(key_file).read().strip())

    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(conf)

    lock = threading.Lock()
    statuses = {}
    seen_states = {r: set() for r in robots}

    def on_status(sample):
        st = json.loads(sample.payload.to_string())
        with lock:
            statuses[st["robot"]] = st
            seen_states.setdefault(st["robot"], set()).add(st["state"])

    sub = session.declare_subscriber(f"bite/{team}/status/*", on_status)

    def wait_for(pred, what):
        deadline = time.time() + timeout
        while time.time() < deadline:
            with lock:
                if pred():
                    return
            time.sleep(0.05)
        with lock:
            raise SystemExit(f"timed out waiting for {what}: {json.dumps(statuses)}")

    wait_for(lambda: all(r in statuses for r in robots), "every robot's status")
    waiting = {r: statuses[r]["state"] for r in robots}

    body = json.dumps({
        "id": f"py-{int(time.time() * 1000)}",
        "issued_at": int(time.time() * 1000),
        "graph": open(graph_file).read(),
        "scenario": open(scenario_file).read(),
    })
    mac = hmac.new(key, b"bite-mission-v1\0" + team.encode() + b"\0" + body.encode(),
                   hashlib.sha256).hexdigest()
    session.put(f"bite/{team}/mission", json.dumps({"body": body, "mac": mac}))
    # A submission with a wrong MAC must be refused.
    session.put(f"bite/{team}/mission", json.dumps({"body": body.replace("py-", "forged-"), "mac": mac}))

    wait_for(lambda: all(statuses[r]["state"] == "running" or statuses[r]["state"] == "completed"
                         for r in robots), "the mission to start")
    running = {r: statuses[r]["stack"] for r in robots}
    wait_for(lambda: all(statuses[r]["state"] == "completed" for r in robots), "the mission to complete")

    members = []
    # Every robot answers: ask all queryables, not the best-matching one.
    for reply in session.get(f"bite/{team}/members/*", target=zenoh.QueryTarget.ALL,
                             consolidation=zenoh.ConsolidationMode.NONE, timeout=5.0):
        if reply.ok is not None:
            members.append(json.loads(reply.ok.payload.to_string()))

    with lock:
        report = {
            "before": waiting,
            "stacks_while_running": running,
            "final": statuses,
            "states_seen": {r: sorted(s) for r, s in seen_states.items()},
            "members": sorted(members, key=lambda m: m["robot"]),
        }
    sub.undeclare()
    session.close()
    print(json.dumps(report))


if __name__ == "__main__":
    main()
