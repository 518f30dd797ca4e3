//! `bite studio` in a real browser: Debian's chromium, driven by
//! playwright-core (npm, installed by `npm ci` from the lockfile in
//! `tests/studio/` into the target directory's test scratch space).
//!
//! Each test starts its own studio on a free port of 127.0.0.1 and runs one
//! scenario of `tests/studio/studio.mjs`. Screenshots go to the scratch
//! space, or to `$BITE_SCREENSHOTS` (`BITE_SCREENSHOTS=docs/figures/studio
//! cargo test -p bite-cli --test studio` refreshes the ones the docs show).
//!
//! The browser is needed: CI installs it (`.ci/run`: `apt-get install
//! chromium`); without it these tests fail and say how to get it.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::OnceLock;
use std::time::Duration;

const BITE: &str = env!("CARGO_BIN_EXE_bite");

fn root() -> PathBuf {
    let r = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    r.canonicalize().unwrap_or(r)
}

/// Debian's chromium: installed with apt-get when missing and the tests
/// run as root (the README's test command does all set-up).
fn chromium() -> String {
    static INSTALL: OnceLock<()> = OnceLock::new();
    let path = std::env::var("BITE_CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    INSTALL.get_or_init(|| {
        let root = Command::new("id")
            .arg("-u")
            .output()
            .is_ok_and(|o| o.stdout.trim_ascii() == b"0");
        if !Path::new(&path).exists() && root {
            eprintln!("installing Debian's chromium for the browser tests");
            let _ = Command::new("apt-get").args(["update", "-qq"]).status();
            let _ = Command::new("apt-get")
                .args(["install", "-y", "-qq", "chromium"])
                .env("DEBIAN_FRONTEND", "noninteractive")
                .status();
        }
    });
    assert!(
        Path::new(&path).exists(),
        "the browser tests need Debian's chromium at {path}: `apt-get install chromium` \
         (or set BITE_CHROMIUM)"
    );
    path
}

/// The test scripts' directory, with playwright-core installed (once per
/// target directory and lockfile).
fn node_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/studio");
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("studio-node");
        std::fs::create_dir_all(&dir).expect("scratch space");
        let lock = std::fs::read(src.join("package-lock.json")).expect("the lockfile");
        let installed = std::fs::read(dir.join("package-lock.json")).ok();
        for f in ["package.json", "package-lock.json", "studio.mjs"] {
            std::fs::copy(src.join(f), dir.join(f)).expect("copying the test scripts");
        }
        if installed.as_deref() != Some(&lock[..])
            || !dir.join("node_modules/playwright-core").exists()
        {
            let s = Command::new("npm")
                .args(["ci", "--no-audit", "--no-fund", "--loglevel=error"])
                .current_dir(&dir)
                .status()
                .expect("npm (Node.js) is needed for the browser tests");
            assert!(s.success(), "npm ci in {} failed", dir.display());
        }
        dir
    })
}

fn shots_dir() -> PathBuf {
    let d = match std::env::var("BITE_SCREENSHOTS") {
        Ok(d) => root().join(d),
        Err(_) => Path::new(env!("CARGO_TARGET_TMPDIR")).join("studio-screenshots"),
    };
    std::fs::create_dir_all(&d).expect("screenshot directory");
    d
}

/// A process killed when the test ends, however it ends.
struct Kill(Child);
impl Drop for Kill {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The first thing `pick` finds in a child's standard error, line by line;
/// the rest is drained on a thread so the child never blocks on the pipe.
fn stderr_line(
    child: &mut Child,
    what: &str,
    mut pick: impl FnMut(&str) -> Option<String>,
) -> String {
    let err = child.stderr.take().expect("stderr piped");
    let mut lines = BufReader::new(err).lines();
    let found = loop {
        let line = lines.next().expect(what).expect("stderr readable");
        if let Some(x) = pick(&line) {
            break x;
        }
    };
    std::thread::spawn(move || for _ in lines.by_ref() {});
    found
}

/// Start `bite studio ARGS` on a free port; its URL.
fn studio(args: &[&str], cwd: &Path) -> (Kill, String) {
    let mut child = Command::new(BITE)
        .arg("studio")
        .args(["--port", "0"])
        .args(args)
        .current_dir(cwd)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("bite studio starts");
    let url = stderr_line(&mut child, "bite studio said where it serves", |line| {
        let at = line.find("http://")?;
        let url = line[at..]
            .split_whitespace()
            .next()
            .unwrap_or("")
            .to_string();
        assert!(
            url.starts_with("http://127.0.0.1:"),
            "served on loopback only: {line}"
        );
        Some(url)
    });
    (Kill(child), url)
}

/// Run scenario `name` of studio.mjs against `url`; its output.
fn browse(name: &str, url: &str, arg: Option<&str>) -> String {
    let dir = node_dir();
    let mut cmd = Command::new("node");
    cmd.arg("studio.mjs")
        .args([name, url])
        .arg(shots_dir())
        .current_dir(dir)
        .env("BITE_CHROMIUM", chromium());
    if let Some(a) = arg {
        cmd.arg(a);
    }
    let out = cmd.output().expect("node runs");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "browser scenario `{name}` failed:\n{stdout}\n{stderr}"
    );
    eprintln!("{stdout}");
    stdout
}

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("studio-runs")
        .join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("scratch dir");
    d
}

