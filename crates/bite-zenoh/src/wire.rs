//! What travels inside frames between robots (compact, binary, versioned),
//! and the JSON outside interface (`docs/zenoh-interface.md`).

use crate::auth::{AuthStats, TeamKey, from_hex, to_hex};
use bite_core::graph::BehaviorGraph;
use bite_core::ids::RobotId;
use bite_core::interaction::Recipients;
use bite_core::kernel::Kernel;
use bite_core::msg::{Envelope, WireError};
use bite_core::org::MemberSet;
use bite_core::wm::Inform;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::sync::Arc;

/// Version of the payloads inside frames. 4: world-model reports carry
/// the age of each value (`age_us`), no longer the sender's clock time.
/// 5: a heartbeat's position ends with the count of its skill's steps
/// (`Position::progress`). 6: a heartbeat's position begins with the
/// robot it is of (`Position::robot`).
pub const PAYLOAD_VERSION: u8 = 6;

/// Who a kernel message is for.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum To {
    /// One robot.
    One(u32),
    /// Every member of a set but the sender.
    Team(MemberSet),
}

impl To {
    /// From the kernel's recipients.
    pub fn of(r: &Recipients) -> To {
        match r {
            Recipients::One(x) => To::One(x.0),
            Recipients::Team(s) => To::Team((**s).clone()),
        }
    }
    /// Is robot `me` a recipient?
    pub fn includes(&self, me: RobotId) -> bool {
        match self {
            To::One(x) => *x == me.0,
            To::Team(s) => s.contains(me),
        }
    }
}

/// A kernel frame's payload: version, recipients, the kernel's own encoding
/// of the envelope (`bite_core::msg::encode`).
pub fn encode_kernel(to: &Recipients, env: &Envelope) -> Vec<u8> {
    let mut out = vec![PAYLOAD_VERSION];
    out = postcard::to_extend(&To::of(to), out).unwrap_or_else(|_| vec![PAYLOAD_VERSION]);
    out.extend_from_slice(&bite_core::msg::encode(env));
    out
}

/// Decode a kernel frame's payload. Never panics. Only the payload's own
/// first byte is a payload version ([`WireError::Version`]): a bad version
/// byte of the envelope inside (`bite_core::msg::encode`'s) is a malformed
/// payload, not a teammate running another version of bite.
pub fn decode_kernel(bytes: &[u8]) -> Result<(To, Envelope), WireError> {
    let rest = version(bytes)?;
    let (to, rest): (To, &[u8]) =
        postcard::take_from_bytes(rest).map_err(|e| WireError::Malformed(e.to_string()))?;
    let env = bite_core::msg::decode(rest).map_err(|e| match e {
        WireError::Version(v) => WireError::Malformed(format!("envelope version {v}")),
        e => e,
    })?;
    Ok((to, env))
}

/// A world-model frame's payload: version, recipients, the report.
pub fn encode_inform(to: &[RobotId], msg: &Inform) -> Vec<u8> {
    let to: Vec<u32> = to.iter().map(|r| r.0).collect();
    postcard::to_extend(&(to, msg), vec![PAYLOAD_VERSION]).unwrap_or_default()
}

/// Decode a world-model frame's payload.
pub fn decode_inform(bytes: &[u8]) -> Result<(Vec<u32>, Inform), WireError> {
    let rest = version(bytes)?;
    let (v, tail): ((Vec<u32>, Inform), &[u8]) =
        postcard::take_from_bytes(rest).map_err(|e| WireError::Malformed(e.to_string()))?;
    if !tail.is_empty() {
        return Err(WireError::Malformed("trailing bytes".into()));
    }
    Ok(v)
}

/// A heartbeat's payload.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Heartbeat {
    /// The sender has completed the mission.
    pub finished: bool,
    /// What the sender runs in each of its subteams (its team view), so
    /// that teammates detect and heal splits (`Kernel::peer`). `None`
    /// before its mission starts.
    pub position: Option<bite_core::kernel::Position>,
}

/// Encode a heartbeat.
pub fn encode_heartbeat(h: &Heartbeat) -> Vec<u8> {
    postcard::to_extend(h, vec![PAYLOAD_VERSION]).unwrap_or_default()
}

/// Decode a heartbeat.
pub fn decode_heartbeat(bytes: &[u8]) -> Result<Heartbeat, WireError> {
    let rest = version(bytes)?;
    let (h, tail): (Heartbeat, &[u8]) =
        postcard::take_from_bytes(rest).map_err(|e| WireError::Malformed(e.to_string()))?;
    if !tail.is_empty() {
        return Err(WireError::Malformed("trailing bytes".into()));
    }
    Ok(h)
}

