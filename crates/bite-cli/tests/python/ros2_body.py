"""A ROS 2 peer written from rmw_zenoh's conventions (docs/ros2.md), with
an independent CDR codec (rosbags), against `bite sim serve --ros2`.

Usage: ros2_body.py ENDPOINT ROBOT TIMEOUT_S

  - finds the server's publisher of /ROBOT/odom among the liveliness tokens
    (@ros2_lv/0/**), with the Odometry type name and hash;
  - subscribes to the odometry and scan data keys, checks each sample's
    attachment (33 bytes: sequence, timestamp, 0x10, GID) and decodes the
    CDR with rosbags;
  - publishes Twist commands (forward 0.2 m/s, turning 0.5 rad/s) on
    /ROBOT/cmd_vel with rmw_zenoh's attachment, and watches the odometry
    report the body moving;
  - prints a JSON report.
"""

import json
import struct
import sys
import threading
import time

import zenoh
from rosbags.typesys import Stores, get_typestore

ts = get_typestore(Stores.ROS2_JAZZY)
ODOM, SCAN, TWIST = "nav_msgs/msg/Odometry", "sensor_msgs/msg/LaserScan", "geometry_msgs/msg/Twist"


def key(domain, topic, typename):
    pkg, _, name = typename.split("/")
    return f"{domain}/{topic.strip('/')}/{pkg}::msg::dds_::{name}_/{ts.hash_rihs01(typename)}"


def attachment(seq, gid):
    return struct.pack("<qq", seq, time.time_ns()) + bytes([16]) + gid


def main():
    endpoint, robot, timeout = sys.argv[1], sys.argv[2], float(sys.argv[3])
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(conf)
    report = {"tokens": [], "odom": 0, "scan": 0, "bad_attachments": 0, "first": None, "last": None,
              "frame_id": None, "child_frame_id": None, "scan_rays": None, "moved_forward": None}
    lock = threading.Lock()

    def attached_ok(sample):
        a = sample.attachment
        if a is None:
            return False
        b = a.to_bytes()
        return len(b) == 33 and b[16] == 16

    def on_odom(sample):
        with lock:
            if not attached_ok(sample):
                report["bad_attachments"] += 1
                return
            m = ts.deserialize_cdr(sample.payload.to_bytes(), ODOM)
            p = m.pose.pose.position
            report["odom"] += 1
            report["frame_id"], report["child_frame_id"] = m.header.frame_id, m.child_frame_id
            here = [p.x, p.y, m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, m.twist.twist.linear.x,
                    m.twist.twist.angular.z]
            if report["first"] is None:
                report["first"] = here
            report["last"] = here

    def on_scan(sample):
        with lock:
            if not attached_ok(sample):
                report["bad_attachments"] += 1
                return
            m = ts.deserialize_cdr(sample.payload.to_bytes(), SCAN)
            report["scan"] += 1
            report["scan_rays"] = len(m.ranges)

    subs = [session.declare_subscriber(key(0, f"/{robot}/odom", ODOM), on_odom),
            session.declare_subscriber(key(0, f"/{robot}/scan", SCAN), on_scan)]
    # Discovery: the body's endpoints as liveliness tokens.
    deadline = time.time() + timeout
    while time.time() < deadline and not report["tokens"]:
        for reply in session.liveliness().get("@ros2_lv/0/**"):
            try:
                report["tokens"].append(str(reply.ok.key_expr))
            except Exception:
                pass
        time.sleep(0.2)
    # Drive: a Twist ten times a second for two seconds.
    V3, T = ts.types["geometry_msgs/msg/Vector3"], ts.types[TWIST]
    twist = T(linear=V3(x=0.2, y=0.0, z=0.0), angular=V3(x=0.0, y=0.0, z=0.5))
    payload = bytes(ts.serialize_cdr(twist, TWIST))
    gid = bytes(range(16))
    pub = session.declare_publisher(key(0, f"/{robot}/cmd_vel", TWIST))
    while time.time() < deadline and report["odom"] == 0:
        time.sleep(0.1)
    with lock:
        start = report["last"]
    for seq in range(1, 21):
        pub.put(payload, attachment=attachment(seq, gid))
        time.sleep(0.1)
    time.sleep(0.3)
    with lock:
        end = report["last"]
        if start and end:
            report["moved_forward"] = ((end[0] - start[0]) ** 2 + (end[1] - start[1]) ** 2) ** 0.5
            report["speed_reported"] = end[3]
    for s in subs:
        s.undeclare()
    session.close()
    print(json.dumps(report))


if __name__ == "__main__":
    main()
