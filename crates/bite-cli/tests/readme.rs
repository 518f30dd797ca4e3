//! The README against the program: its sample output is what `bite run`
//! prints, every `bite` command it shows works as written, and its table of
//! exit codes is the code's.
//!
//! When the program's output changes on purpose, regenerate the sample:
//!
//! ```sh
//! BITE_BLESS=1 cargo test -p bite-cli --test readme
//! ```
//!
//! The sample comes from the binary this test builds (the dev or test
//! profile); `cargo run --release -- run`, which the README shows, prints
//! the same bytes: the simulator does no floating point that depends on
//! the optimisation level.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use bite_sim::summary::{EXIT_VIOLATION, Outcome};

fn bite() -> Command {
    Command::new(env!("CARGO_BIN_EXE_bite"))
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn readme_path() -> PathBuf {
    root().join("README.md")
}

fn readme() -> String {
    std::fs::read_to_string(readme_path()).expect("README.md")
}

/// A fresh directory to run commands in, with `examples` linking to the
/// repository's, so that the README's relative paths work and what the
/// commands write (`out/`, pictures, keys) stays out of the repository.
fn scratch(name: &str) -> PathBuf {
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("bite-readme-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("scratch dir");
    std::os::unix::fs::symlink(root().join("examples"), d.join("examples")).expect("link examples");
    d
}

/// The fenced blocks of `text` in language `lang`: the line range of each
/// block's content (0-based, end exclusive).
fn blocks(text: &str, lang: &str) -> Vec<(usize, usize)> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        if lines[i].trim_end() == format!("```{lang}") {
            let start = i + 1;
            let end = (start..lines.len())
                .find(|&j| lines[j].trim_end() == "```")
                .unwrap_or_else(|| panic!("README.md:{}: unclosed ```{lang} block", i + 1));
            out.push((start, end));
            i = end;
        }
        i += 1;
    }
    out
}

/// Run a command; fail if it takes longer than `limit`.
#[allow(clippy::disallowed_methods)] // a time limit on a child process is wall time
fn run_with_limit(cmd: &mut Command, limit: Duration, what: &str) -> Output {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("bite starts");
    // Drain the pipes while waiting, so a chatty command cannot block.
    let mut stdout = child.stdout.take().expect("stdout");
    let mut stderr = child.stderr.take().expect("stderr");
    let out = std::thread::spawn(move || {
        let mut b = Vec::new();
        std::io::Read::read_to_end(&mut stdout, &mut b).ok();
        b
    });
    let err = std::thread::spawn(move || {
        let mut b = Vec::new();
        std::io::Read::read_to_end(&mut stderr, &mut b).ok();
        b
    });
    let started = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait") {
            break s;
        }
        if started.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "`{what}` still runs after {limit:?}: too long for this test; \
                 check it for parsing only (PARSE_ONLY in tests/readme.rs)"
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Output {
        status,
        stdout: out.join().expect("stdout reader"),
        stderr: err.join().expect("stderr reader"),
    }
}

// ---------------------------------------------------------------------
// The sample output.

