//! The `bite` binary end to end: pictures and benchmark figures.

use std::path::PathBuf;
use std::process::Command;

fn bite() -> Command {
    Command::new(env!("CARGO_BIN_EXE_bite"))
}

fn scratch(name: &str) -> PathBuf {
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("bite-cli-test-{}-{name}", std::process::id()));
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
    // Decoded: the run lasts over 50 s, so at least 6 frames at one per
    // 10 s, each 800 pixels wide, shown a second apart.
    let mut opts = gif::DecodeOptions::new();
    opts.set_color_output(gif::ColorOutput::Indexed);
    let mut d = opts.read_info(bytes.as_slice()).expect("a GIF");
    assert_eq!(d.width(), 800);
    let mut frames = 0;
    while let Some(f) = d.read_next_frame().expect("a frame") {
        assert_eq!(f.delay, 100);
        frames += 1;
    }
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

/// Run a mission and return (summary JSON, run-log records).
fn run_mission(mission: &str, tag: &str) -> (serde_json::Value, Vec<serde_json::Value>) {
    let d = scratch(tag);
    let log = d.join("run.jsonl");
    let out = bite()
        .arg("run")
        .arg(root().join(mission))
        .arg("--json")
        .arg("--log")
        .arg(&log)
        .output()
        .expect("bite runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary: serde_json::Value =
        serde_json::from_slice(&out.stdout).expect("the summary is JSON");
    let records = std::fs::read_to_string(&log)
        .expect("run log")
        .lines()
        .map(|l| serde_json::from_str(l).expect("a JSON record"))
        .collect();
    (summary, records)
}

/// The behaviors robot `r` was selected for, in order.
fn selected(records: &[serde_json::Value], r: &str) -> Vec<String> {
    records
        .iter()
        .filter(|x| x["event"] == "selected" && x["robot"] == r)
        .filter_map(|x| x["behavior"].as_str().map(str::to_string))
        .collect()
}

#[test]
fn the_search_and_rescue_mission_compiles_runs_and_delivers_the_box_in_order() {
    let (summary, records) = run_mission("examples/search-rescue.rtcl", "rescue");
    assert_eq!(summary["completed"], true, "{summary:#}");
    let world = &summary["world"];
    assert!(
        world["goal_met_at"].is_number(),
        "the box never reached the goal: {world:#}"
    );
    // The behavior sets ran in the order the commands were entered: every
    // robot searched, then moved the box, first leg before last leg.
    let mut pushers = Vec::new();
    for r in ["r0", "r1"] {
        let s = selected(&records, r);
        let at = |b: &str| {
            s.iter()
                .position(|x| x == b)
                .unwrap_or_else(|| panic!("{r} never ran {b}: {s:?}"))
        };
        assert!(at("find_1") < at("move_2"), "{r}: {s:?}");
        assert!(at("move_2") < at("move_2_first_leg"), "{r}: {s:?}");
        assert!(at("move_2_first_leg") < at("move_2_last_leg"), "{r}: {s:?}");
        if s.iter().any(|x| x == "move_2_push") {
            // The relay: whoever pushed first steps aside.
            assert!(at("move_2_push") < at("move_2_step_aside"), "{r}: {s:?}");
            pushers.push(r);
        } else {
            assert!(at("move_2_watch") < at("move_2_finish_push"), "{r}: {s:?}");
        }
    }
    assert_eq!(
        pushers.len(),
        1,
        "exactly one robot pushes first: {pushers:?}"
    );
}

#[test]
fn the_red_cube_mission_brings_back_the_red_cube_and_nothing_else() {
    let (summary, records) = run_mission("examples/red-cube.rtcl", "cube");
    assert_eq!(summary["completed"], true, "{summary:#}");
    assert!(summary["world"]["goal_met_at"].is_number(), "{summary:#}");
    // Of the four objects, only the red 0.25 m cube moved far: not the red
    // crate (wrong size), the blue cube (wrong colour) or the yellow box.
    let poses: Vec<&serde_json::Value> = records.iter().filter(|x| x["event"] == "poses").collect();
    let (first, last) = (poses.first().expect("poses"), poses.last().expect("poses"));
    let moved = |o: &str| {
        let a = &first["objects"][o];
        let b = &last["objects"][o];
        let (ax, ay, bx, by) = (
            a[0].as_f64().unwrap_or(0.0),
            a[1].as_f64().unwrap_or(0.0),
            b[0].as_f64().unwrap_or(0.0),
            b[1].as_f64().unwrap_or(0.0),
        );
        ((ax - bx).powi(2) + (ay - by).powi(2)).sqrt()
    };
    assert!(
        moved("red_cube") > 3.0,
        "red cube moved {:.2} m",
        moved("red_cube")
    );
    for other in ["red_crate", "blue_cube", "yellow_box"] {
        assert!(moved(other) < 0.3, "{other} moved {:.2} m", moved(other));
    }
}

#[test]
fn compile_prints_the_graph_and_locates_mistakes() {
    let out = bite()
        .arg("compile")
        .arg(root().join("examples/search-rescue.rtcl"))
        .arg("--world")
        .output()
        .expect("bite runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("graph: search-rescue") && text.contains("targets:"),
        "{text}"
    );
    // The origin as the docs write it, negative numbers included.
    let out = bite()
        .arg("compile")
        .arg(root().join("examples/search-rescue.rtcl"))
        .args(["--world", "--origin", "-1,2.5"])
        .output()
        .expect("bite runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("[-1.5, 3]"),
        "the goal moved with the origin:\n{text}"
    );
    let out = bite()
        .arg("compile")
        .arg(root().join("examples/search-rescue.rtcl"))
        .args(["--origin", "1"])
        .output()
        .expect("bite runs");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("x,y"));
    let d = scratch("bad-mission");
    let bad = d.join("bad.rtcl");
    std::fs::write(&bad, "find::::yellow=>box\nmvoe:box:1:2\n").expect("write");
    let out = bite().arg("compile").arg(&bad).output().expect("bite runs");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad.rtcl:2:1") && err.contains("move"),
        "{err}"
    );
}

