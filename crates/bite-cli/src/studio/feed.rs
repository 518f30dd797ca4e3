//! The records the monitor shows, and what each page is sent.
//!
//! One feed at a time: a run the studio started, a live Zenoh team, or a
//! run log opened for replay. The feed is the run-log records in order
//! (append-only until the next source); every page keeps its own
//! [`View`] at its own time over it, so a live run, a Zenoh team and a
//! replay are shown by the same code, and any of them can be scrubbed.

use bite_foxglove::View;
use serde_json::{Value as J, json};

/// Where the records come from.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Source {
    /// Nothing yet.
    None,
    /// A run the studio started.
    Run,
    /// A team over Zenoh.
    Zenoh,
    /// A run log.
    Replay,
}

/// Most records a growing feed (a run, a live team) keeps: past it, the
/// oldest quarter is dropped (counted in [`Dropped::oldest`]).
pub const MAX_RECORDS: usize = 200_000;
/// Most bytes of JSON a growing feed keeps (as for [`MAX_RECORDS`]).
pub const MAX_BYTES: usize = 64 << 20;
/// Largest record taken from a live team (bytes of JSON): a robot's
/// records are far smaller; larger ones are dropped ([`Dropped::oversize`]).
pub const MAX_RECORD_BYTES: usize = 256 << 10;
/// Records dropped from the front that pages starting over still apply
/// (the world's layout, the run's start), at most.
const PINNED: usize = 64;

/// What a feed did not keep, by reason (sent with every snapshot).
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Dropped {
    /// Records larger than [`MAX_RECORD_BYTES`].
    pub oversize: u64,
    /// The oldest records, dropped to stay within [`MAX_RECORDS`] and
    /// [`MAX_BYTES`].
    pub oldest: u64,
    /// Records of robots not on the team's roster.
    pub not_on_roster: u64,
    /// Payloads that are not a JSON object.
    pub garbage: u64,
}

impl Dropped {
    fn any(&self) -> bool {
        *self != Dropped::default()
    }
}

/// Why a live team's payload is not a record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refused {
    /// Larger than [`MAX_RECORD_BYTES`].
    Oversize,
    /// Not a JSON object.
    Garbage,
}

/// A live team's payload as a record (`status`: a robot's status, made a
/// record), parsed out of the feed's lock.
pub fn live_record(bytes: &[u8], status: bool) -> Result<J, Refused> {
    if bytes.len() > MAX_RECORD_BYTES {
        return Err(Refused::Oversize);
    }
    let mut rec = match serde_json::from_slice::<J>(bytes) {
        Ok(r @ J::Object(_)) => r,
        _ => return Err(Refused::Garbage),
    };
    if status {
        rec["event"] = json!("status");
    }
    Ok(rec)
}

/// The current source's records.
pub struct Feed {
    /// Bumped at every new source: pages start over.
    pub generation: u64,
    /// Bumped at every change (a record, the end of a run): pages are sent
    /// a snapshot.
    pub version: u64,
    /// Where the records come from.
    pub source: Source,
    /// What it is (`bite run formation`, `team bite on tcp/...`, a file).
    pub label: String,
    /// Still growing.
    pub live: bool,
    /// The records, in order (after the [`Feed::first`] dropped).
    pub records: Vec<J>,
    /// Records dropped from the front (the oldest): the index, among all
    /// the source's records, of `records[0]`.
    pub first: usize,
    /// The layout and start records among those dropped.
    pub pinned: Vec<J>,
    /// Bytes of JSON of `records` (of those pushed).
    bytes: usize,
    /// What was not kept.
    pub dropped: Dropped,
    /// The team's roster, once known (a live team: from the world's layout
    /// or a robot's membership answer): records of other robots are not
    /// kept. Set through [`Feed::set_roster`].
    pub roster: Option<Vec<String>>,
    /// Times kept records were taken out from among the others (those of
    /// robots off a roster learned late): a page that sees it change
    /// rebuilds its view from the start.
    pub purges: u64,
    /// How a run the studio started ended (outcome, exit code, log path,
    /// violations), once it has.
    pub ended: Option<J>,
    /// Lines of a replayed log that were not records (`file:line:col:
    /// why`), the first 20.
    pub problems: Vec<String>,
    /// Tells the pages' monitors that something changed (the version).
    changed: tokio::sync::watch::Sender<u64>,
}

