//! Recording a robot's mind and replaying it: every input an [`Agent`]
//! takes goes through [`Agent::handle`], so its whole input stream can be
//! written down, and the mind re-run from it later. The record is JSON
//! lines: a header (what mission, which robot, which seed: the caller's
//! JSON, kept verbatim), then one line per input with its time, the input
//! and a fingerprint of every output the mind produced for it. A replay
//! feeds the same inputs to a fresh mind and compares the fingerprints:
//! the test of "same inputs, same decisions" in every runtime.

use crate::agent::{Agent, AgentOutput, Input};
use crate::schema::Sensed;
use bite_core::ids::{Fnv1a, RobotId};
use bite_core::kernel::Position;
use bite_core::msg::Envelope;
use bite_core::time::Time;
use bite_core::wm::Inform;
use serde::{Deserialize, Serialize};
use std::io::{BufRead, Write};

/// An input, owned (as recorded).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Recorded {
    /// [`Input::Tick`]; `world` in microseconds.
    Tick {
        /// The world's time, µs.
        world: u64,
        /// The sensor readings.
        sensed: Option<Sensed>,
    },
    /// [`Input::Message`].
    Message(Envelope),
    /// [`Input::Inform`].
    Inform {
        /// The teammate.
        from: u32,
        /// The report.
        msg: Inform,
    },
    /// [`Input::Timer`].
    Timer,
    /// [`Input::Peer`].
    Peer {
        /// The teammate.
        from: u32,
        /// Its position.
        pos: Position,
    },
    /// [`Input::Lost`].
    Lost(u32),
    /// [`Input::Back`].
    Back(u32),
}

impl Recorded {
    /// The owned form of `input`.
    pub fn of(input: &Input<'_>) -> Recorded {
        match *input {
            Input::Tick { world, sensed } => Recorded::Tick {
                world: world.as_micros(),
                sensed: sensed.cloned(),
            },
            Input::Message(e) => Recorded::Message(e.clone()),
            Input::Inform { from, msg } => Recorded::Inform {
                from: from.0,
                msg: msg.clone(),
            },
            Input::Timer => Recorded::Timer,
            Input::Peer { from, pos } => Recorded::Peer {
                from: from.0,
                pos: pos.clone(),
            },
            Input::Lost(r) => Recorded::Lost(r.0),
            Input::Back(r) => Recorded::Back(r.0),
        }
    }

    /// The input it records.
    pub fn input(&self) -> Input<'_> {
        match self {
            Recorded::Tick { world, sensed } => Input::Tick {
                world: Time(*world),
                sensed: sensed.as_ref(),
            },
            Recorded::Message(e) => Input::Message(e),
            Recorded::Inform { from, msg } => Input::Inform {
                from: RobotId(*from),
                msg,
            },
            Recorded::Timer => Input::Timer,
            Recorded::Peer { from, pos } => Input::Peer {
                from: RobotId(*from),
                pos,
            },
            Recorded::Lost(r) => Input::Lost(RobotId(*r)),
            Recorded::Back(r) => Input::Back(RobotId(*r)),
        }
    }
}

/// One recorded input: when (the robot's clock, µs), what, and the
/// fingerprint of what the mind produced for it (and how many outputs).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Line {
    /// The robot's clock, µs.
    pub t: u64,
    /// The input.
    pub input: Recorded,
    /// Outputs produced.
    pub outputs: usize,
    /// Their fingerprint (hex).
    pub fingerprint: String,
}

/// The fingerprint of a sequence of outputs (their full debug form:
/// every message, event and command, with every number).
pub fn fingerprint<'a>(outputs: impl IntoIterator<Item = &'a AgentOutput>) -> u64 {
    let mut h = Fnv1a::new();
    for o in outputs {
        h.write(format!("{o:?}").as_bytes());
        h.write(b"\n");
    }
    h.finish()
}

