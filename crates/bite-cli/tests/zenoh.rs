//! Robots as separate processes over Zenoh, on 127.0.0.1 only (multicast
//! scouting off, explicit endpoints): the acceptance tests of the
//! distributed runtime. Each test uses its own team name and ports, and
//! every process it starts is stopped when the test ends, pass or fail.

use bite_zenoh::auth::{FrameKind, Scope, TeamKey, seal_with};
use bite_zenoh::net::unix_micros;
use bite_zenoh::zenoh::{self, Wait};
use serde_json::Value;

mod support {
    pub mod venv;
}
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// One team at a time: these tests run real processes against wall-clock
/// failure detectors, and two cores shared by four teams would make
/// heartbeats late.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner())
}

fn bite() -> Command {
    Command::new(env!("CARGO_BIN_EXE_bite"))
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("bite-zenoh-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn free_port() -> u16 {
    bite_zenoh::net::free_ports(1).expect("a free port")[0]
}

fn read_jsonl(p: &Path) -> Vec<Value> {
    std::fs::read_to_string(p)
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

/// Child processes killed when dropped (a failing test leaves nothing behind).
struct Procs(Vec<(String, Child)>);

impl Drop for Procs {
    fn drop(&mut self) {
        for (_, c) in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

impl Procs {
    /// Ask every process to stop (SIGTERM: they write their logs) and wait.
    fn terminate(&mut self) {
        for (_, c) in &mut self.0 {
            let pid = nix::unistd::Pid::from_raw(c.id() as i32);
            let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM);
        }
        self.wait_all(Duration::from_secs(10));
    }

    /// Wait for every process to exit (at most `limit`); their exit codes.
    /// (These tests exercise the real transport: wall time is what they wait on.)
    #[allow(clippy::disallowed_methods)]
    fn wait_all(&mut self, limit: Duration) -> Vec<(String, Option<i32>)> {
        let t0 = Instant::now();
        let mut out = vec![None; self.0.len()];
        while t0.elapsed() < limit && out.iter().any(Option::is_none) {
            for (i, (_, c)) in self.0.iter_mut().enumerate() {
                if out[i].is_none()
                    && let Ok(Some(s)) = c.try_wait()
                {
                    out[i] = Some(s.code());
                }
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        self.0
            .iter()
            .zip(out)
            .map(|((n, _), c)| (n.clone(), c.flatten()))
            .collect()
    }
}

fn launch(out: &Path, extra: &[&str]) -> Value {
    let status = bite()
        .current_dir(repo())
        .args([
            "launch",
            "examples/formation.yaml",
            "--speed",
            "2",
            "--json",
        ])
        .arg("--out")
        .arg(out)
        .args(extra)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&status.stdout);
    let summary: Value = serde_json::from_str(&text).unwrap_or_else(|e| {
        panic!(
            "launch printed no summary ({e}); stderr:\n{}\nstdout:\n{text}\nlogs in {}",
            String::from_utf8_lossy(&status.stderr),
            out.display()
        )
    });
    summary
}

/// Joint decisions every robot's log has, checked here independently of
/// `bite launch`: same instance, same outcome.
fn check_agreement(out: &Path, robots: &[&str]) -> usize {
    let mut by_instance: std::collections::BTreeMap<String, Vec<(String, Value)>> =
        Default::default();
    for r in robots {
        for rec in read_jsonl(&out.join(format!("{r}.jsonl"))) {
            // Silent rules may split (healed through the heartbeats; the
            // invariant checker of `bite launch` holds them to that).
            let silent = [
                "sync.by-rule",
                "sync.round-robin",
                "alloc.by-id",
                "term.local",
            ];
            if rec["event"] == "interaction_decided"
                && rec["timed_out"] != true
                && !silent.contains(&rec["protocol"].as_str().unwrap_or(""))
            {
                by_instance
                    .entry(rec["instance"].to_string())
                    .or_default()
                    .push((r.to_string(), rec["outcome"].clone()));
            }
        }
    }
    let mut joint = 0;
    for (inst, v) in &by_instance {
        if v.len() >= 2 {
            joint += 1;
            assert!(
                v.iter().all(|(_, o)| *o == v[0].1),
                "robots disagree on {inst}: {v:?}"
            );
        }
    }
    joint
}

#[test]
fn three_robot_processes_and_the_sim_server_complete_the_formation() {
    let _one = serial();
    let out = tmp("formation");
    let mcap = out.join("team.mcap");
    let s = launch(&out, &["--mcap", mcap.to_str().unwrap()]);
    assert_eq!(s["completed"], true, "{s:#}");
    let robots = s["robots"].as_array().unwrap();
    assert_eq!(robots.len(), 3);
    for r in robots {
        assert_eq!(r["completed"], true, "{r}");
        assert_eq!(r["exit"], 0, "{r}");
        assert_eq!(r["lost"].as_array().unwrap().len(), 0, "{r}");
        assert_eq!(r["frames_rejected"], 0, "{r}");
    }
    assert_eq!(s["disagreements"].as_array().unwrap().len(), 0, "{s:#}");
    assert_eq!(s["invariants"]["violations"], 0, "{s:#}");
    assert!(s["records_checked"].as_u64().unwrap() > 50, "{s:#}");
    let joint = check_agreement(&out, &["r0", "r1", "r2"]);
    assert!(joint >= 3, "only {joint} joint decisions");
    // The robots drove through the server: it applied their commands and
    // they got to the finish (x beyond 6.6 m).
    let world = read_jsonl(&out.join("server.jsonl"));
    let stopped = world
        .iter()
        .find(|r| r["event"] == "server_stopped")
        .unwrap();
    for c in stopped["commands"].as_array().unwrap() {
        assert!(c.as_u64().unwrap() > 100, "{stopped}");
    }
    let last = world.iter().rev().find(|r| r["event"] == "poses").unwrap();
    let xs: Vec<f64> = (last["robots"].as_array().unwrap().iter())
        .map(|p| p[0].as_f64().unwrap())
        .collect();
    assert!(xs.iter().any(|x| *x > 5.0), "nobody walked: {xs:?}");
    // One MCAP file for the team: the server's world and every robot's
    // records, in time order, with the Foxglove schemas.
    let bytes = std::fs::read(&mcap).expect("the team's MCAP file");
    let mut topics: std::collections::BTreeMap<String, (String, usize)> = Default::default();
    let mut last = 0;
    for m in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
        let m = m.expect("a message");
        assert!(m.log_time >= last, "time order");
        last = m.log_time;
        let schema = m
            .channel
            .schema
            .as_ref()
            .map(|s| s.name.clone())
            .unwrap_or_default();
        topics
            .entry(m.channel.topic.clone())
            .or_insert((schema, 0))
            .1 += 1;
    }
    assert_eq!(topics["/scene"].0, "foxglove.SceneUpdate");
    assert_eq!(topics["/tf"].0, "foxglove.FrameTransforms");
    let total: usize = topics.values().map(|t| t.1).sum();
    assert!(total > 100, "{topics:?}");
    let decided: usize = ["r0", "r1", "r2"]
        .iter()
        .map(|r| {
            (read_jsonl(&out.join(format!("{r}.jsonl"))).iter())
                .filter(|x| x["event"] == "interaction_decided")
                .count()
        })
        .sum();
    assert_eq!(topics["/bite/decisions"].1, decided);
    for r in ["r0", "r1", "r2"] {
        assert!(
            topics.contains_key(&format!("/bite/{r}/stack")),
            "{topics:?}"
        );
    }
}

#[test]
fn killing_a_robot_the_survivors_detect_it_reallocate_and_complete() {
    let _one = serial();
    let out = tmp("kill");
    // Table II row 7 (an elected leader decides at A): see agent.rs in
    // bite-sim for why the default silent rule at A may split survivors.
    let s = launch(
        &out,
        &["--kill", "r2@12s", "--config", "examples/configs/7.yaml"],
    );
    assert_eq!(s["completed"], true, "{s:#}");
    let robots = s["robots"].as_array().unwrap();
    let r2 = robots.iter().find(|r| r["robot"] == "r2").unwrap();
    assert!(r2["killed_at"].as_f64().is_some(), "{r2}");
    for name in ["r0", "r1"] {
        let r = robots.iter().find(|r| r["robot"] == name).unwrap();
        assert_eq!(r["completed"], true, "{r}");
        assert_eq!(r["lost"], serde_json::json!(["r2"]), "{r}");
        let log = read_jsonl(&out.join(format!("{name}.jsonl")));
        let lost_at = log
            .iter()
            .find(|e| e["event"] == "member_lost")
            .and_then(|e| e["t"].as_f64())
            .unwrap();
        let killed = r2["killed_at"].as_f64().unwrap();
        assert!(
            lost_at > killed && lost_at < killed + 6.0,
            "{name} noticed at {lost_at}, killed at {killed}"
        );
        // The team allocated again without r2: a new allocation round, or
        // a fresh allocation of the formation's roles among the survivors.
        let realloc = log.iter().any(|e| {
            e["event"] == "reallocating"
                || (e["event"] == "interaction_decided"
                    && e["instance"]["kind"] == "allocate"
                    && e["t"].as_f64().unwrap_or(0.0) > lost_at
                    && !e["outcome"].to_string().contains("r2"))
        });
        assert!(realloc, "{name} did not re-allocate after losing r2");
    }
    check_agreement(&out, &["r0", "r1"]);
}

/// `bite launch --per-process 2`: three robots in two processes (r0 and r1
/// sharing one Zenoh session, r2 alone) and the simulator server complete
/// the formation, each robot with its own log, agreeing on every joint
/// decision. The launcher is killed if it has not ended within three
/// minutes (its own limits end the team well before).
#[test]
#[allow(clippy::disallowed_methods)] // a wall-clock timeout on a real team
fn two_robots_per_process_complete_the_formation() {
    let _one = serial();
    let out = tmp("per-process");
    let child = bite()
        .current_dir(repo())
        .args([
            "launch",
            "examples/formation.yaml",
            "--speed",
            "2",
            "--json",
            "--per-process",
            "2",
            "--time-limit",
            "120s",
        ])
        .arg("--out")
        .arg(&out)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut procs = Procs(vec![("launch".into(), child)]);
    let exits = procs.wait_all(Duration::from_secs(180));
    assert!(
        exits[0].1.is_some(),
        "bite launch did not end within 3 minutes"
    );
    let (_, child) = procs.0.pop().unwrap();
    let o = child.wait_with_output().unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    let s: Value = serde_json::from_str(&text).unwrap_or_else(|e| {
        panic!(
            "no summary ({e}): {}\n{text}",
            String::from_utf8_lossy(&o.stderr)
        )
    });
    assert_eq!(s["completed"], true, "{s:#}");
    assert_eq!(s["processes"], 2, "{s:#}");
    let robots = s["robots"].as_array().unwrap();
    assert_eq!(robots.len(), 3);
    for r in robots {
        let name = r["robot"].as_str().unwrap();
        let process = if name == "r2" { "r2" } else { "r0+r1" };
        assert_eq!(r["process"], process, "{r}");
        assert_eq!(r["completed"], true, "{r}");
        assert_eq!(r["exit"], 0, "{r}");
        assert_eq!(r["lost"].as_array().unwrap().len(), 0, "{r}");
        assert_eq!(r["frames_rejected"], 0, "{r}");
        // Its own log, started and finished as its own.
        let log = read_jsonl(&out.join(format!("{name}.jsonl")));
        assert!(log.iter().all(|e| e["robot"] == name), "{name}");
        assert!(
            log.iter()
                .any(|e| e["event"] == "run_finished" && e["completed"] == true),
            "{name}"
        );
        // Each robot of the shared session sends its own position under
        // its own name: none is taken for another's.
        assert!(
            !log.iter()
                .any(|e| e["event"] == "dropped" && e["reason"] == "misattributed"),
            "{name}"
        );
    }
    assert_eq!(s["disagreements"].as_array().unwrap().len(), 0, "{s:#}");
    assert_eq!(s["invariants"]["violations"], 0, "{s:#}");
    assert!(check_agreement(&out, &["r0", "r1", "r2"]) >= 3);
    // The shared process says how each of its robots ended.
    let shared = std::fs::read_to_string(out.join("r0+r1.log")).unwrap();
    for name in ["r0", "r1"] {
        assert!(
            shared.contains(&format!("robot {name}: mission completed")),
            "{shared}"
        );
    }
}

/// Several robots in one process need one log file each: a `--log`
/// without `{name}` is refused before anything starts, as is a name
/// given twice or one not on the roster.
#[test]
fn several_robots_in_one_process_are_checked_before_they_start() {
    let d = tmp("per-process-args");
    let key = d.join("team.key");
    std::fs::write(&key, "ab".repeat(32)).unwrap();
    for (extra, says) in [
        (&["--name", "r1", "--log", "one.jsonl"][..], "{name}"),
        (&["--name", "r0"][..], "given twice"),
        (&["--name", "r9"][..], "not on the roster"),
    ] {
        let o = bite()
            .current_dir(repo())
            .args(["robot", "examples/formation.yaml", "--name", "r0"])
            .args(extra)
            .arg("--key")
            .arg(&key)
            .stdin(Stdio::null())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{extra:?}: {err}");
        assert!(err.contains(says), "{extra:?}: {err}");
    }
}

struct Team {
    procs: Procs,
    endpoints: Vec<String>,
    key: TeamKey,
    key_file: PathBuf,
    team: String,
    out: PathBuf,
}

impl Team {
    /// Every robot exits 0 (completed its mission) within `limit`.
    fn all_complete(&mut self, limit: Duration) {
        for (name, code) in self.procs.wait_all(limit) {
            assert_eq!(
                code,
                Some(0),
                "{name} did not complete; logs in {}",
                self.out.display()
            );
        }
    }
}

/// Three robots in the timed world, started by hand (no launcher), with
/// or without a mission (a graph, run in the timed world next to it).
fn team(name: &str, mission: Option<&str>, speed: &str) -> Team {
    let out = tmp(name);
    let key = TeamKey::new((0..32).map(|i| i as u8 ^ 0x5a).collect()).unwrap();
    let key_file = out.join("team.key");
    std::fs::write(&key_file, key.to_hex()).unwrap();
    let team = format!("{name}-{}", std::process::id());
    let ports: Vec<u16> = bite_zenoh::net::free_ports(3).expect("free ports");
    let endpoints: Vec<String> = ports.iter().map(|p| format!("tcp/127.0.0.1:{p}")).collect();
    let mut procs = Procs(Vec::new());
    for k in 0..3 {
        let name = format!("r{k}");
        let mut c = bite();
        c.current_dir(repo()).args(["robot", "--name", &name]);
        if let Some(graph) = mission {
            c.args([graph, "--timed", "--exit-when-done"]);
        } else {
            c.args(["--scenario", "examples/scenarios/formation.yaml"]);
        }
        c.args(["--team", &team, "--speed", speed, "--time-limit", "300s"])
            .args(["--listen", &endpoints[k]])
            .arg("--key")
            .arg(&key_file)
            .arg("--log")
            .arg(out.join(format!("{name}.jsonl")));
        for e in &endpoints[..k] {
            c.args(["--connect", e]);
        }
        let log = std::fs::File::create(out.join(format!("{name}.log"))).unwrap();
        c.stdout(log.try_clone().unwrap())
            .stderr(log)
            .stdin(Stdio::null());
        procs.0.push((name, c.spawn().unwrap()));
    }
    Team {
        procs,
        endpoints,
        key,
        key_file,
        team,
        out,
    }
}

/// Robot r0's statuses as it publishes them, and its first, which says it
/// waits for a mission (the subscriber must be kept while they are read).
fn waiting_status(
    session: &zenoh::Session,
    team: &str,
) -> (
    zenoh::pubsub::Subscriber<()>,
    std::sync::mpsc::Receiver<Value>,
    Value,
) {
    let (tx, rx) = std::sync::mpsc::channel::<Value>();
    let sub = session
        .declare_subscriber(format!("bite/{team}/status/r0"))
        .callback(move |s| {
            if let Ok(v) = serde_json::from_slice(&s.payload().to_bytes()) {
                let _ = tx.send(v);
            }
        })
        .wait()
        .unwrap();
    let first = rx.recv_timeout(Duration::from_secs(20)).expect("a status");
    assert_eq!(first["state"], "waiting", "{first}");
    (sub, rx, first)
}

fn client(endpoints: &[String]) -> zenoh::Session {
    let mut c = zenoh::Config::default();
    c.insert_json5("mode", "\"peer\"").unwrap();
    c.insert_json5("scouting/multicast/enabled", "false")
        .unwrap();
    c.insert_json5(
        "connect/endpoints",
        &serde_json::to_string(endpoints).unwrap(),
    )
    .unwrap();
    zenoh::open(c).wait().unwrap()
}

#[test]
fn forged_tampered_and_replayed_frames_are_rejected_and_counted() {
    let _one = serial();
    let mut t = team("attack", Some("examples/formation.yaml"), "2");
    let session = client(&t.endpoints);
    // Capture r0's frames as they go by.
    let (tx, rx) = std::sync::mpsc::channel::<Vec<u8>>();
    let _sub = session
        .declare_subscriber(format!("bite/{}/net/r0", t.team))
        .callback(move |s| {
            let _ = tx.send(s.payload().to_bytes().into_owned());
        })
        .wait()
        .unwrap();
    // Once the team runs (everyone connected), take one of r0's frames and
    // replay it at once (well inside every receiver's window).
    std::thread::sleep(Duration::from_secs(4));
    while rx.try_recv().is_ok() {}
    let frame = rx
        .recv_timeout(Duration::from_secs(20))
        .expect("no frame from r0");
    let put = |key: &str, bytes: Vec<u8>| {
        session
            .put(format!("bite/{}/net/{key}", t.team), bytes)
            .wait()
            .unwrap();
    };
    // 1. Replayed: r0's captured frame, again.
    put("r0", frame.clone());
    // 2. Tampered: one byte flipped.
    let mut tampered = frame.clone();
    tampered[20] ^= 1;
    put("r0", tampered);
    // The mission these robots run (started from the command line, no
    // shared origin): frames must carry its tag to verify.
    let g = bite_core::graph::load(&repo().join("examples/formation.yaml")).unwrap();
    let scope = Scope::new(&t.team, bite_zenoh::robot::mission_tag(None, &g, None));
    // 3. Forged: a heartbeat claiming r0, sealed with another key.
    let wrong = TeamKey::new(vec![1; 32]).unwrap();
    let hb = [1, 0];
    put(
        "r0",
        seal_with(&wrong, &scope, FrameKind::Heartbeat, 0, unix_micros(), &hb),
    );
    // 4. From a non-member (roster index 7), even with the right key.
    put(
        "r7",
        seal_with(&t.key, &scope, FrameKind::Heartbeat, 7, unix_micros(), &hb),
    );
    // 5. r1's identity on r0's key expression.
    put(
        "r0",
        seal_with(&t.key, &scope, FrameKind::Heartbeat, 1, unix_micros(), &hb),
    );
    // 6. Addressed to r1 alone, on r0's key to r1, with r1's own identity:
    //    r1 takes the sender from the chunk after `net` (r0, not the
    //    addressee's chunk, which would pass it off as its own echo) and
    //    rejects it; r2 never receives it.
    put(
        "r0/r1",
        seal_with(&t.key, &scope, FrameKind::Heartbeat, 1, unix_micros(), &hb),
    );
    // 7. Genuine (r0's identity, the team's key) but of another payload
    //    version, as from a robot of an older build: authenticated, then
    //    dropped as unreadable, said once, and shown in the status.
    let (stx, srx) = std::sync::mpsc::channel::<Value>();
    let _status = session
        .declare_subscriber(format!("bite/{}/status/r1", t.team))
        .callback(move |s| {
            if let Ok(v) = serde_json::from_slice(&s.payload().to_bytes()) {
                let _ = stx.send(v);
            }
        })
        .wait()
        .unwrap();
    for _ in 0..2 {
        put(
            "r0",
            seal_with(
                &t.key,
                &scope,
                FrameKind::Heartbeat,
                0,
                unix_micros(),
                &[3, 0],
            ),
        );
    }
    // 8. Larger than any frame: counted as `oversize`, never copied.
    put("r0", vec![0; 70_000]);
    // 9. Genuine, of this payload version, but the envelope inside it has
    //    a bad version byte: malformed, not a teammate of another version
    //    (r0 is fine: its later frames read).
    let to_r1 = [bite_zenoh::wire::PAYLOAD_VERSION, 0, 1, 127, 0, 0, 0];
    put(
        "r0",
        seal_with(&t.key, &scope, FrameKind::Kernel, 0, unix_micros(), &to_r1),
    );
    // 10. Readings no body makes, and one too large, on r1's sensor key
    //     (not authenticated: dropped and counted); a submission too large.
    let sensors = format!("bite/{}/sim/sensors/r1", t.team);
    let forged = r#"{"t": 1.0, "pose": {"x": 0, "y": 0, "heading": 0}, "odometer": 1e308}"#;
    session.put(&sensors, forged).wait().unwrap();
    session.put(&sensors, vec![b' '; 2 << 20]).wait().unwrap();
    session
        .put(format!("bite/{}/mission", t.team), vec![b' '; 2 << 20])
        .wait()
        .unwrap();
    t.all_complete(Duration::from_secs(240));
    // r1 and r2 each received every injected frame once, and r1 the frame
    // addressed to it.
    for (r, addressed) in [("r1", 1), ("r2", 0)] {
        let log = read_jsonl(&t.out.join(format!("{r}.jsonl")));
        let fin = log
            .iter()
            .rev()
            .find(|e| e["event"] == "run_finished")
            .unwrap();
        let rej = &fin["auth"]["rejected"];
        assert_eq!(rej["oversize"], 1, "{r}: {fin}");
        assert_eq!(rej["replay"], 1, "{r}: {fin}");
        assert_eq!(rej["bad-mac"], 2, "{r}: {fin}");
        assert_eq!(rej["not-member"], 1, "{r}: {fin}");
        assert_eq!(rej["wrong-sender"], 1 + addressed, "{r}: {fin}");
        // (A teammate's frame that came while this robot was starting is
        // logged as `before-mission`: a race of the launch, not injected.)
        let logged = log
            .iter()
            .filter(|e| e["event"] == "frame_rejected" && e["reason"] != "before-mission")
            .count();
        assert_eq!(logged, 6 + addressed as usize, "{r}");
        assert_eq!(fin["payload_rejects"]["payload-version"], 2, "{r}: {fin}");
        assert_eq!(fin["payload_rejects"]["kernel-malformed"], 1, "{r}: {fin}");
        if r == "r1" {
            let p = &fin["payload_rejects"];
            assert_eq!(p["sensors-malformed"], 1, "{r}: {fin}");
            assert_eq!(p["sensors-oversize"], 1, "{r}: {fin}");
        }
        let refused: Vec<_> = (log.iter())
            .filter(|e| e["event"] == "mission_rejected")
            .collect();
        assert_eq!(refused.len(), 1, "{r}: the oversized submission");
        assert!(
            (refused[0]["reason"].as_str().unwrap_or("")).contains("larger than"),
            "{r}: {}",
            refused[0]
        );
        let told: Vec<_> = log
            .iter()
            .filter(|e| e["event"] == "peer_version")
            .collect();
        assert_eq!(told.len(), 1, "{r}: said once per teammate");
        assert_eq!(told[0]["teammate"], "r0", "{r}");
        assert_eq!(told[0]["theirs"], 3, "{r}");
        assert_eq!(told[0]["ours"], bite_zenoh::wire::PAYLOAD_VERSION, "{r}");
        assert!(fin["auth"]["accepted"].as_u64().unwrap() > 10, "{fin}");
    }
    let statuses: Vec<Value> = srx.try_iter().collect();
    let shown = (statuses.iter()).any(|v| v["peer_versions"] == serde_json::json!({"r0": 3}));
    assert!(shown, "r1's status never showed r0's payload version");
    // r0's later frames read: it is not left blamed.
    let last = statuses.last().expect("r1's statuses");
    assert!(last.get("peer_versions").is_none(), "{last}");
    assert_eq!(last["missions_rejected"], 1, "{last}");
    check_agreement(&t.out, &["r0", "r1", "r2"]);
    let _ = &t.key_file;
}

#[test]
fn a_robot_without_a_valid_key_refuses_to_start() {
    let out = tmp("nokey");
    let bad = out.join("bad.key");
    std::fs::write(&bad, "abcd").unwrap();
    for args in [vec!["--key", bad.to_str().unwrap()], vec![]] {
        let o = bite()
            .current_dir(repo())
            .args([
                "robot",
                "--name",
                "r0",
                "examples/formation.yaml",
                "--timed",
            ])
            .args(&args)
            .env_remove("BITE_TEAM_KEY")
            .output()
            .unwrap();
        assert!(!o.status.success());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("team key"), "{err}");
    }
}

/// A virtual environment with the `eclipse-zenoh` package from PyPI.
fn python_with_zenoh() -> PathBuf {
    support::venv::python_venv("venv-zenoh", "import zenoh", &["eclipse-zenoh==1.10.*"])
}

#[test]
fn a_python_client_follows_the_status_and_submits_a_mission() {
    let _one = serial();
    let py = python_with_zenoh();
    let mut t = team("python", None, "2");
    let o = Command::new(&py)
        .current_dir(repo())
        .arg("crates/bite-cli/tests/python/client.py")
        .args([&t.endpoints[2], &t.team])
        .arg(&t.key_file)
        .args([
            "examples/formation.yaml",
            "examples/scenarios/formation.yaml",
            "r0,r1,r2",
            "120",
        ])
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "client failed: {}\n{}\nlogs in {}",
        String::from_utf8_lossy(&o.stderr),
        String::from_utf8_lossy(&o.stdout),
        t.out.display()
    );
    let report: Value = serde_json::from_slice(&o.stdout).unwrap();
    for r in ["r0", "r1", "r2"] {
        assert_eq!(report["before"][r], "waiting", "{report}");
        assert_eq!(report["final"][r]["state"], "completed");
        assert_eq!(report["final"][r]["mission"], "formation");
        assert!(report["stacks_while_running"][r].as_array().is_some());
        // The forged submission was refused by every robot.
        assert_eq!(report["final"][r]["missions_rejected"], 1, "{report}");
    }
    let members = report["members"].as_array().unwrap();
    assert_eq!(members.len(), 3, "{report}");
    for m in members {
        assert_eq!(m["roster"], serde_json::json!(["r0", "r1", "r2"]));
        assert_eq!(m["alive"].as_array().unwrap().len(), 2, "{m}");
    }
    t.procs.terminate();
    check_agreement(&t.out, &["r0", "r1", "r2"]);
}

#[test]
fn the_zenoh_benchmark_measures_every_protocol() {
    let _one = serial();
    let out = tmp("bench");
    let o = bite()
        .current_dir(repo())
        .args([
            "bench",
            "zenoh",
            "--robots",
            "3",
            "--decisions",
            "3",
            "--pings",
            "50",
        ])
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(text.contains("Raw Zenoh round trip"), "{text}");
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("bench-zenoh.json")).unwrap())
            .unwrap();
    assert!(report["rtt_median_us"].as_f64().unwrap() > 0.0);
    let rows = report["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 3);
    for r in rows {
        assert_eq!(r["completed"], true, "{r}");
        assert_eq!(r["decisions"], 3, "{r}");
        assert!(r["latency_median_us"].as_f64().unwrap() > 0.0, "{r}");
    }
}

