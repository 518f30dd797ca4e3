//! A robot's body in ROS 2 terms, on rmw_zenoh's wire conventions, so that
//! a robot running ROS 2 with `rmw_zenoh_cpp` (Jazzy, Rolling) drives and
//! senses through `bite robot --ros2` without a bridge:
//!
//! | topic (under the robot's namespace) | type | direction |
//! |---|---|---|
//! | `cmd_vel` | `geometry_msgs/msg/Twist` | mind → body |
//! | `odom` | `nav_msgs/msg/Odometry` | body → mind |
//! | `scan` | `sensor_msgs/msg/LaserScan` | body → mind |
//! | `bite/status` | `std_msgs/msg/String` (the status JSON) | mind → anyone |
//!
//! What rmw_zenoh expects, and where it says so (docs/ros2.md has the
//! sources): data on `<domain>/<topic without its outer slashes>/<type
//! mangled as pkg::msg::dds_::Name_>/<RIHS01 type hash>`; a payload of the
//! 4-byte CDR encapsulation header then little-endian plain CDR; on every
//! sample an attachment of 33 bytes (sequence number i64, source timestamp
//! i64 in ns, then the 16-byte publisher GID after its length byte) without
//! which a ROS subscriber drops the sample; and liveliness tokens under
//! `@ros2_lv/` so that `ros2 topic list/info/echo` see the endpoints.
//!
//! Encoding and decoding are pure; the runtime (`robot.rs`, `server.rs`)
//! does the IO. Payloads were checked byte for byte against an independent
//! codec (the Python `rosbags` package, `tests/ros2.rs`).

use serde::{Deserialize, Deserializer, Serialize};

/// The longest string taken from a ROS 2 message (frame ids, the status).
pub const MAX_STRING: usize = 1 << 16;

/// Read a CDR string as the sequence of bytes it is on the wire (length,
/// bytes, NUL), so that a forged length allocates nothing: bytes are taken
/// one at a time and the input ends first. (The `cdr` crate's own string
/// reader allocates the claimed length before it reads.)
fn cdr_string<'de, D: Deserializer<'de>>(d: D) -> Result<String, D::Error> {
    struct Bytes;
    impl<'de> serde::de::Visitor<'de> for Bytes {
        type Value = String;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            write!(f, "a CDR string of at most {MAX_STRING} bytes")
        }
        fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<String, A::Error> {
            let mut v = Vec::new();
            while let Some(b) = seq.next_element::<u8>()? {
                if v.len() > MAX_STRING {
                    return Err(serde::de::Error::custom("string too long"));
                }
                v.push(b);
            }
            if v.pop() != Some(0) {
                return Err(serde::de::Error::custom("string without its NUL"));
            }
            String::from_utf8(v).map_err(serde::de::Error::custom)
        }
    }
    d.deserialize_seq(Bytes)
}

/// `builtin_interfaces/msg/Time`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds, below 1e9.
    pub nanosec: u32,
}

impl Time {
    /// A time in seconds (clamped to what the message can hold).
    pub fn from_secs(t: f64) -> Time {
        let t = if t.is_finite() { t.max(0.0) } else { 0.0 };
        let sec = t.floor().min(i32::MAX as f64);
        Time {
            sec: sec as i32,
            nanosec: (((t - sec) * 1e9).round() as u32).min(999_999_999),
        }
    }
    /// Seconds.
    pub fn as_secs(&self) -> f64 {
        self.sec as f64 + self.nanosec as f64 * 1e-9
    }
}

/// `std_msgs/msg/Header`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// When.
    pub stamp: Time,
    /// The frame.
    #[serde(deserialize_with = "cdr_string")]
    pub frame_id: String,
}

/// `geometry_msgs/msg/Vector3`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/msg/Twist`: the velocity command (body frame: `linear.x`
/// forward, `linear.y` left, `angular.z` counter-clockwise turn rate).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    /// m/s.
    pub linear: Vector3,
    /// rad/s.
    pub angular: Vector3,
}

/// `geometry_msgs/msg/Point` (same layout as `Vector3`).
pub type Point = Vector3;

/// `geometry_msgs/msg/Quaternion`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