#[test]
fn the_editor_shows_a_misspelled_command_at_its_line_and_a_dropped_command_lands_there() {
    let mission = root().join("examples/search-rescue.rtcl");
    let (_s, url) = studio(&[mission.to_str().expect("path")], &scratch("editor"));
    let out = browse("editor", &url, None);
    assert!(out.contains("did you mean `move`"), "{out}");
}

#[test]
fn run_from_the_page_shows_three_robots_stacks_changing_until_it_completes() {
    let dir = scratch("run");
    let (_s, url) = studio(&[], &dir);
    let out = browse("run", &url, Some("5"));
    assert!(out.contains("ok: 3 robots"), "{out}");
    // The run wrote its log where the page said.
    let logs: Vec<_> = std::fs::read_dir(dir.join("out/studio"))
        .expect("the run's log directory")
        .collect();
    assert_eq!(logs.len(), 1, "one run log");
}

#[test]
fn replaying_a_run_log_moves_the_robots_with_the_scrubber() {
    let dir = scratch("replay");
    let log = dir.join("formation.jsonl");
    let mcap = dir.join("formation.mcap");
    let s = Command::new(BITE)
        .args(["run", "--log"])
        .arg(&log)
        .arg("--mcap")
        .arg(&mcap)
        .current_dir(&dir)
        .output()
        .expect("bite run");
    assert!(s.status.success(), "{}", String::from_utf8_lossy(&s.stderr));
    // Opened from the page's file input.
    let (_s, url) = studio(&[], &dir);
    browse("replay", &url, Some(log.to_str().expect("path")));
    // And given on the command line.
    let (_s2, url2) = studio(&[log.to_str().expect("path")], &dir);
    browse("replay", &url2, None);
    // An MCAP file BITE wrote: its records are the log's.
    let (_s3, url3) = studio(&[mcap.to_str().expect("path")], &dir);
    browse("replay", &url3, None);
}

#[test]
fn a_file_that_is_no_run_log_is_refused_with_where_and_why() {
    let dir = scratch("bad-log");
    let bad = dir.join("bad.mcap");
    std::fs::write(&bad, b"\x89MCAP0\r\nnot really").expect("write");
    let out = Command::new(BITE)
        .args(["studio", "--port", "0"])
        .arg(&bad)
        .current_dir(&dir)
        .output()
        .expect("bite studio");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.mcap: not a readable MCAP file"), "{err}");
}