/// A split forced by perception (r1 alone believes `narrow`, so the silent
/// rule at `look` sends it `right` and the others `left`) is found through
/// the heartbeats and healed across processes within about a second: every
/// robot ends on the same successor, and the mission completes without a
/// deadline.
#[test]
fn a_silent_split_heals_across_robot_processes() {
    let _one = serial();
    let out = tmp("split");
    let graph = out.join("split.yaml");
    let scenario = out.join("split-scenario.yaml");
    std::fs::write(
        &graph,
        "graph: split\nteam: { robots: 3 }\nstart: mission\n\
         defaults: { sync: sync.by-rule, terminate: term.wait-all }\nbehaviors:\n  \
         mission: { team: true, children: [look] }\n  \
         look: { team: true, skill: look, until: looked, next: [left, right] }\n  \
         left: { team: true, skill: go, pre: not narrow, until: there }\n  \
         right: { team: true, skill: go, pre: narrow, until: there }\n",
    )
    .unwrap();
    std::fs::write(
        &scenario,
        "scenario: split\nworld: timed\nseed: 1\ncontrol_hz: 10\ntime_limit: 60s\n\
         network: { latency: 5ms, jitter: 10ms }\nskills:\n  \
         look: { duration: [1.0, 1.5], start: { looked: false }, done: { looked: true } }\n  \
         go: { duration: [5.0, 6.0], start: { there: false }, done: { there: true } }\n\
         events:\n  - { at: 0s, robots: [r1], set: { narrow: true } }\n",
    )
    .unwrap();
    let run = bite()
        .current_dir(repo())
        .arg("launch")
        .arg(&graph)
        .arg("--scenario")
        .arg(&scenario)
        .args(["--speed", "2", "--json", "--out"])
        .arg(&out)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let s: Value = serde_json::from_slice(&run.stdout)
        .unwrap_or_else(|e| panic!("no summary ({e}): {}", String::from_utf8_lossy(&run.stderr)));
    assert_eq!(s["completed"], true, "{s:#}");
    assert_eq!(s["invariants"]["violations"], 0, "{s:#}");
    let mut ends = Vec::new();
    let mut split_times = Vec::new();
    for r in ["r0", "r1", "r2"] {
        let log = read_jsonl(&out.join(format!("{r}.jsonl")));
        for e in &log {
            if e["event"] == "split" {
                split_times.push(e["t"].as_f64().unwrap());
            }
            // No termination needed its deadline.
            if e["event"] == "interaction_decided" {
                assert_ne!(e["timed_out"], true, "{r}: {e}");
            }
        }
        let last = log
            .iter()
            .rev()
            .find(|e| {
                e["event"] == "selected"
                    && ["left", "right"].contains(&e["behavior"].as_str().unwrap())
            })
            .unwrap_or_else(|| panic!("{r} never left `look`"));
        ends.push(last["behavior"].as_str().unwrap().to_string());
    }
    assert!(!split_times.is_empty(), "the split was never noticed");
    assert!(ends.iter().all(|b| *b == ends[0]), "still split: {ends:?}");
    let first = split_times.iter().cloned().fold(f64::INFINITY, f64::min);
    let last = split_times.iter().cloned().fold(0.0, f64::max);
    assert!(last - first < 1.0, "healing took {:.2} s", last - first);
}

