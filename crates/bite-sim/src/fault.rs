//! Faults as one-line specs, laid over a scenario: what `bite run --fault`
//! replays and what `bite sweep` generates for each fault class of the
//! reliability matrix (`../shared/RELIABILITY.md`, `docs/reliability.md`).
//!
//! | spec | fault |
//! |---|---|
//! | `loss=P` | each copy of a message is lost with probability `P` |
//! | `dup=P` | a message is delivered twice with probability `P` (three times with `P²`) |
//! | `jitter=DUR` | each copy is delayed by up to `DUR` more (reorders messages) |
//! | `partition=A,B\|C@FROM+LEN` | robots in different groups cannot talk from `FROM` for `LEN` |
//! | `oneway=A>B,C@FROM+LEN` | messages from `A` to `B` and `C` are dropped (the other way works) |
//! | `hold=FROM+LEN` | every message sent in the window is held, then delivered as a burst |
//! | `pause=R@FROM+LEN` | robot `R` stops (no ticks, messages, timers) and resumes with its state |
//! | `crash=R@AT` | robot `R` stops for good |
//! | `restart=R@AT+DOWN` | robot `R` stops, and its process restarts `DOWN` later with a fresh mind that rejoins the team where it is |
//! | `skew=R:RATE[:OFFSET]` | robot `R`'s clock runs `RATE` times as fast and `OFFSET` ahead |
//! | `inject=EVERY` | every `EVERY`, a forged, replayed or malformed message reaches a random robot |
//!
//! Robots are named as in the roster (`r0`) or by index. Durations as in
//! files (`250ms`, `2s`). Specs are separated by `;` when given as one
//! string.

use bite_agent::scenario::{Crash, PartitionRef, RobotRef, Scenario};
use bite_core::diag::Loc;
use bite_core::time::{Time, parse_duration};
use std::fmt;
use std::time::Duration;

/// One fault laid over a scenario.
#[derive(Clone, Debug, PartialEq)]
pub enum Fault {
    /// Uniform loss probability.
    Loss(f64),
    /// Duplication probability.
    Dup(f64),
    /// Extra jitter.
    Jitter(Duration),
    /// Symmetric partition: groups, start, length.
    Partition(Vec<Vec<String>>, Duration, Duration),
    /// One-way partition: senders, receivers, start, length.
    OneWay(Vec<String>, Vec<String>, Duration, Duration),
    /// Messages held and released as a burst: start, length.
    Hold(Duration, Duration),
    /// A robot paused: robot, start, length.
    Pause(String, Duration, Duration),
    /// A robot crashed for good: robot, time.
    Crash(String, Duration),
    /// A robot restarted with a fresh mind: robot, time, downtime.
    Restart(String, Duration, Duration),
    /// A robot's clock: robot, rate, offset (seconds, may be negative).
    Skew(String, f64, f64),
    /// Forged, replayed or malformed messages every period.
    Inject(Duration),
}

fn secs(d: Duration) -> String {
    let s = d.as_secs_f64();
    if (s * 1000.0).fract() == 0.0 && s < 1.0 {
        format!("{}ms", (s * 1000.0) as u64)
    } else {
        let t = format!("{s:.3}");
        format!("{}s", t.trim_end_matches('0').trim_end_matches('.'))
    }
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Fault::Loss(p) => write!(f, "loss={p}"),
            Fault::Dup(p) => write!(f, "dup={p}"),
            Fault::Jitter(d) => write!(f, "jitter={}", secs(*d)),
            Fault::Partition(g, at, len) => write!(
                f,
                "partition={}@{}+{}",
                g.iter().map(|g| g.join(",")).collect::<Vec<_>>().join("|"),
                secs(*at),
                secs(*len)
            ),
            Fault::OneWay(a, b, at, len) => {
                write!(
                    f,
                    "oneway={}>{}@{}+{}",
                    a.join(","),
                    b.join(","),
                    secs(*at),
                    secs(*len)
                )
            }
            Fault::Hold(at, len) => write!(f, "hold={}+{}", secs(*at), secs(*len)),
            Fault::Pause(r, at, len) => write!(f, "pause={r}@{}+{}", secs(*at), secs(*len)),
            Fault::Crash(r, at) => write!(f, "crash={r}@{}", secs(*at)),
            Fault::Restart(r, at, down) => write!(f, "restart={r}@{}+{}", secs(*at), secs(*down)),
            Fault::Skew(r, rate, off) => write!(f, "skew={r}:{rate}:{off}s"),
            Fault::Inject(d) => write!(f, "inject={}", secs(*d)),
        }
    }
}