fn version(bytes: &[u8]) -> Result<&[u8], WireError> {
    let (&v, rest) = bytes.split_first().ok_or(WireError::Empty)?;
    if v != PAYLOAD_VERSION {
        return Err(WireError::Version(v));
    }
    Ok(rest)
}

// ----- The JSON outside interface -----

/// One frame of a robot's behavior stack, by name.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StackEntry {
    /// The behavior.
    pub behavior: String,
    /// The subteam executing it (short id; `root` is the whole team).
    pub team: String,
    /// Its members, by name.
    pub members: Vec<String>,
    /// The team's execution count of the behavior.
    pub epoch: u32,
}

/// A robot's status, published periodically on `bite/<team>/status/<robot>`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Status {
    /// The robot.
    pub robot: String,
    /// The team (key prefix).
    pub team: String,
    /// The mission it runs (graph name), if any.
    pub mission: Option<String>,
    /// The submission id it came from, if submitted over the network.
    pub mission_id: Option<String>,
    /// Mission time, seconds (team clock).
    pub t: f64,
    /// `waiting` (no mission), `gathering` (waiting for teammates),
    /// `running`, `completed`.
    pub state: String,
    /// The kernel's phase (Algorithm 1).
    pub phase: Option<String>,
    /// The behavior stack, root first.
    pub stack: Vec<StackEntry>,
    /// The subteam of the leaf behavior.
    pub subteam: Option<StackEntry>,
    /// Beliefs with a value, by name.
    pub beliefs: BTreeMap<String, serde_json::Value>,
    /// Teammates presumed lost.
    pub lost: Vec<String>,
    /// Frames accepted and dropped, by reason.
    pub auth: AuthStats,
    /// Mission submissions rejected (bad MAC, replayed id, malformed) or
    /// refused (busy, no world to run it in, does not load).
    pub missions_rejected: u64,
    /// The last of those: its id (when it could be read) and why, so that a
    /// client learns what became of its submission.
    #[serde(default)]
    pub last_rejection: Option<Rejection>,
    /// The version of the mission it runs (0: as started; see
    /// [`MissionBody::version`]) and the newer one it holds, if any.
    #[serde(default)]
    pub version: u32,
    /// A newer version held until the team's next safe point.
    #[serde(default)]
    pub pending_version: Option<u32>,
    /// Teammates heard speaking another payload version than
    /// [`PAYLOAD_VERSION`], and which: every frame of theirs is dropped
    /// (the team was not upgraded together).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub peer_versions: BTreeMap<String, u8>,
}

/// A submission a robot did not run, and why.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Rejection {
    /// The submission id, when the submission could be opened.
    pub id: Option<String>,
    /// `rejected` (not authentic, stale, replayed) or `refused` (authentic
    /// but not run: busy, no world, does not load).
    pub event: String,
    /// Why, in words.
    pub reason: String,
}

impl Status {
    /// The status of a running kernel.
    pub fn of_kernel(k: &Kernel, graph: &BehaviorGraph) -> (Vec<StackEntry>, Option<StackEntry>) {
        let names =
            |m: &MemberSet| -> Vec<String> { m.iter().map(|r| graph.roster().name(r)).collect() };
        let stack: Vec<StackEntry> = k
            .stack()
            .iter()
            .map(|f| StackEntry {
                behavior: graph.name_of(f.behavior).to_string(),
                team: f.team.to_string(),
                members: k
                    .org()
                    .team(f.team)
                    .map_or_else(Vec::new, |t| names(&t.members)),
                epoch: f.epoch,
            })
            .collect();
        let sub = stack.last().cloned();
        (stack, sub)
    }
}

/// A mission submission, put on `bite/<team>/mission`: the body (JSON text)
/// and its MAC under the team key, so only team members can task the team.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Submission {
    /// The [`MissionBody`] as JSON text (signed as is, byte for byte).
    pub body: String,
    /// Hex HMAC-SHA256 over `"bite-mission-v1\0" + team + "\0" + body`.
    pub mac: String,
}