/// The README's `bite launch` commands, exactly as written (no graph: the
/// built-in formation; and the kill with Table II row 7), run in a scratch
/// directory whose `examples` is the repository's: each completes, exits 0
/// and reports every surviving robot COMPLETED.
#[test]
fn the_readme_launch_commands_complete_as_written() {
    let _one = serial();
    let readme = std::fs::read_to_string(repo().join("README.md")).unwrap();
    let cmds: Vec<Vec<String>> = readme
        .lines()
        .map(|l| l.split(" #").next().unwrap_or("").trim())
        .filter(|l| l.starts_with("bite launch"))
        .map(|l| l.split_whitespace().skip(1).map(String::from).collect())
        .collect();
    assert!(
        cmds.iter().any(|c| c.len() == 1),
        "the README shows no bare `bite launch`: {cmds:?}"
    );
    assert!(
        cmds.iter().any(|c| c.iter().any(|a| a == "--kill")),
        "the README shows no `bite launch --kill`: {cmds:?}"
    );
    for (i, args) in cmds.iter().enumerate() {
        let d = tmp(&format!("readme-launch-{i}"));
        std::os::unix::fs::symlink(repo().join("examples"), d.join("examples")).unwrap();
        let out = bite()
            .current_dir(&d)
            .args(args)
            .stdin(Stdio::null())
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        let what = format!(
            "`bite {}` in {}:\n{text}\n{}",
            args.join(" "),
            d.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        assert_eq!(out.status.code(), Some(0), "{what}");
        let rows: Vec<&str> = (text.lines())
            .filter(|l| l.trim_start().starts_with('r') && l.contains(" exit "))
            .collect();
        assert_eq!(rows.len(), 3, "{what}");
        let killed = args.iter().any(|a| a == "--kill");
        for r in rows {
            let ok = r.contains("COMPLETED") || (killed && r.contains("KILLED"));
            assert!(ok, "{r}\n{what}");
        }
        assert!(text.contains(" 0 disagreements"), "{what}");
        assert!(d.join("out/launch/r0.jsonl").exists(), "{what}");
    }
}

/// A client written from `docs/zenoh-interface.md` alone (Python: hashlib,
/// hmac, struct) builds robot-to-robot frames: one sealed with the team key
/// is accepted (its copy counts as a replay, which only an accepted frame
/// can be), one sealed with another key is rejected as `bad-mac`, and a
/// valid one on another robot's key as `wrong-sender`; the team completes.
#[test]
fn a_python_client_builds_frames_from_the_documented_layout() {
    let _one = serial();
    let py = python_with_zenoh();
    let mut t = team("frames", None, "2");
    let o = Command::new(&py)
        .current_dir(repo())
        .arg("crates/bite-cli/tests/python/frames.py")
        .args([&t.endpoints[2], &t.team])
        .arg(&t.key_file)
        .args([
            "examples/formation.yaml",
            "examples/scenarios/formation.yaml",
            "120",
        ])
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "frames.py failed: {}\n{}\nlogs in {}",
        String::from_utf8_lossy(&o.stderr),
        String::from_utf8_lossy(&o.stdout),
        t.out.display()
    );
    let report: Value = serde_json::from_slice(&o.stdout).unwrap();
    let delta = |r: &str, reason: &str| {
        report["after"][r][reason].as_u64().unwrap_or(0)
            - report["before"][r][reason].as_u64().unwrap_or(0)
    };
    for r in ["r0", "r2"] {
        assert_eq!(delta(r, "replay"), 1, "{r}: {report}");
        assert_eq!(delta(r, "bad-mac"), 1, "{r}: {report}");
        assert_eq!(delta(r, "too-old"), 0, "{r}: {report}");
    }
    assert_eq!(delta("r0", "wrong-sender"), 1, "{report}");
    assert_eq!(report["unknown_phases"], serde_json::json!([]), "{report}");
    assert!(
        report["phases"].as_array().is_some_and(|p| p.len() >= 2),
        "{report}"
    );
    for r in ["r0", "r1", "r2"] {
        assert_eq!(report["final"][r], "completed", "{report}");
    }
    t.procs.terminate();
    check_agreement(&t.out, &["r0", "r1", "r2"]);
}

