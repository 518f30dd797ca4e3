//! BITE's ROS 2 payloads against an independent CDR codec: the Python
//! `rosbags` package (PyPI, in a virtual environment the test makes) decodes
//! what BITE encodes, encodes the same messages byte for byte, and computes
//! the same RIHS01 type hashes BITE puts in its keys.

use bite_zenoh::ros2::{self, Header, Odometry, RosString, Time, Twist, Vector3};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

#[path = "../../bite-cli/tests/support/venv.rs"]
mod venv;

fn python_with_rosbags() -> PathBuf {
    venv::python_venv(
        "venv-rosbags",
        "import rosbags.typesys, numpy",
        &["rosbags==0.11.*"],
    )
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

#[test]
fn rosbags_reads_what_bite_writes_and_agrees_on_type_hashes() {
    let twist = Twist {
        linear: Vector3 {
            x: 0.5,
            y: 0.0,
            z: 0.0,
        },
        angular: Vector3 {
            x: 0.0,
            y: 0.0,
            z: -0.25,
        },
    };
    let mut odom: Odometry =
        ros2::odometry(12.5, ("odom", "r0/base_link"), [1.0, 2.0, 0.0], [0.5, 0.0]);
    odom.twist.twist = twist;
    let scan = ros2::LaserScan {
        header: Header {
            stamp: Time { sec: 1, nanosec: 2 },
            frame_id: "laser".into(),
        },
        angle_min: -1.0,
        angle_max: 1.0,
        angle_increment: 1.0,
        time_increment: 0.0,
        scan_time: 0.1,
        range_min: 0.1,
        range_max: 10.0,
        ranges: vec![1.0, 2.0, 3.0],
        intensities: Vec::new(),
    };
    let ours = serde_json::json!({
        "twist": hex(&ros2::encode(&twist)),
        "odometry": hex(&ros2::encode(&odom)),
        "scan": hex(&ros2::encode(&scan)),
        "string": hex(&ros2::encode(&RosString { data: "hi".into() })),
    });
    let mut child = Command::new(python_with_rosbags())
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/ros2_codec.py"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python runs");
    child
        .stdin
        .take()
        .unwrap()
        .write_all(ours.to_string().as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    for name in ["twist", "odometry", "scan", "string"] {
        assert_eq!(v["identical"][name], true, "{name}: {v}");
    }
    assert_eq!(v["decoded"]["twist"], serde_json::json!([0.5, -0.25]));
    assert_eq!(
        v["decoded"]["odometry"],
        serde_json::json!([12, 500000000, "odom", "r0/base_link", 1.0, 2.0, 1.0, 0.5])
    );
    assert_eq!(v["decoded"]["string"], "hi");
    for ty in [ros2::TWIST, ros2::ODOMETRY, ros2::LASER_SCAN, ros2::STRING] {
        assert_eq!(v["hashes"][ty.name], ty.hash, "{}", ty.name);
    }
}
