//! Same inputs, same decisions: a launched team records every robot's
//! inputs (`bite launch --record`), and `bite replay` re-runs each mind
//! from them with every output identical — the timed and the physical
//! world, and after a robot is killed (its record is cut mid-line). A
//! record whose fingerprint was altered is reported as different.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

fn bite() -> Command {
    Command::new(env!("CARGO_BIN_EXE_bite"))
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("bite-replay-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn launch(out: &Path, graph: &str, extra: &[&str]) {
    let run = bite()
        .current_dir(repo())
        .args(["launch", graph, "--speed", "4", "--record", "--json"])
        .arg("--out")
        .arg(out)
        .args(extra)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let s: serde_json::Value = serde_json::from_slice(&run.stdout)
        .unwrap_or_else(|e| panic!("no summary ({e}): {}", String::from_utf8_lossy(&run.stderr)));
    assert_eq!(s["completed"], true, "{s:#}");
}

fn replay(file: &Path) -> (bool, String) {
    let out = bite()
        .current_dir(repo())
        .arg("replay")
        .arg(file)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).to_string(),
    )
}

#[test]
fn every_robot_replays_identically_from_its_recorded_inputs() {
    const FORMATION: &str = "examples/formation.yaml";
    for (name, graph, extra) in [
        ("timed", FORMATION, vec!["--timed"]),
        ("physical", FORMATION, vec![]),
        (
            "physical-kill",
            FORMATION,
            vec!["--kill", "r2@12s", "--config", "examples/configs/7.yaml"],
        ),
        ("box-push", "examples/search-rescue.rtcl", vec![]),
    ] {
        let out = tmp(name);
        launch(&out, graph, &extra);
        let robots: Vec<String> = (std::fs::read_dir(&out).unwrap())
            .filter_map(|e| e.ok()?.file_name().into_string().ok())
            .filter_map(|f| f.strip_suffix(".inputs").map(String::from))
            .collect();
        assert!(robots.len() >= 2, "{name}: records of {robots:?}");
        for r in &robots {
            let file = out.join(format!("{r}.inputs"));
            let (ok, text) = replay(&file);
            assert!(ok && text.starts_with("identical"), "{name} {r}: {text}");
            let n: usize = text
                .trim_start_matches("identical (")
                .split(' ')
                .next()
                .and_then(|n| n.parse().ok())
                .unwrap_or(0);
            assert!(n > 50, "{name} {r}: only {n} inputs: {text}");
        }
    }
    // An altered record is caught.
    let out = tmp("altered");
    launch(&out, FORMATION, &["--timed"]);
    let file = out.join("r0.inputs");
    let text = std::fs::read_to_string(&file).unwrap();
    let altered: Vec<String> = text
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i == 10 {
                l.replace("\"fingerprint\":\"", "\"fingerprint\":\"0")
            } else {
                l.to_string()
            }
        })
        .collect();
    std::fs::write(&file, altered.join("\n") + "\n").unwrap();
    let (ok, text) = replay(&file);
    assert!(!ok && text.starts_with("differs at line 11"), "{text}");
}