fn prob(v: &str) -> Result<f64, String> {
    let p: f64 = v
        .parse()
        .map_err(|_| format!("`{v}` is not a probability (0 to 1)"))?;
    if (0.0..=1.0).contains(&p) {
        Ok(p)
    } else {
        Err(format!("`{v}` is not a probability (0 to 1)"))
    }
}

fn dur(v: &str) -> Result<Duration, String> {
    parse_duration(v)
}

/// `FROM+LEN`.
fn window(v: &str) -> Result<(Duration, Duration), String> {
    let (a, b) = v
        .split_once('+')
        .ok_or_else(|| format!("`{v}`: expected FROM+LENGTH, e.g. `10s+5s`"))?;
    Ok((dur(a)?, dur(b)?))
}

fn robots(v: &str) -> Result<Vec<String>, String> {
    let rs: Vec<String> = v
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(str::to_string)
        .collect();
    if rs.is_empty() {
        return Err(format!("`{v}`: expected robot names, e.g. `r0,r1`"));
    }
    Ok(rs)
}

/// `WHO@REST`.
fn at<'a>(v: &'a str, what: &str) -> Result<(&'a str, &'a str), String> {
    v.split_once('@')
        .ok_or_else(|| format!("`{v}`: expected {what}@TIME"))
}

impl Fault {
    /// Parse one spec (see the module documentation).
    pub fn parse(spec: &str) -> Result<Fault, String> {
        let spec = spec.trim();
        let (kind, v) = spec
            .split_once('=')
            .ok_or_else(|| format!("`{spec}`: expected KIND=VALUE, e.g. `loss=0.2`"))?;
        let v = v.trim();
        Ok(match kind.trim() {
            "loss" => Fault::Loss(prob(v)?),
            "dup" => Fault::Dup(prob(v)?),
            "jitter" => Fault::Jitter(dur(v)?),
            "partition" => {
                let (groups, w) = at(v, "GROUP|GROUP")?;
                let groups = groups
                    .split('|')
                    .map(robots)
                    .collect::<Result<Vec<_>, _>>()?;
                let (a, l) = window(w)?;
                Fault::Partition(groups, a, l)
            }
            "oneway" => {
                let (who, w) = at(v, "FROM>TO")?;
                let (a, b) = who
                    .split_once('>')
                    .ok_or_else(|| format!("`{who}`: expected SENDERS>RECEIVERS"))?;
                let (s, l) = window(w)?;
                Fault::OneWay(robots(a)?, robots(b)?, s, l)
            }
            "hold" => {
                let (a, l) = window(v)?;
                Fault::Hold(a, l)
            }
            "pause" => {
                let (r, w) = at(v, "ROBOT")?;
                let (a, l) = window(w)?;
                Fault::Pause(r.trim().to_string(), a, l)
            }
            "crash" => {
                let (r, t) = at(v, "ROBOT")?;
                Fault::Crash(r.trim().to_string(), dur(t)?)
            }
            "restart" => {
                let (r, w) = at(v, "ROBOT")?;
                let (a, l) = window(w)?;
                Fault::Restart(r.trim().to_string(), a, l)
            }
            "skew" => {
                let parts: Vec<&str> = v.split(':').collect();
                let (r, rate, off) = match parts.as_slice() {
                    [r, rate] => (*r, *rate, "0s"),
                    [r, rate, off] => (*r, *rate, *off),
                    _ => return Err(format!("`{v}`: expected ROBOT:RATE[:OFFSET]")),
                };
                let rate: f64 = rate
                    .parse()
                    .ok()
                    .filter(|x: &f64| x.is_finite() && *x > 0.0 && *x <= 100.0)
                    .ok_or_else(|| format!("`{rate}`: a clock rate is a positive number"))?;
                let (neg, off) = match off.strip_prefix('-') {
                    Some(o) => (true, o),
                    None => (false, off),
                };
                // To the microsecond, as every time in a run.
                let off = (dur(off)?.as_secs_f64() * 1e6).round() / 1e6;
                Fault::Skew(r.trim().to_string(), rate, if neg { -off } else { off })
            }
            "inject" => Fault::Inject(dur(v)?.max(Duration::from_millis(1))),
            other => {
                return Err(format!(
                    "unknown fault `{other}`: one of loss, dup, jitter, partition, oneway, hold, pause, crash, restart, skew, inject"
                ));
            }
        })
    }

