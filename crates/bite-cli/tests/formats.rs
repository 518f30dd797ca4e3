//! Runs in robotics' formats, end to end: `bite run --mcap` read back by the
//! MCAP format's own readers (the Rust `mcap` crate, and the Python `mcap`
//! package from PyPI), `bite log convert`, and the live Foxglove WebSocket
//! server driven by an independent client.

// The live test is a network test: its deadlines are wall time.
#![allow(clippy::disallowed_methods)]

use prost::Message as _;
use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod support {
    pub mod venv;
}

fn bite() -> Command {
    Command::new(env!("CARGO_BIN_EXE_bite"))
}

fn scratch(name: &str) -> PathBuf {
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("bite-formats-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("scratch dir");
    d
}

/// What an MCAP file holds, read with the `mcap` crate: per topic, the
/// schema name, message encoding and messages (log time, bytes).
struct Mcap {
    topics: Topics,
}

/// Topic → (schema name, message encoding, messages as (log time, bytes)).
type Topics = BTreeMap<String, (String, String, Vec<(u64, Vec<u8>)>)>;

impl Mcap {
    fn read(p: &Path) -> Mcap {
        let bytes = std::fs::read(p).expect("mcap written");
        let mut topics: Topics = BTreeMap::new();
        for m in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
            let m = m.expect("a message");
            let e = topics.entry(m.channel.topic.clone()).or_insert_with(|| {
                (
                    m.channel
                        .schema
                        .as_ref()
                        .map(|s| s.name.clone())
                        .unwrap_or_default(),
                    m.channel.message_encoding.clone(),
                    Vec::new(),
                )
            });
            e.2.push((m.log_time, m.data.to_vec()));
        }
        // The summary section agrees with the messages.
        let summary = mcap::Summary::read(&bytes)
            .expect("readable")
            .expect("a summary");
        let stats = summary.stats.expect("statistics");
        let total: usize = topics.values().map(|t| t.2.len()).sum();
        assert_eq!(stats.message_count as usize, total);
        Mcap { topics }
    }
    fn count(&self, topic: &str) -> usize {
        self.topics.get(topic).map_or(0, |t| t.2.len())
    }
    fn json(&self, topic: &str) -> Vec<serde_json::Value> {
        (self
            .topics
            .get(topic)
            .map(|t| t.2.as_slice())
            .unwrap_or(&[]))
        .iter()
        .map(|(_, b)| serde_json::from_slice(b).expect("JSON message"))
        .collect()
    }
}

/// The command exited 0 (else its standard error is the message).
fn succeeded(out: &std::process::Output) {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn run_formation(d: &Path, extra: &[&str]) -> (PathBuf, PathBuf) {
    let (log, mcap) = (d.join("run.jsonl"), d.join("run.mcap"));
    let out = bite()
        .arg("run")
        .arg("--log")
        .arg(&log)
        .arg("--mcap")
        .arg(&mcap)
        .args(extra)
        .output()
        .expect("bite runs");
    succeeded(&out);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("run.mcap"), "{stdout}");
    (log, mcap)
}

fn records(log: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(log)
        .expect("log")
        .lines()
        .map(|l| serde_json::from_str(l).expect("record"))
        .collect()
}

#[test]
fn a_formation_run_is_an_mcap_file_with_foxglove_schemas() {
    let d = scratch("run");
    let (log, path) = run_formation(&d, &[]);
    let m = Mcap::read(&path);
    for (topic, schema) in [
        ("/scene", "foxglove.SceneUpdate"),
        ("/trails", "foxglove.SceneUpdate"),
        ("/tf", "foxglove.FrameTransforms"),
        ("/poses", "foxglove.PosesInFrame"),
        ("/log", "foxglove.Log"),
        ("/bite/decisions", "bite.Decision"),
        ("/bite/events", "bite.Record"),
        ("/bite/summary", "bite.Summary"),
        ("/bite/r0/stack", "bite.Stack"),
    ] {
        let t = m
            .topics
            .get(topic)
            .unwrap_or_else(|| panic!("no {topic}: {:?}", m.topics.keys()));
        assert_eq!(t.0, schema, "{topic}");
    }
    assert_eq!(m.topics["/scene"].1, "protobuf");
    assert_eq!(m.topics["/bite/decisions"].1, "json");
    let total: usize = m.topics.values().map(|t| t.2.len()).sum();
    assert!(total > 100, "{total} messages");
    // Every record is on /bite/events; every decision on /bite/decisions.
    let recs = records(&log);
    let decided = recs
        .iter()
        .filter(|r| r["event"] == "interaction_decided")
        .count();
    assert_eq!(m.count("/bite/decisions"), decided);
    // The watcher sees poses ten times a second; the log keeps one a second.
    let logged_poses = recs.iter().filter(|r| r["event"] == "poses").count();
    let events = m.json("/bite/events");
    assert_eq!(events.len(), recs.len() - logged_poses + m.count("/poses"));
    assert!(
        m.count("/poses") >= 9 * logged_poses,
        "{} vs {logged_poses}",
        m.count("/poses")
    );
    // Stamped in simulated time: the last scene is at the end of the run.
    let end = recs.last().unwrap()["t"].as_f64().unwrap();
    let last = m.topics["/scene"].2.last().unwrap();
    assert!(
        (last.0 as f64 / 1e9 - end).abs() < 0.5,
        "{} vs {end}",
        last.0
    );
    // The scene draws three robots, the arena, and decodes as the schema.
    let scene = foxglove::messages::SceneUpdate::decode(last.1.as_slice()).expect("SceneUpdate");
    let robots: Vec<&str> = (scene.entities.iter())
        .map(|e| e.id.as_str())
        .filter(|id| id.starts_with("robot/"))
        .collect();
    assert_eq!(robots, ["robot/r0", "robot/r1", "robot/r2"]);
    assert!(scene.entities.iter().any(|e| e.id == "arena"));
    let tf = foxglove::messages::FrameTransforms::decode(m.topics["/tf"].2[0].1.as_slice())
        .expect("FrameTransforms");
    assert_eq!(tf.transforms.len(), 3);
    assert_eq!(tf.transforms[0].parent_frame_id, "world");
    // Each robot's stack ends empty (mission completed), and went through
    // the formation's behaviors.
    let stacks = m.json("/bite/r1/stack");
    assert!(
        stacks
            .iter()
            .any(|s| s["leaf"] == "triangle" || s["depth"].as_u64() > Some(1))
    );
    assert_eq!(stacks.last().unwrap()["depth"], 0);
    let summary = m.json("/bite/summary");
    assert_eq!(summary.len(), 1);
    assert_eq!(summary[0]["outcome"], "completed");
}