impl Feed {
    /// No source.
    pub fn new() -> Self {
        Feed {
            generation: 0,
            version: 0,
            source: Source::None,
            label: String::new(),
            live: false,
            records: Vec::new(),
            first: 0,
            pinned: Vec::new(),
            bytes: 0,
            dropped: Dropped::default(),
            roster: None,
            purges: 0,
            ended: None,
            problems: Vec::new(),
            changed: tokio::sync::watch::Sender::new(0),
        }
    }

    /// Something changed: the pages are told.
    pub fn touch(&mut self) {
        self.version += 1;
        self.changed.send_replace(self.version);
    }

    /// Be told when something changes.
    pub fn subscribe(&self) -> tokio::sync::watch::Receiver<u64> {
        self.changed.subscribe()
    }

    /// Start over with a new source.
    pub fn reset(&mut self, source: Source, label: String, live: bool) {
        self.generation += 1;
        self.source = source;
        self.label = label;
        self.live = live;
        self.records.clear();
        self.first = 0;
        self.pinned.clear();
        self.bytes = 0;
        self.dropped = Dropped::default();
        self.roster = None;
        self.ended = None;
        self.problems.clear();
        self.touch();
    }

    /// Add a record; the oldest quarter goes when the feed holds more
    /// than [`MAX_RECORDS`] or [`MAX_BYTES`]. Its size is counted as it is
    /// written out ([`json_len`]), the measure its dropping subtracts: a
    /// payload's own length (its spacing, its escapes) would make the
    /// count drift.
    pub fn push(&mut self, rec: J) {
        let len = json_len(&rec);
        self.records.push(rec);
        self.bytes = self.bytes.saturating_add(len);
        if self.records.len() > MAX_RECORDS || self.bytes > MAX_BYTES {
            self.drop_oldest();
        }
        self.touch();
    }

    /// A record from a live team ([`live_record`] of its payload): kept
    /// if it is one, of a robot on the roster (when the roster is known);
    /// counted otherwise.
    pub fn push_live(&mut self, rec: Result<J, Refused>) {
        let rec = match rec {
            Ok(r) => r,
            Err(Refused::Oversize) => {
                self.dropped.oversize += 1;
                return self.touch();
            }
            Err(Refused::Garbage) => {
                self.dropped.garbage += 1;
                return self.touch();
            }
        };
        if let Some(roster) = &self.roster
            && !on_roster(roster, &rec)
        {
            self.dropped.not_on_roster += 1;
            return self.touch();
        }
        if rec["event"] == "world"
            && let Some(names) = rec["robots"].as_array()
        {
            let names: Vec<String> = names
                .iter()
                .filter_map(|n| n.as_str().map(String::from))
                .collect();
            if !names.is_empty() {
                self.set_roster(names);
            }
        }
        self.push(rec);
    }

    /// The team's roster is known: records kept before it of robots off it
    /// (anyone could publish them: a forged status, a stray team's) are
    /// taken out and counted as [`Dropped::not_on_roster`], and pages
    /// rebuild their views without them.
    pub fn set_roster(&mut self, names: Vec<String>) {
        let on = |r: &J| on_roster(&names, r);
        let before = self.records.len() + self.pinned.len();
        self.records.retain(on);
        self.pinned.retain(on);
        let gone = before - self.records.len() - self.pinned.len();
        self.roster = Some(names);
        if gone > 0 {
            self.dropped.not_on_roster += gone as u64;
            self.bytes = self.records.iter().map(json_len).sum();
            self.purges += 1;
        }
        self.touch();
    }

