//! `bite studio`: the second paper's planned editor and status monitor, as
//! a web app served on 127.0.0.1.
//!
//! - **Editor**: a mission (`.rtcl`) or a behavior graph (YAML) with the
//!   command library as a sidebar; diagnostics from the project's own
//!   compiler and checker as you type; the graph drawn with its points and
//!   their bound protocols; Run.
//! - **Monitor**: each robot's stack, the organization, protocol instances
//!   in flight, beliefs, lost teammates, authentication counters, the arena
//!   and a timeline of decisions, for a run the studio started, a live
//!   Zenoh team (`--connect`) or a run log (replay, with a scrubber).
//!
//! The page's assets are compiled into the binary (`crates/bite-cli/studio/`:
//! plain JavaScript modules and CodeMirror 5, vendored), so it works
//! offline. The server is axum on a two-thread Tokio runtime; a run is
//! simulated on its own thread and paced by the wall clock.

pub mod analyze;
pub mod feed;

use analyze::Kind;
use anyhow::{Context, Result};
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{DefaultBodyLimit, Query, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use bite_sim::Scenario;
use feed::{Cursor, Feed, Source};
use serde_json::{Value as J, json};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

/// `bite studio` arguments.
#[derive(clap::Args, Debug)]
pub struct StudioArgs {
    /// A mission (`.rtcl`) or behavior graph (YAML) to open in the editor,
    /// or a run log to replay (`.jsonl`, or an `.mcap` file BITE wrote).
    pub file: Option<PathBuf>,
    /// The port on 127.0.0.1 (0: any free port).
    #[arg(long, default_value_t = 7700)]
    pub port: u16,
    /// Monitor a live team over Zenoh: connect to these endpoints (a
    /// robot's `--listen`, e.g. `tcp/127.0.0.1:7447`; `bite launch`
    /// prints its team's).
    #[arg(long, value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// The team's name on Zenoh (`bite/<team>/...`).
    #[arg(long, default_value = "bite")]
    pub team: String,
    /// The command library (default: the built-in one).
    #[arg(long)]
    pub library: Option<PathBuf>,
    /// The world a run from the page takes place in (default: the file's
    /// `scenarios/<stem>-physics.yaml`, else the built-in formation arena).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Team size of runs from the page (default: the scenario's).
    #[arg(long, value_parser = crate::parse_robots)]
    pub robots: Option<usize>,
    /// Simulated seconds per wall second for runs started from the page
    /// (default 1; 0: as fast as they go).
    #[arg(long, default_value_t = 1.0)]
    pub pace: f64,
}

const INDEX: &str = include_str!("../../studio/index.html");
const APP_JS: &str = include_str!("../../studio/app.js");
const APP_CSS: &str = include_str!("../../studio/app.css");
const VENDOR: &[(&str, &str, &str)] = &[
    (
        "codemirror.js",
        "text/javascript",
        include_str!("../../studio/vendor/codemirror/codemirror.js"),
    ),
    (
        "codemirror.css",
        "text/css",
        include_str!("../../studio/vendor/codemirror/codemirror.css"),
    ),
    (
        "simple.js",
        "text/javascript",
        include_str!("../../studio/vendor/codemirror/simple.js"),
    ),
    (
        "yaml.js",
        "text/javascript",
        include_str!("../../studio/vendor/codemirror/yaml.js"),
    ),
    (
        "lint.js",
        "text/javascript",
        include_str!("../../studio/vendor/codemirror/lint.js"),
    ),
    (
        "lint.css",
        "text/css",
        include_str!("../../studio/vendor/codemirror/lint.css"),
    ),
];

/// Snapshots sent to a page at most this often (50 per second): one per
/// change (a pose record 25 times a simulated second), never faster.
const FRAME: Duration = Duration::from_millis(20);

/// The studio's state, shared by every request.
struct Studio {
    lib: bite_rtcl::Library,
    scenario: Scenario,
    robots: Option<usize>,
    file: Option<(String, Kind, String)>,
    feed: Mutex<Feed>,
    /// The run in progress: asked to stop (finish unpaced), and its thread.
    run: Mutex<Option<(Arc<AtomicBool>, std::thread::JoinHandle<()>)>>,
    /// Pace of runs, simulated seconds per wall second (f64 bits).
    pace: AtomicU64,
    connected: Option<String>,
    team: String,
    /// The Zenoh session of `--connect`.
    session: std::sync::OnceLock<bite_zenoh::zenoh::Session>,
    /// One uploaded log read at a time (another is answered 503).
    replaying: tokio::sync::Semaphore,
}

impl Studio {
    fn feed(&self) -> MutexGuard<'_, Feed> {
        // A panicked writer leaves records that are still records.
        self.feed.lock().unwrap_or_else(|e| e.into_inner())
    }
}