    /// Parse specs separated by `;`.
    pub fn parse_all(specs: &str) -> Result<Vec<Fault>, String> {
        specs
            .split(';')
            .filter(|s| !s.trim().is_empty())
            .map(Fault::parse)
            .collect()
    }

    /// Lay this fault over `s`.
    pub fn apply(&self, s: &mut Scenario) {
        let name = |r: &str| match r.parse::<u64>() {
            Ok(i) => RobotRef::Index(i),
            Err(_) => RobotRef::Name(r.to_string()),
        };
        let names = |rs: &[String]| rs.iter().map(|r| name(r)).collect::<Vec<_>>();
        let t = |d: Duration| Time::ZERO + d;
        match self {
            Fault::Loss(p) => s.network.loss = *p,
            Fault::Dup(p) => s.network.duplicate = *p,
            Fault::Jitter(d) => s.network.jitter = *d,
            Fault::Partition(groups, at, len) => s.partitions.push(PartitionRef {
                from: t(*at),
                until: t(*at + *len),
                groups: Some(groups.iter().map(|g| names(g)).collect()),
                one_way: None,
                loc: Loc::UNKNOWN,
            }),
            Fault::OneWay(a, b, at, len) => s.partitions.push(PartitionRef {
                from: t(*at),
                until: t(*at + *len),
                groups: None,
                one_way: Some((names(a), names(b))),
                loc: Loc::UNKNOWN,
            }),
            Fault::Hold(at, len) => s.network.holds.push((t(*at), t(*at + *len))),
            Fault::Pause(r, at, len) => s.crashes.push(Crash {
                robot: name(r),
                at: t(*at),
                until: Some(t(*at + *len)),
                restart: false,
                loc: Loc::UNKNOWN,
            }),
            Fault::Crash(r, at) => s.crashes.push(Crash {
                robot: name(r),
                at: t(*at),
                until: None,
                restart: false,
                loc: Loc::UNKNOWN,
            }),
            Fault::Restart(r, at, down) => s.crashes.push(Crash {
                robot: name(r),
                at: t(*at),
                until: Some(t(*at + *down)),
                restart: true,
                loc: Loc::UNKNOWN,
            }),
            Fault::Skew(r, rate, off) => s.clocks.push((name(r), *rate, *off, Loc::UNKNOWN)),
            Fault::Inject(every) => s.inject = Some(*every),
        }
    }
}

/// Lay faults over a scenario; the scenario's name says so.
pub fn apply_all(s: &Scenario, faults: &[Fault]) -> Scenario {
    let mut out = s.clone();
    for f in faults {
        f.apply(&mut out);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_round_trip_through_their_text() {
        for spec in [
            "loss=0.2",
            "dup=0.3",
            "jitter=200ms",
            "partition=r0|r1,r2@10s+15s",
            "oneway=r0>r1,r2@5s+3.5s",
            "hold=12s+2s",
            "pause=r1@12s+5s",
            "crash=r2@20s",
            "restart=r1@15s+2s",
            "skew=r1:1.1:2s",
            "skew=r2:0.5:-1.5s",
            "inject=200ms",
        ] {
            let f = Fault::parse(spec).unwrap_or_else(|e| panic!("{spec}: {e}"));
            assert_eq!(f.to_string(), spec);
            assert_eq!(Fault::parse(&f.to_string()), Ok(f));
        }
    }

    #[test]
    fn bad_specs_say_what_was_expected() {
        for (spec, want) in [
            ("loss=2", "probability"),
            ("loss", "KIND=VALUE"),
            ("warp=1", "unknown fault"),
            ("partition=r0|r1@10s", "FROM+LENGTH"),
            ("oneway=r0@1s+1s", "SENDERS>RECEIVERS"),
            ("skew=r1:-1", "positive"),
            ("crash=r1", "ROBOT@TIME"),
            ("jitter=fast", "duration"),
        ] {
            let e = Fault::parse(spec).expect_err(spec);
            assert!(e.contains(want), "{spec}: {e}");
        }
    }
}
