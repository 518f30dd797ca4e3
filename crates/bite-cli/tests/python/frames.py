"""Robot-to-robot frames built from docs/zenoh-interface.md alone.

Usage: frames.py ENDPOINT TEAM KEY_FILE GRAPH_FILE SCENARIO_FILE TIMEOUT_S

Submits the graph as a signed mission (id known, so the mission tag is
known), waits until every robot runs it, then puts on the robots' net keys,
as robot r1:
  - a heartbeat sealed with the team key, twice (the second is a replay),
  - the same heartbeat sealed with a wrong key,
  - a validly sealed heartbeat from r1 on r2's key (wrong sender),
and reports on standard output (JSON) every robot's `auth.rejected`
counters before and after, the phases seen, and whether the mission still
completed. Uses hashlib, hmac and struct only, besides zenoh.
"""

import hashlib
import hmac
import json
import struct
import sys
import threading
import time

import zenoh

PHASES = {"not-started", "expanding", "waiting-for-child", "allocating", "running",
          "idle", "terminating", "selecting", "finished"}


def fnv1a64(data: bytes) -> int:
    h = 0xCBF29CE484222325
    for b in data:
        h ^= b
        h = (h * 0x100000001B3) % (1 << 64)
    return h


def frame(key: bytes, team: str, tag: int, kind: int, sender: int, counter: int,
          payload: bytes) -> bytes:
    body = b"BZ" + bytes([1, kind]) + struct.pack("<IQ", sender, counter) + payload
    mac_input = b"bite-frame-v1\0" + team.encode() + b"\0" + struct.pack("<Q", tag) + body
    return body + hmac.new(key, mac_input, hashlib.sha256).digest()


def main():
    endpoint, team, key_file, graph_file, scenario_file, timeout = sys.argv[1:7]
    timeout = float(timeout)
    key = bytes.fromhex(open(key_file).read().strip())
    robots = ["r0", "r1", "r2"]

    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(conf)

    lock = threading.Lock()
    statuses = {}
    phases = set()

    def on_status(sample):
        st = json.loads(sample.payload.to_string())
        with lock:
            statuses[st["robot"]] = st
            if st.get("phase") is not None:
                phases.add(st["phase"])

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

    def rejected():
        with lock:
            return {r: dict(statuses[r]["auth"]["rejected"]) for r in robots}

    wait_for(lambda: all(r in statuses for r in robots), "every robot's status")
    mission_id = f"frames-{int(time.time() * 1000)}"
    body = json.dumps({
        "id": mission_id,
        "issued_at": int(time.time() * 1000),
        "graph": open(graph_file).read(),
        "scenario": open(scenario_file).read(),
    })
    mac = hmac.new(key, b"bite-mission-v1\0" + team.encode() + b"\0" + body.encode(),
                   hashlib.sha256).hexdigest()
    session.put(f"bite/{team}/mission", json.dumps({"body": body, "mac": mac}))
    wait_for(lambda: all(statuses[r]["state"] == "running" and statuses[r]["t"] > 1.0
                         for r in robots), "the mission to run")
    time.sleep(0.6)  # one more status from everyone
    before = rejected()

    tag = fnv1a64(b"id\0" + mission_id.encode())
    # A heartbeat of an older payload version (4): only the frame checks
    # matter here, and the robots act on no part of it.
    heartbeat = bytes([4, 0, 0])
    now_us = time.time_ns() // 1000
    good = frame(key, team, tag, 3, 1, now_us, heartbeat)
    forged = frame(b"\x11" * 32, team, tag, 3, 1, now_us + 1, heartbeat)
    misplaced = frame(key, team, tag, 3, 1, now_us + 2, heartbeat)
    session.put(f"bite/{team}/net/r1", good)
    time.sleep(0.3)
    session.put(f"bite/{team}/net/r1", good)  # the same frame again: a replay
    session.put(f"bite/{team}/net/r1", forged)
    session.put(f"bite/{team}/net/r2", misplaced)
    time.sleep(1.5)  # statuses go out every 0.5 s
    after = rejected()

    wait_for(lambda: all(statuses[r]["state"] == "completed" for r in robots),
             "the mission to complete")
    with lock:
        report = {
            "mission_id": mission_id,
            "tag": tag,
            "before": before,
            "after": after,
            "phases": sorted(phases),
            "unknown_phases": sorted(phases - PHASES),
            "final": {r: statuses[r]["state"] for r in robots},
        }
    sub.undeclare()
    session.close()
    print(json.dumps(report))


if __name__ == "__main__":
    main()
