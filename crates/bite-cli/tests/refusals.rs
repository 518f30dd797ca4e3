//! Input that a command must refuse, quickly and with a clear error,
//! rather than run with: team sizes and thread counts out of bounds,
//! records and files without end, outputs that would overwrite the
//! command's own inputs, baselines that do not load.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

fn bite() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_bite"));
    c.current_dir(root());
    c
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A fresh scratch directory `name` for a test.
fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("bite-refusals-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("scratch dir");
    d
}

/// Run `c`, killed if it takes longer than `limit`: what a refusal must
/// not (a refused input is refused at once, not after eating the machine).
#[allow(clippy::disallowed_methods)] // a test's deadline is wall time
fn within(mut c: Command, limit: Duration) -> Output {
    let mut child = c
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("bite starts");
    let started = Instant::now();
    loop {
        if child.try_wait().expect("bite waits").is_some() {
            return child.wait_with_output().expect("bite output");
        }
        if started.elapsed() > limit {
            let _ = child.kill();
            let out = child.wait_with_output().expect("bite output");
            panic!(
                "still running after {limit:?}: {c:?}\n{}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// `bite ARGS`, which must fail within `limit` with `code` and a standard
/// error that says `says`; returns standard error.
fn refused(args: &[&std::ffi::OsStr], code: i32, says: &str) -> String {
    let mut c = bite();
    c.args(args);
    let out = within(c, Duration::from_secs(60));
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(code), "{args:?}: {err}");
    assert!(err.contains(says), "{args:?}: expected `{says}` in:\n{err}");
    err
}

fn os(s: &str) -> &std::ffi::OsStr {
    s.as_ref()
}

#[test]
fn sweep_holds_robots_and_jobs_to_their_bounds() {
    let d = scratch("sweep");
    let out = d.join("sweep.jsonl");
    let base = |extra: &[&str]| -> Vec<std::ffi::OsString> {
        let mut v: Vec<std::ffi::OsString> = ["sweep", "--classes", "none", "--seeds", "1"]
            .iter()
            .map(Into::into)
            .collect();
        v.extend(extra.iter().map(Into::into));
        v.push("--out".into());
        v.push(out.clone().into());
        v
    };
    for (extra, says) in [
        (&["--robots", "0"][..], "a team needs at least one robot"),
        (&["--robots", "100000000000"][..], "at most 1000000 robots"),
        (&["--jobs", "0"][..], "at least one thread"),
        (&["--jobs", "100000"][..], "at most 1024 threads"),
    ] {
        let args = base(extra);
        let args: Vec<&std::ffi::OsStr> = args.iter().map(|a| a.as_os_str()).collect();
        refused(&args, 2, says);
    }
    assert!(!out.exists(), "a refused sweep wrote nothing");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn experiment_and_tune_hold_jobs_to_their_bounds() {
    refused(
        &[
            os("experiment"),
            os("examples/experiments/table2.yaml"),
            os("--jobs"),
            os("0"),
        ],
        2,
        "at least one thread",
    );
    refused(
        &[
            os("tune"),
            os("examples/formation.yaml"),
            os("--jobs"),
            os("5000"),
        ],
        2,
        "at most 1024 threads",
    );
}

/// A record whose header says the mission ran with `robots`.
fn record_with_robots(d: &Path, robots: &str) -> PathBuf {
    let f = d.join(format!("r0-{robots}.inputs"));
    let graph = root().join("examples/formation.yaml");
    std::fs::write(
        &f,
        format!(
            "{{\"bite_inputs\":1,\"header\":{{\"robot\":\"r0\",\"origin\":{{\"args\":{{\"graph\":{:?},\"timed\":true,\"robots\":{robots}}}}}}}}}\n",
            graph.display().to_string()
        ),
    )
    .expect("write the record");
    f
}

#[test]
fn replay_holds_the_recorded_team_size_to_the_bounds_of_robots() {
    let d = scratch("replay-robots");
    for (robots, says) in [
        ("100000000000", "at most 1000000 robots"),
        ("0", "a team needs at least one robot"),
        ("-3", "not a number of robots"),
    ] {
        let f = record_with_robots(&d, robots);
        let err = refused(&[os("replay"), f.as_os_str()], 3, says);
        assert!(err.contains(&f.display().to_string()), "{err}");
        assert!(err.contains("`robots`"), "{err}");
    }
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn replay_of_an_endless_file_stops_at_the_line_cap() {
    if !Path::new("/dev/zero").exists() {
        eprintln!("no /dev/zero here: skipped");
        return;
    }
    let err = refused(
        &[os("replay"), os("/dev/zero")],
        3,
        "more than 16777216 bytes without a line break",
    );
    assert!(err.contains("/dev/zero: line 1"), "{err}");
}

#[test]
fn frames_are_at_least_a_hundredth_of_a_second_apart() {
    let d = scratch("frames");
    let frames = d.join("frames");
    let log = d.join("run.jsonl");
    let run = |every: &str, limit: &str| {
        vec![
            os("run").to_owned(),
            os("examples/formation.yaml").to_owned(),
            os("--every").to_owned(),
            os(every).to_owned(),
            os("--time-limit").to_owned(),
            os(limit).to_owned(),
            os("--frames").to_owned(),
            frames.clone().into_os_string(),
            os("--log").to_owned(),
            log.clone().into_os_string(),
        ]
    };
    let args = run("1e-9", "1s");
    let args: Vec<&std::ffi::OsStr> = args.iter().map(|a| a.as_os_str()).collect();
    refused(
        &args,
        2,
        "frames are at least 0.01 s of simulated time apart",
    );
    assert!(!frames.exists(), "no frame written");
    assert!(!log.exists(), "refused before the run");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn tune_refuses_a_baseline_that_does_not_load_and_zero_passes() {
    let d = scratch("tune");
    let bad_yaml = d.join("bad.yaml");
    std::fs::write(&bad_yaml, "config: x\nbindings: [A: \n").expect("write");
    let unknown = d.join("unknown.yaml");
    std::fs::write(&unknown, "config: x\nbindings:\n  A: no.such-protocol\n").expect("write");
    let missing = d.join("missing.yaml");
    let nothing = d.join("none-*.yaml");
    // A pattern: the files it matches that do not fit are skipped, each
    // said; one none of whose files fits is refused.
    let unfit = d.join("*.yaml");
    let out = d.join("out");
    for (baseline, says) in [
        (&missing, "missing.yaml"),
        (&bad_yaml, "bad.yaml"),
        (&unknown, "unknown.yaml"),
        (&nothing, "no file matches"),
        (&unfit, "no file it matches is a configuration"),
    ] {
        let err = refused(
            &[
                os("tune"),
                os("examples/formation.yaml"),
                os("--timed"),
                os("--seeds"),
                os("1"),
                os("--holdout"),
                os("2"),
                os("--baseline"),
                baseline.as_os_str(),
                os("--out"),
                out.as_os_str(),
            ],
            if baseline == &nothing || baseline == &unfit {
                3
            } else {
                2
            },
            says,
        );
        assert!(err.contains("--baseline"), "{err}");
        if baseline == &unfit {
            assert!(err.contains("unknown.yaml skipped"), "{err}");
        }
    }
    refused(
        &[
            os("tune"),
            os("examples/formation.yaml"),
            os("--passes"),
            os("0"),
        ],
        2,
        "at least one pass",
    );
    let _ = std::fs::remove_dir_all(&d);
}

/// Every command that writes files made from input files refuses an output
/// that is one of its inputs, or another of its outputs, and leaves the
/// input as it was.
#[test]
fn an_output_that_would_overwrite_an_input_is_refused() {
    let d = scratch("clobber");
    let graph = d.join("clob.yaml");
    std::fs::copy(root().join("examples/formation.yaml"), &graph).expect("copy");
    let mission = d.join("m.rtcl");
    std::fs::copy(root().join("examples/red-cube.rtcl"), &mission).expect("copy");
    let scenario = root().join("examples/scenarios/formation.yaml");
    let log = d.join("real.jsonl");
    // A real run log, to convert.
    let made = bite()
        .args(["run", "examples/formation.yaml", "--timed", "--log"])
        .arg(&log)
        .output()
        .expect("bite runs");
    assert!(made.status.success(), "{made:?}");
    let linked = d.join("linked.yaml");
    std::fs::hard_link(&graph, &linked).expect("hard link");
    let before = |p: &Path| std::fs::read(p).expect("read");
    let (g0, m0, l0) = (before(&graph), before(&mission), before(&log));
    let cases: Vec<(Vec<&std::ffi::OsStr>, &str)> = vec![
        (
            vec![
                os("log"),
                os("convert"),
                log.as_os_str(),
                os("-o"),
                log.as_os_str(),
            ],
            "--output",
        ),
        (
            vec![
                os("run"),
                graph.as_os_str(),
                os("--scenario"),
                scenario.as_os_str(),
                os("--log"),
                graph.as_os_str(),
            ],
            "--log",
        ),
        (
            vec![
                os("run"),
                graph.as_os_str(),
                os("--scenario"),
                scenario.as_os_str(),
                os("--log"),
                linked.as_os_str(),
            ],
            "--log",
        ),
        (
            vec![
                os("compile"),
                mission.as_os_str(),
                os("-o"),
                mission.as_os_str(),
            ],
            "--output",
        ),
        (
            vec![os("graph"), graph.as_os_str(), os("-o"), graph.as_os_str()],
            "--output",
        ),
        (
            vec![
                os("sweep"),
                os("--graph"),
                graph.as_os_str(),
                os("--out"),
                graph.as_os_str(),
            ],
            "--out",
        ),
    ];
    for (args, flag) in cases {
        let err = refused(&args, 3, "would overwrite the input");
        assert!(err.contains(flag), "{err}");
    }
    // Two outputs of one run to one file.
    let both = d.join("both.out");
    let err = refused(
        &[
            os("run"),
            graph.as_os_str(),
            os("--scenario"),
            scenario.as_os_str(),
            os("--log"),
            both.as_os_str(),
            os("--mcap"),
            both.as_os_str(),
        ],
        3,
        "are the same file",
    );
    assert!(err.contains("--log") && err.contains("--mcap"), "{err}");
    assert!(!both.exists());
    assert_eq!(before(&graph), g0, "the graph is untouched");
    assert_eq!(before(&mission), m0, "the mission is untouched");
    assert_eq!(before(&log), l0, "the run log is untouched");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn messages_say_the_real_bound_and_the_real_command_once() {
    // `control_hz` is more than 0, at most 1000.
    let d = scratch("messages");
    let s = d.join("zero-hz.yaml");
    let text = std::fs::read_to_string(root().join("examples/scenarios/formation.yaml"))
        .expect("the scenario");
    let text: String = text
        .lines()
        .map(|l| {
            if l.starts_with("control_hz:") {
                "control_hz: 0".to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    assert!(
        text.contains("control_hz: 0"),
        "the scenario sets control_hz"
    );
    std::fs::write(&s, text).expect("write");
    let err = refused(
        &[
            os("run"),
            os("examples/formation.yaml"),
            os("--scenario"),
            s.as_os_str(),
            os("--log"),
            d.join("run.jsonl").as_os_str(),
        ],
        2,
        "more than 0 and at most 1000",
    );
    assert!(!err.contains("between 0 and"), "{err}");
    // `bite submit --help` names no command that does not exist.
    let help = bite()
        .args(["submit", "--help"])
        .output()
        .expect("bite runs");
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(help.contains("mission_refused"), "{help}");
    assert!(!help.contains("bite status"), "{help}");
    // A directory as the MCAP file: said once.
    let log = d.join("l.jsonl");
    std::fs::write(&log, "").expect("write");
    let err = refused(
        &[
            os("log"),
            os("convert"),
            log.as_os_str(),
            os("-o"),
            d.as_os_str(),
        ],
        3,
        "Is a directory",
    );
    assert_eq!(err.matches("Is a directory").count(), 1, "{err}");
    let _ = std::fs::remove_dir_all(&d);
}