impl Quaternion {
    /// A rotation about z.
    pub fn yaw(yaw: f64) -> Quaternion {
        Quaternion {
            x: 0.0,
            y: 0.0,
            z: (yaw / 2.0).sin(),
            w: (yaw / 2.0).cos(),
        }
    }
    /// The rotation about z (heading), radians.
    pub fn to_yaw(&self) -> f64 {
        (2.0 * (self.w * self.z + self.x * self.y))
            .atan2(1.0 - 2.0 * (self.y * self.y + self.z * self.z))
    }
}

/// `geometry_msgs/msg/Pose`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Where.
    pub position: Point,
    /// Which way.
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/PoseWithCovariance`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    /// The pose.
    pub pose: Pose,
    /// Row-major 6×6 covariance (x, y, z, rotations about x, y, z).
    #[serde(with = "serde_big_array::BigArray")]
    pub covariance: [f64; 36],
}

/// `geometry_msgs/msg/TwistWithCovariance`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    /// The twist.
    pub twist: Twist,
    /// Row-major 6×6 covariance.
    #[serde(with = "serde_big_array::BigArray")]
    pub covariance: [f64; 36],
}

/// `nav_msgs/msg/Odometry`: the body's pose estimate and velocity.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    /// Stamp and the frame of the pose (`odom`).
    pub header: Header,
    /// The frame of the twist (the robot's base).
    #[serde(deserialize_with = "cdr_string")]
    pub child_frame_id: String,
    /// Pose in `header.frame_id`.
    pub pose: PoseWithCovariance,
    /// Velocity in `child_frame_id`.
    pub twist: TwistWithCovariance,
}

/// `sensor_msgs/msg/LaserScan`: the range rays.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LaserScan {
    /// Stamp and the sensor's frame.
    pub header: Header,
    /// Angle of the first ray, rad (0 = ahead, counter-clockwise).
    pub angle_min: f32,
    /// Angle of the last ray.
    pub angle_max: f32,
    /// Between two rays.
    pub angle_increment: f32,
    /// Between two measurements, s.
    pub time_increment: f32,
    /// Between two scans, s.
    pub scan_time: f32,
    /// Shortest range measured, m.
    pub range_min: f32,
    /// Longest range measured, m.
    pub range_max: f32,
    /// One per ray; `+inf` where nothing was hit within `range_max`.
    pub ranges: Vec<f32>,
    /// Empty (not measured).
    pub intensities: Vec<f32>,
}

/// `std_msgs/msg/String`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RosString {
    /// The text.
    #[serde(deserialize_with = "cdr_string")]
    pub data: String,
}

/// A ROS 2 message type BITE speaks: its name, its DDS-mangled name and its
/// RIHS01 type hash (REP-2016; computed with `rosbags`, checked against
/// public rmw_zenoh transcripts).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MsgType {
    /// `pkg/msg/Name`.
    pub name: &'static str,
    /// `pkg::msg::dds_::Name_`.
    pub mangled: &'static str,
    /// `RIHS01_<64 hex>`.
    pub hash: &'static str,
}

/// `geometry_msgs/msg/Twist`.
pub const TWIST: MsgType = MsgType {
    name: "geometry_msgs/msg/Twist",
    mangled: "geometry_msgs::msg::dds_::Twist_",
    hash: "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
};
/// `nav_msgs/msg/Odometry`.
pub const ODOMETRY: MsgType = MsgType {
    name: "nav_msgs/msg/Odometry",
    mangled: "nav_msgs::msg::dds_::Odometry_",
    hash: "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
};
/// `sensor_msgs/msg/LaserScan`.
pub const LASER_SCAN: MsgType = MsgType {
    name: "sensor_msgs/msg/LaserScan",
    mangled: "sensor_msgs::msg::dds_::LaserScan_",
    hash: "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828",
};
/// `std_msgs/msg/String`.
pub const STRING: MsgType = MsgType {
    name: "std_msgs/msg/String",
    mangled: "std_msgs::msg::dds_::String_",
    hash: "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
};

/// What can be wrong with a ROS 2 sample.
#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    /// The payload is not the CDR of the expected type.
    #[error("not a CDR-encoded {0}: {1}")]
    Cdr(&'static str, String),
    /// The attachment is not rmw_zenoh's.
    #[error("the attachment is not rmw_zenoh's (33 bytes: sequence, timestamp, GID)")]
    Attachment,
}

/// Encode a message: the encapsulation header (CDR, little-endian) and
/// its plain CDR body.
pub fn encode<T: Serialize>(msg: &T) -> Vec<u8> {
    cdr::serialize::<_, _, cdr::CdrLe>(msg, cdr::Infinite).unwrap_or_default()
}

/// Decode a message of type `ty` (either byte order).
pub fn decode<T: for<'de> Deserialize<'de>>(ty: &MsgType, bytes: &[u8]) -> Result<T, Ros2Error> {
    cdr::deserialize::<T>(bytes).map_err(|e| Ros2Error::Cdr(ty.name, e.to_string()))
}

/// The topic name under a namespace: `ns` `/r0`, topic `odom` → `/r0/odom`.
pub fn topic(namespace: &str, name: &str) -> String {
    let ns = namespace.trim_matches('/');
    if ns.is_empty() {
        format!("/{name}")
    } else {
        format!("/{ns}/{name}")
    }
}

/// rmw_zenoh's data key of a topic: `<domain>/<topic without its outer
/// slashes>/<mangled type>/<type hash>`.
pub fn data_key(domain: u32, topic: &str, ty: &MsgType) -> String {
    let t = topic.strip_prefix('/').unwrap_or(topic);
    let t = t.strip_suffix('/').unwrap_or(t);
    format!("{domain}/{t}/{}/{}", ty.mangled, ty.hash)
}