/// A robot started with no graph and no scenario refuses a submission that
/// carries no scenario, and says why in its status (it used to run it in
/// an empty world and stay `running` for ever).
#[test]
fn a_submission_without_a_world_is_refused_with_the_reason() {
    let _one = serial();
    let out = tmp("no-world");
    let key = TeamKey::new((0..32).map(|i| i as u8 ^ 0x33).collect()).unwrap();
    let key_file = out.join("team.key");
    std::fs::write(&key_file, key.to_hex()).unwrap();
    // The graph alone, with no scenario next to it.
    let graph = out.join("formation.yaml");
    std::fs::copy(repo().join("examples/formation.yaml"), &graph).unwrap();
    let team = format!("noworld-{}", std::process::id());
    let ep = format!("tcp/127.0.0.1:{}", free_port());
    let mut procs = Procs(Vec::new());
    let log = std::fs::File::create(out.join("r0.log")).unwrap();
    let child = bite()
        .args(["robot", "--name", "r0", "--team", &team, "--listen", &ep])
        .arg("--key")
        .arg(&key_file)
        .stdout(log.try_clone().unwrap())
        .stderr(log)
        .stdin(Stdio::null())
        .spawn()
        .unwrap();
    procs.0.push(("r0".into(), child));
    let session = client(std::slice::from_ref(&ep));
    let (_sub, rx, _) = waiting_status(&session, &team);
    let sub = bite()
        .args([
            "submit",
            "--team",
            &team,
            "--connect",
            &ep,
            "--id",
            "m-noworld",
        ])
        .arg("--key")
        .arg(&key_file)
        .arg(&graph)
        .output()
        .unwrap();
    assert!(
        sub.status.success(),
        "{}",
        String::from_utf8_lossy(&sub.stderr)
    );
    let deadline = Duration::from_secs(20);
    let refused = std::iter::from_fn(|| rx.recv_timeout(deadline).ok())
        .find(|s| !s["last_rejection"].is_null())
        .expect("a status with the refusal");
    assert_eq!(refused["state"], "waiting", "{refused}");
    let r = &refused["last_rejection"];
    assert_eq!(r["id"], "m-noworld", "{refused}");
    assert_eq!(r["event"], "refused", "{refused}");
    assert!(
        r["reason"]
            .as_str()
            .unwrap_or("")
            .contains("carries no scenario"),
        "{refused}"
    );
    procs.terminate();
}