fn kind_of(p: &Path) -> Kind {
    if crate::rtcl::is_mission(p) {
        Kind::Rtcl
    } else {
        Kind::Yaml
    }
}

fn is_log(p: &Path) -> bool {
    p.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("jsonl") || e.eq_ignore_ascii_case("mcap"))
}

/// A run log's records: JSON lines, or an MCAP file BITE wrote (its
/// `/bite/events` channel). Lines that are not records are reported
/// (`file:line:col: why`, the first 20) and skipped.
fn read_log(name: &str, bytes: &[u8]) -> Result<feed::Parsed, String> {
    if bytes.starts_with(bite_foxglove::MCAP_MAGIC) {
        return bite_foxglove::read_mcap(name, bytes)
            .map(|records| feed::Parsed {
                records,
                ..Default::default()
            })
            .map_err(|e| e.to_string());
    }
    let text = std::str::from_utf8(bytes).map_err(|e| {
        format!(
            "{name}: not UTF-8 text (byte {}): expected JSON lines or an MCAP file",
            e.valid_up_to()
        )
    })?;
    Ok(feed::parse_log(name, text))
}

/// `bite studio`.
pub fn cmd_studio(a: StudioArgs) -> Result<ExitCode> {
    if !(a.pace.is_finite() && a.pace >= 0.0) {
        anyhow::bail!("--pace must be a number of simulated seconds per wall second, 0 or more");
    }
    let lib = crate::rtcl::library(a.library.as_deref())?;
    let mut feed = Feed::new();
    let mut file = None;
    let mut scenario_path = a.scenario.clone();
    if let Some(p) = &a.file {
        if is_log(p) {
            let bytes =
                std::fs::read(p).with_context(|| format!("reading the run log {}", p.display()))?;
            let log = read_log(&p.display().to_string(), &bytes).map_err(|e| {
                eprintln!("error: {e}");
                anyhow::Error::new(crate::Reported(2))
            })?;
            for x in &log.problems {
                eprintln!("warning: {x}");
            }
            if log.bad > log.problems.len() {
                eprintln!(
                    "warning: {} more lines were not records",
                    log.bad - log.problems.len()
                );
            }
            if log.torn {
                eprintln!("note: its last line, a record cut short, was skipped");
            }
            feed.reset(Source::Replay, p.display().to_string(), false);
            feed.records = log.records;
            feed.problems = log.problems;
        } else {
            let text = crate::read_input(p)?;
            if scenario_path.is_none() {
                let guess = crate::sibling_scenario(p, true);
                if guess.exists() {
                    scenario_path = Some(guess);
                }
            }
            file = Some((p.display().to_string(), kind_of(p), text));
        }
    }
    // Nothing opened: the built-in formation example, as `bite run` runs.
    if file.is_none() && a.file.as_ref().is_none_or(|p| !is_log(p)) {
        file = Some((
            "examples/formation.yaml (built in)".to_string(),
            Kind::Yaml,
            crate::FORMATION_GRAPH.to_string(),
        ));
    }
    let scenario = match &scenario_path {
        Some(s) => Scenario::load(s).map_err(crate::bad_input)?,
        None => Scenario::load_str(
            &Arc::from("examples/scenarios/formation-physics.yaml (built in)"),
            crate::FORMATION_PHYSICS,
        )
        .map_err(crate::bad_input)?,
    };
    let connected = (!a.connect.is_empty()).then(|| a.connect.join(", "));
    if let Some(c) = &connected {
        feed.reset(
            Source::Zenoh,
            format!("team `{}` over Zenoh ({c})", a.team),
            true,
        );
    }
    let studio = Arc::new(Studio {
        lib,
        scenario,
        robots: a.robots,
        file,
        feed: Mutex::new(feed),
        run: Mutex::new(None),
        pace: AtomicU64::new(a.pace.to_bits()),
        connected,
        team: a.team.clone(),
        session: std::sync::OnceLock::new(),
        replaying: tokio::sync::Semaphore::new(1),
    });
    // The Zenoh session lives as long as the studio.
    let _session = if a.connect.is_empty() {
        None
    } else {
        Some(subscribe(&studio, &a.connect, &a.team)?)
    };
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the web server's runtime")?;
    rt.block_on(serve(studio, a.port))?;
    Ok(ExitCode::SUCCESS)
}