    fn drop_oldest(&mut self) {
        let n = (self.records.len() / 4).max(1);
        for r in self.records.drain(..n) {
            self.bytes = self.bytes.saturating_sub(json_len(&r));
            let e = r["event"].as_str().unwrap_or("");
            if matches!(e, "world" | "run_started" | "server_started") {
                if self.pinned.len() >= PINNED {
                    self.pinned.remove(0);
                }
                self.pinned.push(r);
            }
        }
        self.first += n;
        self.dropped.oldest += n as u64;
    }

    /// Record `i` of the source (counting those dropped), if kept.
    pub fn get(&self, i: usize) -> Option<&J> {
        i.checked_sub(self.first).and_then(|k| self.records.get(k))
    }

    /// The time of the last record, s.
    pub fn end_time(&self) -> f64 {
        self.records
            .iter()
            .rev()
            .find_map(|r| r["t"].as_f64())
            .unwrap_or(0.0)
    }
}

/// True when `rec` is of no robot (the world's layout, the run's start)
/// or of a robot on `roster`.
fn on_roster(roster: &[String], rec: &J) -> bool {
    rec.get("robot").is_none_or(|robot| {
        robot
            .as_str()
            .is_some_and(|n| roster.iter().any(|m| m == n))
    })
}

/// Parse a run log (JSON lines) as `bite log convert` reads one; lines
/// that are not records are reported (`file:line:col: why`, the first 20)
/// and skipped, and the records put in time order (several processes'
/// logs concatenated).
pub fn parse_log(name: &str, text: &str) -> Parsed {
    let (records, bad, torn) = bite_foxglove::read_records_torn(name, text);
    Parsed {
        records: bite_foxglove::merge(vec![records]),
        problems: bad.iter().take(20).map(|e| e.to_string()).collect(),
        bad: bad.len(),
        torn,
    }
}

/// A run log read for replay.
#[derive(Debug, Default)]
pub struct Parsed {
    /// Its records, in time order.
    pub records: Vec<J>,
    /// The first 20 lines that are not records (`file:line:col: why`).
    pub problems: Vec<String>,
    /// Lines that are not records.
    pub bad: usize,
    /// Its last line was a record cut short (no newline after it: a log
    /// being written, or a process killed mid-write), skipped.
    pub torn: bool,
}

/// Records a page applies per snapshot at most.
pub const BATCH: usize = 20_000;

/// Seconds after which a decision some participant never logged (it
/// crashed, or lost the instance) is not sent again.
const DECISION_SETTLES: f64 = 30.0;

/// One page's place in the feed.
pub struct Cursor {
    generation: u64,
    /// The feed's [`Feed::purges`] the view was built after.
    purges: u64,
    /// Records applied to the view.
    applied: usize,
    /// The feed's version last seen.
    version: u64,
    /// The view at the page's time.
    pub view: View,
    /// `None`: follow the feed; `Some(t)`: show the run at time `t`.
    pub at: Option<f64>,
    trail_sent: Vec<usize>,
    decisions_sent: usize,
    layout_sent: bool,
    /// The page must drop what it has (a new feed, or back in time).
    fresh: bool,
    /// Something changed since the last snapshot.
    pub dirty: bool,
}

impl Cursor {
    /// At the start of no feed.
    pub fn new() -> Self {
        Cursor {
            generation: u64::MAX,
            purges: 0,
            applied: 0,
            version: u64::MAX,
            view: View::new(),
            at: None,
            trail_sent: Vec::new(),
            decisions_sent: 0,
            layout_sent: false,
            fresh: true,
            dirty: true,
        }
    }

    fn restart(&mut self, generation: u64) {
        self.generation = generation;
        self.applied = 0;
        self.view = View::new();
        self.trail_sent.clear();
        self.decisions_sent = 0;
        self.layout_sent = false;
        self.fresh = true;
        self.dirty = true;
    }

