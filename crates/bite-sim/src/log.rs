//! The run log: one JSON object per line, every kernel event with its time
//! and robot, ids replaced by names (by [`Namer`], shared with robot
//! processes) so that people and scripts can read it.
//!
//! ```text
//! {"t":0.0,"robot":"r0","event":"selected","behavior":"formation","team":"root","epoch":1,"depth":0,"via":"start"}
//! ```
//!
//! The first line describes the run (graph, configuration, scenario, seed,
//! team); the last line is the summary. The same graph, scenario and seed
//! give the same log, byte for byte.

pub use bite_agent::log::Namer;
use bite_core::ids::Fnv1a;
use serde_json::Value as J;
use std::io::{self, Write};

/// Writes JSON lines and keeps a fingerprint of everything written.
pub struct RunLog<'w> {
    out: Option<&'w mut dyn Write>,
    watch: Option<&'w mut dyn FnMut(&J)>,
    hash: Fnv1a,
    lines: u64,
    error: Option<io::Error>,
}

impl<'w> RunLog<'w> {
    /// A log writing to `out`, or only fingerprinting when `None`.
    pub fn new(out: Option<&'w mut dyn Write>) -> Self {
        RunLog {
            out,
            watch: None,
            hash: Fnv1a::new(),
            lines: 0,
            error: None,
        }
    }
    /// Also hand every record to `watch` as it is made (a live view, an
    /// MCAP file). The fingerprint covers what is written, not what is
    /// watched.
    pub fn with_watch(mut self, watch: Option<&'w mut dyn FnMut(&J)>) -> Self {
        self.watch = watch;
        self
    }
    /// True when records go somewhere (a log or a watcher).
    pub fn is_writing(&self) -> bool {
        self.out.is_some() || self.watch.is_some()
    }
    /// True when a watcher sees the records.
    pub fn is_watched(&self) -> bool {
        self.watch.is_some()
    }
    /// Write one record (and show it to the watcher).
    pub fn write(&mut self, record: &J) {
        self.show(record);
        self.write_only(record);
    }
    /// Show a record to the watcher only (not in the log).
    pub fn show(&mut self, record: &J) {
        if let Some(w) = self.watch.as_mut() {
            w(record);
        }
    }
    /// Write a record to the log only (not to the watcher).
    pub fn write_only(&mut self, record: &J) {
        let Some(out) = self.out.as_mut() else {
            return;
        };
        let mut line = record.to_string();
        line.push('\n');
        self.hash.write(line.as_bytes());
        self.lines += 1;
        if self.error.is_none()
            && let Err(e) = out.write_all(line.as_bytes())
        {
            self.error = Some(e);
        }
    }
    /// Flush, reporting the first write error.
    pub fn finish(&mut self) -> io::Result<()> {
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        if let Some(out) = self.out.as_mut() {
            out.flush()?;
        }
        Ok(())
    }
    /// Fingerprint of the lines written so far.
    pub fn fingerprint(&self) -> u64 {
        self.hash.finish()
    }
    /// Lines written so far.
    pub fn lines(&self) -> u64 {
        self.lines
    }
}