async fn serve(studio: Arc<Studio>, port: u16) -> Result<()> {
    let listener = tokio::net::TcpListener::bind(("127.0.0.1", port))
        .await
        .with_context(|| format!("listening on 127.0.0.1:{port}"))?;
    let addr = listener.local_addr()?;
    let app = Router::new()
        .route("/", get(|| async { html(INDEX) }))
        .route(
            "/app.js",
            get(|| async { asset("text/javascript", APP_JS) }),
        )
        .route("/app.css", get(|| async { asset("text/css", APP_CSS) }))
        .route("/vendor/{name}", get(vendor))
        .route("/api/info", get(info))
        .route("/api/analyze", post(analyze_text))
        .route("/api/run", post(run_text))
        .route("/api/stop", post(stop_run))
        .route("/api/live", post(live))
        .route("/api/replay", post(replay))
        .route("/api/monitor", get(monitor))
        .layer(DefaultBodyLimit::max(MAX_TEXT_BYTES))
        .layer(axum::middleware::from_fn_with_state(
            addr.port(),
            same_origin,
        ))
        .with_state(studio);
    eprintln!("BITE Studio: http://{addr}/ (served on 127.0.0.1 only; Ctrl-C stops it)");
    axum::serve(listener, app)
        .with_graceful_shutdown(async {
            let _ = tokio::signal::ctrl_c().await;
        })
        .await
        .context("serving the studio")?;
    Ok(())
}

/// Largest mission or graph text the editor sends.
const MAX_TEXT_BYTES: usize = 4 << 20;
/// Largest run log a page uploads for replay. Its records take some 40
/// times its size in memory while it is parsed (JSON values), so 64 MiB
/// needs some 2.7 GB at most; one upload is parsed at a time
/// ([`Studio::replaying`]).
const MAX_LOG_BYTES: usize = 64 << 20;

/// Only the studio's own page may use it: the `Host` must be this
/// loopback address (a DNS-rebinding page names another host) and an
/// `Origin`, when sent (every cross-site request and WebSocket carries
/// one), must be the studio's own.
async fn same_origin(
    State(port): State<u16>,
    req: axum::extract::Request,
    next: axum::middleware::Next,
) -> Response {
    let ok = {
        // Browsers leave out the default port.
        let ours = |v: &str, scheme: &str| {
            ["127.0.0.1", "localhost"].iter().any(|h| {
                v == format!("{scheme}{h}:{port}") || (port == 80 && v == format!("{scheme}{h}"))
            })
        };
        let h = req.headers();
        let host_ok = h
            .get(header::HOST)
            .and_then(|v| v.to_str().ok())
            .is_some_and(|v| ours(v, ""));
        let origin_ok = h
            .get(header::ORIGIN)
            .is_none_or(|v| v.to_str().is_ok_and(|v| ours(v, "http://")));
        host_ok && origin_ok
    };
    if !ok {
        return (
            StatusCode::FORBIDDEN,
            "the studio answers its own page only (Host and Origin 127.0.0.1 or localhost)",
        )
            .into_response();
    }
    next.run(req).await
}

fn html(body: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, "text/html; charset=utf-8"),
            (header::CACHE_CONTROL, "no-cache"),
            // Scripts from the studio only: a record's text can never run.
            (
                header::CONTENT_SECURITY_POLICY,
                "default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; \
                 img-src 'self' data:; connect-src 'self'; object-src 'none'; base-uri 'none'; \
                 frame-ancestors 'none'",
            ),
        ],
        body,
    )
        .into_response()
}