/// The attachment rmw_zenoh puts on (and requires of) every sample:
/// sequence number and source timestamp (ns since the Unix epoch), little-
/// endian i64s, then the 16-byte publisher GID after its length (16).
pub fn attachment(sequence: i64, timestamp_ns: i64, gid: &[u8; 16]) -> [u8; 33] {
    let mut a = [0u8; 33];
    a[..8].copy_from_slice(&sequence.to_le_bytes());
    a[8..16].copy_from_slice(&timestamp_ns.to_le_bytes());
    a[16] = 16;
    a[17..].copy_from_slice(gid);
    a
}

/// Read an attachment: (sequence number, source timestamp ns, GID).
pub fn parse_attachment(a: &[u8]) -> Result<(i64, i64, [u8; 16]), Ros2Error> {
    if a.len() < 33 || a[16] != 16 {
        return Err(Ros2Error::Attachment);
    }
    let i = |r: std::ops::Range<usize>| a[r].try_into().map(i64::from_le_bytes);
    let (Ok(seq), Ok(ts)) = (i(0..8), i(8..16)) else {
        return Err(Ros2Error::Attachment);
    };
    let mut gid = [0u8; 16];
    gid.copy_from_slice(&a[17..33]);
    Ok((seq, ts, gid))
}

/// A name in a liveliness token: every `/` becomes `%`; empty is `%`.
fn mangle(s: &str) -> String {
    if s.is_empty() {
        "%".into()
    } else {
        s.replace('/', "%")
    }
}

/// rmw_zenoh's QoS field of a token for reliable, volatile, keep-last
/// `depth` (each item written only where it differs from rmw_zenoh's
/// default: keep-last 42, reliable, volatile, infinite durations).
pub fn qos_keep_last(depth: u32) -> String {
    let d = if depth == 42 {
        String::new()
    } else {
        depth.to_string()
    };
    format!("::,{d}:,:,:,,")
}

/// What a liveliness token announces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Entity {
    /// A node (`NN`).
    Node,
    /// A publisher (`MP`).
    Publisher,
    /// A subscription (`MS`).
    Subscription,
}

/// A node's identity on the ROS 2 graph: domain, the Zenoh session id,
/// the node's entity id, namespace and name.
#[derive(Clone, Debug)]
pub struct Node {
    /// `ROS_DOMAIN_ID`.
    pub domain: u32,
    /// The Zenoh session id (lowercase hex).
    pub zid: String,
    /// The node's entity id.
    pub id: u32,
    /// Namespace (`/r0`; `/` for none).
    pub namespace: String,
    /// Node name.
    pub name: String,
}