/// `bite submit --replace`: a team of robot processes running the
/// formation takes a new version of its mission (a longer course, a
/// column instead of the line) without restarting; every robot switches
/// at the same safe point, and the team completes the new course.
#[test]
fn a_running_team_takes_a_new_version_of_its_mission_over_zenoh() {
    let _one = serial();
    let mut t = team("replace", Some("examples/formation-change.yaml"), "4");
    // Let the team get going (a few team seconds), then replace.
    std::thread::sleep(Duration::from_secs(5));
    let sub = bite()
        .current_dir(repo())
        .args([
            "submit",
            "--replace",
            "--timed",
            "--team",
            &t.team,
            "--id",
            "v2",
        ])
        .args(["--connect", &t.endpoints[0]])
        .arg("--key")
        .arg(&t.key_file)
        .arg("examples/formation-change-v2.yaml")
        .output()
        .unwrap();
    assert!(
        sub.status.success(),
        "{}",
        String::from_utf8_lossy(&sub.stderr)
    );
    t.all_complete(Duration::from_secs(120));
    let mut switches = Vec::new();
    for r in ["r0", "r1", "r2"] {
        let log = read_jsonl(&t.out.join(format!("{r}.jsonl")));
        let changed: Vec<&Value> = log
            .iter()
            .filter(|e| e["event"] == "mission_changed")
            .collect();
        assert_eq!(
            changed.len(),
            1,
            "{r}: {changed:?} (logs in {})",
            t.out.display()
        );
        switches.push((changed[0]["version"].clone(), changed[0]["after"].clone()));
        // The new version ran: the column, not the line.
        let ran = |b: &str| {
            log.iter()
                .any(|e| e["event"] == "selected" && e["behavior"] == b)
        };
        assert!(
            ran("column") && !ran("line"),
            "{r} (logs in {})",
            t.out.display()
        );
        assert!(log.iter().any(|e| e["event"] == "mission_completed"), "{r}");
    }
    assert!(
        switches.iter().all(|s| *s == switches[0]),
        "not all at the same safe point: {switches:?}"
    );
    check_agreement(&t.out, &["r0", "r1", "r2"]);
}