#[test]
fn the_formation_and_coverage_missions_complete_in_their_worlds() {
    let (summary, _) = run_mission("examples/formation-walk.rtcl", "walk");
    assert_eq!(summary["completed"], true, "{summary:#}");
    let err = summary["world"]["formation_error"][0]
        .as_f64()
        .unwrap_or(f64::MAX);
    assert!(err < 0.25, "formation error {err}");
    let (summary, _) = run_mission("examples/coverage-sweep.rtcl", "sweep");
    assert_eq!(summary["completed"], true, "{summary:#}");
    assert_eq!(summary["robots"], 5, "{summary:#}");
    let covered = summary["world"]["coverage"].as_f64().unwrap_or(0.0);
    assert!(covered >= 0.9, "covered {covered}");
}

/// A run that did not complete prints the command that replays it, and
/// that command runs the same run: the same world (a timed run replayed
/// without `--timed` ran in the physical world), faults, limit and seed.
#[test]
fn the_replay_line_of_a_run_replays_that_run() {
    let d = scratch("replay-line");
    let run = |args: &[String], log: &str| {
        let out = bite()
            .current_dir(root())
            .args(args)
            .arg("--log")
            .arg(d.join(log))
            .output()
            .expect("bite runs");
        let text = String::from_utf8_lossy(&out.stdout).into_owned();
        (out.status.code(), text)
    };
    // A timed run under a configuration (its replay must say `--timed`),
    // and a compiled mission (its replay must name the `.rtcl` file, not
    // the compiled graph's display name).
    let cases: [(&[&str], &str); 2] = [
        (
            &[
                "run",
                "--timed",
                "--config",
                "examples/configs/6.yaml",
                "--fault",
                "loss=0.2",
                "--time-limit",
                "20s",
                "--seed",
                "5",
            ],
            "--timed",
        ),
        (
            &[
                "run",
                "examples/search-rescue.rtcl",
                "--time-limit",
                "8s",
                "--seed",
                "3",
            ],
            "examples/search-rescue.rtcl",
        ),
    ];
    for (i, (first, must_name)) in cases.iter().enumerate() {
        let first: Vec<String> = first.iter().map(|w| w.to_string()).collect();
        let (code, text) = run(&first, &format!("first{i}.jsonl"));
        assert_ne!(code, Some(0), "cut short by its time limit: {text}");
        let line = text
            .lines()
            .find_map(|l| l.trim().strip_prefix("replay"))
            .unwrap_or_else(|| panic!("no replay line in {text}"));
        let again: Vec<String> = line
            .split_whitespace()
            .skip_while(|w| *w != "run")
            .map(|w| w.trim_matches('\'').to_string())
            .collect();
        assert!(again.iter().any(|w| w == must_name), "{line}");
        let (code2, text2) = run(&again, &format!("again{i}.jsonl"));
        assert_eq!(code, code2, "{line}: {text2}");
        let summary = |t: &str| -> Vec<String> {
            t.lines()
                .filter(|l| !l.contains("run log"))
                .map(String::from)
                .collect()
        };
        assert_eq!(summary(&text), summary(&text2));
    }
}

