//! `bite bench zenoh`: decision latency of interaction protocols between
//! robot processes over Zenoh on 127.0.0.1, next to a raw Zenoh ping-pong
//! round trip measured in the same run.
//!
//! For each protocol and team size, a team of `bite robot` processes runs
//! a graph that takes the same decision again and again (a synchronization
//! point that loops, or an allocation that is made anew each round); each
//! instance's latency is the time from the first member entering it to the
//! last member deciding, read from the robots' run logs (one team clock).
//! The same graph in the discrete-event simulator with a fixed 1 ms
//! one-way latency gives the protocol's critical path in one-way message
//! hops, so the latency per hop can be set against a raw one-way trip (half
//! the ping-pong round trip).

use anyhow::{Context, Result};
use bite_zenoh::zenoh::Wait;
use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{ExitCode, Stdio};
use std::sync::Arc;
use std::time::Duration;

use crate::team::{LaunchArgs, MissionArgs, Tuning, launch, read_jsonl};

/// The protocols measured.
pub const PROTOCOLS: [&str; 3] = ["sync.leader", "sync.vote", "alloc.auction"];

fn graph_yaml(protocol: &str, n: usize, decisions: usize) -> String {
    if protocol.starts_with("sync.") {
        format!(
            "graph: bench-{protocol}\nteam: {{ robots: {n} }}\nstart: bench\n\
             defaults: {{ sync: {protocol}, allocate: alloc.by-id, terminate: term.wait-all }}\n\
             behaviors:\n\
             \x20 bench: {{ team: true, children: [step] }}\n\
             \x20 step:\n    team: true\n    skill: tick\n    pre: runs(step) < {decisions}\n    until: ticked\n    next: [step, done]\n\
             \x20 done:\n    team: true\n    skill: tick\n    pre: runs(step) >= {decisions}\n    until: ticked\n"
        )
    } else {
        format!(
            "graph: bench-{protocol}\nteam: {{ robots: {n} }}\nstart: bench\n\
             defaults: {{ sync: sync.by-rule, allocate: {protocol}, terminate: term.wait-all }}\n\
             behaviors:\n\
             \x20 bench: {{ team: true, children: [round] }}\n\
             \x20 round:\n    team: true\n    pre: runs(round) < {decisions}\n    children: [x, y]\n    next: [round, done]\n\
             \x20 x: {{ skill: tick, until: ticked, members: \"1..\" }}\n\
             \x20 y: {{ skill: tick, until: ticked, members: \"1..\" }}\n\
             \x20 done:\n    team: true\n    skill: tick\n    pre: runs(round) >= {decisions}\n    until: ticked\n"
        )
    }
}

fn scenario_yaml(latency_ms: f64) -> String {
    format!(
        "scenario: bench\nworld: timed\nseed: 1\ncontrol_hz: 20\ntime_limit: 300s\n\
         network: {{ latency: {latency_ms}ms }}\n\
         skills:\n  tick: {{ duration: [0.15, 0.15], start: {{ ticked: false }}, done: {{ ticked: true }} }}\n"
    )
}

/// Per instance of `kind`: first member's start to last member's decision,
/// seconds. (Robots tick on one team clock, so members enter together up
/// to scheduling jitter, which this counts against the protocol.)
fn latencies(logs: &[Vec<Value>], kind: &str) -> Vec<f64> {
    let mut started: BTreeMap<String, f64> = BTreeMap::new();
    let mut decided: BTreeMap<String, f64> = BTreeMap::new();
    for log in logs {
        for r in log {
            if r["instance"]["kind"] != kind {
                continue;
            }
            let key = r["instance"].to_string();
            let t = r["t"].as_f64().unwrap_or(0.0);
            match r["event"].as_str() {
                Some("interaction_started") => {
                    let s = started.entry(key).or_insert(t);
                    *s = s.min(t);
                }
                Some("interaction_decided") => {
                    let d = decided.entry(key).or_insert(t);
                    *d = d.max(t);
                }
                _ => continue,
            }
        }
    }
    decided
        .iter()
        .filter_map(|(k, d)| started.get(k).map(|s| (d - s).max(0.0)))
        .collect()
}

