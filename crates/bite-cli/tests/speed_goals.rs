//! `scripts/speed_goals.py`, which measures every speed goal of issue 20
//! (docs/performance.md): its parsers on captured benchmark output, and a
//! quick run on the binary's own JSON, so that a renamed field of a `bite
//! bench` command breaks a test rather than the next measurement.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn script(args: &[&str]) -> Output {
    Command::new("python3")
        .arg(root().join("scripts/speed_goals.py"))
        .args(args)
        .output()
        .expect("python3 runs")
}

fn text(o: &Output) -> String {
    format!(
        "status {:?}\nstdout:\n{}\nstderr:\n{}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

#[test]
fn the_parsers_read_divan_tables() {
    let o = script(&["--self-test"]);
    assert!(o.status.success(), "{}", text(&o));
}

#[test]
fn a_quick_run_reads_every_bench_commands_json() {
    let dir =
        Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("speed-goals-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch dir");
    let json = dir.join("goals.json");
    let o = script(&[
        "--quick",
        "--only",
        "team,sim,protocols",
        "--rounds",
        "1",
        "--bite",
        env!("CARGO_BIN_EXE_bite"),
        "--json",
        json.to_str().expect("utf-8 path"),
    ]);
    // A quick run gives no verdict: it exits 0 when every command ran.
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("report written"))
            .expect("report is JSON");
    let goals = report["goals"].as_array().expect("goals");
    let ids: Vec<&str> = goals.iter().filter_map(|g| g["goal"].as_str()).collect();
    assert_eq!(
        ids,
        [
            "team_one_thread",
            "team_two_threads",
            "team_memory",
            "sim_two_threads",
            "auction"
        ],
        "{}",
        text(&o)
    );
    for g in goals {
        let values = g["values"].as_array().expect("values");
        assert!(!values.is_empty(), "{g}");
        for v in values {
            let v = v.as_f64().expect("a number");
            assert!(v.is_finite() && v > 0.0, "{g}");
        }
    }
    let table = String::from_utf8_lossy(&o.stdout);
    assert!(
        table.contains("| 10,000 physical robots, two threads | ≥ 5 × real time |"),
        "{table}"
    );
}

#[test]
fn an_unknown_goal_group_is_named() {
    let o = script(&["--only", "team,warp"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("unknown goal group(s) ['warp']"),
        "{}",
        text(&o)
    );
}