/// Run `bite` with these arguments: exit code and standard error.
fn bite_err(args: &[&std::ffi::OsStr]) -> (Option<i32>, String) {
    let out = bite().args(args).output().expect("bite runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn devices_and_endless_fifos_are_refused_at_the_size_cap() {
    let zero = std::ffi::OsStr::new("/dev/zero");
    let formation = root().join("examples/formation.yaml");
    let cases: Vec<Vec<&std::ffi::OsStr>> = vec![
        vec!["check".as_ref(), zero],
        vec!["compile".as_ref(), zero],
        vec![
            "check".as_ref(),
            formation.as_ref(),
            "--config".as_ref(),
            zero,
        ],
        vec![
            "run".as_ref(),
            formation.as_ref(),
            "--timed".as_ref(),
            "--scenario".as_ref(),
            zero,
        ],
    ];
    for args in cases {
        let (code, err) = bite_err(&args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert!(
            err.contains("/dev/zero: error[too-large]") && err.contains("16777216"),
            "{args:?}: {err}"
        );
    }
    // A FIFO fed without end.
    let d = scratch("fifo");
    let fifo = d.join("endless.yaml");
    let made = Command::new("mkfifo").arg(&fifo).status();
    if !made.is_ok_and(|s| s.success()) {
        eprintln!("no mkfifo here: FIFO case skipped");
        return;
    }
    let writer = {
        let fifo = fifo.clone();
        std::thread::spawn(move || {
            use std::io::Write as _;
            let Ok(mut f) = std::fs::OpenOptions::new().write(true).open(&fifo) else {
                return;
            };
            let chunk = [b'#'; 65536];
            // Until the reader hangs up (EPIPE).
            while f.write_all(&chunk).is_ok() {}
        })
    };
    let (code, err) = bite_err(&["check".as_ref(), fifo.as_os_str()]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("error[too-large]"), "{err}");
    writer.join().expect("writer ends");
}

#[test]
fn invalid_utf8_is_located_in_every_input() {
    let d = scratch("utf8");
    let formation = root().join("examples/formation.yaml");
    let graph = d.join("g.yaml");
    std::fs::write(
        &graph,
        b"graph: g\nstart: a\nbehaviors:\n  a: {description: \"caf\xe9\"}\n",
    )
    .expect("write");
    let config = d.join("c.yaml");
    std::fs::write(&config, b"bindings:\n  \xff: {}\n").expect("write");
    let scenario = d.join("s.yaml");
    std::fs::write(&scenario, b"scenario: s\r\nseed: 1\r\n  \xc3\x28\r\n").expect("write");
    let mission = d.join("m.rtcl");
    std::fs::write(
        &mission,
        "find:box\nmove:ü\u{1}"
            .bytes()
            .chain([0x80])
            .collect::<Vec<u8>>(),
    )
    .expect("write");
    let cases: Vec<(Vec<&std::ffi::OsStr>, String)> = vec![
        (
            vec!["check".as_ref(), graph.as_ref()],
            format!("{}:4:24: error[invalid-utf8]", graph.display()),
        ),
        (
            vec![
                "check".as_ref(),
                formation.as_ref(),
                "--config".as_ref(),
                config.as_ref(),
            ],
            format!("{}:2:3: error[invalid-utf8]", config.display()),
        ),
        (
            vec![
                "run".as_ref(),
                formation.as_ref(),
                "--timed".as_ref(),
                "--scenario".as_ref(),
                scenario.as_ref(),
            ],
            format!("{}:3:3: error[invalid-utf8]", scenario.display()),
        ),
        (
            vec!["compile".as_ref(), mission.as_ref()],
            format!("{}:2:8: error[invalid-utf8]", mission.display()),
        ),
    ];
    for (args, want) in cases {
        let (code, err) = bite_err(&args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert!(err.contains(&want), "want {want:?} in:\n{err}");
    }
}

#[test]
fn garbage_missions_exit_2_with_a_code() {
    let d = scratch("garbage");
    // Bytes from a fixed generator (xorshift), as a random file would be;
    // once as they are, once made printable ASCII.
    let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
    let bytes: Vec<u8> = (0..4096)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect();
    let ascii: Vec<u8> = bytes.iter().map(|b| b' ' + b % 95).collect();
    for (name, content) in [("raw.rtcl", bytes), ("ascii.rtcl", ascii)] {
        let p = d.join(name);
        std::fs::write(&p, content).expect("write");
        for cmd in ["check", "compile"] {
            let (code, err) = bite_err(&[cmd.as_ref(), p.as_os_str()]);
            assert_eq!(code, Some(2), "{cmd} {name}: {err}");
            assert!(
                err.contains(&format!("{}:", p.display())) && err.contains("error["),
                "{cmd} {name}: a located diagnostic with a code:\n{err}"
            );
        }
    }
}

#[test]
fn check_refuses_a_loop_back_to_an_ancestor() {
    let g = root().join("crates/bite-core/tests/fixtures/loop-to-ancestor.yaml");
    let (code, err) = bite_err(&["check".as_ref(), g.as_os_str()]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains(&format!("{}:8:12: error[loop-to-ancestor]", g.display()))
            && err.contains("(mission > work)"),
        "{err}"
    );
}

#[test]
fn graph_svg_draws_every_behavior_with_its_bound_protocols() {
    let out = bite()
        .args(["graph", "--svg", "--config"])
        .arg(root().join("examples/configs/7.yaml"))
        .arg(root().join("examples/formation.yaml"))
        .output()
        .expect("bite graph");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let svg = String::from_utf8_lossy(&out.stdout);
    assert!(svg.starts_with("<svg"), "{svg}");
    for b in [
        "formation",
        "triangle",
        "line",
        "search",
        "walk",
        "linewalk",
        "lead",
    ] {
        assert!(svg.contains(&format!("data-behavior=\"{b}\"")), "{b}");
    }
    // The protocols of the configuration, not the graph's defaults.
    let check = bite()
        .args(["check", "--config"])
        .arg(root().join("examples/configs/7.yaml"))
        .arg(root().join("examples/formation.yaml"))
        .output()
        .expect("bite check");
    let listing = String::from_utf8_lossy(&check.stdout);
    let bound: Vec<&str> = listing
        .lines()
        .filter_map(|l| l.split_whitespace().nth(2))
        .filter(|p| p.contains('.') && !p.ends_with(':'))
        .collect();
    assert!(!bound.is_empty(), "{listing}");
    for p in bound {
        assert!(svg.contains(&format!(": {p}<")), "{p} not drawn");
    }
}

#[test]
fn bench_commands_print_json_rows_for_scripts() {
    let parse = |args: &[&str]| -> serde_json::Value {
        let out = bite().args(args).output().expect("bite bench");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice(&out.stdout)
            .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stdout)))
    };
    let team = parse(&["bench", "team", "--robots", "20", "--json"]);
    assert_eq!(team["rows"][0]["robots"], 20);
    assert!(
        team["rows"][0]["real_time_factor"]
            .as_f64()
            .is_some_and(|f| f > 0.0)
    );
    assert_eq!(team["rows"][0]["completed"], true);
    // The run's outcome, honestly: fault-free, it needed no deadline.
    assert_eq!(team["rows"][0]["outcome"], "completed", "{team}");
    assert_eq!(team["rows"][0]["timeouts"], 0, "{team}");
    // Sizes × thread counts × repetitions, one row each, and the picture.
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("bite-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch dir");
    let svg = dir.join("team.svg");
    let svg_arg = svg.to_string_lossy().to_string();
    let team = parse(&[
        "bench",
        "team",
        "--robots",
        "5,12",
        "--threads",
        "1,2",
        "--repeat",
        "2",
        "--json",
        "--plot",
        &svg_arg,
    ]);
    let rows = team["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), 8, "{rows:?}");
    let key = |r: &serde_json::Value| {
        (
            r["threads"].clone(),
            r["robots"].clone(),
            r["repeat"].clone(),
        )
    };
    assert_eq!(key(&rows[0]), (1.into(), 5.into(), 0.into()));
    assert_eq!(key(&rows[7]), (2.into(), 12.into(), 1.into()));
    // The same run on one thread and on two: the same messages.
    assert_eq!(rows[0]["messages"], rows[4]["messages"]);
    // One thread handles no robots' events side by side.
    assert_eq!(rows[0]["side_by_side"]["windows"], 0, "{:?}", rows[0]);
    let picture = std::fs::read_to_string(&svg).expect("the plot");
    assert!(picture.contains("one thread") && picture.contains("2 threads"));
    let _ = std::fs::remove_dir_all(&dir);
    let protocols = parse(&[
        "bench",
        "protocols",
        "--robots",
        "3",
        "--large",
        "0",
        "--json",
    ]);
    let rows = protocols["rows"].as_array().expect("rows");
    assert!(rows.len() >= 10, "{rows:?}");
    assert!(
        rows.iter()
            .all(|r| r["decided"] == true && r["robots"] == 3)
    );
    let sim = parse(&["bench", "sim", "--robots", "10", "--seconds", "3", "--json"]);
    let rows = sim["rows"].as_array().expect("rows");
    assert_eq!(
        rows.len(),
        4,
        "three shipped scenarios and one coverage size"
    );
    assert_eq!(rows[3]["robots"], 10);
    assert_eq!(rows[3]["run"], "coverage 10");
    // The shipped missions run to their end, fault-free and without a
    // deadline; the coverage team is stopped after 3 s.
    for r in &rows[..3] {
        assert_eq!(
            (&r["outcome"], &r["timeouts"]),
            (&"completed".into(), &0.into()),
            "{r}"
        );
    }
    assert_eq!(rows[3]["outcome"], "not-completed", "{:?}", rows[3]);
    let sim = parse(&[
        "bench",
        "sim",
        "--robots",
        "10",
        "--seconds",
        "3",
        "--mission",
        "crossing",
        "--json",
    ]);
    let rows = sim["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), 4, "{rows:?}");
    assert_eq!(rows[3]["run"], "crossing 10", "{rows:?}");
    assert_eq!(rows[3]["simulated_s"], 3.0, "{rows:?}");
}

/// `bite run ARGS --json --log LOG` from the repository's root: the
/// summary and how the command exited.
fn run_json(args: &[&str], log: &std::path::Path) -> (serde_json::Value, std::process::ExitStatus) {
    let out = bite()
        .current_dir(root())
        .arg("run")
        .args(args)
        .args(["--json", "--log"])
        .arg(log)
        .output()
        .expect("bite runs");
    let summary = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stderr)));
    (summary, out.status)
}

