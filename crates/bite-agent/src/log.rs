//! Run-log records: a kernel event as one JSON object, ids replaced by
//! names so that people and scripts can read it, and back (for the
//! invariant checker). Every runtime writes the same records: the
//! simulator's run log (`bite_sim::log::RunLog`) and a robot process's.
//!
//! ```text
//! {"t":0.0,"robot":"r0","event":"selected","behavior":"formation","team":"root","epoch":1,"depth":0,"via":"start"}
//! ```

use bite_core::event::Event;
use bite_core::graph::BehaviorGraph;
use bite_core::ids::{BehaviorId, RobotId, TeamId};
use bite_core::mission::Mission;
use bite_core::msg::InstanceKey;
use bite_core::time::Time;
use serde_json::{Map, Value as J};

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

impl Namer<'_> {
    /// A `message` record: robot `from` sent `env` to `to` (a team
    /// multicast lists its members but the sender), `bytes` on the wire.
    /// Written with `bite run --log-messages`, to trace a conversation.
    pub fn message(
        &self,
        t: Time,
        from: RobotId,
        to: &bite_core::interaction::Recipients,
        env: &bite_core::msg::Envelope,
        bytes: u32,
    ) -> J {
        use bite_core::interaction::Recipients;
        let to: Vec<J> = match to {
            Recipients::One(r) => vec![self.robot(*r)],
            Recipients::Team(set) => set
                .iter()
                .filter(|r| *r != from)
                .map(|r| self.robot(r))
                .collect(),
        };
        let mut instance = serde_json::to_value(env.instance).unwrap_or(J::Null);
        if let J::Object(m) = &mut instance {
            self.rename_all(m);
        }
        serde_json::json!({
            "t": t.as_secs_f64(),
            "robot": self.robot(from),
            "event": "message",
            "to": to,
            "instance": instance,
            "seq": env.seq,
            "body": env.body.name(),
            "bytes": bytes,
        })
    }

    /// The reverse of [`Namer::record`] for the events the invariant
    /// checker reads (selections, terminations, protocol instances,
    /// lost and returning teammates), so that the logs of a team that ran
    /// as separate processes are checked like a simulated run
    /// (`bite_sim::check::check_logs`). `None` for other records, and for
    /// records that do not name this graph's behaviors and robots.
    ///
    /// Team ids are logged shortened (`t1234abcd`); they come back as a
    /// stand-in id that is equal exactly when the short names are, which
    /// is all the checker compares.
    pub fn unrecord(&self, mission: &Mission, rec: &J) -> Option<(Time, RobotId, Event)> {
        let t = Time::from_secs_f64(rec.get("t")?.as_f64()?.max(0.0));
        let robot = self.graph.roster().find(rec.get("robot")?.as_str()?)?;
        let kind = rec.get("event")?.as_str()?;
        let mut ev = rec.as_object()?.clone();
        for (k, v) in ev.iter_mut() {
            if !self.unname(k, v) {
                return None;
            }
        }
        fn field<T: serde::de::DeserializeOwned>(ev: &Map<String, J>, name: &str) -> Option<T> {
            serde_json::from_value(ev.get(name).cloned().unwrap_or(J::Null)).ok()
        }
        let instance = |name: &str| -> Option<(InstanceKey, &'static str)> {
            let key: InstanceKey = field(&ev, name)?;
            let protocol = mission.bound(key.behavior, key.kind)?.protocol.name();
            Some((key, protocol))
        };
        let e = match kind {
            "selected" => Event::Selected {
                behavior: field(&ev, "behavior")?,
                team: field(&ev, "team")?,
                epoch: field(&ev, "epoch")?,
                depth: field(&ev, "depth")?,
                via: field(&ev, "via")?,
                after: field(&ev, "after").unwrap_or(None),
            },
            "terminated" => Event::Terminated {
                behavior: field(&ev, "behavior")?,
                team: field(&ev, "team")?,
                epoch: field(&ev, "epoch")?,
                reason: field(&ev, "reason")?,
            },
            "interaction_started" => {
                let (instance, protocol) = instance("instance")?;
                Event::InteractionStarted {
                    instance,
                    protocol,
                    excluded: field(&ev, "excluded").unwrap_or_default(),
                    options: field(&ev, "options").unwrap_or_default(),
                }
            }
            "left_out" => Event::LeftOut {
                instance: instance("instance")?.0,
                members: field(&ev, "members")?,
            },
            "interaction_decided" => {
                let (instance, protocol) = instance("instance")?;
                Event::InteractionDecided {
                    instance,
                    protocol,
                    outcome: field(&ev, "outcome")?,
                    waited_us: field(&ev, "waited_us").unwrap_or(0),
                    sent: field(&ev, "sent").unwrap_or(0),
                    bytes: field(&ev, "bytes").unwrap_or(0),
                    received: field(&ev, "received").unwrap_or(0),
                    timed_out: field(&ev, "timed_out").unwrap_or(false),
                }
            }
            "interaction_aborted" => {
                let (instance, protocol) = instance("instance")?;
                Event::InteractionAborted { instance, protocol }
            }
            "member_lost" => Event::MemberLost {
                member: field(&ev, "member")?,
            },
            "member_back" => Event::MemberBack {
                member: field(&ev, "member")?,
            },
            "member_given_up" => Event::MemberGivenUp {
                member: field(&ev, "member")?,
            },
            "mission_changed" => Event::MissionChanged {
                version: field(&ev, "version")?,
                team: field(&ev, "team")?,
                after: field(&ev, "after").unwrap_or(None),
                changed: field(&ev, "changed").unwrap_or_default(),
            },
            _ => return None,
        };
        Some((t, robot, e))
    }

    /// Names back to ids, in place (the reverse of `rename`); false when a
    /// name is not this graph's.
    fn unname(&self, key: &str, v: &mut J) -> bool {
        let robot = |v: &mut J| match v.as_str().map(|n| self.graph.roster().find(n)) {
            Some(Some(r)) => {
                *v = J::from(r.0);
                true
            }
            Some(None) => false,
            None => true,
        };
        match (key, &mut *v) {
            ("behavior" | "choice" | "next", J::String(n)) => match self.graph.find(n) {
                Some(b) => {
                    *v = J::from(b.0);
                    true
                }
                None => false,
            },
            ("team", J::String(n)) => {
                let id = if n == "root" {
                    Some(TeamId::ROOT.0)
                } else {
                    n.strip_prefix('t')
                        .and_then(|h| u64::from_str_radix(h, 16).ok())
                };
                match id {
                    Some(id) => {
                        *v = J::from(id);
                        true
                    }
                    None => false,
                }
            }
            ("members" | "excluded", J::Array(rs)) => rs.iter_mut().all(robot),
            ("options", J::Array(bs)) => bs.iter_mut().all(|b| self.unname("behavior", b)),
            ("from" | "member" | "winner", _) => robot(v),
            ("assignment", J::Array(pairs)) => pairs.iter_mut().all(|p| match p {
                J::Array(pair) => match pair.as_mut_slice() {
                    [b, J::Array(ms)] => self.unname("behavior", b) && ms.iter_mut().all(robot),
                    [b, _] => self.unname("behavior", b),
                    _ => false,
                },
                _ => false,
            }),
            (_, J::Object(m)) => m.iter_mut().all(|(k, v)| self.unname(k, v)),
            _ => true,
        }
    }
}
