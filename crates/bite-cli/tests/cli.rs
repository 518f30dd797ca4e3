//! The `bite` binary end to end: pictures and benchmark figures.

use std::path::PathBuf;
use std::process::Command;

fn bite() -> Command {
    Command::new(env!("CARGO_BIN_EXE_bite"))
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("bite-cli-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("scratch dir");
    d
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

#[test]
fn run_writes_an_animated_gif_of_the_box_push() {
    let d = scratch("gif");
    let gif = d.join("push.gif");
    let out = bite()
        .arg("run")
        .arg(root().join("examples/box-push.yaml"))
        .args(["--every", "10", "--gif"])
        .arg(&gif)
        .arg("--log")
        .arg(d.join("run.jsonl"))
        .output()
        .expect("bite runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let bytes = std::fs::read(&gif).expect("gif written");
    assert_eq!(&bytes[..6], b"GIF89a");
    // One image descriptor (0x2C after a graphic control block) per frame:
    // the run lasts over 50 s, so at least 6 frames at one per 10 s.
    let frames = bytes.windows(2).filter(|w| w == &[0x00, 0x2C]).count();
    assert!(frames >= 6, "{frames} frames");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("push.gif"), "{stdout}");
}

#[test]
fn bench_sim_reports_every_team_size_and_draws_the_curve() {
    let d = scratch("bench");
    let plot = d.join("scale.svg");
    let out = bite()
        .args([
            "bench",
            "sim",
            "--robots",
            "4,9",
            "--seconds",
            "5",
            "--plot",
        ])
        .arg(&plot)
        .output()
        .expect("bite runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let table = String::from_utf8_lossy(&out.stdout);
    for row in [
        "| formation |",
        "| box-push |",
        "| coverage 4 | 4 |",
        "| coverage 9 | 9 |",
    ] {
        assert!(table.contains(row), "missing {row}:\n{table}");
    }
    let svg = std::fs::read_to_string(&plot).expect("plot written");
    assert!(svg.starts_with("<svg") && svg.contains("robots"), "{svg}");
}

#[test]
fn drawing_a_timed_world_is_a_clear_error() {
    let out = bite()
        .arg("run")
        .arg(root().join("examples/patrol.yaml"))
        .args(["--timed", "--gif", "/nonexistent/x.gif"])
        .output()
        .expect("bite runs");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--gif"), "{err}");
}