    /// Move to time `t` (`None`: follow the live end).
    pub fn seek(&mut self, t: Option<f64>) {
        if let Some(t) = t
            && t < self.view.t
        {
            // Back in time: start over and apply up to `t`.
            self.restart(self.generation);
        }
        self.at = t;
        self.dirty = true;
    }

    /// Records of the feed the page has still to apply (up to its time).
    pub fn behind(&self, feed: &Feed) -> bool {
        feed.generation == self.generation
            && (self.applied < feed.first
                || feed.get(self.applied).is_some_and(|r| {
                    self.at
                        .is_none_or(|at| r["t"].as_f64().unwrap_or(0.0) <= at + 1e-9)
                }))
    }

    /// Apply the feed's records up to the page's time, at most
    /// [`BATCH`] of them (the rest at the next call: a long rebuild never
    /// holds the feed for long).
    pub fn catch_up(&mut self, feed: &Feed) {
        if feed.generation != self.generation {
            self.restart(feed.generation);
            self.purges = feed.purges;
            self.at = None;
        }
        if feed.purges != self.purges {
            // Records it applied were taken out: start over, at the same
            // time.
            self.restart(feed.generation);
            self.purges = feed.purges;
        }
        if feed.version != self.version {
            self.version = feed.version;
            self.dirty = true;
        }
        if self.applied < feed.first {
            // Records dropped before this page applied them: a page that
            // starts over takes the layout and the start from them.
            if self.applied == 0 {
                for r in &feed.pinned {
                    self.view.apply(r);
                }
            }
            self.applied = feed.first;
            self.dirty = true;
        }
        let until = self.applied.saturating_add(BATCH);
        while self.applied < until
            && let Some(r) = feed.get(self.applied)
        {
            if let Some(at) = self.at
                && r["t"].as_f64().unwrap_or(0.0) > at + 1e-9
            {
                break;
            }
            self.view.apply(r);
            self.applied += 1;
            self.dirty = true;
        }
    }