/// A virtual environment with `eclipse-zenoh` and `rosbags` (an
/// independent ROS 2 CDR codec and type-hash implementation).
fn python_with_ros2() -> PathBuf {
    support::venv::python_venv(
        "venv-ros2",
        "import zenoh, rosbags.typesys",
        &["eclipse-zenoh==1.10.*", "rosbags==0.11.*"],
    )
}

/// A ROS 2 peer written from rmw_zenoh's conventions with an independent
/// CDR codec (Python: zenoh + rosbags) sees the simulator's bodies as ROS 2
/// endpoints (liveliness tokens), reads their odometry and scans (every
/// sample with rmw_zenoh's attachment), and drives one with Twist commands.
#[test]
fn a_ros2_peer_reads_odometry_and_scans_and_drives_a_body_by_cmd_vel() {
    let _one = serial();
    let py = python_with_ros2();
    let out = tmp("ros2-body");
    let port = free_port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let mut server = bite()
        .current_dir(repo())
        .args([
            "sim",
            "serve",
            "examples/formation.yaml",
            "--ros2",
            "--team",
            "ros2test",
        ])
        .args(["--listen", &endpoint, "--time-limit", "60s"])
        .arg("--log")
        .arg(out.join("server.jsonl"))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    let o = Command::new(&py)
        .arg(repo().join("crates/bite-cli/tests/python/ros2_body.py"))
        .args([&endpoint, "r0", "20"])
        .output()
        .unwrap();
    let _ = nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(server.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    );
    let _ = server.wait();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: Value = serde_json::from_slice(&o.stdout).unwrap();
    let tokens: Vec<&str> = r["tokens"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|t| t.as_str())
        .collect();
    assert!(
        tokens.iter().any(|t| t
            .contains("/MP/%/%r0/r0_body/%r0%odom/nav_msgs::msg::dds_::Odometry_/RIHS01_3cc97dc7")),
        "{tokens:#?}"
    );
    assert!(
        tokens
            .iter()
            .any(|t| t.contains("/MS/") && t.contains("%r0%cmd_vel")),
        "{tokens:#?}"
    );
    assert!(r["odom"].as_u64().unwrap() > 10, "{r}");
    assert!(r["scan"].as_u64().unwrap() > 10, "{r}");
    assert_eq!(r["bad_attachments"], 0, "{r}");
    assert_eq!(r["frame_id"], "r0/odom");
    assert_eq!(r["child_frame_id"], "r0/base_link");
    assert!(r["scan_rays"].as_u64().unwrap() >= 8, "{r}");
    let moved = r["moved_forward"].as_f64().unwrap();
    assert!(moved > 0.15, "the body did not follow cmd_vel: {r}");
    // The server counted the Twist commands it applied.
    let log = read_jsonl(&out.join("server.jsonl"));
    let stopped = log.iter().find(|x| x["event"] == "server_stopped").unwrap();
    assert!(stopped["twists"][0].as_u64().unwrap() >= 15, "{stopped}");
    assert_eq!(stopped["ros2_rejected"], 0, "{stopped}");
}