#[test]
fn log_convert_gives_the_same_records_and_names_a_bad_line() {
    let d = scratch("convert");
    let (log, path) = run_formation(&d, &["--timed"]);
    let converted = d.join("converted.mcap");
    let out = bite()
        .args(["log", "convert"])
        .arg(&log)
        .arg("-o")
        .arg(&converted)
        .output()
        .expect("bite runs");
    succeeded(&out);
    let (a, b) = (Mcap::read(&path), Mcap::read(&converted));
    // A timed world has no poses: both carry exactly the same messages.
    assert_eq!(a.count("/poses"), 0);
    for (topic, t) in &a.topics {
        assert_eq!(t.2.len(), b.count(topic), "{topic}");
        if t.1 == "json" {
            assert_eq!(a.json(topic), b.json(topic), "{topic}");
        }
    }
    // A malformed line: its file, line and column, exit 2.
    let bad = d.join("bad.jsonl");
    let mut text = std::fs::read_to_string(&log).unwrap();
    text = text.replacen('\n', "\n{\"t\": 1.0, \"event\" oops}\n", 1);
    std::fs::write(&bad, text).unwrap();
    let out = bite()
        .args(["log", "convert"])
        .arg(&bad)
        .arg("-o")
        .arg(d.join("bad.mcap"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.jsonl:2:"), "{err}");
}

/// A virtual environment with the `mcap` package from PyPI.
fn python_with_mcap() -> PathBuf {
    support::venv::python_venv("venv-formats", "import mcap.reader", &["mcap==1.*"])
}

#[test]
fn the_python_mcap_reader_reads_a_run() {
    let d = scratch("python");
    let (_, path) = run_formation(&d, &[]);
    let py = python_with_mcap();
    let script = r#"
import sys, json
from collections import Counter
from mcap.reader import make_reader
with open(sys.argv[1], "rb") as f:
    r = make_reader(f)
    s = r.get_summary()
    schemas = {c.topic: s.schemas[c.schema_id].name for c in s.channels.values()}
    counts = Counter()
    last = None
    for schema, channel, message in r.iter_messages(log_time_order=True):
        counts[channel.topic] += 1
        if last is not None:
            assert message.log_time >= last
        last = message.log_time
    print(json.dumps({"schemas": schemas, "counts": counts, "total": s.statistics.message_count}))
"#;
    let out = Command::new(&py)
        .arg("-c")
        .arg(script)
        .arg(&path)
        .output()
        .expect("python runs");
    succeeded(&out);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let m = Mcap::read(&path);
    assert_eq!(v["schemas"]["/scene"], "foxglove.SceneUpdate");
    assert_eq!(v["schemas"]["/tf"], "foxglove.FrameTransforms");
    assert_eq!(v["schemas"]["/log"], "foxglove.Log");
    for (topic, t) in &m.topics {
        assert_eq!(
            v["counts"][topic].as_u64(),
            Some(t.2.len() as u64),
            "{topic}"
        );
    }
    assert!(v["total"].as_u64().unwrap() > 100);
}

/// Read one WebSocket message, text or binary.
fn next(
    ws: &mut tungstenite::WebSocket<tungstenite::stream::MaybeTlsStream<std::net::TcpStream>>,
) -> Option<tungstenite::Message> {
    loop {
        match ws.read() {
            Ok(m @ (tungstenite::Message::Text(_) | tungstenite::Message::Binary(_))) => {
                return Some(m);
            }
            Ok(_) => continue,
            Err(_) => return None,
        }
    }
}

#[test]
fn a_live_run_is_served_over_the_foxglove_websocket_protocol() {
    use tungstenite::client::IntoClientRequest;
    let d = scratch("live");
    let mut child = bite()
        .arg("run")
        .arg("--log")
        .arg(d.join("run.jsonl"))
        .args(["--foxglove", "0", "--pace", "20"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("bite runs");
    let mut err = BufReader::new(child.stderr.take().unwrap());
    let port: u16 = loop {
        let mut line = String::new();
        assert!(
            err.read_line(&mut line).unwrap() > 0,
            "bite ended before serving"
        );
        if let Some(rest) = line.split("ws://127.0.0.1:").nth(1) {
            break rest
                .split(|c: char| !c.is_ascii_digit())
                .next()
                .unwrap()
                .parse()
                .unwrap();
        }
    };
    // Keep draining standard error (progress) so the run never blocks.
    std::thread::spawn(move || for _ in err.lines() {});
    let mut req = format!("ws://127.0.0.1:{port}")
        .into_client_request()
        .unwrap();
    req.headers_mut()
        .insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
    let (mut ws, resp) = tungstenite::connect(req).expect("connects");
    assert_eq!(resp.headers()["sec-websocket-protocol"], "foxglove.sdk.v1");
    // A viewer that asks by the older name (Lichtblick before December
    // 2025, PlotJuggler) is answered by that name and served the same.
    let mut old = format!("ws://127.0.0.1:{port}")
        .into_client_request()
        .unwrap();
    old.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        "foxglove.websocket.v1".parse().unwrap(),
    );
    let (mut legacy, resp) = tungstenite::connect(old).expect("connects by the older name");
    assert_eq!(
        resp.headers()["sec-websocket-protocol"],
        "foxglove.websocket.v1"
    );
    let Some(tungstenite::Message::Text(t)) = next(&mut legacy) else {
        panic!("no serverInfo by the older name");
    };
    let info: serde_json::Value = serde_json::from_str(&t).unwrap();
    assert_eq!(info["op"], "serverInfo", "{info}");
    drop(legacy);
    // serverInfo, then the channels advertised.
    let mut channels: BTreeMap<String, (u64, String)> = BTreeMap::new();
    let deadline = Instant::now() + Duration::from_secs(20);
    while !(channels.contains_key("/scene") && channels.contains_key("/bite/decisions")) {
        assert!(
            Instant::now() < deadline,
            "channels not advertised: {channels:?}"
        );
        if let Some(tungstenite::Message::Text(t)) = next(&mut ws) {
            let v: serde_json::Value = serde_json::from_str(&t).unwrap();
            if v["op"] == "advertise" {
                for c in v["channels"].as_array().unwrap() {
                    channels.insert(
                        c["topic"].as_str().unwrap().into(),
                        (
                            c["id"].as_u64().unwrap(),
                            c["schemaName"].as_str().unwrap_or("").into(),
                        ),
                    );
                }
            }
        }
    }
    assert_eq!(channels["/scene"].1, "foxglove.SceneUpdate");
    let sub = serde_json::json!({"op": "subscribe", "subscriptions": [
        {"id": 1, "channelId": channels["/scene"].0},
        {"id": 2, "channelId": channels["/bite/decisions"].0},
    ]});
    ws.send(tungstenite::Message::Text(sub.to_string().into()))
        .unwrap();
    let (mut scenes, mut decisions, mut times) = (0, 0, 0);
    let mut last_robots = 0;
    while scenes < 50 || decisions < 10 {
        assert!(
            Instant::now() < deadline + Duration::from_secs(40),
            "{scenes} scenes, {decisions} decisions"
        );
        let Some(tungstenite::Message::Binary(b)) = next(&mut ws) else {
            continue;
        };
        match b[0] {
            1 => {
                let sub = u32::from_le_bytes(b[1..5].try_into().unwrap());
                let payload = &b[13..];
                if sub == 1 {
                    let s = foxglove::messages::SceneUpdate::decode(payload).expect("SceneUpdate");
                    last_robots = s
                        .entities
                        .iter()
                        .filter(|e| e.id.starts_with("robot/"))
                        .count();
                    scenes += 1;
                } else {
                    let v: serde_json::Value = serde_json::from_slice(payload).expect("JSON");
                    assert_eq!(v["event"], "interaction_decided");
                    decisions += 1;
                }
            }
            2 => times += 1,
            _ => {}
        }
    }
    assert_eq!(last_robots, 3);
    assert!(times > 0, "the server announces simulated time");
    // Disconnecting ends the run's linger; the process exits by itself.
    let _ = ws.close(None);
    drop(ws);
    let until = Instant::now() + Duration::from_secs(60);
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            assert!(s.success(), "{s}");
            break;
        }
        assert!(
            Instant::now() < until,
            "bite run did not stop after the viewer left"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}
