//! Runs in robotics' formats: `--mcap FILE` and `--foxglove [PORT]` on
//! `bite run` and `bite launch`, and `bite log convert`.

use anyhow::{Context, Result};
use bite_foxglove::{Live, McapFile, Recorder};
use serde_json::Value as J;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

#[derive(clap::Args, Clone, Debug, Default)]
pub struct VizArgs {
    /// Also write the run as an MCAP file (Foxglove schemas for the arena,
    /// robots, poses and log; JSON channels for behavior stacks, decisions,
    /// protocol instances, informs and the summary), stamped in simulated
    /// time. Open it in Foxglove or Lichtblick.
    #[arg(long, value_name = "FILE")]
    pub mcap: Option<PathBuf>,
    /// Serve the run live to Foxglove or Lichtblick over the Foxglove
    /// WebSocket protocol on 127.0.0.1 (default port 8765; 0: any free
    /// port). Waits for a viewer to connect before the run starts, and
    /// keeps serving after it ends until the viewer disconnects (or Ctrl-C).
    #[arg(long, value_name = "PORT", num_args = 0..=1, default_missing_value = "8765")]
    pub foxglove: Option<u16>,
    /// With `--foxglove`: simulated seconds per wall second (default 1,
    /// real time; 0: as fast as it goes).
    #[arg(long, value_name = "FACTOR")]
    pub pace: Option<f64>,
}

/// A run being recorded and/or served.
pub struct Viz {
    recorder: Recorder,
    mcap: Option<(McapFile, PathBuf)>,
    live: Option<Live>,
    pace: f64,
    began: Instant,
    last_time: f64,
}

impl Viz {
    /// Set up what `args` asks for (`None` when nothing); `name` names the
    /// server. `pace` applies to a simulation; a team runs at its own pace.
    #[allow(clippy::disallowed_methods)] // a live view is paced by the wall clock
    pub fn start(args: &VizArgs, name: &str, simulated: bool) -> Result<Option<Viz>> {
        if args.mcap.is_none() && args.foxglove.is_none() {
            if args.pace.is_some() {
                anyhow::bail!("--pace paces a live view: give --foxglove too");
            }
            return Ok(None);
        }
        let pace = match (args.foxglove, simulated) {
            (Some(_), true) => args.pace.unwrap_or(1.0),
            _ => 0.0,
        };
        if !(pace.is_finite() && (pace == 0.0 || pace >= 1e-3)) {
            anyhow::bail!(
                "--pace must be a number of simulated seconds per wall second, 0 or more"
            );
        }
        let recorder = Recorder::new().context("setting up the Foxglove channels")?;
        let mcap = match &args.mcap {
            Some(p) => {
                if let Some(dir) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
                    std::fs::create_dir_all(dir)
                        .with_context(|| format!("creating {}", dir.display()))?;
                }
                let f = McapFile::create(&recorder, p)
                    .with_context(|| format!("creating {}", p.display()))?;
                Some((f, p.clone()))
            }
            None => None,
        };
        let live = match args.foxglove {
            Some(port) => {
                let live = Live::start(&recorder, port, name).with_context(|| {
                    format!("serving the Foxglove WebSocket protocol on 127.0.0.1:{port}")
                })?;
                eprintln!(
                    "foxglove: serving on ws://127.0.0.1:{} (127.0.0.1 only); open it in Foxglove or Lichtblick (Open connection → Foxglove WebSocket)",
                    live.port()
                );
                eprintln!("foxglove: waiting for a viewer to connect (Ctrl-C to give up)");
                let stop = crate::team::stop_flag()?;
                while live.clients() == 0 {
                    if stop.load(Ordering::Relaxed) {
                        anyhow::bail!("interrupted before a viewer connected");
                    }
                    std::thread::sleep(Duration::from_millis(50));
                }
                eprintln!("foxglove: a viewer connected");
                // Let it subscribe to the channels it was just told of.
                std::thread::sleep(Duration::from_millis(300));
                Some(live)
            }
            None => None,
        };
        Ok(Some(Viz {
            recorder,
            mcap,
            live,
            pace,
            began: Instant::now(),
            last_time: f64::NEG_INFINITY,
        }))
    }

    /// Take one run-log record (pacing a simulation to the wall clock;
    /// after Ctrl-C the run finishes unpaced and nothing lingers).
    pub fn record(&mut self, rec: &J) {
        let t = rec["t"].as_f64().unwrap_or(0.0);
        if self.pace > 0.0 && crate::team::stop_flag().is_ok_and(|s| s.load(Ordering::Relaxed)) {
            eprintln!("foxglove: stopping; the run finishes unpaced");
            self.pace = 0.0;
        }
        if self.pace > 0.0
            && t.is_finite()
            && t > 0.0
            && let Ok(due) = Duration::try_from_secs_f64(t / self.pace)
            && let Some(wait) = due.checked_sub(self.began.elapsed())
        {
            std::thread::sleep(wait);
        }
        self.recorder.record(rec);
        if let Some(l) = &self.live
            && t > self.last_time
        {
            self.last_time = t;
            l.time(t);
        }
    }

    /// Close the MCAP file and, when serving, keep serving until the viewer
    /// disconnects or Ctrl-C. Returns what was written, for the summary.
    pub fn finish(self) -> Result<Vec<String>> {
        let mut written = Vec::new();
        if let Some((f, p)) = self.mcap {
            f.close()
                .with_context(|| format!("writing {}", p.display()))?;
            written.push(format!(
                "{} ({} messages)",
                p.display(),
                self.recorder.messages()
            ));
        }
        if let Some(live) = self.live {
            eprintln!(
                "foxglove: the run is over; still serving on ws://127.0.0.1:{} until the viewer disconnects (or Ctrl-C)",
                live.port()
            );
            let stop = crate::team::stop_flag()?;
            while live.clients() > 0 && !stop.load(Ordering::Relaxed) {
                std::thread::sleep(Duration::from_millis(100));
            }
            live.stop();
        }
        Ok(written)
    }
}