/// The formation team with ROS 2 bodies: each robot's mind takes its
/// odometry and scans from `/<robot>/odom` and `/<robot>/scan` and drives by
/// `/<robot>/cmd_vel` (rmw_zenoh conventions), and the team completes.
#[test]
fn a_team_with_ros2_bodies_completes_the_formation() {
    let _one = serial();
    let out = tmp("ros2-team");
    let s = launch(&out, &["--ros2", "7"]);
    assert_eq!(s["completed"], true, "{s:#}");
    assert_eq!(s["invariants"]["violations"], 0, "{s:#}");
    let world = read_jsonl(&out.join("server.jsonl"));
    let stopped = world
        .iter()
        .find(|r| r["event"] == "server_stopped")
        .unwrap();
    assert_eq!(stopped["ros2_rejected"], 0, "{stopped}");
    // The bodies were driven by cmd_vel, not by BITE's own commands.
    for k in 0..3 {
        let twists = stopped["twists"][k].as_u64().unwrap();
        assert!(twists > 100, "{stopped}");
        // (A BITE command may arrive before the first Twist.)
        assert!(stopped["commands"][k].as_u64().unwrap() < 5, "{stopped}");
    }
    let last = world.iter().rev().find(|r| r["event"] == "poses").unwrap();
    let xs: Vec<f64> = (last["robots"].as_array().unwrap().iter())
        .map(|p| p[0].as_f64().unwrap())
        .collect();
    assert!(xs.iter().any(|x| *x > 5.0), "nobody walked: {xs:?}");
    for r in ["r0", "r1", "r2"] {
        let log = read_jsonl(&out.join(format!("{r}.jsonl")));
        let fin = log
            .iter()
            .rev()
            .find(|x| x["event"] == "run_finished")
            .unwrap();
        assert_eq!(fin["payload_rejects"], serde_json::json!({}), "{fin}");
    }
}