#[test]
fn the_sample_output_is_what_bite_run_prints() {
    let d = scratch("sample");
    let out = run_with_limit(
        bite().arg("run").current_dir(&d),
        Duration::from_secs(120),
        "bite run",
    );
    assert!(
        out.status.success(),
        "bite run: {}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    let printed = String::from_utf8(out.stdout).expect("UTF-8");
    let printed: Vec<&str> = printed.lines().collect();

    let text = readme();
    let lines: Vec<&str> = text.lines().collect();
    let samples: Vec<(usize, usize)> = blocks(&text, "text")
        .into_iter()
        .filter(|&(s, e)| s < e && lines[s].starts_with("mission `"))
        .collect();
    let [(start, end)] = samples[..] else {
        panic!(
            "README.md should have one ```text block of `bite run`'s summary (starting \
             \"mission `\"), found {}",
            samples.len()
        );
    };
    let shown = &lines[start..end];
    // The README may show the first lines and elide the rest with `...`.
    let elided = shown.last().is_some_and(|l| l.trim() == "...");
    let expected: Vec<String> = if elided {
        let keep = shown.len() - 1;
        assert!(
            printed.len() > keep,
            "README.md:{}: the sample shows {keep} lines and `...`, but `bite run` prints only {}",
            start + 1,
            printed.len()
        );
        printed[..keep]
            .iter()
            .map(|l| l.to_string())
            .chain([shown[keep].to_string()])
            .collect()
    } else {
        printed.iter().map(|l| l.to_string()).collect()
    };
    if shown != expected {
        if std::env::var_os("BITE_BLESS").is_some() {
            let mut new: Vec<String> = lines[..start].iter().map(|l| l.to_string()).collect();
            new.extend(expected);
            new.extend(lines[end..].iter().map(|l| l.to_string()));
            let mut body = new.join("\n");
            if text.ends_with('\n') {
                body.push('\n');
            }
            // Atomically: the other tests read the README meanwhile.
            let tmp = root().join(format!(".README.md.bless-{}", std::process::id()));
            std::fs::write(&tmp, body).expect("write README");
            std::fs::rename(&tmp, readme_path()).expect("replace README");
            eprintln!(
                "README.md:{}: sample output rewritten from `bite run`",
                start + 1
            );
        } else {
            let diff: Vec<String> = (0..shown.len().max(expected.len()))
                .filter(|&i| shown.get(i) != expected.get(i).map(String::as_str).as_ref())
                .map(|i| {
                    format!(
                        "README.md:{}\n  README: {}\n  bite:   {}",
                        start + 1 + i,
                        shown.get(i).unwrap_or(&"(nothing)"),
                        expected.get(i).map_or("(nothing)", String::as_str)
                    )
                })
                .collect();
            panic!(
                "the README's sample output is not what `bite run` prints:\n{}\n\
                 regenerate it with: BITE_BLESS=1 cargo test -p bite-cli --test readme",
                diff.join("\n")
            );
        }
    }
    // The prose names the run log the run writes.
    let log = printed
        .iter()
        .find_map(|l| l.strip_prefix("  run log").map(str::trim))
        .expect("`bite run` names its run log");
    assert!(
        text.contains(&format!("`{log}`")),
        "the README should say that `bite run` writes its run log to `{log}`"
    );
    assert!(d.join(log).is_file(), "{log} written");
    let _ = std::fs::remove_dir_all(&d);
}

// ---------------------------------------------------------------------
// The commands.

/// A `bite` command of a README ```sh block.
#[derive(Debug)]
struct ShCommand {
    /// README line (1-based).
    line: usize,
    /// The words, `bite` first (`cargo run --release --` is `bite`, as the
    /// README says).
    words: Vec<String>,
    /// What its output is piped into, if anything.
    pipe: Vec<String>,
}

impl ShCommand {
    fn text(&self) -> String {
        self.words.join(" ")
    }
    fn args(&self) -> &[String] {
        &self.words[1..]
    }
    fn sub(&self) -> (&str, &str) {
        let w = |i: usize| self.words.get(i).map_or("", String::as_str);
        (w(1), w(2))
    }
}

/// Split a shell line into words: quotes, a comment from an unquoted `#`
/// at the start of a word; `|` and `>` are words of their own.
fn shell_words(line: &str) -> Vec<String> {
    let mut words = Vec::new();
    let mut cur = String::new();
    let mut in_word = false;
    let mut quote: Option<char> = None;
    for c in line.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), c) => cur.push(c),
            (None, '\'' | '"') => {
                quote = Some(c);
                in_word = true;
            }
            (None, '#') if !in_word => break,
            (None, c) if c.is_whitespace() => {
                if in_word {
                    words.push(std::mem::take(&mut cur));
                    in_word = false;
                }
            }
            (None, c) => {
                cur.push(c);
                in_word = true;
            }
        }
    }
    assert!(quote.is_none(), "unclosed quote in `{line}`");
    if in_word {
        words.push(cur);
    }
    words
}

/// Every `bite` command in the README's ```sh blocks, in order.
fn readme_commands(text: &str) -> Vec<ShCommand> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    for (start, end) in blocks(text, "sh") {
        for (i, line) in lines.iter().enumerate().take(end).skip(start) {
            let mut words = shell_words(line);
            if words.starts_with(&["cargo", "run", "--release", "--"].map(String::from)) {
                words.splice(0..4, ["bite".to_string()]);
            }
            if words.first().map(String::as_str) != Some("bite") {
                continue;
            }
            let pipe = match words.iter().position(|w| w == "|") {
                Some(p) => words.split_off(p).split_off(1),
                None => Vec::new(),
            };
            // Not handled here (none in the README so far): redirecting
            // `bite` itself, continued lines.
            assert!(
                !words.iter().any(|w| w == ">" || w == "<") && !line.trim_end().ends_with('\\'),
                "README.md:{}: teach tests/readme.rs this shell syntax",
                i + 1
            );
            out.push(ShCommand {
                line: i + 1,
                words,
                pipe,
            });
        }
    }
    out
}