/// What a submission asks for.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MissionBody {
    /// Unique id (a submission id is run at most once: replays are dropped).
    pub id: String,
    /// When it was issued, milliseconds since the Unix epoch; robots refuse
    /// submissions more than 5 minutes from their clock (recorded ones
    /// replayed later).
    pub issued_at: u64,
    /// A behavior graph (YAML text) ...
    #[serde(default)]
    pub graph: Option<String>,
    /// ... or a mission in the robot team command language.
    #[serde(default)]
    pub rtcl: Option<String>,
    /// A configuration (YAML text) binding protocols to points.
    #[serde(default)]
    pub config: Option<String>,
    /// A scenario (YAML text); default: the one the robot was started with.
    #[serde(default)]
    pub scenario: Option<String>,
    /// Seed for the robots' random streams (default: the scenario's).
    #[serde(default)]
    pub seed: Option<u64>,
    /// A new version of the running mission (`bite submit --replace`): a
    /// team at work takes it at its safe points instead of refusing it as
    /// busy; its version is [`MissionBody::version`].
    #[serde(default)]
    pub replace: bool,
}

/// 2020-01-01T00:00:00Z, seconds since the Unix epoch.
const VERSION_EPOCH_S: u64 = 1_577_836_800;

impl MissionBody {
    /// The version a replacement is numbered with on every robot: the
    /// second it was issued, counted from 2020 (newer submissions have
    /// higher versions, whichever robot numbers them; two replacements
    /// issued within the same second: the second is refused as not newer).
    pub fn version(&self) -> u32 {
        let s = (self.issued_at / 1000).saturating_sub(VERSION_EPOCH_S);
        u32::try_from(s).unwrap_or(u32::MAX).max(1)
    }
}

const MISSION_DOMAIN: &[u8] = b"bite-mission-v1\0";

/// Sign a mission body.
pub fn sign_submission(key: &TeamKey, team: &str, body: &MissionBody) -> Submission {
    let body = serde_json::to_string(body).unwrap_or_default();
    let mac = key.mac(&[MISSION_DOMAIN, team.as_bytes(), b"\0", body.as_bytes()]);
    Submission {
        body,
        mac: to_hex(&mac),
    }
}

/// Why a submission was refused.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum SubmissionError {
    /// Not the JSON the interface documents.
    #[error("malformed submission: {0}")]
    Malformed(String),
    /// The MAC does not match.
    #[error("bad MAC")]
    BadMac,
    /// Neither or both of `graph` and `rtcl`.
    #[error("a submission carries exactly one of `graph` and `rtcl`")]
    WhatToRun,
}

/// Largest mission submission (and sensor reading) a robot takes, bytes of
/// its JSON: larger ones are dropped and counted (`bite submit` refuses to
/// send one).
pub const MAX_SUBMISSION_BYTES: usize = 1 << 20;

/// Check a submission's MAC and read its body.
pub fn open_submission(
    key: &TeamKey,
    team: &str,
    bytes: &[u8],
) -> Result<MissionBody, SubmissionError> {
    if bytes.len() > MAX_SUBMISSION_BYTES {
        return Err(SubmissionError::Malformed("larger than 1 MiB".into()));
    }
    let s: Submission =
        serde_json::from_slice(bytes).map_err(|e| SubmissionError::Malformed(e.to_string()))?;
    let tag = from_hex(s.mac.trim()).map_err(|_| SubmissionError::BadMac)?;
    if !key.verify(
        &[MISSION_DOMAIN, team.as_bytes(), b"\0", s.body.as_bytes()],
        &tag,
    ) {
        return Err(SubmissionError::BadMac);
    }
    let body: MissionBody =
        serde_json::from_str(&s.body).map_err(|e| SubmissionError::Malformed(e.to_string()))?;
    if body.graph.is_some() == body.rtcl.is_some() {
        return Err(SubmissionError::WhatToRun);
    }
    Ok(body)
}

/// The answer to a membership query on `bite/<team>/members/<robot>`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Membership {
    /// The robot answering.
    pub robot: String,
    /// The mission's roster, by name (empty: no mission).
    pub roster: Vec<String>,
    /// Teammates it hears (heartbeats within the failure detector's bound).
    pub alive: Vec<String>,
    /// Teammates it presumes lost.
    pub lost: Vec<String>,
    /// The subteams it belongs to now, leaf last.
    pub subteams: Vec<StackEntry>,
}

/// Shared, immutable name table for a team.
pub type Names = Arc<[String]>;

#[cfg(test)]
mod tests {
    use super::*;
    use bite_core::ids::{BehaviorId, TeamId};
    use bite_core::msg::{Body, InstanceKey, Kind};