    /// What the page is sent: the whole state but trails and decisions,
    /// which are sent as they grow (`reset`: drop what you have).
    pub fn snapshot(&mut self, feed: &Feed) -> J {
        let v = &self.view;
        let reset = std::mem::take(&mut self.fresh);
        let robots: Vec<J> = v
            .names
            .iter()
            .zip(&v.robots)
            .map(|(name, r)| {
                let leaf = r.stack.last().map(|f| f.behavior.as_str());
                json!({
                    "name": name,
                    "stack": r.stack.iter().map(|f| [&f.behavior, &f.team]).collect::<Vec<_>>(),
                    "pose": r.pose.map(|p| [round3(p.x), round3(p.y), round3(p.heading)]),
                    "colour": v.behavior_colour(r.moving_as.as_deref().or(leaf)),
                    "moving_as": r.moving_as,
                    "link": r.link,
                    "lost": r.lost,
                    "completed": r.completed,
                    "crashed": r.crashed,
                    "beliefs": r.beliefs,
                    "informs": r.informs,
                    "auth": r.auth,
                    "phase": r.phase,
                })
            })
            .collect();
        self.trail_sent.resize(v.robots.len(), 0);
        let trails: Vec<J> = v
            .robots
            .iter()
            .zip(self.trail_sent.iter_mut())
            .enumerate()
            .filter(|(_, (r, sent))| r.trail.len() > **sent)
            .map(|(i, (r, sent))| {
                let pts: Vec<J> = r.trail[*sent..]
                    .iter()
                    .map(|p| {
                        json!([
                            round3(p.x),
                            round3(p.y),
                            v.behavior_colour(p.behavior.as_deref())
                        ])
                    })
                    .collect();
                *sent = r.trail.len();
                json!([i, pts])
            })
            .collect();
        let decisions: Vec<J> = v.decisions[self.decisions_sent..]
            .iter()
            .filter_map(|d| {
                let i = v.instances.get(&d.key)?;
                let outcomes: Vec<&J> = i.decided.iter().map(|(_, o)| o).collect();
                let agree = outcomes.windows(2).all(|w| w[0] == w[1]);
                Some(json!({
                    "key": d.key, "t": d.t, "point": i.point, "team": i.team,
                    "epoch": i.epoch, "round": i.round, "protocol": i.protocol,
                    "outcome": outcomes.first(), "agree": agree, "robots": i.decided.len(),
                    "waiting": i.waiting, "timed_out": i.timed_out,
                    "sent": i.sent, "received": i.received, "bytes": i.bytes,
                }))
            })
            .collect();
        // Decisions some participant has still to log are sent again
        // (for a while: one that never will does not hold the rest back).
        self.decisions_sent = v.decisions[self.decisions_sent..]
            .iter()
            .position(|d| {
                v.t - d.t < DECISION_SETTLES
                    && v.instances
                        .get(&d.key)
                        .is_some_and(|i| !i.waiting.is_empty())
            })
            .map_or(v.decisions.len(), |k| self.decisions_sent + k);
        let in_flight: Vec<J> = v
            .in_flight()
            .map(|(k, i)| {
                json!({"key": k, "point": i.point, "team": i.team, "protocol": i.protocol,
                       "started": i.started, "waiting": i.waiting, "decided": i.decided.len(),
                       "sent": i.sent, "received": i.received})
            })
            .collect();
        let layout = if self.layout_sent {
            J::Null
        } else {
            v.layout.clone().unwrap_or(J::Null)
        };
        if v.layout.is_some() {
            self.layout_sent = true;
        }
        self.dirty = false;
        json!({
            "type": "snapshot",
            "generation": feed.generation,
            "source": feed.source,
            "label": feed.label,
            "live": feed.live,
            "end": feed.end_time(),
            "at": self.at,
            "t": v.t,
            "records": v.records,
            "reset": reset,
            "robots": robots,
            "objects": v.objects,
            "layout": layout,
            "trails": trails,
            "decisions": decisions,
            "in_flight": in_flight,
            "summary": v.summary,
            "ended": feed.ended,
            "problems": feed.problems,
            "dropped": feed.dropped.any().then_some(&feed.dropped),
        })
    }
}