fn quantile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// The protocol's critical path in one-way hops: the same graph in the
/// discrete-event simulator with a 1 ms latency.
fn rounds_in_sim(graph: &str, protocol: &str) -> Result<f64> {
    let g = bite_core::graph::load_str(&Arc::from("bench graph"), graph)
        .map_err(|d| anyhow::anyhow!("{d}"))?;
    let sc = bite_sim::Scenario::load_str(&Arc::from("bench scenario"), &scenario_yaml(1.0))
        .map_err(|d| anyhow::anyhow!("{d}"))?;
    let mission =
        bite_sim::prepare(&g, &sc, None, &crate::registry()).map_err(|d| anyhow::anyhow!("{d}"))?;
    let mut buf = Vec::new();
    bite_sim::run(
        mission,
        &sc,
        bite_sim::runner::RunOptions {
            log: Some(&mut buf),
            ..Default::default()
        },
    )
    .map_err(|d| anyhow::anyhow!("{d}"))?;
    let log: Vec<Value> = String::from_utf8_lossy(&buf)
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect();
    let kind = if protocol.starts_with("sync.") {
        "sync"
    } else {
        "allocate"
    };
    let mut l = latencies(&[log], kind);
    Ok((quantile(&mut l, 0.5) / 1e-3).round())
}

/// Raw Zenoh round trips (µs) to an echo process, `n` of them after a warm-up.
#[allow(clippy::disallowed_methods)] // a benchmark measures wall time
fn ping_pong(exe: &Path, out: &Path, n: usize) -> Result<Vec<f64>> {
    let port = crate::team::free_ports(1)?[0];
    let ep = format!("tcp/127.0.0.1:{port}");
    let team = format!("bench-{}", std::process::id());
    let log = std::fs::File::create(out.join("pong.log"))?;
    let mut child = std::process::Command::new(exe)
        .args(["bench", "pong", "--team", &team, "--listen", &ep])
        .stdin(Stdio::null())
        .stdout(log.try_clone()?)
        .stderr(log)
        .spawn()
        .context("starting the echo process")?;
    let result = (|| -> Result<Vec<f64>> {
        let net = bite_zenoh::net::NetOptions {
            connect: vec![ep.clone()],
            ..Default::default()
        };
        let session = net.open()?;
        let (tx, rx) = std::sync::mpsc::channel::<Vec<u8>>();
        let _sub = session
            .declare_subscriber(format!("bench/{team}/pong"))
            .callback(move |s| {
                let _ = tx.send(s.payload().to_bytes().into_owned());
            })
            .wait()
            .map_err(|e| anyhow::anyhow!("zenoh: {e}"))?;
        let publisher = session
            .declare_publisher(format!("bench/{team}/ping"))
            .wait()
            .map_err(|e| anyhow::anyhow!("zenoh: {e}"))?;
        let mut rtts = Vec::new();
        let warmup = 50;
        let mut i: u64 = 0;
        let deadline = std::time::Instant::now() + Duration::from_secs(60);
        while rtts.len() < n && std::time::Instant::now() < deadline {
            i += 1;
            // About the size of a kernel frame.
            let mut payload = i.to_le_bytes().to_vec();
            payload.resize(96, 0);
            let t0 = std::time::Instant::now();
            publisher
                .put(payload)
                .wait()
                .map_err(|e| anyhow::anyhow!("zenoh: {e}"))?;
            loop {
                match rx.recv_timeout(Duration::from_millis(500)) {
                    Ok(b) if b.get(..8) == Some(&i.to_le_bytes()[..]) => {
                        if i > warmup {
                            rtts.push(t0.elapsed().as_secs_f64() * 1e6);
                        }
                        break;
                    }
                    Ok(_) => continue,
                    // Not connected yet: try again.
                    Err(_) => break,
                }
            }
        }
        let _ = session.close().wait();
        Ok(rtts)
    })();
    let _ = child.kill();
    let _ = child.wait();
    let rtts = result?;
    if rtts.len() < n / 2 {
        anyhow::bail!("the echo process answered {} of {n} pings", rtts.len());
    }
    Ok(rtts)
}