/// Writes a record.
pub struct Recorder {
    out: Box<dyn Write + Send>,
    /// The first write error (recording stops there).
    pub error: Option<std::io::Error>,
    /// Inputs written.
    pub inputs: u64,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("inputs", &self.inputs)
            .finish_non_exhaustive()
    }
}

impl Recorder {
    /// A record into `out`, starting with the `header` line (the caller's
    /// description of the mission, robot and seed).
    pub fn new(mut out: Box<dyn Write + Send>, header: &serde_json::Value) -> Recorder {
        let error = serde_json::to_writer(
            &mut out,
            &serde_json::json!({ "bite_inputs": 1, "header": header }),
        )
        .map_err(std::io::Error::other)
        .and_then(|_| out.write_all(b"\n"))
        .err();
        Recorder {
            out,
            error,
            inputs: 0,
        }
    }

    /// Write one input and what it produced.
    pub fn write(&mut self, t: Time, input: Recorded, outputs: &[&AgentOutput]) {
        if self.error.is_some() {
            return;
        }
        let line = Line {
            t: t.as_micros(),
            input,
            outputs: outputs.len(),
            fingerprint: format!("{:016x}", fingerprint(outputs.iter().copied())),
        };
        self.inputs += 1;
        if let Err(e) = serde_json::to_writer(&mut self.out, &line)
            .map_err(std::io::Error::other)
            .and_then(|_| self.out.write_all(b"\n"))
        {
            self.error = Some(e);
        }
    }

    /// Flush.
    pub fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

/// Why a record cannot be replayed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// Reading failed.
    #[error("line {line}: {source}")]
    Io {
        /// Line number (1-based).
        line: usize,
        /// The error.
        source: std::io::Error,
    },
    /// A line is not what a record holds.
    #[error("line {line}: {what}")]
    Malformed {
        /// Line number (1-based).
        line: usize,
        /// What is wrong.
        what: String,
    },
    /// The mind could not be rebuilt from the header.
    #[error("{0}")]
    Mind(String),
    /// A line is longer than any record writes ([`MAX_LINE_BYTES`]): not a
    /// record (a device such as `/dev/zero`, a binary file).
    #[error(
        "line {line}: more than {limit} bytes without a line break (reading stopped there): not a record of a robot's inputs"
    )]
    TooLong {
        /// Line number (1-based).
        line: usize,
        /// The limit, bytes.
        limit: usize,
    },
}

/// The longest line a record may hold, bytes: the cap on every file the
/// project reads ([`bite_core::yaml::MAX_FILE_BYTES`]), far above what one
/// input takes. A longer line is refused rather than read without bound.
pub const MAX_LINE_BYTES: usize = bite_core::yaml::MAX_FILE_BYTES;

/// Read line `line` of a record, at most `limit` bytes of it; `None` at the
/// end of the file. The text keeps its line break (none: a cut last line).
fn read_line(
    r: &mut impl BufRead,
    line: usize,
    limit: usize,
) -> Result<Option<String>, ReplayError> {
    let mut bytes = Vec::new();
    let cap = u64::try_from(limit).unwrap_or(u64::MAX).saturating_add(1);
    let n = std::io::Read::take(&mut *r, cap)
        .read_until(b'\n', &mut bytes)
        .map_err(|source| ReplayError::Io { line, source })?;
    if n == 0 {
        return Ok(None);
    }
    if bytes.len() > limit {
        return Err(ReplayError::TooLong { line, limit });
    }
    String::from_utf8(bytes)
        .map(Some)
        .map_err(|e| ReplayError::Malformed {
            line,
            what: format!("not UTF-8 text ({e})"),
        })
}

/// How a replay went.
#[derive(Debug)]
pub struct Replayed {
    /// Inputs fed.
    pub inputs: usize,
    /// The record ends in a cut line (the robot was killed while writing
    /// it); the inputs before it were replayed.
    pub truncated: bool,
    /// The first input whose outputs differ: its line, time, and the
    /// recorded and replayed fingerprints and output counts.
    pub first_difference: Option<Difference>,
}