impl Node {
    /// The liveliness token of the node itself (`id`: its entity id), or
    /// of one of its endpoints (`id`: the endpoint's entity id) on `topic`.
    pub fn token(&self, kind: Entity, id: u32, topic: Option<(&str, &MsgType)>) -> String {
        let code = match kind {
            Entity::Node => "NN",
            Entity::Publisher => "MP",
            Entity::Subscription => "MS",
        };
        let ns = if self.namespace.is_empty() {
            "/"
        } else {
            &self.namespace
        };
        let mut t = format!(
            "@ros2_lv/{}/{}/{}/{}/{code}/%/{}/{}",
            self.domain,
            self.zid,
            self.id,
            id,
            mangle(ns),
            mangle(&self.name)
        );
        if let Some((topic, ty)) = topic {
            t.push_str(&format!(
                "/{}/{}/{}/{}",
                mangle(topic),
                ty.mangled,
                ty.hash,
                qos_keep_last(10)
            ));
        }
        t
    }
}

/// A publisher's GID: 16 bytes, stable for its token (FNV-1a over the
/// token, twice with different seeds). ROS subscribers copy it into the
/// message info; any stable 16 bytes will do.
pub fn gid_of(token: &str) -> [u8; 16] {
    let h = |seed: u64| {
        let mut x: u64 = 0xcbf29ce484222325 ^ seed;
        for b in token.bytes() {
            x ^= b as u64;
            x = x.wrapping_mul(0x100000001b3);
        }
        x
    };
    let mut g = [0u8; 16];
    g[..8].copy_from_slice(&h(0).to_le_bytes());
    g[8..].copy_from_slice(&h(0x9e3779b97f4a7c15).to_le_bytes());
    g
}

/// Range rays as a `LaserScan`: `hits` are (angle relative to the heading,
/// distance) of the rays that hit something; `count` rays evenly spread
/// over the full circle from straight ahead (ray `k` at `2πk/count`, as the
/// simulator casts them); the others read `+inf`.
pub fn scan_of(
    stamp: f64,
    frame: &str,
    count: usize,
    range: f64,
    hits: &[(f64, f64)],
) -> LaserScan {
    let count = count.max(1);
    let inc = std::f64::consts::TAU / count as f64;
    let mut ranges = vec![f32::INFINITY; count];
    for &(a, d) in hits {
        let k = ((a / inc).round() as i64).rem_euclid(count as i64) as usize;
        ranges[k] = ranges[k].min(d as f32);
    }
    LaserScan {
        header: Header {
            stamp: Time::from_secs(stamp),
            frame_id: frame.into(),
        },
        angle_min: 0.0,
        angle_max: (inc * (count - 1) as f64) as f32,
        angle_increment: inc as f32,
        time_increment: 0.0,
        scan_time: 0.0,
        range_min: 0.0,
        range_max: range as f32,
        ranges,
        intensities: Vec::new(),
    }
}

/// The rays of a `LaserScan` that hit something: (angle, distance).
pub fn hits_of(scan: &LaserScan) -> Vec<(f64, f64)> {
    (scan.ranges.iter().enumerate())
        .filter(|(_, r)| r.is_finite() && **r >= scan.range_min && **r <= scan.range_max)
        .map(|(k, r)| {
            let a = scan.angle_min as f64 + k as f64 * scan.angle_increment as f64;
            (a, *r as f64)
        })
        .collect()
}

/// An `Odometry` of a planar pose (`[x, y, heading]`) in `frames.0` and a
/// body velocity (`[forward, turn]`) in `frames.1`.
pub fn odometry(stamp: f64, frames: (&str, &str), pose: [f64; 3], velocity: [f64; 2]) -> Odometry {
    let [x, y, heading] = pose;
    let [forward, turn] = velocity;
    let (frame, child) = frames;
    Odometry {
        header: Header {
            stamp: Time::from_secs(stamp),
            frame_id: frame.into(),
        },
        child_frame_id: child.into(),
        pose: PoseWithCovariance {
            pose: Pose {
                position: Point { x, y, z: 0.0 },
                orientation: Quaternion::yaw(heading),
            },
            covariance: [0.0; 36],
        },
        twist: TwistWithCovariance {
            twist: Twist {
                linear: Vector3 {
                    x: forward,
                    y: 0.0,
                    z: 0.0,
                },
                angular: Vector3 {
                    x: 0.0,
                    y: 0.0,
                    z: turn,
                },
            },
            covariance: [0.0; 36],
        },
    }
}