#[test]
fn a_fault_may_name_any_robot_of_the_team_as_it_runs() {
    // `--robots 6` grows the formation example's team of three: a fault
    // may name r5, and r6 is an input error that says the team's size.
    let d = scratch("fault-robots");
    let run = |fault: &str| {
        bite()
            .current_dir(root())
            .args(["run", "examples/formation.yaml", "--timed", "--robots", "6"])
            .args(["--fault", fault, "--json", "--log"])
            .arg(d.join("run.jsonl"))
            .output()
            .expect("bite runs")
    };
    let out = run("crash=r5@20s");
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stderr)));
    assert_eq!(summary["robots"], 6, "{summary:#}");
    assert_eq!(summary["crashed_robots"], 1, "{summary:#}");
    let out = run("crash=r6@20s");
    assert_eq!(out.status.code(), Some(2), "an input error");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no robot `r6` in the team of 6 robots"),
        "{err}"
    );
}

#[test]
fn a_crowd_finds_the_box_together_and_pushes_it_home_without_a_deadline() {
    // `find` is collaborative: the first robot to see the box tells the
    // team. Before, each robot had to see it for itself, and at 30 robots
    // in the search-and-rescue hall one boxed in by its teammates never
    // did: the search's barrier gave up on it after its deadline (seeds 2
    // and 3), or the team waited minutes for it.
    let d = scratch("crowd-find");
    for seed in ["2", "3"] {
        let (summary, status) = run_json(
            &[
                "examples/search-rescue.rtcl",
                "--robots",
                "30",
                "--seed",
                seed,
            ],
            &d.join("run.jsonl"),
        );
        assert_eq!(summary["outcome"], "completed", "seed {seed}: {summary:#}");
        assert_eq!(summary["timeouts"], 0, "seed {seed}: {summary:#}");
        assert!(status.success(), "seed {seed}: {summary:#}");
    }
}