fn asset(mime: &'static str, body: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, mime),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}

async fn vendor(axum::extract::Path(name): axum::extract::Path<String>) -> Response {
    match VENDOR.iter().find(|(n, _, _)| *n == name) {
        Some((_, mime, body)) => asset(mime, body),
        None => (StatusCode::NOT_FOUND, "no such asset").into_response(),
    }
}

/// The command library for the sidebar: each command's usage, summary,
/// parameters and the template a drop inserts.
fn library_json(lib: &bite_rtcl::Library) -> J {
    use bite_rtcl::library::ParamType as T;
    let commands: Vec<J> = lib
        .names()
        .filter_map(|n| lib.command(n))
        .map(|c| {
            let mut template = c.name.clone();
            for p in &c.params {
                template.push(':');
                if !p.optional {
                    template.push_str(&match &p.ty {
                        T::Name => p.name.clone(),
                        T::Choice(v) => v.first().cloned().unwrap_or_default(),
                        T::Colour => "red".into(),
                        _ => "0".into(),
                    });
                }
            }
            if c.result.is_some() {
                template.push_str("=>object");
            }
            json!({
                "name": c.name,
                "usage": c.usage(),
                "summary": c.summary,
                "template": template,
                "min_robots": c.min_robots,
                "params": c.params.iter().map(|p| json!({
                    "name": p.name, "type": p.ty.describe(), "optional": p.optional, "doc": p.doc,
                })).collect::<Vec<_>>(),
            })
        })
        .collect();
    json!(commands)
}

async fn info(State(s): State<Arc<Studio>>) -> Json<J> {
    let file = s.file.as_ref().map(|(name, kind, text)| {
        json!({"name": name, "kind": if *kind == Kind::Rtcl { "rtcl" } else { "yaml" }, "text": text})
    });
    let physics = s.scenario.physics.as_ref();
    Json(json!({
        "version": env!("CARGO_PKG_VERSION"),
        "library": library_json(&s.lib),
        "file": file,
        "scenario": {
            "name": s.scenario.name,
            "file": &*s.scenario.file,
            "physical": physics.is_some(),
            "robots": s.robots.or(s.scenario.robots).unwrap_or(physics.map_or(0, |p| p.start.len())),
        },
        "zenoh": s.connected.as_ref().map(|c| json!({"team": s.team, "endpoints": c})),
        "pace": f64::from_bits(s.pace.load(Ordering::Relaxed)),
    }))
}

#[derive(serde::Deserialize)]
struct TextReq {
    kind: Kind,
    #[serde(default)]
    file: Option<String>,
    text: String,
    #[serde(default)]
    seed: Option<u64>,
    #[serde(default)]
    pace: Option<f64>,
}

impl TextReq {
    fn label(&self) -> String {
        self.file.clone().unwrap_or_else(|| match self.kind {
            Kind::Rtcl => "mission.rtcl".into(),
            Kind::Yaml => "graph.yaml".into(),
        })
    }
}

fn analysis_json(a: &analyze::Analysis) -> J {
    json!({
        "diagnostics": a.diagnostics.iter().map(analyze::diagnostic_json).collect::<Vec<_>>(),
        "graph": a.mission.as_ref().map(|(m, _)| analyze::graph_json(m)),
    })
}

async fn analyze_text(State(s): State<Arc<Studio>>, Json(req): Json<TextReq>) -> Json<J> {
    let s2 = s.clone();
    let out = tokio::task::spawn_blocking(move || {
        let a = analyze::analyze(
            req.kind,
            &req.label(),
            &req.text,
            &s2.lib,
            &s2.scenario,
            s2.robots,
            &crate::registry(),
        );
        analysis_json(&a)
    })
    .await
    .unwrap_or_else(|e| json!({"diagnostics": [], "error": e.to_string()}));
    Json(out)
}

async fn run_text(State(s): State<Arc<Studio>>, Json(req): Json<TextReq>) -> Response {
    let label = req.label();
    let s2 = s.clone();
    let text = req.text.clone();
    let kind = req.kind;
    let label2 = label.clone();
    let Ok(a) = tokio::task::spawn_blocking(move || {
        analyze::analyze(
            kind,
            &label2,
            &text,
            &s2.lib,
            &s2.scenario,
            s2.robots,
            &crate::registry(),
        )
    })
    .await
    else {
        return (StatusCode::INTERNAL_SERVER_ERROR, "the compiler failed").into_response();
    };
    let Some((mission, scenario)) = a.mission.clone() else {
        return (StatusCode::UNPROCESSABLE_ENTITY, Json(analysis_json(&a))).into_response();
    };
    if let Some(p) = req.pace
        && p.is_finite()
        && p >= 0.0
    {
        s.pace.store(p.to_bits(), Ordering::Relaxed);
    }
    let seed = req.seed.unwrap_or(scenario.seed);
    // The log's name: the graph's, reduced to a safe file name (a graph
    // names itself; the name must not climb out of `out/studio`).
    let name: String = mission
        .graph()
        .name()
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .take(80)
        .collect();
    let log = PathBuf::from("out")
        .join("studio")
        .join(format!("{name}-seed{seed}.jsonl"));
    let stop = Arc::new(AtomicBool::new(false));
    // One run at a time, and the feed switched to it under one lock.
    let mut run = s.run.lock().unwrap_or_else(|e| e.into_inner());
    let previous = run.take().map(|(flag, handle)| {
        // The one before finishes unpaced, unseen; the new one waits for
        // it (they may write the same log).
        flag.store(true, Ordering::Relaxed);
        handle
    });
    let generation = {
        let mut f = s.feed();
        f.reset(Source::Run, format!("bite run {label} (seed {seed})"), true);
        f.generation
    };
    let s2 = s.clone();
    let log2 = log.clone();
    let stop2 = stop.clone();
    let handle = std::thread::spawn(move || {
        if let Some(h) = previous {
            let _ = h.join();
        }
        let s3 = s2.clone();
        let ran = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            run_mission(s2, mission, scenario, seed, log2, stop2, generation)
        }));
        if ran.is_err() {
            // The page must not say "running" for ever.
            let mut f = s3.feed();
            if f.generation == generation {
                f.live = false;
                f.ended = Some(
                    json!({"outcome": "error", "error": "the run panicked (see the studio's output)"}),
                );
                f.touch();
            }
        }
    });
    *run = Some((stop, handle));
    drop(run);
    Json(json!({"ok": true, "log": log.display().to_string(), "seed": seed, "graph": analysis_json(&a)["graph"]}))
        .into_response()
}