#[test]
fn a_live_zenoh_team_started_by_bite_launch_appears_in_the_monitor() {
    let dir = scratch("team");
    // The browser and its driver first: the team's clock starts at launch.
    node_dir();
    chromium();
    let mut launch = Command::new(BITE)
        .args([
            "launch",
            "--robots",
            "3",
            "--speed",
            "1",
            "--time-limit",
            "90s",
        ])
        .arg("--out")
        .arg(dir.join("team"))
        .args(["--team", "studiotest"])
        .current_dir(&dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("bite launch");
    let monitor = stderr_line(
        &mut launch,
        "bite launch says how to monitor its team",
        |line| line.strip_prefix("monitor: bite studio ").map(String::from),
    );
    let launch = Kill(launch);
    let args: Vec<&str> = monitor.split_whitespace().collect();
    let (_s, url) = studio(&args, &dir);
    browse("team", &url, Some("3"));
    drop(launch);
    std::thread::sleep(Duration::from_millis(100));
}

/// The monitor's rate with 100 simulated robots (a measurement for
/// docs/performance.md, not a check): `cargo test -p bite-cli --release
/// --test studio -- --ignored --nocapture` (`BITE_STUDIO_PACE=5` for five
/// times real time).
#[test]
#[ignore]
fn measure_the_monitor_rate_with_100_robots() {
    let dir = scratch("rate");
    let graph = root().join("examples/coverage.yaml");
    let (_s, url) = studio(&[graph.to_str().expect("path"), "--robots", "100"], &dir);
    let pace = std::env::var("BITE_STUDIO_PACE").unwrap_or_else(|_| "1".into());
    browse("rate", &url, Some(&pace));
}

/// A raw HTTP/1.1 request to the studio; the status line and headers.
fn http(url: &str, request: &str) -> String {
    use std::io::{Read, Write};
    let addr = url
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_string();
    let mut s = std::net::TcpStream::connect(&addr).expect("connects");
    s.set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    s.write_all(request.replace("{addr}", &addr).as_bytes())
        .expect("sends");
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    String::from_utf8_lossy(&out).into_owned()
}

#[test]
fn only_the_studios_own_page_may_use_it() {
    let dir = scratch("origin");
    let (_s, url) = studio(&[], &dir);
    let page = http(
        &url,
        "GET / HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n",
    );
    assert!(page.starts_with("HTTP/1.1 200"), "{page}");
    assert!(
        page.to_ascii_lowercase()
            .contains("content-security-policy: default-src 'self'; script-src 'self'"),
        "{page}"
    );
    // Another site's page posting a run log (a "simple" request, no CORS
    // preflight), and a DNS-rebinding page (its own host name).
    let cross = http(
        &url,
        "POST /api/replay HTTP/1.1\r\nHost: {addr}\r\nOrigin: http://evil.example\r\n\
         Content-Type: text/plain\r\nContent-Length: 2\r\nConnection: close\r\n\r\n{}",
    );
    assert!(cross.starts_with("HTTP/1.1 403"), "{cross}");
    let rebound = http(
        &url,
        "GET /api/info HTTP/1.1\r\nHost: evil.example:80\r\nConnection: close\r\n\r\n",
    );
    assert!(rebound.starts_with("HTTP/1.1 403"), "{rebound}");
    let own = http(
        &url,
        "GET /api/info HTTP/1.1\r\nHost: {addr}\r\nOrigin: http://{addr}\r\nConnection: close\r\n\r\n",
    );
    assert!(own.starts_with("HTTP/1.1 200"), "{own}");
}

/// `/api/replay`: a last line that is no record is a bad line, one cut
/// short is reported torn; one upload is read at a time (another, while
/// the first is still arriving, is answered 503).
#[test]
fn an_uploaded_log_is_read_one_at_a_time_and_its_last_line_reported() {
    use std::io::{Read, Write};
    let dir = scratch("upload");
    let (_s, url) = studio(&[], &dir);
    let post = |body: &str| {
        http(
            &url,
            &format!(
                "POST /api/replay HTTP/1.1\r\nHost: {{addr}}\r\nContent-Type: text/plain\r\n\
                 Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
                body.len()
            ),
        )
    };
    let garbage = post("not json");
    assert!(garbage.starts_with("HTTP/1.1 200"), "{garbage}");
    assert!(garbage.contains(r#""bad_lines":1"#), "{garbage}");
    assert!(garbage.contains(r#""records":0"#), "{garbage}");
    assert!(garbage.contains(r#""torn_last_line":false"#), "{garbage}");
    let torn = post("{\"t\":0.0,\"event\":\"x\"}\n{\"t\":1.0,\"ev");
    assert!(torn.contains(r#""bad_lines":0"#), "{torn}");
    assert!(torn.contains(r#""records":1"#), "{torn}");
    assert!(torn.contains(r#""torn_last_line":true"#), "{torn}");
    // A first upload whose body has not all arrived holds the reader.
    let addr = url.trim_start_matches("http://").trim_end_matches('/');
    let mut first = std::net::TcpStream::connect(addr).expect("connects");
    first
        .set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    let body = "{\"t\":0.0,\"event\":\"x\"}\n";
    write!(
        first,
        "POST /api/replay HTTP/1.1\r\nHost: {addr}\r\nContent-Type: text/plain\r\n\
         Content-Length: {}\r\nConnection: close\r\n\r\n{}",
        body.len(),
        &body[..5]
    )
    .expect("sends");
    first.flush().expect("sent");
    std::thread::sleep(Duration::from_millis(500));
    let busy = post("{}\n");
    assert!(busy.starts_with("HTTP/1.1 503"), "{busy}");
    first.write_all(&body.as_bytes()[5..]).expect("sends");
    let mut out = String::new();
    let _ = first.read_to_string(&mut out);
    assert!(out.starts_with("HTTP/1.1 200"), "{out}");
    assert!(out.contains(r#""records":1"#), "{out}");
    let after = post("{}\n");
    assert!(after.starts_with("HTTP/1.1 200"), "{after}");
}