#[test]
fn a_large_team_sweeps_the_whole_hall_however_thin_its_strips() {
    // `scan` splits the hall into one strip per robot: with 30 robots a
    // strip of the 5 m hall is 17 cm, thinner than half the 0.6 m between
    // sweeps. Each still has its lane (it had none: the team "completed"
    // in 3 s, having swept 14 % of the hall).
    let d = scratch("thin-strips");
    let (summary, _) = run_json(
        &["examples/coverage-sweep.rtcl", "--robots", "30"],
        &d.join("run.jsonl"),
    );
    assert_eq!(summary["outcome"], "completed", "{summary:#}");
    let covered = summary["world"]["coverage"].as_f64().expect("coverage");
    assert!(covered > 0.9, "{covered} of the hall swept");
    let least = (summary["world"]["distance"].as_array().expect("distances"))
        .iter()
        .filter_map(serde_json::Value::as_f64)
        .fold(f64::INFINITY, f64::min);
    assert!(least > 1.0, "every robot drove its lane: {least} m");
}

/// `--log-messages` adds a `message` record for every message a robot
/// sends (as many as the summary counts), each naming sender, recipients,
/// instance and kind; the rest of the log is the run's without it.
#[test]
fn the_run_log_may_record_every_message_sent() {
    let d = scratch("log-messages");
    let args = ["--timed", "--seed", "1", "--fault", "loss=0.2"];
    let (with, _) = run_json(
        &[&args[..], &["--log-messages"]].concat(),
        &d.join("with.jsonl"),
    );
    let (_, _) = run_json(&args, &d.join("without.jsonl"));
    let read = |f: &str| std::fs::read_to_string(d.join(f)).expect("the run log");
    let (with_log, without_log) = (read("with.jsonl"), read("without.jsonl"));
    let records: Vec<serde_json::Value> = with_log
        .lines()
        .map(|l| serde_json::from_str(l).expect("a JSON line"))
        .collect();
    let messages: Vec<&serde_json::Value> =
        records.iter().filter(|r| r["event"] == "message").collect();
    let counted: u64 = ["sync", "allocate", "terminate"]
        .iter()
        .map(|k| with["messages"][k].as_u64().expect("a count"))
        .sum();
    assert!(counted > 0, "{with:#}");
    assert_eq!(messages.len() as u64, counted);
    for m in &messages {
        assert!(
            m["robot"].as_str().is_some_and(|r| r.starts_with('r')),
            "{m}"
        );
        assert!(m["to"].as_array().is_some_and(|to| !to.is_empty()), "{m}");
        assert!(m["instance"]["behavior"].is_string(), "{m}");
        assert!(m["body"].is_string() && m["bytes"].is_u64(), "{m}");
    }
    // Everything else is the same run (the summary's fingerprint is the
    // log's, so the last line differs).
    let others = |log: &str| -> Vec<String> {
        log.lines()
            .filter(|l| !l.contains(r#""event":"message""#) && !l.contains("run_finished"))
            .map(str::to_string)
            .collect()
    };
    assert_eq!(others(&with_log), others(&without_log));
}