/// Simulate a mission, pushing its records to the feed as they are made,
/// paced by the wall clock; then say how it ended.
#[allow(clippy::disallowed_methods)] // a watched run is paced by the wall clock
fn run_mission(
    s: Arc<Studio>,
    mission: Arc<bite_core::mission::Mission>,
    scenario: Scenario,
    seed: u64,
    log: PathBuf,
    stop: Arc<AtomicBool>,
    generation: u64,
) {
    let began = std::time::Instant::now();
    let mut shown = true;
    let mut on_record = |r: &J| {
        if !shown {
            return;
        }
        {
            let mut f = s.feed();
            if f.generation != generation {
                // Replaced by another source: finish unseen, unpaced.
                shown = false;
                return;
            }
            f.push(r.clone());
        }
        let pace = f64::from_bits(s.pace.load(Ordering::Relaxed));
        // Stop: the run finishes without pacing (still shown).
        if pace > 0.0
            && !stop.load(Ordering::Relaxed)
            && let Some(t) = r["t"].as_f64()
            && let Ok(due) = Duration::try_from_secs_f64(t / pace)
            && let Some(wait) = due.checked_sub(began.elapsed())
        {
            std::thread::sleep(wait.min(Duration::from_secs(1)));
        }
    };
    let result = (|| -> Result<J> {
        if let Some(d) = log.parent() {
            std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
        }
        let file = std::fs::File::create(&log)
            .with_context(|| format!("creating the run log {}", log.display()))?;
        let mut w = std::io::BufWriter::new(file);
        let report = bite_sim::runner::run(
            mission.clone(),
            &scenario,
            bite_sim::runner::RunOptions {
                seed: Some(seed),
                time_limit: None,
                log: Some(&mut w),
                record: false,
                progress: None,
                changes: Vec::new(),
                watch: Some(bite_sim::runner::Watch {
                    on_record: &mut on_record,
                    poses_every: Duration::from_millis(40),
                }),
                pool: None,
                batch_from: None,
                batch_most: None,
                log_messages: false,
            },
        )
        .map_err(|d| anyhow::anyhow!("{d}"))?;
        drop(w);
        Ok(json!({
            "outcome": report.summary.outcome,
            "exit_code": crate::run_exit_code(&report),
            "log": log.display().to_string(),
            "violations": report.violations.iter().map(|v| v.to_string()).collect::<Vec<_>>(),
            "summary": report.summary.to_string(),
        }))
    })();
    let mut f = s.feed();
    if f.generation == generation {
        f.live = false;
        f.touch();
        f.ended = Some(match result {
            Ok(mut j) => {
                j["shown"] = json!(shown);
                j
            }
            Err(e) => json!({"outcome": "error", "error": format!("{e:#}")}),
        });
    }
}