/// Where a team's bodies are on the ROS 2 graph: each robot's topics are
/// under `/<robot name>` in this domain (`ROS_DOMAIN_ID`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Ros2Options {
    /// `ROS_DOMAIN_ID`.
    pub domain: u32,
}

/// Wall time now, ns since the Unix epoch (for attachments' source
/// timestamps, which rmw_zenoh takes from the system clock).
fn wall_ns() -> i64 {
    (crate::net::unix_micros() as i64).saturating_mul(1000)
}

/// Entity ids, unique in every session of this process (rmw_zenoh keeps
/// one counter per context; nodes sharing a session must not share ids).
static NEXT_ENTITY: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);

fn next_entity() -> u32 {
    NEXT_ENTITY.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

/// A node on the ROS 2 graph over a Zenoh session: its liveliness tokens
/// (so `ros2 node list` / `ros2 topic info` see it and its endpoints).
pub struct RosNode {
    node: Node,
    tokens: Vec<zenoh::liveliness::LivelinessToken>,
}

/// A publisher: its data key, sequence number and GID.
pub struct RosPublisher {
    key: String,
    sequence: i64,
    gid: [u8; 16],
}

impl RosNode {
    /// Declare node `name` in `namespace` (e.g. `/r0`).
    pub fn declare(
        session: &zenoh::Session,
        domain: u32,
        namespace: &str,
        name: &str,
    ) -> Result<RosNode, zenoh::Error> {
        use zenoh::Wait;
        let id = next_entity();
        let node = Node {
            domain,
            zid: session.zid().to_string(),
            id,
            namespace: namespace.to_string(),
            name: name.to_string(),
        };
        let token = session
            .liveliness()
            .declare_token(node.token(Entity::Node, id, None))
            .wait()?;
        Ok(RosNode {
            node,
            tokens: vec![token],
        })
    }

    fn endpoint(
        &mut self,
        session: &zenoh::Session,
        kind: Entity,
        topic: &str,
        ty: &MsgType,
    ) -> Result<(String, String), zenoh::Error> {
        use zenoh::Wait;
        let id = next_entity();
        let token = self.node.token(kind, id, Some((topic, ty)));
        self.tokens
            .push(session.liveliness().declare_token(token.clone()).wait()?);
        Ok((data_key(self.node.domain, topic, ty), token))
    }

    /// Announce a publisher on `topic` (a full name: `/r0/cmd_vel`).
    pub fn publisher(
        &mut self,
        session: &zenoh::Session,
        topic: &str,
        ty: &MsgType,
    ) -> Result<RosPublisher, zenoh::Error> {
        let (key, token) = self.endpoint(session, Entity::Publisher, topic, ty)?;
        Ok(RosPublisher {
            key,
            sequence: 0,
            gid: gid_of(&token),
        })
    }

    /// Announce a subscription on `topic`; returns the data key to
    /// subscribe to.
    pub fn subscription(
        &mut self,
        session: &zenoh::Session,
        topic: &str,
        ty: &MsgType,
    ) -> Result<String, zenoh::Error> {
        Ok(self.endpoint(session, Entity::Subscription, topic, ty)?.0)
    }
}

impl RosPublisher {
    /// Publish a message with rmw_zenoh's attachment.
    pub fn put<T: Serialize>(&mut self, session: &zenoh::Session, msg: &T) {
        use zenoh::Wait;
        self.sequence += 1;
        let a = attachment(self.sequence, wall_ns(), &self.gid);
        let _ = session
            .put(&self.key, encode(msg))
            .attachment(a.to_vec())
            .wait();
    }

    /// The data key it publishes on.
    pub fn key(&self) -> &str {
        &self.key
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(b: &[u8]) -> String {
        b.iter().map(|x| format!("{x:02x}")).collect()
    }

    #[test]
    fn twist_and_string_encode_as_rosbags_does() {
        // Bytes from `rosbags` (Stores.ROS2_JAZZY, serialize_cdr).
        let t = Twist {
            linear: Vector3 {
                x: 0.5,
                ..Default::default()
            },
            angular: Vector3 {
                z: -0.25,
                ..Default::default()
            },
        };
        assert_eq!(
            hex(&encode(&t)),
            "00010000000000000000e03f0000000000000000000000000000000000000000000000000000000000000000000000000000d0bf"
        );
        let s = RosString { data: "hi".into() };
        assert_eq!(hex(&encode(&s)), "0001000003000000686900");
        let back: Twist = decode(&TWIST, &encode(&t)).unwrap();
        assert_eq!(back, t);
    }

    #[test]
    fn keys_tokens_and_attachments_follow_rmw_zenoh() {
        assert_eq!(
            data_key(0, "/robot1/odom", &ODOMETRY),
            "0/robot1/odom/nav_msgs::msg::dds_::Odometry_/RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"
        );
        assert_eq!(topic("/r0", "cmd_vel"), "/r0/cmd_vel");
        assert_eq!(topic("/", "cmd_vel"), "/cmd_vel");
        let node = Node {
            domain: 0,
            zid: "z".into(),
            id: 0,
            namespace: "/".into(),
            name: "teleop".into(),
        };
        assert_eq!(
            node.token(Entity::Node, 0, None),
            "@ros2_lv/0/z/0/0/NN/%/%/teleop"
        );
        assert_eq!(
            node.token(Entity::Publisher, 1, Some(("/cmd_vel", &TWIST))),
            "@ros2_lv/0/z/0/1/MP/%/%/teleop/%cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a/::,10:,:,:,,"
        );
        let gid: [u8; 16] = std::array::from_fn(|i| i as u8);
        let a = attachment(1, 1700000000123456789, &gid);
        assert_eq!(
            hex(&a),
            "010000000000000015cd853dfe9c971710000102030405060708090a0b0c0d0e0f"
        );
        assert_eq!(parse_attachment(&a).unwrap(), (1, 1700000000123456789, gid));
        assert!(parse_attachment(&a[..20]).is_err());
    }

    #[test]
    fn a_forged_string_length_is_an_error_not_an_allocation() {
        let mut o = encode(&odometry(1.0, ("odom", "b"), [0.0; 3], [0.0; 2]));
        // The frame id's length (after the header and the stamp).
        o[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(decode::<Odometry>(&ODOMETRY, &o).is_err());
        let mut s = encode(&RosString { data: "hi".into() });
        s[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(decode::<RosString>(&STRING, &s).is_err());
        // A string without its NUL.
        let bad = [0u8, 1, 0, 0, 2, 0, 0, 0, b'h', b'i'];
        assert!(decode::<RosString>(&STRING, &bad).is_err());
    }

    #[test]
    fn odd_ray_counts_keep_their_angles() {
        let tau = std::f64::consts::TAU;
        let hits: Vec<(f64, f64)> = (0..5)
            .map(|k| (tau * k as f64 / 5.0, 1.0 + k as f64))
            .collect();
        let back = hits_of(&scan_of(0.0, "s", 5, 10.0, &hits));
        assert_eq!(back.len(), 5);
        for ((a, d), (b, e)) in hits.iter().zip(&back) {
            assert!((a - b).abs() < 1e-5 && (d - e).abs() < 1e-5, "{back:?}");
        }
    }

    #[test]
    fn scans_and_poses_go_there_and_back() {
        let hits = vec![(0.0, 1.5), (std::f64::consts::FRAC_PI_2, 0.7)];
        let s = scan_of(3.25, "r0/base_scan", 16, 4.0, &hits);
        assert_eq!(s.ranges.len(), 16);
        let back = hits_of(&decode::<LaserScan>(&LASER_SCAN, &encode(&s)).unwrap());
        assert_eq!(back.len(), 2);
        for ((a, d), (b, e)) in hits.iter().zip(&back) {
            assert!((a - b).abs() < 1e-6 && (d - e).abs() < 1e-6, "{back:?}");
        }
        let o = odometry(1.5, ("odom", "r0/base_link"), [1.0, 2.0, 2.5], [0.3, -0.1]);
        let o2: Odometry = decode(&ODOMETRY, &encode(&o)).unwrap();
        assert!((o2.pose.pose.orientation.to_yaw() - 2.5).abs() < 1e-12);
        assert_eq!(
            o2.header.stamp,
            Time {
                sec: 1,
                nanosec: 500_000_000
            }
        );
        assert!(decode::<Odometry>(&ODOMETRY, &[0, 1, 0, 0, 1]).is_err());
    }
}