/// `bite bench pong`: echo `bench/<team>/ping` on `bench/<team>/pong`.
pub fn cmd_pong(team: &str, listen: &str) -> Result<ExitCode> {
    let net = bite_zenoh::net::NetOptions {
        listen: vec![listen.to_string()],
        ..Default::default()
    };
    let session = net.open()?;
    let publisher = session
        .declare_publisher(format!("bench/{team}/pong"))
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh: {e}"))?;
    // Echo straight from Zenoh's callback: the raw round trip.
    let _sub = session
        .declare_subscriber(format!("bench/{team}/ping"))
        .callback(move |s| {
            let _ = publisher.put(s.payload().clone()).wait();
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh: {e}"))?;
    // Runs until killed by the benchmark (at most ten minutes).
    std::thread::sleep(Duration::from_secs(600));
    Ok(ExitCode::SUCCESS)
}

/// `bite bench zenoh`.
pub fn cmd_bench_zenoh(
    robots: &[usize],
    decisions: usize,
    pings: usize,
    out: &Path,
    as_json: bool,
    tuning: &Tuning,
) -> Result<ExitCode> {
    let variant = tuning.label();
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let exe = std::env::current_exe()?;
    eprintln!("raw Zenoh ping-pong between two processes ({pings} round trips)...");
    let mut rtt = ping_pong(&exe, out, pings)?;
    let (rtt_med, rtt_p90) = (quantile(&mut rtt, 0.5), quantile(&mut rtt, 0.9));
    let bar = indicatif::ProgressBar::new((PROTOCOLS.len() * robots.len()) as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{spinner} [{bar:30}] {pos}/{len} {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let mut rows = Vec::new();
    for protocol in PROTOCOLS {
        for &n in robots {
            bar.set_message(format!("{protocol} with {n} robots ({variant})"));
            let dir = out.join(format!("{protocol}-{n}"));
            std::fs::create_dir_all(&dir)?;
            let graph = graph_yaml(protocol, n, decisions);
            let (gp, sp): (PathBuf, PathBuf) = (dir.join("graph.yaml"), dir.join("scenario.yaml"));
            std::fs::write(&gp, &graph)?;
            std::fs::write(&sp, scenario_yaml(1.0))?;
            let rounds = rounds_in_sim(&graph, protocol)?;
            let args = LaunchArgs {
                mission: MissionArgs {
                    graph: Some(gp),
                    scenario: Some(sp),
                    ..Default::default()
                },
                team: None,
                key: None,
                speed: 1.0,
                out: dir.clone(),
                kill: Vec::new(),
                time_limit: Some(Duration::from_secs(120)),
                json: false,
                tuning: tuning.clone(),
                record: false,
                viz: Default::default(),
                ros2: None,
            };
            let (summary, ok) = launch(&args, true)?;
            let logs: Vec<Vec<Value>> = (0..n)
                .map(|k| read_jsonl(&dir.join(format!("r{k}.jsonl"))))
                .collect::<Result<_>>()?;
            let kind = if protocol.starts_with("sync.") {
                "sync"
            } else {
                "allocate"
            };
            let mut l: Vec<f64> = latencies(&logs, kind).iter().map(|s| s * 1e6).collect();
            let (med, p90) = (quantile(&mut l, 0.5), quantile(&mut l, 0.9));
            // `rounds` counts one-way hops (a call, its answers): each is
            // compared with a one-way trip, half the ping-pong round trip.
            let per_hop = med / rounds.max(1.0);
            let one_way = rtt_med / 2.0;
            rows.push(json!({
                "variant": variant, "per_process": tuning.per_process,
                "frames": tuning.frames.name(), "runtime": tuning.zenoh_runtime.name(),
                "processes": summary["processes"],
                "protocol": protocol, "robots": n, "completed": ok,
                "decisions": l.len(), "hops": rounds,
                "latency_median_us": med, "latency_p90_us": p90,
                "per_hop_us": per_hop, "one_way_us": one_way,
                "per_hop_over_one_way": per_hop / one_way,
                "joint_decisions": summary["joint_decisions"],
            }));
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    let report = json!({
        "variant": variant,
        "rtt_median_us": rtt_med,
        "rtt_p90_us": rtt_p90,
        "rows": rows,
    });
    std::fs::write(
        out.join("bench-zenoh.json"),
        serde_json::to_string_pretty(&report)?,
    )?;
    if as_json {
        println!("{report}");
        return Ok(ExitCode::SUCCESS);
    }
    println!(
        "Raw Zenoh round trip (ping-pong, two processes, 96-byte payload): median {rtt_med:.0} µs, p90 {rtt_p90:.0} µs ({} samples).",
        rtt.len()
    );
    println!(
        "| variant | protocol | robots | processes | decisions | hops (one-way) | decision latency median | p90 | per hop | per hop / one-way trip (half the round trip) |"
    );
    println!("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
    for r in &rows {
        println!(
            "| {} | `{}` | {} | {} | {}{} | {} | {:.0} µs | {:.0} µs | {:.0} µs | {:.2}× |",
            r["variant"].as_str().unwrap_or("?"),
            r["protocol"].as_str().unwrap_or("?"),
            r["robots"],
            r["processes"],
            r["decisions"],
            if r["completed"] == true {
                ""
            } else {
                " (incomplete)"
            },
            r["hops"],
            r["latency_median_us"].as_f64().unwrap_or(f64::NAN),
            r["latency_p90_us"].as_f64().unwrap_or(f64::NAN),
            r["per_hop_us"].as_f64().unwrap_or(f64::NAN),
            r["per_hop_over_one_way"].as_f64().unwrap_or(f64::NAN),
        );
    }
    println!("details: {}", out.join("bench-zenoh.json").display());
    Ok(ExitCode::SUCCESS)
}