/// Commands that run for minutes or start a team of processes over Zenoh:
/// checked for parsing only (`BITE_PARSE_ONLY`), with the example files
/// they name checked to exist and their graph and configuration checked
/// by `bite check`.
const PARSE_ONLY: &[((&str, &str), &str)] = &[
    (("bench", "team"), "a 10,000-robot team runs for minutes"),
    (
        ("bench", "sim"),
        "physics up to 10,000 robots runs for minutes",
    ),
    (("bench", "zenoh"), "starts teams of processes over Zenoh"),
    (("launch", ""), "starts a team of processes over Zenoh"),
    (("sim", "serve"), "a server that runs until stopped"),
    (("robot", ""), "a robot process that waits for its team"),
    (("submit", ""), "needs a running team"),
    (("studio", ""), "a web server that runs until stopped"),
];

/// Longest a command that the test runs may take (debug build, 2 cores).
const RUN_LIMIT: Duration = Duration::from_secs(120);

#[test]
fn every_readme_command_works_as_written() {
    let text = readme();
    let cmds = readme_commands(&text);
    // A broken extraction must not pass for a clean README.
    assert!(
        cmds.len() >= 25,
        "only {} commands found: {cmds:#?}",
        cmds.len()
    );
    let d = scratch("commands");
    let mut ran = 0;
    let mut parsed = 0;
    for c in &cmds {
        let at = format!("README.md:{}: `{}`", c.line, c.text());
        // `bite robot --name r1 ...`: an elision of the command above it.
        if c.words.iter().any(|w| w == "...") {
            let shown: Vec<&String> = c.words.iter().take_while(|w| *w != "...").collect();
            assert!(
                cmds.iter().any(|o| !o.words.contains(&"...".to_string())
                    && o.sub() == c.sub()
                    && o.line < c.line),
                "{at}: elides a command the README does not show in full before it"
            );
            assert!(shown.len() >= 2, "{at}: elides too much");
            continue;
        }
        for w in c.args() {
            if w.starts_with("examples/") {
                assert!(root().join(w).exists(), "{at}: {w} does not exist");
            }
        }
        let live = c.words.iter().any(|w| w == "--foxglove");
        if let Some((_, why)) = PARSE_ONLY
            .iter()
            .find(|(s, _)| s.0 == c.sub().0 && (s.1.is_empty() || s.1 == c.sub().1))
            .or(live.then_some(&(
                ("", ""),
                "serves a live view until a viewer has come and gone",
            )))
        {
            let out = run_with_limit(
                bite()
                    .args(c.args())
                    .env("BITE_PARSE_ONLY", "1")
                    .current_dir(&d),
                Duration::from_secs(30),
                &c.text(),
            );
            assert!(
                out.status.success(),
                "{at} (parsed only: {why}): {}\n{}",
                out.status,
                String::from_utf8_lossy(&out.stderr)
            );
            check_inputs(c, &d, &at);
            parsed += 1;
            continue;
        }
        let out = run_with_limit(bite().args(c.args()).current_dir(&d), RUN_LIMIT, &c.text());
        assert!(
            out.status.success(),
            "{at}: {}\n{}{}",
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        // (A run exits 0 only when its mission completed.)
        if c.sub().0 == "graph" {
            let stdout = String::from_utf8_lossy(&out.stdout);
            assert!(stdout.starts_with("digraph"), "{at}:\n{stdout}");
        }
        // The output is piped into Graphviz, which this test does not
        // need: the DOT it reads is checked above.
        if !c.pipe.is_empty() {
            assert_eq!(c.pipe.first().map(String::as_str), Some("dot"), "{at}");
        }
        // What the command says it writes is there.
        for flag in ["--svg", "--gif", "-o", "--output"] {
            if let Some(p) = c.args().iter().position(|w| w == flag) {
                let file = &c.args()[p + 1];
                assert!(d.join(file).is_file(), "{at}: {file} not written");
            }
        }
        ran += 1;
    }
    assert!(ran >= 15 && parsed >= 5, "{ran} run, {parsed} parsed only");
    let _ = std::fs::remove_dir_all(&d);
}

/// The graph and configuration a parse-only command names, checked by
/// `bite check` (the built-in graph is `examples/formation.yaml`).
fn check_inputs(c: &ShCommand, dir: &Path, at: &str) {
    let graph = c
        .args()
        .iter()
        .find(|w| w.starts_with("examples/") && !w.contains("/configs/") && w.ends_with(".yaml"))
        .map_or("examples/formation.yaml", String::as_str);
    let mut cmd = bite();
    cmd.args(["check", graph]).current_dir(dir);
    if let Some(p) = c.args().iter().position(|w| w == "--config") {
        cmd.args(["--config", &c.args()[p + 1]]);
    }
    let out = run_with_limit(&mut cmd, Duration::from_secs(30), "bite check");
    assert!(
        out.status.success(),
        "{at}: `bite check {graph}` fails:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

// ---------------------------------------------------------------------
// The exit codes.

/// Every outcome. The match fails to compile when an outcome is added, so
/// the README's table cannot miss one.
fn outcomes() -> [Outcome; 4] {
    let all = [
        Outcome::Completed,
        Outcome::NotCompleted,
        Outcome::CompletedWithTimeouts,
        Outcome::Stalled,
    ];
    for o in all {
        match o {
            Outcome::Completed
            | Outcome::NotCompleted
            | Outcome::CompletedWithTimeouts
            | Outcome::Stalled => {}
        }
    }
    all
}

/// The rows of the table under `## Outcomes and exit codes`: code and
/// outcome (backticks removed).
fn exit_code_table(text: &str) -> Vec<(u8, String)> {
    let section = text
        .split("\n## ")
        .find(|s| s.starts_with("Outcomes and exit codes"))
        .expect("README.md has a section `## Outcomes and exit codes`");
    section
        .lines()
        .filter(|l| l.starts_with('|'))
        .filter_map(|l| {
            let cells: Vec<&str> = l.trim_matches('|').split('|').map(str::trim).collect();
            let code = cells.first()?.parse::<u8>().ok()?;
            Some((code, cells.get(1)?.replace('`', "")))
        })
        .collect()
}

fn exit_of(cmd: &mut Command, what: &str) -> i32 {
    let out = run_with_limit(cmd, Duration::from_secs(60), what);
    out.status.code().expect("exited")
}

#[test]
fn the_exit_code_table_is_the_code() {
    let table = exit_code_table(&readme());
    let code_of = |label: &str| {
        let rows: Vec<u8> = table
            .iter()
            .filter(|(_, l)| l == label)
            .map(|(c, _)| *c)
            .collect();
        assert_eq!(rows.len(), 1, "one row for `{label}` in {table:?}");
        rows[0]
    };
    for o in outcomes() {
        assert_eq!(code_of(o.label()), o.exit_code(), "{o:?}");
    }
    assert_eq!(code_of("invariant violated"), EXIT_VIOLATION);
    assert_eq!(code_of("input error"), 2);
    assert_eq!(code_of("other error"), 3);
    assert_eq!(table.len(), outcomes().len() + 3, "{table:?}");
    let mut codes: Vec<u8> = table.iter().map(|(c, _)| *c).collect();
    codes.sort_unstable();
    codes.dedup();
    assert_eq!(
        codes.len(),
        table.len(),
        "every row its own code: {table:?}"
    );

    // And the program exits so.
    let d = scratch("exit");
    assert_eq!(
        exit_of(
            bite().args(["check", "no-such-graph.yaml"]).current_dir(&d),
            "check"
        ),
        2,
        "a missing file is an input error"
    );
    assert_eq!(
        exit_of(
            bite().args(["run", "--no-such-flag"]).current_dir(&d),
            "run"
        ),
        2,
        "a bad command line is an input error"
    );
    assert_eq!(
        exit_of(
            bite()
                .args(["run", "--timed", "--log", "/dev/null/run.jsonl"])
                .current_dir(&d),
            "run --log"
        ),
        3,
        "a run log that cannot be written is an other error"
    );
    assert_eq!(
        exit_of(
            bite()
                .args(["run", "--timed", "--time-limit", "5s"])
                .current_dir(&d),
            "run --time-limit"
        ),
        i32::from(Outcome::NotCompleted.exit_code())
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn shell_words_split_as_sh_does() {
    assert_eq!(
        shell_words("bite run --fault 'pause=r1@12s+5s'  # a comment"),
        ["bite", "run", "--fault", "pause=r1@12s+5s"]
    );
    assert_eq!(
        shell_words("bite graph g.yaml | dot -Tsvg > f.svg"),
        ["bite", "graph", "g.yaml", "|", "dot", "-Tsvg", ">", "f.svg"]
    );
    assert_eq!(shell_words("a#b \"c d\""), ["a#b", "c d"]);
    assert!(shell_words("   # only a comment").is_empty());
}
