//! The run log: one JSON object per line, every kernel event with its time
//! and robot, ids replaced by names so that people and scripts can read it.
//!
//! ```text
//! {"t":0.0,"robot":"r0","event":"selected","behavior":"formation","team":"root","epoch":1,"depth":0,"via":"start"}
//! ```
//!
//! The first line describes the run (graph, configuration, scenario, seed,
//! team); the last line is the summary. The same graph, scenario and seed
//! give the same log, byte for byte.

use bite_core::event::Event;
use bite_core::graph::BehaviorGraph;
use bite_core::ids::{BehaviorId, Fnv1a, RobotId, TeamId};
use bite_core::time::Time;
use serde_json::{Map, Value as J};
use std::io::{self, Write};

/// Turns ids into names for the log.
#[derive(Clone, Copy)]
pub struct Namer<'g> {
    graph: &'g BehaviorGraph,
}

impl<'g> Namer<'g> {
    /// A namer for a graph (its behaviors and roster).
    pub fn new(graph: &'g BehaviorGraph) -> Self {
        Namer { graph }
    }
    /// A behavior's name.
    pub fn behavior(&self, b: BehaviorId) -> J {
        J::String(self.graph.name_of(b).to_string())
    }
    /// A robot's name.
    pub fn robot(&self, r: RobotId) -> J {
        J::String(self.graph.roster().name(r))
    }
    /// A team's short name.
    pub fn team(&self, t: TeamId) -> J {
        J::String(t.to_string())
    }

    fn rename(&self, key: &str, v: &mut J) {
        match (key, &mut *v) {
            ("behavior" | "choice" | "next", J::Number(n)) => {
                if let Some(i) = n.as_u64() {
                    *v = self.behavior(BehaviorId(i as u32));
                }
            }
            ("team", J::Number(n)) => {
                if let Some(i) = n.as_u64() {
                    *v = self.team(TeamId(i));
                }
            }
            ("members" | "excluded", J::Array(rs)) => {
                for r in rs {
                    self.rename("from", r);
                }
            }
            ("options", J::Array(bs)) => {
                for b in bs {
                    self.rename("behavior", b);
                }
            }
            ("from" | "member" | "winner", J::Number(n)) => {
                if let Some(i) = n.as_u64() {
                    *v = self.robot(RobotId(i as u32));
                }
            }
            ("assignment", J::Array(pairs)) => {
                for p in pairs {
                    if let J::Array(pair) = p
                        && let [b, members] = pair.as_mut_slice()
                    {
                        self.rename("behavior", b);
                        if let J::Array(ms) = members {
                            for m in ms {
                                self.rename("from", m);
                            }
                        }
                    }
                }
            }
            (_, J::Object(m)) => self.rename_all(m),
            _ => {}
        }
    }

    fn rename_all(&self, m: &mut Map<String, J>) {
        for (k, v) in m.iter_mut() {
            self.rename(k, v);
        }
    }

    /// One log record as JSON.
    pub fn record(&self, t: Time, robot: RobotId, e: &Event) -> J {
        let mut m = Map::new();
        m.insert("t".into(), J::from(t.as_secs_f64()));
        m.insert("robot".into(), self.robot(robot));
        if let Ok(J::Object(mut ev)) = serde_json::to_value(e) {
            self.rename_all(&mut ev);
            // `event` first, then its fields in declaration order.
            if let Some(kind) = ev.shift_remove("event") {
                m.insert("event".into(), kind);
            }
            m.extend(ev);
        }
        J::Object(m)
    }
}

/// Writes JSON lines and keeps a fingerprint of everything written.
pub struct RunLog<'w> {
    out: Option<&'w mut dyn Write>,
    hash: Fnv1a,
    lines: u64,
    error: Option<io::Error>,
}

impl<'w> RunLog<'w> {
    /// A log writing to `out`, or only fingerprinting when `None`.
    pub fn new(out: Option<&'w mut dyn Write>) -> Self {
        RunLog {
            out,
            hash: Fnv1a::new(),
            lines: 0,
            error: None,
        }
    }
    /// True when records are written somewhere.
    pub fn is_writing(&self) -> bool {
        self.out.is_some()
    }
    /// Write one record.
    pub fn write(&mut self, record: &J) {
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
