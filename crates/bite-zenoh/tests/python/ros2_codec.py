"""Check BITE's ROS 2 payloads with an independent CDR codec (rosbags).

Reads JSON from stdin: {"twist": hex, "odometry": hex, "scan": hex, "string": hex}
(BITE's encodings of known messages). Decodes each with rosbags, encodes
rosbags' own copy of the same message, and prints JSON: the decoded fields,
whether the bytes are identical, and rosbags' RIHS01 hashes of the types.
"""
import json
import sys

import numpy as np
from rosbags.typesys import Stores, get_typestore

ts = get_typestore(Stores.ROS2_JAZZY)
T = ts.types
V3 = T["geometry_msgs/msg/Vector3"]
H = T["std_msgs/msg/Header"]
Tm = T["builtin_interfaces/msg/Time"]

twist = T["geometry_msgs/msg/Twist"](linear=V3(x=0.5, y=0.0, z=0.0), angular=V3(x=0.0, y=0.0, z=-0.25))
odom = T["nav_msgs/msg/Odometry"](
    header=H(stamp=Tm(sec=12, nanosec=500000000), frame_id="odom"),
    child_frame_id="r0/base_link",
    pose=T["geometry_msgs/msg/PoseWithCovariance"](
        pose=T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=0.0),
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        ),
        covariance=np.zeros(36),
    ),
    twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
)
scan = T["sensor_msgs/msg/LaserScan"](
    header=H(stamp=Tm(sec=1, nanosec=2), frame_id="laser"),
    angle_min=-1.0, angle_max=1.0, angle_increment=1.0, time_increment=0.0, scan_time=0.1,
    range_min=0.1, range_max=10.0,
    ranges=np.array([1.0, 2.0, 3.0], dtype=np.float32),
    intensities=np.array([], dtype=np.float32),
)
string = T["std_msgs/msg/String"](data="hi")
theirs = {
    "twist": (twist, "geometry_msgs/msg/Twist"),
    "odometry": (odom, "nav_msgs/msg/Odometry"),
    "scan": (scan, "sensor_msgs/msg/LaserScan"),
    "string": (string, "std_msgs/msg/String"),
}
ours = json.load(sys.stdin)
out = {"identical": {}, "decoded": {}, "hashes": {}}
for name, (msg, typename) in theirs.items():
    mine = bytes.fromhex(ours[name])
    out["identical"][name] = bytes(ts.serialize_cdr(msg, typename)) == mine
    d = ts.deserialize_cdr(mine, typename)
    if name == "twist":
        out["decoded"][name] = [d.linear.x, d.angular.z]
    elif name == "odometry":
        out["decoded"][name] = [d.header.stamp.sec, d.header.stamp.nanosec, d.header.frame_id,
                                d.child_frame_id, d.pose.pose.position.x, d.pose.pose.position.y,
                                d.pose.pose.orientation.w, d.twist.twist.linear.x]
    elif name == "scan":
        out["decoded"][name] = [d.header.frame_id, float(d.angle_min), [float(x) for x in d.ranges]]
    else:
        out["decoded"][name] = d.data
    out["hashes"][typename] = ts.hash_rihs01(typename)
print(json.dumps(out))