async fn stop_run(State(s): State<Arc<Studio>>) -> Json<J> {
    let stopped = s
        .run
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .as_ref()
        .map(|(f, _)| f.store(true, Ordering::Relaxed))
        .is_some();
    Json(json!({"ok": stopped}))
}

async fn live(State(s): State<Arc<Studio>>) -> Response {
    match &s.connected {
        None => (
            StatusCode::CONFLICT,
            Json(json!({"error": "the studio was not started with --connect"})),
        )
            .into_response(),
        Some(c) => {
            let label = format!("team `{}` over Zenoh ({c})", s.team);
            s.feed().reset(Source::Zenoh, label, true);
            fetch_layout(&s);
            Json(json!({"ok": true})).into_response()
        }
    }
}

#[derive(serde::Deserialize)]
struct ReplayQuery {
    #[serde(default)]
    name: Option<String>,
}

async fn replay(
    State(s): State<Arc<Studio>>,
    Query(q): Query<ReplayQuery>,
    body: axum::body::Body,
) -> Response {
    // One upload at a time, before its body is read: each may take some
    // 40 times its size while it is parsed.
    let Ok(_one) = s.replaying.try_acquire() else {
        return (
            StatusCode::SERVICE_UNAVAILABLE,
            Json(json!({"error": "another run log is being read: try again when it is done"})),
        )
            .into_response();
    };
    let body = match axum::body::to_bytes(body, MAX_LOG_BYTES).await {
        Ok(b) => b,
        Err(_) => {
            return (
                StatusCode::PAYLOAD_TOO_LARGE,
                Json(json!({"error": format!(
                    "the run log could not be read whole: the studio replays logs of at most {} MiB",
                    MAX_LOG_BYTES >> 20
                )})),
            )
                .into_response();
        }
    };
    let name = q.name.unwrap_or_else(|| "run log".into());
    // Parsing a large log is long work: off the server's threads.
    let name2 = name.clone();
    let parsed = tokio::task::spawn_blocking(move || read_log(&name2, &body)).await;
    let log = match parsed {
        Ok(Ok(x)) => x,
        Ok(Err(e)) => {
            return (StatusCode::UNPROCESSABLE_ENTITY, Json(json!({"error": e}))).into_response();
        }
        Err(e) => {
            return (
                StatusCode::INTERNAL_SERVER_ERROR,
                Json(json!({"error": format!("reading the log failed: {e}")})),
            )
                .into_response();
        }
    };
    let (n, bad, torn) = (log.records.len(), log.bad, log.torn);
    let (old, end) = {
        let mut f = s.feed();
        let old = std::mem::take(&mut f.records);
        f.reset(Source::Replay, name, false);
        f.records = log.records;
        f.problems = log.problems;
        f.touch();
        (old, f.end_time())
    };
    // The old records are freed here, not under the feed's lock.
    drop(old);
    Json(json!({"ok": true, "records": n, "bad_lines": bad, "torn_last_line": torn, "end": end}))
        .into_response()
}

async fn monitor(State(s): State<Arc<Studio>>, ws: WebSocketUpgrade) -> Response {
    ws.on_upgrade(move |socket| watch(s, socket))
}

/// One page's monitor: a snapshot whenever something changed, at most
/// every [`FRAME`]; the page may ask to see another time (`{"seek": t}`,
/// `{"seek": null}` to follow the end).
async fn watch(s: Arc<Studio>, mut socket: WebSocket) {
    let mut cursor = Cursor::new();
    let mut changed = s.feed().subscribe();
    let mut last: Option<tokio::time::Instant> = None;
    // The first snapshot at once: the feed may be full already.
    let mut behind = true;
    loop {
        // Wait for a change or a request (not when records are still to
        // be applied: a long rebuild goes on at once).
        if !behind {
            tokio::select! {
                msg = socket.recv() => match msg {
                    Some(Ok(Message::Text(t))) => {
                        if let Ok(m) = serde_json::from_str::<J>(t.as_str())
                            && m.get("seek").is_some()
                        {
                            cursor.seek(m["seek"].as_f64());
                        }
                    }
                    Some(Ok(_)) => continue,
                    _ => break,
                },
                r = changed.changed() => if r.is_err() { break },
            }
        }
        if let Some(at) = last {
            tokio::time::sleep_until(at + FRAME).await;
        }
        let snap = {
            let f = s.feed();
            changed.mark_unchanged();
            cursor.catch_up(&f);
            behind = cursor.behind(&f);
            cursor.dirty.then(|| cursor.snapshot(&f))
        };
        if let Some(snap) = snap {
            last = Some(tokio::time::Instant::now());
            if socket
                .send(Message::Text(snap.to_string().into()))
                .await
                .is_err()
            {
                break;
            }
        }
    }
}