/// A robot waiting for its mission counts the frames that reach it
/// (`before-mission`; an oversized one as `oversize`) in its status.
#[test]
#[allow(clippy::disallowed_methods)] // a wall-clock deadline on a real process
fn frames_reaching_a_robot_without_a_mission_are_counted() {
    let _one = serial();
    let out = tmp("before-mission");
    let key = TeamKey::new((0..32).map(|i| i as u8 ^ 0x44).collect()).unwrap();
    let key_file = out.join("team.key");
    std::fs::write(&key_file, key.to_hex()).unwrap();
    let team = format!("waiting-{}", std::process::id());
    let ep = format!("tcp/127.0.0.1:{}", free_port());
    let log = std::fs::File::create(out.join("r0.log")).unwrap();
    let child = bite()
        .current_dir(repo())
        .args(["robot", "--name", "r0", "--team", &team, "--listen", &ep])
        .args(["--scenario", "examples/scenarios/formation.yaml"])
        .arg("--key")
        .arg(&key_file)
        .stdout(log.try_clone().unwrap())
        .stderr(log)
        .stdin(Stdio::null())
        .spawn()
        .unwrap();
    let mut procs = Procs(vec![("r0".into(), child)]);
    let session = client(std::slice::from_ref(&ep));
    let (_sub, rx, first) = waiting_status(&session, &team);
    let scope = Scope::new(&team, 1);
    let hb = [bite_zenoh::wire::PAYLOAD_VERSION, 0, 0];
    for on in ["r1", "r2"] {
        let frame = seal_with(&key, &scope, FrameKind::Heartbeat, 1, unix_micros(), &hb);
        session
            .put(format!("bite/{team}/net/{on}"), frame)
            .wait()
            .unwrap();
    }
    session
        .put(format!("bite/{team}/net/r1"), vec![0; 70_000])
        .wait()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    let want = serde_json::json!({"before-mission": 2, "oversize": 1});
    let mut last = first;
    while last["auth"]["rejected"] != want && Instant::now() < deadline {
        if let Ok(v) = rx.recv_timeout(Duration::from_secs(1)) {
            last = v;
        }
    }
    assert_eq!(last["auth"]["rejected"], want, "{last}");
    assert_eq!(last["state"], "waiting", "{last}");
    procs.terminate();
}

/// `bite submit` checks what it sends as a robot would: a mission that
/// does not load, or is larger than robots take, is refused (exit 2)
/// before anything is sent.
#[test]
fn bite_submit_refuses_what_robots_would_drop() {
    let out = tmp("submit-check");
    let key = TeamKey::new(vec![0x21; 32]).unwrap();
    let key_file = out.join("team.key");
    std::fs::write(&key_file, key.to_hex()).unwrap();
    let bad = out.join("bad.yaml");
    std::fs::write(&bad, "name: [unclosed\n").unwrap();
    let big = out.join("big.yaml");
    let graph = std::fs::read_to_string(repo().join("examples/formation.yaml")).unwrap();
    std::fs::write(&big, format!("{graph}\n# {}\n", "x".repeat(2 << 20))).unwrap();
    let scenario = repo().join("examples/scenarios/formation.yaml");
    for (file, why) in [(&bad, "robots would refuse"), (&big, "1 MiB")] {
        let o = bite()
            .args(["submit", "--team", "nobody", "--id", "m-check"])
            .arg("--key")
            .arg(&key_file)
            .arg("--scenario")
            .arg(&scenario)
            .arg(file)
            .stdin(Stdio::null())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{}: {err}", file.display());
        assert!(err.contains(why), "{}: {err}", file.display());
        assert!(err.contains("nothing was sent"), "{err}");
        assert!(o.stdout.is_empty(), "no id printed: nothing was submitted");
    }
}

/// A robot process frozen (`SIGSTOP`) mid-run: its teammates presume it
/// lost and complete; `bite launch` stops it after a short grace instead
/// of waiting out the wall limit, reports it unresponsive, exits 1, and
/// holds it to no invariant past its freeze.
#[test]
#[allow(clippy::disallowed_methods)] // wall-clock deadlines on real processes
fn a_frozen_robot_is_stopped_and_reported_unresponsive() {
    let _one = serial();
    let out = tmp("frozen");
    let team = format!("frozen-{}", std::process::id());
    let began = Instant::now();
    let child = bite()
        .current_dir(repo())
        .args([
            "launch",
            "examples/formation.yaml",
            "--speed",
            "2",
            "--json",
        ])
        .args(["--team", &team])
        .arg("--out")
        .arg(&out)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut procs = Procs(vec![("launch".into(), child)]);
    // r1's process, found by its command line.
    let r1 = {
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            let found = std::fs::read_dir("/proc").unwrap().flatten().find_map(|d| {
                let cmd = std::fs::read(d.path().join("cmdline")).ok()?;
                let args: Vec<&[u8]> = cmd.split(|b| *b == 0).collect();
                let has = |w: &[&str]| {
                    args.windows(w.len())
                        .any(|x| x.iter().zip(w).all(|(a, b)| *a == b.as_bytes()))
                };
                (has(&["robot"]) && has(&["--name", "r1"]) && has(&["--team", &team]))
                    .then(|| d.file_name().to_string_lossy().parse::<i32>().ok())
                    .flatten()
            });
            if let Some(pid) = found {
                break nix::unistd::Pid::from_raw(pid);
            }
            assert!(Instant::now() < deadline, "r1's process never started");
            std::thread::sleep(Duration::from_millis(100));
        }
    };
    // Whatever happens, r1 is not left frozen.
    struct Thaw(nix::unistd::Pid);
    impl Drop for Thaw {
        fn drop(&mut self) {
            let _ = nix::sys::signal::kill(self.0, nix::sys::signal::Signal::SIGKILL);
        }
    }
    let _thaw = Thaw(r1);
    // Frozen at about 16 s of team time (2 s to start, then 8 s at 2x).
    std::thread::sleep(Duration::from_secs(10));
    nix::sys::signal::kill(r1, nix::sys::signal::Signal::SIGSTOP).unwrap();
    // The wall limit is 300 s / 2 + 20 s = 170 s: it must end well before.
    let exits = procs.wait_all(Duration::from_secs(130));
    assert!(
        exits[0].1.is_some(),
        "bite launch waited for the frozen robot"
    );
    let (_, child) = procs.0.pop().unwrap();
    let o = child.wait_with_output().unwrap();
    let took = began.elapsed();
    let text = String::from_utf8_lossy(&o.stdout);
    let err = String::from_utf8_lossy(&o.stderr);
    let s: Value =
        serde_json::from_str(&text).unwrap_or_else(|e| panic!("no summary ({e}): {err}\n{text}"));
    assert_eq!(o.status.code(), Some(1), "{s:#}\n{err}");
    assert_eq!(s["completed"], false, "{s:#}");
    assert_eq!(s["unresponsive"], serde_json::json!(["r1"]), "{s:#}");
    assert_eq!(s["invariants"]["violations"], 0, "{s:#}");
    for r in s["robots"].as_array().unwrap() {
        if r["robot"] == "r1" {
            assert!(r["unresponsive_at"].as_f64().is_some(), "{r}");
            assert_eq!(r["completed"], false, "{r}");
        } else {
            assert_eq!(r["completed"], true, "{r}");
            let lost = r["lost"].as_array().unwrap();
            assert!(lost.contains(&serde_json::json!("r1")), "{r}");
        }
    }
    assert!(took < Duration::from_secs(120), "took {took:?}");
}
