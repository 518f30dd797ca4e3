//! `bite experiment` and `bite tune` end to end, on the shipped files.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bite() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_bite"));
    c.current_dir(root());
    c
}

fn scratch(name: &str) -> PathBuf {
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("bite-exp-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("scratch dir");
    d
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn ok(out: &Output) {
    assert!(
        out.status.success(),
        "exit {:?}\n{}\n{}",
        out.status.code(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn experiment(out: &Path, jobs: &str) -> Output {
    bite()
        .args([
            "experiment",
            "examples/experiments/table2.yaml",
            "--seeds",
            "1..3",
            "--jobs",
            jobs,
            "--out",
        ])
        .arg(out)
        .output()
        .expect("bite runs")
}

#[test]
fn the_table2_experiment_writes_runs_plots_and_a_report_and_resumes() {
    let d = scratch("table2");
    let a = d.join("a");
    let first = experiment(&a, "2");
    ok(&first);
    let csv = std::fs::read_to_string(a.join("runs.csv")).expect("runs.csv");
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().expect("a header").split(',').collect();
    for c in [
        "key",
        "config",
        "world",
        "seed",
        "outcome",
        "task_time",
        "interaction_time.sync",
        "interaction_time.allocate",
        "messages.total",
        "replay",
    ] {
        assert!(header.contains(&c), "column {c} in {header:?}");
    }
    let world = header.iter().position(|c| *c == "world").expect("world");
    let seed = header.iter().position(|c| *c == "seed").expect("seed");
    let config = header.iter().position(|c| *c == "config").expect("config");
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    for w in ["timed", "physics"] {
        let n = rows.iter().filter(|r| r[world] == w).count();
        assert_eq!(n, 21, "7 configurations × 3 seeds in the {w} world");
    }
    // Row 3 is the paper's second series of row 2: other seeds.
    assert!(
        rows.iter()
            .filter(|r| r[config] == "3")
            .all(|r| r[seed].parse::<u64>().is_ok_and(|s| s > 1000))
    );
    for f in [
        "figure3-formation-timed.svg",
        "figure3-formation-timed.png",
        "figure3-formation-physics.svg",
        "figure3-formation-physics.png",
        "box-formation-physics-task-time.svg",
        "box-formation-physics-task-time.png",
    ] {
        let bytes = std::fs::read(a.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        if f.ends_with(".png") {
            assert_eq!(&bytes[1..4], b"PNG", "{f}");
        } else {
            assert!(String::from_utf8_lossy(&bytes).contains("<svg"), "{f}");
        }
    }
    let report = std::fs::read_to_string(a.join("report.md")).expect("report.md");
    assert!(report.contains("## formation · timed"));
    assert!(report.contains("Spearman ρ"));
    assert!(report.contains("p (Holm"));
    assert!(report.contains("![formation · physics](figure3-formation-physics.svg)"));

    // Again: nothing left to run, the same table.
    let again = experiment(&a, "2");
    ok(&again);
    assert!(
        String::from_utf8_lossy(&again.stderr).contains("42 done before, 0 to run"),
        "{}",
        String::from_utf8_lossy(&again.stderr)
    );
    assert_eq!(std::fs::read_to_string(a.join("runs.csv")).unwrap(), csv);

    // One thread gives the same bytes as two.
    let b = d.join("b");
    ok(&experiment(&b, "1"));
    assert_eq!(std::fs::read_to_string(b.join("runs.csv")).unwrap(), csv);
    assert_eq!(
        std::fs::read_to_string(b.join("report.md")).unwrap(),
        report.replace(&a.display().to_string(), &b.display().to_string())
    );

    // An interrupted experiment: half the log kept, the rest is run.
    let c = d.join("c");
    std::fs::create_dir_all(&c).unwrap();
    let log = std::fs::read_to_string(a.join("runs.jsonl")).unwrap();
    let half: Vec<&str> = log.lines().take(20).collect();
    std::fs::write(c.join("runs.jsonl"), half.join("\n") + "\n{\"key\": \"torn").unwrap();
    let resumed = experiment(&c, "2");
    ok(&resumed);
    assert!(
        String::from_utf8_lossy(&resumed.stderr).contains("20 done before, 22 to run"),
        "{}",
        String::from_utf8_lossy(&resumed.stderr)
    );
    assert_eq!(std::fs::read_to_string(c.join("runs.csv")).unwrap(), csv);
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn a_malformed_experiment_names_file_line_and_column() {
    let d = scratch("bad");
    let f = d.join("bad.yaml");
    let graph = root().join("examples/formation.yaml");
    std::fs::write(
        &f,
        format!(
            "experiment: bad\nmissions:\n  - graph: {}\n    worlds: [timed, physix]\nfigures: [task_tme]\nfaults: [los]\n",
            graph.display()
        ),
    )
    .unwrap();
    let out = bite()
        .arg("experiment")
        .arg(&f)
        .output()
        .expect("bite runs");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    let name = f.display().to_string();
    assert!(err.contains(&format!("{name}:4:")), "{err}");
    assert!(err.contains("unknown world `physix`"), "{err}");
    assert!(err.contains(&format!("{name}:5:")), "{err}");
    assert!(err.contains("did you mean `task_time`?"), "{err}");
    assert!(err.contains("unknown fault class `los`"), "{err}");
    // A shape error from the YAML reader is located too.
    std::fs::write(&f, "experiment: bad\nmissions: 3\n").unwrap();
    let out = bite()
        .arg("experiment")
        .arg(&f)
        .output()
        .expect("bite runs");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&format!("{name}:2:")), "{err}");
    let _ = std::fs::remove_dir_all(&d);
}

/// `bite experiment FILE` of an experiment file with `body` (after its
/// name): refused with exit 2; standard error.
fn refused_experiment(d: &Path, name: &str, body: &str) -> (PathBuf, String) {
    let f = d.join(format!("{name}.yaml"));
    std::fs::write(&f, format!("experiment: {name}\n{body}")).unwrap();
    let out = bite()
        .arg("experiment")
        .arg(&f)
        .arg("--out")
        .arg(d.join(format!("out-{name}")))
        .output()
        .expect("bite runs");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "{name}: {err}");
    assert!(
        !d.join(format!("out-{name}")).exists(),
        "{name}: nothing ran"
    );
    (f, err)
}

#[test]
fn an_experiment_that_would_count_a_run_twice_or_merge_rows_is_refused() {
    let d = scratch("dups");
    let graph = root().join("examples/formation.yaml");
    let g = graph.display();
    let configs = root().join("examples/configs");
    let c1 = configs.join("1.yaml");
    let c2 = configs.join("2.yaml");
    let (c1, c2) = (c1.display(), c2.display());
    let cases = [
        (
            "labels",
            format!(
                "missions:\n  - graph: {g}\n    worlds: [timed]\n    configs:\n      - {{ file: {c1}, label: x }}\n      - {{ file: {c2}, label: x }}\n"
            ),
            7,
            "configuration label `x` names two configurations",
        ),
        (
            "mission-labels",
            format!(
                "missions:\n  - graph: {g}\n    label: m\n    worlds: [timed]\n  - graph: {}\n    label: m\n",
                root().join("examples/squads.yaml").display()
            ),
            7,
            "mission label `m` names two missions",
        ),
        (
            "seeds",
            format!("seeds: [1, 1, 1]\nmissions:\n  - graph: {g}\n    worlds: [timed]\n"),
            2,
            "seed 1 is given twice",
        ),
        (
            "missions",
            format!(
                "missions:\n  - graph: {g}\n    worlds: [timed]\n  - graph: {g}\n    worlds: [physics]\n"
            ),
            5,
            "is listed twice",
        ),
        (
            "worlds",
            format!("missions:\n  - graph: {g}\n    worlds: [timed, timed]\n"),
            4,
            "world `timed` is listed twice",
        ),
        (
            "scenarios",
            format!(
                "missions:\n  - graph: {g}\n    worlds: [timed]\n    scenarios: [{}]\n",
                root().join("examples/scenarios/formation.yaml").display()
            ),
            4,
            "is picked twice",
        ),
        (
            "configs",
            format!(
                "missions:\n  - graph: {g}\n    worlds: [timed]\n    configs:\n      - {c1}\n      - {{ file: {c1}, label: again }}\n"
            ),
            7,
            "is listed twice with seed_offset 0",
        ),
        (
            "offset",
            format!(
                "seeds: [1, 2]\nmissions:\n  - graph: {g}\n    worlds: [timed]\n    configs:\n      - {{ file: {c1}, seed_offset: 18446744073709551615 }}\n"
            ),
            7,
            "past the largest seed",
        ),
        (
            // Matched by a bounded walk: refused with a word, not a
            // walk of the whole file system.
            "glob",
            format!(
                "missions:\n  - graph: {g}\n    worlds: [timed]\n    configs: [\"/**/*.yaml\"]\n"
            ),
            5,
            "name a narrower folder",
        ),
    ];
    for (name, body, line, says) in cases {
        let (f, err) = refused_experiment(&d, name, &body);
        assert!(err.contains(says), "{name}: expected `{says}` in\n{err}");
        let at = format!("{}:{line}:", f.display());
        assert!(err.contains(&at), "{name}: expected `{at}` in\n{err}");
    }
    // `--seeds` that repeats a seed is refused too.
    let out = bite()
        .args([
            "experiment",
            "examples/experiments/table2.yaml",
            "--seeds",
            "3,4,3",
        ])
        .output()
        .expect("bite runs");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("seed 3 is given twice"));
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn tune_writes_a_configuration_that_check_accepts_and_compares_on_holdout_seeds() {
    let d = scratch("tune");
    let out = bite()
        .args([
            "tune",
            "examples/formation.yaml",
            "--seeds",
            "1..6",
            "--holdout",
            "7..10",
            "--out",
        ])
        .arg(&d)
        .output()
        .expect("bite runs");
    ok(&out);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("holdout"), "{stdout}");
    assert!(stdout.contains("| tuned | 4 | 100 % |"), "{stdout}");
    assert!(stdout.contains("examples/configs/2.yaml"), "{stdout}");
    let best = d.join("best.yaml");
    let check = bite()
        .args(["check", "examples/formation.yaml", "--config"])
        .arg(&best)
        .output()
        .expect("bite runs");
    ok(&check);
    // The search is deterministic: the same again, on one thread.
    let d2 = scratch("tune2");
    let again = bite()
        .args([
            "tune",
            "examples/formation.yaml",
            "--seeds",
            "1..6",
            "--holdout",
            "7..10",
            "--jobs",
            "1",
            "--out",
        ])
        .arg(&d2)
        .output()
        .expect("bite runs");
    ok(&again);
    let strip = |s: &str| -> String {
        s.lines()
            .filter(|l| !l.contains(" runs in ") && !l.contains("bite run "))
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(
        strip(&std::fs::read_to_string(&best).unwrap()),
        strip(&std::fs::read_to_string(d2.join("best.yaml")).unwrap())
    );
    assert_eq!(
        std::fs::read_to_string(d.join("tune.csv")).unwrap(),
        std::fs::read_to_string(d2.join("tune.csv")).unwrap()
    );
    // Held-out seeds must be new.
    let clash = bite()
        .args([
            "tune",
            "examples/formation.yaml",
            "--seeds",
            "1..6",
            "--holdout",
            "6..10",
        ])
        .output()
        .expect("bite runs");
    assert!(!clash.status.success());
    assert!(String::from_utf8_lossy(&clash.stderr).contains("seed 6"));
    let _ = std::fs::remove_dir_all(&d);
    let _ = std::fs::remove_dir_all(&d2);
}

/// The table of group `title` in a report written by `bite experiment`:
/// the lines starting with `| config` up to the first blank line.
fn group_table(report: &str, title: &str) -> Vec<String> {
    let start = report
        .find(&format!("## {title}\n"))
        .unwrap_or_else(|| panic!("no group `{title}` in the report"));
    report[start..]
        .lines()
        .skip_while(|l| !l.starts_with("| config"))
        .take_while(|l| !l.trim().is_empty())
        .map(str::to_string)
        .collect()
}

#[test]
fn the_reproduction_tables_are_what_bite_experiment_gives() {
    let d = scratch("reproduction");
    let doc_path = root().join("docs/reproduction.md");
    let doc = std::fs::read_to_string(&doc_path).expect("docs/reproduction.md");
    // The experiments the document quotes, each run once.
    let mut reports = std::collections::BTreeMap::new();
    for l in doc.lines() {
        let Some((name, _)) = l
            .strip_prefix("<!-- begin ")
            .and_then(|t| t.strip_suffix(" -->"))
            .and_then(|t| t.split_once(": "))
        else {
            continue;
        };
        if reports.contains_key(name) {
            continue;
        }
        let out_dir = d.join(name);
        let out = bite()
            .arg("experiment")
            .arg(format!("examples/experiments/{name}.yaml"))
            .arg("--out")
            .arg(&out_dir)
            .output()
            .expect("bite runs");
        ok(&out);
        let report = std::fs::read_to_string(out_dir.join("report.md")).expect("report.md");
        reports.insert(name.to_string(), (out_dir, report));
    }
    let mut rewritten = String::new();
    let mut lines = doc.lines();
    let mut differ = Vec::new();
    let mut groups = 0;
    while let Some(l) = lines.next() {
        rewritten.push_str(l);
        rewritten.push('\n');
        let Some((name, title)) = l
            .strip_prefix("<!-- begin ")
            .and_then(|t| t.strip_suffix(" -->"))
            .and_then(|t| t.split_once(": "))
        else {
            continue;
        };
        groups += 1;
        let mut old = Vec::new();
        for l in lines.by_ref() {
            if l == "<!-- end -->" {
                break;
            }
            old.push(l.to_string());
        }
        let new = group_table(&reports[name].1, title);
        if old != new {
            differ.push(format!("{name}: {title}"));
        }
        for l in &new {
            rewritten.push_str(l);
            rewritten.push('\n');
        }
        rewritten.push_str("<!-- end -->\n");
    }
    assert!(
        groups >= 2 && reports.contains_key("table2"),
        "docs/reproduction.md quotes the tables of table2"
    );
    if differ.is_empty() {
        let _ = std::fs::remove_dir_all(&d);
        return;
    }
    if std::env::var_os("BITE_BLESS").is_some() {
        std::fs::write(&doc_path, rewritten).expect("write docs/reproduction.md");
        let figures = root().join("docs/figures/reproduction");
        std::fs::create_dir_all(&figures).expect("figures dir");
        for (dir, _) in reports.values() {
            for e in std::fs::read_dir(dir).expect("the output").flatten() {
                let p = e.path();
                if p.extension().is_some_and(|x| x == "png") {
                    std::fs::copy(&p, figures.join(e.file_name())).expect("copy a picture");
                }
            }
        }
        eprintln!("docs/reproduction.md: tables rewritten for {differ:?}");
    } else {
        panic!(
            "docs/reproduction.md's tables for {differ:?} are not what `bite experiment` \
             gives; regenerate them with: BITE_BLESS=1 cargo test -p bite-cli --test experiment"
        );
    }
    let _ = std::fs::remove_dir_all(&d);
}