/// Bytes of a record's JSON text.
fn json_len(rec: &J) -> usize {
    struct Count(usize);
    impl std::io::Write for Count {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            self.0 += b.len();
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
    let mut c = Count(0);
    let _ = serde_json::to_writer(&mut c, rec);
    c.0
}

fn round3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feed_of(lines: &str) -> Feed {
        let mut f = Feed::new();
        f.reset(Source::Replay, "test".into(), false);
        let p = parse_log("test.jsonl", lines);
        f.records = p.records;
        f.problems = p.problems;
        f
    }

    const LOG: &str = r##"{"t":0.0,"event":"run_started","robots":1}
{"t":0.0,"event":"world","robots":["r0"],"behaviors":["walk"],"palette":["#ff0000"]}
{"t":0.0,"robot":"r0","event":"selected","behavior":"walk","team":"root","depth":0}
{"t":0.0,"event":"poses","robots":[[0.0,0.0,0.0]],"behaviors":["walk"],"links":[null]}
{"t":1.0,"event":"poses","robots":[[1.0,0.0,0.0]],"behaviors":["walk"],"links":[null]}
not json
{"t":2.0,"event":"poses","robots":[[2.0,0.0,0.0]],"behaviors":["walk"],"links":[null]}
"##;

    #[test]
    fn a_bad_line_is_named_and_skipped() {
        let f = feed_of(LOG);
        assert_eq!(f.records.len(), 6);
        assert_eq!(f.problems.len(), 1);
        assert!(
            f.problems[0].starts_with("test.jsonl:6:"),
            "{:?}",
            f.problems
        );
    }

    #[test]
    fn a_last_line_without_a_newline_is_torn_only_when_it_is_a_record_cut_short() {
        let p = parse_log("up.jsonl", "not json");
        assert_eq!((p.records.len(), p.bad, p.torn), (0, 1, false));
        let p = parse_log("up.jsonl", "{\"t\":0.0,\"event\":\"x\"}\n{\"t\":1.0,\"ev");
        assert_eq!((p.records.len(), p.bad, p.torn), (1, 0, true));
        let p = parse_log("up.jsonl", "{\"t\":0.0,\"event\":\"x\"}\n");
        assert_eq!((p.records.len(), p.bad, p.torn), (1, 0, false));
        // Cut short but with its newline: written whole, malformed.
        let p = parse_log("up.jsonl", "{\"t\":1.0,\"ev\n");
        assert_eq!((p.records.len(), p.bad, p.torn), (0, 1, false));
    }

    #[test]
    fn seeking_moves_the_robots_and_back_again() {
        let f = feed_of(LOG);
        let mut c = Cursor::new();
        c.catch_up(&f);
        let s = c.snapshot(&f);
        assert_eq!(s["robots"][0]["pose"][0], 2.0);
        assert_eq!(s["robots"][0]["colour"], "#ff0000");
        c.seek(Some(1.0));
        c.catch_up(&f);
        let s = c.snapshot(&f);
        assert_eq!(s["robots"][0]["pose"][0], 1.0);
        assert_eq!(s["reset"], true, "going back resends the trails");
        c.seek(Some(0.5));
        c.catch_up(&f);
        assert_eq!(c.snapshot(&f)["robots"][0]["pose"][0], 0.0);
        c.seek(None);
        c.catch_up(&f);
        assert_eq!(c.snapshot(&f)["robots"][0]["pose"][0], 2.0);
    }

    #[test]
    fn a_live_feed_keeps_what_is_bounded_and_counts_the_rest() {
        let mut f = Feed::new();
        f.reset(Source::Zenoh, "team".into(), true);
        let live = |f: &mut Feed, b: &[u8], status: bool| {
            f.push_live(live_record(b, status));
        };
        // Garbage, and a record too large.
        live(&mut f, b"not json", false);
        live(&mut f, b"[1, 2]", false);
        let big = format!(
            r#"{{"t":1.0,"robot":"r0","event":"x","pad":"{}"}}"#,
            "a".repeat(MAX_RECORD_BYTES)
        );
        live(&mut f, big.as_bytes(), false);
        assert_eq!(f.records.len(), 0);
        assert_eq!(f.dropped.garbage, 2);
        assert_eq!(f.dropped.oversize, 1);
        // Before the roster is known, any robot; once it is, only its
        // members, and what was kept of others is taken out: a page that
        // showed a forged robot shows it no more.
        live(&mut f, br#"{"t":0.5,"robot":"r9","event":"x"}"#, false);
        live(&mut f, br#"{"robot":"r8","state":"running"}"#, true);
        live(&mut f, br#"{"robot":"r0","state":"running"}"#, true);
        let mut c = Cursor::new();
        c.catch_up(&f);
        let s = c.snapshot(&f);
        let shown = |s: &J| -> Vec<String> {
            (s["robots"].as_array().into_iter().flatten())
                .filter_map(|r| r["name"].as_str().map(String::from))
                .collect()
        };
        assert!(shown(&s).contains(&"r8".to_string()), "{s}");
        let world = br#"{"t":0.0,"event":"world","robots":["r0","r1","r2"]}"#;
        live(&mut f, world, false);
        assert_eq!(f.roster.as_deref().map(<[String]>::len), Some(3));
        assert_eq!(f.dropped.not_on_roster, 2);
        assert_eq!(f.records.len(), 2, "r0's status and the layout");
        live(&mut f, br#"{"robot":"r9","state":"running"}"#, true);
        live(&mut f, br#"{"robot":"r1","state":"running"}"#, true);
        assert_eq!(f.dropped.not_on_roster, 3);
        assert_eq!(f.records.len(), 3);
        assert_eq!(f.records[2]["event"], "status");
        c.catch_up(&f);
        let s = c.snapshot(&f);
        assert_eq!(s["reset"], true, "the page drops what it has: {s}");
        assert!(!shown(&s).iter().any(|n| n == "r8" || n == "r9"), "{s}");
        assert!(shown(&s).contains(&"r0".to_string()), "{s}");
        let kept: usize = f.records.iter().map(json_len).sum();
        assert_eq!(f.bytes, kept);
        assert_eq!(s["dropped"]["not_on_roster"], 3, "{s}");
        assert_eq!(s["dropped"]["garbage"], 2, "{s}");
        // A new source starts its counts again.
        f.reset(Source::Zenoh, "team".into(), true);
        assert_eq!(f.dropped, Dropped::default());
        assert!(f.roster.is_none());
        // Records sent spaced out are counted as kept, not as sent: the
        // count is what dropping them takes off again.
        let spaced = format!(
            "{{ \"t\" : 1.0 ,  \"robot\" : \"r0\" , \"event\" : \"x\", \"pad\": \"{}\" }}{}",
            "b".repeat(4000),
            " ".repeat(500)
        );
        for _ in 0..(MAX_BYTES / 4000 + 100) {
            live(&mut f, spaced.as_bytes(), false);
        }
        assert!(f.dropped.oldest > 0);
        let kept: usize = f.records.iter().map(json_len).sum();
        assert_eq!(f.bytes, kept);
    }

    #[test]
    fn a_growing_feed_drops_its_oldest_records_and_pages_keep_the_layout() {
        let mut f = Feed::new();
        f.reset(Source::Run, "run".into(), true);
        f.push(json!({"t":0.0,"event":"world","robots":["r0"],"behaviors":["walk"],"palette":["#ff0000"]}));
        let pad = "x".repeat(1000);
        let mut follower = Cursor::new();
        for k in 0..(MAX_BYTES / 1000 + 10) {
            f.push(json!({"t": k as f64 * 0.01, "event":"poses","robots":[[k as f64, 0.0, 0.0]],"pad": pad}));
            if k % 10_000 == 0 {
                follower.catch_up(&f);
            }
        }
        assert!(f.bytes <= MAX_BYTES, "{} bytes kept", f.bytes);
        assert!(f.first > 0 && f.dropped.oldest == f.first as u64);
        assert_eq!(f.pinned.len(), 1, "the layout is kept aside");
        // A page that joins now sees the layout and the latest poses.
        let mut c = Cursor::new();
        while c.behind(&f) || c.generation != f.generation {
            c.catch_up(&f);
        }
        let s = c.snapshot(&f);
        assert!(s["layout"].is_object(), "{}", s["layout"]);
        let last = (MAX_BYTES / 1000 + 9) as f64;
        assert_eq!(s["robots"][0]["pose"][0], last);
        // A page that followed from the start goes on from where it is.
        while follower.behind(&f) {
            follower.catch_up(&f);
        }
        assert_eq!(follower.snapshot(&f)["robots"][0]["pose"][0], last);
        assert_eq!(follower.snapshot(&f)["dropped"]["oldest"], f.first);
    }

    #[test]
    fn trails_are_sent_as_they_grow() {
        let f = feed_of(LOG);
        let mut c = Cursor::new();
        // A page first follows the feed, then seeks.
        c.catch_up(&f);
        c.seek(Some(0.0));
        c.catch_up(&f);
        let s = c.snapshot(&f);
        assert_eq!(s["reset"], true);
        assert_eq!(s["trails"][0][1].as_array().map(|a| a.len()), Some(1));
        c.seek(Some(1.0));
        c.catch_up(&f);
        let s = c.snapshot(&f);
        assert_eq!(s["reset"], false);
        assert_eq!(
            s["trails"][0][1].as_array().map(|a| a.len()),
            Some(1),
            "only the new point"
        );
        assert!(s["layout"].is_null(), "the layout is sent once");
    }
}