/// An input whose outputs differ on replay.
#[derive(Debug)]
pub struct Difference {
    /// Line of the record (1-based).
    pub line: usize,
    /// The robot's clock, µs.
    pub t: u64,
    /// Recorded: outputs, fingerprint.
    pub recorded: (usize, String),
    /// Replayed: outputs, fingerprint, and their debug form.
    pub replayed: (usize, String, Vec<String>),
}

/// Read the header of a record.
pub fn header(r: &mut impl BufRead) -> Result<serde_json::Value, ReplayError> {
    header_within(r, MAX_LINE_BYTES)
}

/// [`header`], with a header line of at most `limit` bytes.
fn header_within(r: &mut impl BufRead, limit: usize) -> Result<serde_json::Value, ReplayError> {
    let first = read_line(r, 1, limit)?.unwrap_or_default();
    let v: serde_json::Value =
        serde_json::from_str(&first).map_err(|e| ReplayError::Malformed {
            line: 1,
            what: format!("not a record header: {e}"),
        })?;
    if v["bite_inputs"] != 1 {
        return Err(ReplayError::Malformed {
            line: 1,
            what: "not a record of a robot's inputs (no `bite_inputs: 1`)".into(),
        });
    }
    Ok(v["header"].clone())
}

/// Feed the inputs after the header to `agent` and compare what it
/// produces with the record.
pub fn replay(r: &mut impl BufRead, agent: &mut Agent) -> Result<Replayed, ReplayError> {
    let mut inputs = 0;
    let mut truncated = false;
    let mut line = 1;
    loop {
        line += 1;
        let Some(text) = read_line(r, line, MAX_LINE_BYTES)? else {
            break;
        };
        if !text.ends_with('\n') {
            // The robot was stopped (killed) while writing its last line.
            truncated = true;
            break;
        }
        if text.trim().is_empty() {
            continue;
        }
        let rec: Line = serde_json::from_str(&text).map_err(|e| ReplayError::Malformed {
            line,
            what: e.to_string(),
        })?;
        while agent.poll().is_some() {}
        agent.handle(Time(rec.t), rec.input.input());
        inputs += 1;
        let mut got = Vec::new();
        while let Some(o) = agent.poll() {
            got.push(o);
        }
        let fp = format!("{:016x}", fingerprint(&got));
        if fp != rec.fingerprint || got.len() != rec.outputs {
            return Ok(Replayed {
                inputs,
                truncated,
                first_difference: Some(Difference {
                    line,
                    t: rec.t,
                    recorded: (rec.outputs, rec.fingerprint),
                    replayed: (
                        got.len(),
                        fp,
                        got.iter().map(|o| format!("{o:?}")).collect(),
                    ),
                }),
            });
        }
    }
    Ok(Replayed {
        inputs,
        truncated,
        first_difference: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_endless_header_line_is_refused_at_the_cap() {
        // `/dev/zero`: bytes without end, never a line break.
        let mut r = std::io::BufReader::new(std::io::repeat(0));
        let e = header(&mut r).expect_err("no header in an endless line");
        assert!(
            matches!(e, ReplayError::TooLong { line: 1, limit } if limit == MAX_LINE_BYTES),
            "{e}"
        );
        assert!(e.to_string().contains("without a line break"), "{e}");
    }

    #[test]
    fn a_header_line_over_the_limit_is_refused_and_one_within_is_read() {
        let line = "{\"bite_inputs\":1,\"header\":{\"robot\":\"r0\"}}\n";
        let e = header_within(&mut line.as_bytes(), line.len() - 1).expect_err("too long");
        assert!(matches!(e, ReplayError::TooLong { line: 1, .. }), "{e}");
        let h = header_within(&mut line.as_bytes(), line.len()).expect("within");
        assert_eq!(h["robot"], "r0");
    }

    #[test]
    fn a_header_that_is_not_utf8_is_malformed() {
        let e = header(&mut &b"\xff\xfe\n"[..]).expect_err("not UTF-8");
        assert!(matches!(e, ReplayError::Malformed { line: 1, .. }), "{e}");
    }
}