/// Read run logs for conversion: each file's records, in file order.
pub fn read_logs(inputs: &[PathBuf]) -> Result<Vec<Vec<J>>> {
    inputs
        .iter()
        .map(|p| {
            let text = crate::read_input(p)?;
            bite_foxglove::parse_records(&p.display().to_string(), &text).map_err(|e| {
                eprintln!("error: {e}");
                anyhow::Error::new(crate::Reported(2))
            })
        })
        .collect()
}

/// Write `logs` (one run's, or a team's: merged in time order) as MCAP.
pub fn write_mcap(logs: Vec<Vec<J>>, out: &Path) -> Result<(usize, u64)> {
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let records = bite_foxglove::merge(logs);
    let mut rec = Recorder::new().context("setting up the Foxglove channels")?;
    let file =
        McapFile::create(&rec, out).with_context(|| format!("creating {}", out.display()))?;
    for r in &records {
        rec.record(r);
    }
    file.close()
        .with_context(|| format!("writing {}", out.display()))?;
    Ok((records.len(), rec.messages()))
}

/// `bite log convert`.
pub fn cmd_convert(inputs: &[PathBuf], output: &Path) -> Result<ExitCode> {
    let named: Vec<(&str, &Path)> = inputs.iter().map(|p| ("run log", p.as_path())).collect();
    crate::outputs::check(&named, &[("--output", output)])?;
    let logs = read_logs(inputs)?;
    let (records, messages) = write_mcap(logs, output)?;
    println!(
        "{}: {records} records from {} log{} → {messages} messages",
        output.display(),
        inputs.len(),
        if inputs.len() == 1 { "" } else { "s" }
    );
    Ok(ExitCode::SUCCESS)
}

/// Run logs being written by other processes, read as they grow: each
/// poll returns the complete lines added since the last, in time order.
pub struct Tails {
    files: Vec<(PathBuf, u64, Vec<u8>)>,
}

impl Tails {
    /// Follow these files (they may not exist yet).
    pub fn new(paths: Vec<PathBuf>) -> Self {
        Tails {
            files: paths.into_iter().map(|p| (p, 0, Vec::new())).collect(),
        }
    }

    /// The records completed since the last poll, sorted by time (stable).
    pub fn poll(&mut self) -> Vec<J> {
        use std::io::{Read, Seek, SeekFrom};
        let mut logs = Vec::new();
        for (path, offset, partial) in self.files.iter_mut() {
            let Ok(mut f) = std::fs::File::open(&*path) else {
                continue;
            };
            // A file written anew: read it from its start.
            if f.metadata().is_ok_and(|m| m.len() < *offset) {
                *offset = 0;
                partial.clear();
            }
            if f.seek(SeekFrom::Start(*offset)).is_err() {
                continue;
            }
            let mut buf = Vec::new();
            if f.read_to_end(&mut buf).is_err() {
                continue;
            }
            *offset += buf.len() as u64;
            partial.extend_from_slice(&buf);
            let Some(end) = partial.iter().rposition(|b| *b == b'\n') else {
                continue;
            };
            let done: Vec<u8> = partial.drain(..=end).collect();
            let records: Vec<J> = String::from_utf8_lossy(&done)
                .lines()
                .filter_map(|l| serde_json::from_str::<J>(l).ok())
                .filter(|v| v.is_object())
                .collect();
            logs.push(records);
        }
        bite_foxglove::merge(logs)
    }
}