/// The world's layout was put once, at the start: ask the simulator
/// server for it (again until it answers: it may not be up yet). And the
/// team's roster, from the layout or the robots' membership answers:
/// records of robots not on it are not kept.
fn fetch_layout(studio: &Arc<Studio>) {
    use bite_zenoh::zenoh::Wait;
    use bite_zenoh::zenoh::query::{ConsolidationMode, QueryTarget};
    let Some(session) = studio.session.get().cloned() else {
        return;
    };
    let st = studio.clone();
    let keys = bite_zenoh::Keys::new(&studio.team);
    let key = keys.world();
    let members = keys.members("*");
    let generation = st.feed().generation;
    std::thread::spawn(move || {
        let mut got = false;
        for _ in 0..120 {
            if st.feed().generation != generation {
                return;
            }
            if st.feed().roster.is_none()
                && let Ok(replies) = (session.get(&members))
                    .target(QueryTarget::All)
                    .consolidation(ConsolidationMode::None)
                    .timeout(Duration::from_secs(1))
                    .wait()
            {
                while let Ok(reply) = replies.recv() {
                    let Ok(sample) = reply.result() else { continue };
                    let Ok(m) = serde_json::from_slice::<bite_zenoh::wire::Membership>(
                        &sample.payload().to_bytes(),
                    ) else {
                        continue;
                    };
                    let mut f = st.feed();
                    if !m.roster.is_empty() && f.generation == generation && f.roster.is_none() {
                        f.set_roster(m.roster);
                    }
                }
            }
            if got && st.feed().roster.is_some() {
                return;
            }
            if !got && let Ok(replies) = session.get(&key).timeout(Duration::from_secs(1)).wait() {
                while let Ok(reply) = replies.recv() {
                    let Ok(sample) = reply.result() else { continue };
                    if sample.payload().len() > feed::MAX_RECORD_BYTES {
                        continue;
                    }
                    if let Ok(rec) = serde_json::from_slice::<J>(&sample.payload().to_bytes())
                        && rec["event"] == "world"
                    {
                        let mut f = st.feed();
                        if f.source == Source::Zenoh && f.generation == generation {
                            f.push_live(Ok(rec));
                        }
                        got = true;
                    }
                }
            }
            if got && st.feed().roster.is_some() {
                return;
            }
            std::thread::sleep(Duration::from_millis(500));
        }
    });
}

/// Subscribe to a team's records (`bite/T/log/*`, `bite/T/sim/world`) and
/// statuses (`bite/T/status/*`); they join the feed while it is the
/// team's.
fn subscribe(
    studio: &Arc<Studio>,
    endpoints: &[String],
    team: &str,
) -> Result<(
    bite_zenoh::zenoh::Session,
    Vec<bite_zenoh::zenoh::pubsub::Subscriber<()>>,
)> {
    use bite_zenoh::zenoh::Wait;
    let net = bite_zenoh::net::NetOptions {
        connect: endpoints.to_vec(),
        ..Default::default()
    };
    let session = net.open().context("joining the team over Zenoh")?;
    let keys = bite_zenoh::Keys::new(team);
    let mut subs = Vec::new();
    for (key, status) in [
        (keys.all("log"), false),
        (keys.world(), false),
        (keys.all("status"), true),
    ] {
        let st = studio.clone();
        let sub = session
            .declare_subscriber(&key)
            .callback(move |sample| {
                // Bounded, a record, of a robot on the roster: or counted
                // (`dropped` in the snapshots), never kept.
                let len = sample.payload().len();
                let rec = match len > feed::MAX_RECORD_BYTES {
                    true => Err(feed::Refused::Oversize),
                    false => feed::live_record(&sample.payload().to_bytes(), status),
                };
                let mut f = st.feed();
                if f.source == Source::Zenoh {
                    f.push_live(rec);
                }
            })
            .wait()
            .map_err(|e| anyhow::anyhow!("subscribing to {key}: {e}"))?;
        subs.push(sub);
    }
    let _ = studio.session.set(session.clone());
    fetch_layout(studio);
    eprintln!(
        "studio: monitoring team `{team}` over Zenoh ({})",
        endpoints.join(", ")
    );
    Ok((session, subs))
}