    #[test]
    fn world_model_reports_of_every_value_type_round_trip() {
        use bite_core::ids::BeliefId;
        use bite_core::value::Value;
        use bite_core::wm::{Reason, Report};
        let values = [
            Value::Bool(true),
            Value::Num(2.31),
            Value::Vec2([1.5, -0.5]),
            Value::Text(Arc::from("yellow")),
        ];
        let msg = Inform {
            reason: Reason::Helpful,
            about: Some(BehaviorId(4)),
            beliefs: values
                .iter()
                .enumerate()
                .map(|(i, v)| Report {
                    belief: BeliefId(i as u32),
                    value: v.clone(),
                    age_us: i as u64 * 1000,
                    confidence: 0.75,
                })
                .collect(),
        };
        let bytes = encode_inform(&[RobotId(0), RobotId(2)], &msg);
        let (to, back) = decode_inform(&bytes).expect("a report decodes");
        assert_eq!(to, vec![0, 2]);
        assert_eq!(back, msg);
        for cut in 0..bytes.len() {
            assert!(decode_inform(&bytes[..cut]).is_err());
        }
    }

    #[test]
    fn kernel_payload_round_trip() {
        let env = Envelope {
            instance: InstanceKey {
                team: TeamId::ROOT,
                behavior: BehaviorId(3),
                kind: Kind::Sync,
                epoch: 2,
                round: 0,
            },
            sender: RobotId(1),
            seq: 9,
            body: Body::Ack,
        };
        let to = Recipients::Team(Arc::new(MemberSet::all(3)));
        let bytes = encode_kernel(&to, &env);
        let (t, e) = decode_kernel(&bytes).unwrap();
        assert_eq!(e, env);
        assert!(t.includes(RobotId(2)));
        for cut in 0..bytes.len() {
            assert!(decode_kernel(&bytes[..cut]).is_err());
        }
        let mut v = bytes.clone();
        v[0] = 9;
        assert_eq!(decode_kernel(&v), Err(WireError::Version(9)));
        // The envelope's own version byte, after the recipients, is not the
        // payload's: a frame with a bad one is malformed.
        let inner = bytes.len() - bite_core::msg::encode(&env).len();
        let mut v = bytes.clone();
        v[inner] = 127;
        assert!(
            matches!(decode_kernel(&v), Err(WireError::Malformed(_))),
            "{:?}",
            decode_kernel(&v)
        );
    }

    #[test]
    fn heartbeat_carries_the_team_view() {
        use bite_core::ids::{BehaviorId, TeamId};
        use bite_core::kernel::{FrameId, FrameState, PosFrame, Position};
        let pos = Position {
            frames: vec![PosFrame {
                id: FrameId {
                    team: TeamId(0),
                    behavior: BehaviorId(2),
                    epoch: 3,
                },
                anchor: None,
                state: FrameState::Running,
                alloc: None,
                departed: Some(bite_core::org::MemberSet::from_iter(3, [RobotId(1)])),
            }],
            ended: vec![],
            burned: vec![],
            ..Default::default()
        };
        let h = Heartbeat {
            finished: false,
            position: Some(pos),
        };
        let bytes = encode_heartbeat(&h);
        assert_eq!(decode_heartbeat(&bytes), Ok(h));
        // Truncated, trailing or empty payloads are errors, never panics.
        for cut in 0..bytes.len() {
            let _ = decode_heartbeat(&bytes[..cut]);
        }
        let mut long = bytes.clone();
        long.push(0);
        assert!(decode_heartbeat(&long).is_err());
        assert!(decode_heartbeat(&[]).is_err());
    }

    #[test]
    fn submissions_need_the_key() {
        let key = TeamKey::new(vec![7; 32]).unwrap();
        let body = MissionBody {
            id: "m1".into(),
            issued_at: 0,
            graph: Some("name: x".into()),
            rtcl: None,
            config: None,
            scenario: None,
            seed: None,
            replace: false,
        };
        let s = sign_submission(&key, "t", &body);
        let bytes = serde_json::to_vec(&s).unwrap();
        assert_eq!(open_submission(&key, "t", &bytes), Ok(body.clone()));
        assert_eq!(
            open_submission(&key, "u", &bytes),
            Err(SubmissionError::BadMac)
        );
        let other = TeamKey::new(vec![8; 32]).unwrap();
        assert_eq!(
            open_submission(&other, "t", &bytes),
            Err(SubmissionError::BadMac)
        );
        let mut tampered = s.clone();
        tampered.body = tampered.body.replace("m1", "m2");
        let bytes = serde_json::to_vec(&tampered).unwrap();
        assert_eq!(
            open_submission(&key, "t", &bytes),
            Err(SubmissionError::BadMac)
        );
        assert!(matches!(
            open_submission(&key, "t", b"{"),
            Err(SubmissionError::Malformed(_))
        ));
    }
}
