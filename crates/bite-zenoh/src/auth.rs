//! Authenticated frames between team members (sans-IO).
//!
//! Every message one robot's runtime sends another (kernel messages,
//! world-model reports, heartbeats) travels in a [`Frame`]:
//!
//! ```text
//!  0      2    3     4          8             16          n-32        n
//!  | "BZ" | v1 | kind | sender u32 | counter u64 | payload ... | HMAC-SHA256 |
//! ```
//!
//! The MAC is HMAC-SHA256 under the team key over a domain tag, the team
//! name and everything before it, so a frame cannot be moved to another
//! team or altered. The counter is per sender and strictly increasing; it
//! starts at the sender's incarnation (microseconds since the Unix epoch
//! when it started), so a restarted robot never reuses a counter.
//! Receivers keep a sliding window per sender (the last 30 s of its
//! counters) and accept each counter at most once. Anything that fails a check is dropped and counted
//! by reason ([`AuthStats`]), never acted upon.
//!
//! The team key authenticates **membership**: any holder of the key is a
//! member, so one member can still claim to be another. The key expression
//! a frame arrives on must name the sender the frame claims (checked here),
//! which Zenoh's access control can bind to the member's credentials.

use hmac::{Hmac, Mac};
use serde::{Deserialize, Serialize};
use sha2::Sha256;
use std::collections::BTreeMap;

type HmacSha256 = Hmac<Sha256>;

/// Frame format version.
pub const FRAME_VERSION: u8 = 1;
/// Bytes before the payload.
pub const HEADER: usize = 16;
/// Bytes of the MAC.
pub const MAC: usize = 32;
/// Largest payload accepted.
pub const MAX_PAYLOAD: usize = 64 * 1024;
/// How far (µs of the sender's counter, i.e. of its clock) below the
/// highest counter seen from a sender a frame is still told apart as a
/// replay rather than refused as too old.
pub const WINDOW_US: u64 = 30_000_000;
/// Counters remembered per sender, at most (a sender sending faster than
/// this many frames per window has its oldest ones refused as too old).
pub const MAX_REMEMBERED: usize = 4096;

const MAGIC: &[u8; 2] = b"BZ";
const DOMAIN: &[u8] = b"bite-frame-v1\0";

/// What a frame carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FrameKind {
    /// A kernel (interaction protocol) message.
    Kernel = 1,
    /// A world-model report.
    Inform = 2,
    /// A heartbeat (failure detection).
    Heartbeat = 3,
}

impl FrameKind {
    fn from_byte(b: u8) -> Option<FrameKind> {
        match b {
            1 => Some(FrameKind::Kernel),
            2 => Some(FrameKind::Inform),
            3 => Some(FrameKind::Heartbeat),
            _ => None,
        }
    }
}

/// The shared secret of a team: at least 32 bytes.
#[derive(Clone)]
pub struct TeamKey(Vec<u8>);

impl std::fmt::Debug for TeamKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "TeamKey(<{} bytes>)", self.0.len())
    }
}

/// Why a key could not be read.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum KeyError {
    /// Not hexadecimal.
    #[error("the team key must be hexadecimal (two digits per byte): {0}")]
    NotHex(String),
    /// Too short to be a key.
    #[error("the team key has {0} bytes; at least 32 are needed (64 hex digits)")]
    TooShort(usize),
}

impl TeamKey {
    /// A key from raw bytes (at least 32).
    pub fn new(bytes: Vec<u8>) -> Result<TeamKey, KeyError> {
        if bytes.len() < 32 {
            return Err(KeyError::TooShort(bytes.len()));
        }
        Ok(TeamKey(bytes))
    }

    /// A key from its hexadecimal text (whitespace around it ignored).
    pub fn from_hex(text: &str) -> Result<TeamKey, KeyError> {
        TeamKey::new(from_hex(text.trim())?)
    }

    /// The key as hexadecimal text.
    pub fn to_hex(&self) -> String {
        to_hex(&self.0)
    }

    /// HMAC-SHA256 of `parts` under this key.
    pub fn mac(&self, parts: &[&[u8]]) -> [u8; 32] {
        let mut m = self.hmac();
        for p in parts {
            m.update(p);
        }
        m.finalize().into_bytes().into()
    }

    /// Does `tag` authenticate `parts`? (Constant time.)
    pub fn verify(&self, parts: &[&[u8]], tag: &[u8]) -> bool {
        let mut m = self.hmac();
        for p in parts {
            m.update(p);
        }
        m.verify_slice(tag).is_ok()
    }

    fn hmac(&self) -> HmacSha256 {
        // HMAC takes keys of any length; the error case cannot happen.
        match HmacSha256::new_from_slice(&self.0) {
            Ok(m) => m,
            Err(_) => unreachable!("HMAC accepts keys of every length"),
        }
    }
}

/// Lower-case hexadecimal.
pub fn to_hex(bytes: &[u8]) -> String {
    const D: &[u8; 16] = b"0123456789abcdef";
    let mut s = String::with_capacity(bytes.len() * 2);
    for b in bytes {
        s.push(D[(b >> 4) as usize] as char);
        s.push(D[(b & 15) as usize] as char);
    }
    s
}

/// Bytes from hexadecimal text.
pub fn from_hex(text: &str) -> Result<Vec<u8>, KeyError> {
    if !text.len().is_multiple_of(2) {
        return Err(KeyError::NotHex("odd number of digits".into()));
    }
    let digit = |c: u8| match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'a'..=b'f' => Some(c - b'a' + 10),
        b'A'..=b'F' => Some(c - b'A' + 10),
        _ => None,
    };
    text.as_bytes()
        .chunks(2)
        .enumerate()
        .map(|(i, p)| match (digit(p[0]), digit(p[1])) {
            (Some(a), Some(b)) => Ok(a << 4 | b),
            _ => Err(KeyError::NotHex(format!(
                "not a hex digit at position {}",
                2 * i + 1
            ))),
        })
        .collect()
}

/// A frame that passed every check.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Frame<'a> {
    /// What it carries.
    pub kind: FrameKind,
    /// Who sent it (roster index).
    pub sender: u32,
    /// The sender's counter.
    pub counter: u64,
    /// The payload.
    pub payload: &'a [u8],
}

/// Why a frame was dropped.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize, thiserror::Error,
)]
#[serde(rename_all = "kebab-case")]
pub enum Reject {
    /// Too short, wrong magic, version or kind.
    #[error("malformed frame")]
    Malformed,
    /// Larger than a frame can be ([`HEADER`] + [`MAX_PAYLOAD`] + [`MAC`]):
    /// dropped before it is copied or checked.
    #[error("frame larger than the limit")]
    Oversize,
    /// It arrived while the robot had no mission (nothing to check it
    /// against: the MAC binds a frame to its mission).
    #[error("frame before the robot's mission")]
    BeforeMission,
    /// The MAC does not match (forged with another key, or tampered).
    #[error("bad MAC")]
    BadMac,
    /// The sender is not on the roster.
    #[error("sender is not a team member")]
    NotMember,
    /// The frame claims another sender than the key it came on.
    #[error("sender does not match its key expression")]
    WrongSender,
    /// A counter already accepted.
    #[error("replayed counter")]
    Replay,
    /// A counter below the window.
    #[error("counter older than the window")]
    TooOld,
    /// The robot's own frame echoed back.
    #[error("own frame")]
    Own,
}

/// Seals this robot's frames: sender id, counter, MAC.
#[derive(Debug)]
pub struct Sealer {
    key: TeamKey,
    scope: Scope,
    me: u32,
    counter: u64,
}

/// What a MAC binds a frame to besides its bytes: the team and the mission
/// (a frame of another team or of another mission does not verify).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Scope {
    /// The team name.
    pub team: String,
    /// The mission's tag (e.g. a hash of its submission id).
    pub mission: u64,
}

impl Scope {
    /// Team `team`, mission `mission`.
    pub fn new(team: &str, mission: u64) -> Scope {
        Scope {
            team: team.to_string(),
            mission,
        }
    }
}

impl Sealer {
    /// Frames from robot `me`.
    pub fn new(key: TeamKey, scope: Scope, me: u32) -> Sealer {
        Sealer {
            key,
            scope,
            me,
            counter: 0,
        }
    }

    /// The next frame, at wall time `now_us` (µs since the Unix epoch):
    /// its counter is the larger of the last one plus one and `now_us`, so
    /// counters follow the clock and a restarted robot never reuses one.
    pub fn seal(&mut self, kind: FrameKind, payload: &[u8], now_us: u64) -> Vec<u8> {
        self.counter = (self.counter + 1).max(now_us);
        seal_with(&self.key, &self.scope, kind, self.me, self.counter, payload)
    }

    /// The last counter used.
    pub fn counter(&self) -> u64 {
        self.counter
    }
}

/// A frame sealed with explicit fields (tests build forged ones with it).
pub fn seal_with(
    key: &TeamKey,
    scope: &Scope,
    kind: FrameKind,
    sender: u32,
    counter: u64,
    payload: &[u8],
) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER + payload.len() + MAC);
    out.extend_from_slice(MAGIC);
    out.push(FRAME_VERSION);
    out.push(kind as u8);
    out.extend_from_slice(&sender.to_le_bytes());
    out.extend_from_slice(&counter.to_le_bytes());
    out.extend_from_slice(payload);
    let tag = key.mac(&[
        DOMAIN,
        scope.team.as_bytes(),
        &[0],
        &scope.mission.to_le_bytes(),
        &out,
    ]);
    out.extend_from_slice(&tag);
    out
}

/// The anti-replay window of one sender, over its counters (microseconds
/// on the sender's clock): every counter accepted within [`WINDOW_US`] of
/// the highest one is remembered (at most [`MAX_REMEMBERED`]), so a frame
/// captured and replayed within the window counts as a replay; anything
/// older than the window, or than the oldest counter forgotten to keep the
/// memory bounded, is too old.
#[derive(Clone, Debug, Default)]
struct Window {
    top: u64,
    /// Counters below this are too old (raised when one is forgotten).
    floor: u64,
    seen: std::collections::BTreeSet<u64>,
}

impl Window {
    fn check(&self, c: u64) -> Result<(), Reject> {
        if c < self.floor || c.saturating_add(WINDOW_US) < self.top {
            return Err(Reject::TooOld);
        }
        if self.seen.contains(&c) {
            return Err(Reject::Replay);
        }
        Ok(())
    }

    fn accept(&mut self, c: u64) {
        self.seen.insert(c);
        self.top = self.top.max(c);
        let oldest = self.top.saturating_sub(WINDOW_US);
        while let Some(&first) = self.seen.first() {
            if first < oldest || self.seen.len() > MAX_REMEMBERED {
                self.seen.pop_first();
                self.floor = self.floor.max(first + 1);
            } else {
                break;
            }
        }
    }
}

/// What was accepted and dropped, by reason.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct AuthStats {
    /// Frames accepted.
    pub accepted: u64,
    /// Frames dropped, by reason.
    pub rejected: BTreeMap<Reject, u64>,
}

impl AuthStats {
    /// Frames dropped for any reason (own echoes excluded).
    pub fn rejected_total(&self) -> u64 {
        (self.rejected.iter())
            .filter(|(r, _)| **r != Reject::Own)
            .map(|(_, c)| c)
            .sum()
    }
}

/// How old (µs) a sender's first frame may be: counters follow the sender's
/// clock, so a recorded frame replayed later is refused even by a receiver
/// that has no window for that sender yet (clocks must agree within this).
pub const FRESH_US: u64 = 30_000_000;

/// Opens the team's frames: checks MAC, membership and freshness.
#[derive(Debug)]
pub struct Opener {
    key: TeamKey,
    scope: Scope,
    me: u32,
    roster: u32,
    windows: BTreeMap<u32, Window>,
    stats: AuthStats,
}

impl Opener {
    /// Frames for robot `me` of a team whose roster has `roster` robots.
    pub fn new(key: TeamKey, scope: Scope, me: u32, roster: u32) -> Opener {
        Opener {
            key,
            scope,
            me,
            roster,
            windows: BTreeMap::new(),
            stats: AuthStats::default(),
        }
    }

    /// Check a frame that arrived on the key of `claimed` (if known) at
    /// wall time `now_us`. Counted either way.
    pub fn open<'a>(
        &mut self,
        bytes: &'a [u8],
        claimed: Option<u32>,
        now_us: u64,
    ) -> Result<Frame<'a>, Reject> {
        let r = self.check(bytes, claimed, now_us);
        match &r {
            Ok(_) => self.stats.accepted += 1,
            Err(e) => *self.stats.rejected.entry(*e).or_insert(0) += 1,
        }
        r
    }

    fn check<'a>(
        &mut self,
        bytes: &'a [u8],
        claimed: Option<u32>,
        now_us: u64,
    ) -> Result<Frame<'a>, Reject> {
        if bytes.len() > HEADER + MAX_PAYLOAD + MAC {
            return Err(Reject::Oversize);
        }
        if bytes.len() < HEADER + MAC || &bytes[0..2] != MAGIC || bytes[2] != FRAME_VERSION {
            return Err(Reject::Malformed);
        }
        let kind = FrameKind::from_byte(bytes[3]).ok_or(Reject::Malformed)?;
        let (body, tag) = bytes.split_at(bytes.len() - MAC);
        let mission = self.scope.mission.to_le_bytes();
        let team = self.scope.team.as_bytes();
        if !self.key.verify(&[DOMAIN, team, &[0], &mission, body], tag) {
            return Err(Reject::BadMac);
        }
        let sender = u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]);
        let mut c = [0u8; 8];
        c.copy_from_slice(&bytes[8..16]);
        let counter = u64::from_le_bytes(c);
        if sender >= self.roster {
            return Err(Reject::NotMember);
        }
        if claimed.is_some_and(|c| c != sender) {
            return Err(Reject::WrongSender);
        }
        if sender == self.me {
            return Err(Reject::Own);
        }
        if !self.windows.contains_key(&sender) && counter.saturating_add(FRESH_US) < now_us {
            return Err(Reject::TooOld);
        }
        let w = self.windows.entry(sender).or_default();
        w.check(counter)?;
        w.accept(counter);
        Ok(Frame {
            kind,
            sender,
            counter,
            payload: &body[HEADER..],
        })
    }

    /// What was accepted and dropped.
    pub fn stats(&self) -> &AuthStats {
        &self.stats
    }

    /// Count a frame dropped before it reached [`Opener::open`] (too
    /// large to be copied: [`Reject::Oversize`]).
    pub fn count(&mut self, reason: Reject) {
        *self.stats.rejected.entry(reason).or_insert(0) += 1;
    }

    /// Start from these counts (frames dropped before the opener existed:
    /// before the robot's first mission).
    pub fn with_stats(mut self, stats: AuthStats) -> Opener {
        self.stats = stats;
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const NOW: u64 = 1_800_000_000_000_000;

    fn sc(team: &str) -> Scope {
        Scope::new(team, 7)
    }

    fn key(b: u8) -> TeamKey {
        TeamKey::new(vec![b; 32]).unwrap()
    }

    #[test]
    fn sealed_frames_open_once() {
        let mut s = Sealer::new(key(1), sc("t"), 0);
        let mut o = Opener::new(key(1), sc("t"), 1, 3);
        let f = s.seal(FrameKind::Kernel, b"hello", NOW);
        let got = o.open(&f, Some(0), NOW).unwrap();
        assert_eq!(got.payload, b"hello");
        assert_eq!(got.sender, 0);
        assert_eq!(got.counter, NOW);
        assert_eq!(o.open(&f, Some(0), NOW), Err(Reject::Replay));
    }

    #[test]
    fn every_attack_is_rejected_and_counted() {
        let mut s = Sealer::new(key(1), sc("t"), 0);
        let mut o = Opener::new(key(1), sc("t"), 1, 3);
        let good = s.seal(FrameKind::Heartbeat, b"x", NOW);
        // Forged with another key.
        let forged = seal_with(&key(2), &sc("t"), FrameKind::Kernel, 0, NOW + 99, b"x");
        assert_eq!(o.open(&forged, Some(0), NOW), Err(Reject::BadMac));
        // Another mission's frame.
        let other_mission = seal_with(
            &key(1),
            &Scope::new("t", 8),
            FrameKind::Kernel,
            0,
            NOW,
            b"x",
        );
        assert_eq!(o.open(&other_mission, Some(0), NOW), Err(Reject::BadMac));
        // Another team's frame.
        let other = seal_with(&key(1), &sc("u"), FrameKind::Kernel, 0, NOW + 99, b"x");
        assert_eq!(o.open(&other, Some(0), NOW), Err(Reject::BadMac));
        // Tampered: every byte flipped in turn.
        for i in 0..good.len() {
            let mut t = good.clone();
            t[i] ^= 0x40;
            let want = if i < 4 {
                Reject::Malformed
            } else {
                Reject::BadMac
            };
            assert_eq!(o.open(&t, Some(0), NOW), Err(want), "byte {i}");
        }
        // Not a member, wrong key expression, own.
        let outsider = seal_with(&key(1), &sc("t"), FrameKind::Kernel, 7, NOW + 1, b"x");
        assert_eq!(o.open(&outsider, Some(7), NOW), Err(Reject::NotMember));
        assert_eq!(o.open(&good, Some(2), NOW), Err(Reject::WrongSender));
        let own = seal_with(&key(1), &sc("t"), FrameKind::Kernel, 1, NOW + 1, b"x");
        assert_eq!(o.open(&own, Some(1), NOW), Err(Reject::Own));
        assert!(o.open(&good, Some(0), NOW).is_ok());
        assert_eq!(o.open(&good, Some(0), NOW), Err(Reject::Replay));
        assert_eq!(o.stats().accepted, 1);
        assert_eq!(o.stats().rejected[&Reject::Replay], 1);
        assert_eq!(
            o.stats().rejected[&Reject::BadMac] as usize,
            3 + good.len() - 4
        );
        assert_eq!(o.stats().rejected[&Reject::Malformed], 4);
        assert!(o.open(&[], None, NOW).is_err());
        assert_eq!(o.open(b"BZ\x01", None, NOW), Err(Reject::Malformed));
    }

    #[test]
    fn an_oversized_frame_is_counted_as_oversize() {
        let mut o = Opener::new(key(1), sc("t"), 1, 3);
        let big = seal_with(
            &key(1),
            &sc("t"),
            FrameKind::Kernel,
            0,
            NOW,
            &vec![6; MAX_PAYLOAD + 1],
        );
        assert_eq!(o.open(&big, Some(0), NOW), Err(Reject::Oversize));
        // One the robot's callback dropped before copying it.
        o.count(Reject::Oversize);
        assert_eq!(o.stats().rejected[&Reject::Oversize], 2);
        assert_eq!(o.stats().rejected_total(), 2);
        assert_eq!(
            serde_json::to_value(Reject::Oversize).unwrap(),
            "oversize",
            "the name in `auth.rejected`"
        );
        assert_eq!(
            serde_json::to_value(Reject::BeforeMission).unwrap(),
            "before-mission"
        );
        // Counts made before the opener existed are kept.
        let mut before = AuthStats::default();
        before.rejected.insert(Reject::BeforeMission, 3);
        let o = Opener::new(key(1), sc("t"), 1, 3).with_stats(before);
        assert_eq!(o.stats().rejected_total(), 3);
    }

    #[test]
    fn a_recorded_frame_is_too_old_for_a_receiver_that_never_saw_its_sender() {
        let mut s = Sealer::new(key(1), sc("t"), 0);
        let f = s.seal(FrameKind::Heartbeat, b"x", NOW);
        let mut late = Opener::new(key(1), sc("t"), 1, 3);
        assert_eq!(
            late.open(&f, Some(0), NOW + FRESH_US + 1),
            Err(Reject::TooOld)
        );
        let mut soon = Opener::new(key(1), sc("t"), 1, 3);
        assert!(soon.open(&f, Some(0), NOW + 1000).is_ok());
        // Counters follow the clock, and never go back.
        let g = s.seal(FrameKind::Heartbeat, b"x", NOW - 5);
        assert_eq!(
            soon.open(&g, Some(0), NOW + 1000).map(|f| f.counter),
            Ok(NOW + 1)
        );
    }

    #[test]
    fn a_frame_replayed_within_the_window_is_a_replay_and_later_too_old() {
        let mut s = Sealer::new(key(1), sc("t"), 0);
        let mut o = Opener::new(key(1), sc("t"), 1, 3);
        let captured = s.seal(FrameKind::Heartbeat, b"x", NOW);
        assert!(o.open(&captured, Some(0), NOW).is_ok());
        // The sender goes on for a second (4 heartbeats), then the capture
        // is played back.
        for k in 1..=4 {
            let f = s.seal(FrameKind::Heartbeat, b"x", NOW + k * 250_000);
            assert!(o.open(&f, Some(0), NOW + k * 250_000).is_ok());
        }
        assert_eq!(
            o.open(&captured, Some(0), NOW + 1_000_000),
            Err(Reject::Replay)
        );
        // Out of order within the window: accepted once.
        let late = seal_with(&key(1), &sc("t"), FrameKind::Kernel, 0, NOW + 10, b"y");
        assert!(o.open(&late, Some(0), NOW + 1_000_000).is_ok());
        assert_eq!(o.open(&late, Some(0), NOW + 1_000_000), Err(Reject::Replay));
        // Once the sender is a window further on, the capture is too old.
        let f = s.seal(FrameKind::Heartbeat, b"x", NOW + WINDOW_US + 1_000_000);
        assert!(o.open(&f, Some(0), NOW + WINDOW_US + 1_000_000).is_ok());
        assert_eq!(
            o.open(&captured, Some(0), NOW + WINDOW_US + 1_000_000),
            Err(Reject::TooOld)
        );
    }

    #[test]
    fn the_window_remembers_a_bounded_number_of_counters() {
        let mut w = Window::default();
        for c in 1..=(MAX_REMEMBERED as u64 + 10) {
            assert_eq!(w.check(c), Ok(()));
            w.accept(c);
        }
        assert_eq!(w.seen.len(), MAX_REMEMBERED);
        // The forgotten ones are too old, never accepted again.
        assert_eq!(w.check(5), Err(Reject::TooOld));
        assert_eq!(w.check(MAX_REMEMBERED as u64 + 10), Err(Reject::Replay));
    }

    /// The frame layout and MAC input as `docs/zenoh-interface.md` gives
    /// them, built here byte by byte without the sealer: if either drifts,
    /// this fails.
    #[test]
    fn the_documented_frame_layout_is_what_robots_seal() {
        let key = key(0x5a);
        let (team, id, sender, counter) = ("demo", "m-42", 2u32, 1_795_270_222_967_000u64);
        // Mission tag: FNV-1a 64 (offset 0xcbf29ce484222325, prime
        // 0x100000001b3) over "id\0" + submission id.
        let mut tag: u64 = 0xcbf2_9ce4_8422_2325;
        for b in b"id\0".iter().chain(id.as_bytes()) {
            tag ^= u64::from(*b);
            tag = tag.wrapping_mul(0x0000_0100_0000_01b3);
        }
        // A heartbeat payload: payload version 6, finished = false (postcard
        // bool: one byte), no position (postcard Option: 0 = None).
        let payload = [crate::wire::PAYLOAD_VERSION, 0, 0];
        assert_eq!(payload[0], 6, "docs/zenoh-interface.md gives version 6");
        let hb = crate::wire::Heartbeat {
            finished: false,
            position: None,
        };
        assert_eq!(crate::wire::encode_heartbeat(&hb), payload);
        let mut frame = b"BZ".to_vec();
        frame.push(1); // frame version
        frame.push(3); // kind: heartbeat
        frame.extend_from_slice(&sender.to_le_bytes());
        frame.extend_from_slice(&counter.to_le_bytes());
        frame.extend_from_slice(&payload);
        let mut mac_input = b"bite-frame-v1\0".to_vec();
        mac_input.extend_from_slice(team.as_bytes());
        mac_input.push(0);
        mac_input.extend_from_slice(&tag.to_le_bytes());
        mac_input.extend_from_slice(&frame);
        let mac = key.mac(&[&mac_input]);
        frame.extend_from_slice(&mac);
        let scope = Scope::new(team, tag);
        assert_eq!(
            frame,
            seal_with(
                &key,
                &scope,
                FrameKind::Heartbeat,
                sender,
                counter,
                &payload
            )
        );
        let hb = crate::wire::decode_heartbeat(&payload).expect("a heartbeat");
        assert!(!hb.finished && hb.position.is_none());
        let mut o = Opener::new(key, scope, 0, 3);
        assert!(o.open(&frame, Some(sender), counter).is_ok());
    }

    #[test]
    fn keys_parse_and_refuse_short_or_bad_text() {
        let k = key(0xab);
        assert_eq!(TeamKey::from_hex(&k.to_hex()).unwrap().0, k.0);
        assert!(matches!(
            TeamKey::from_hex("abcd"),
            Err(KeyError::TooShort(2))
        ));
        assert!(matches!(TeamKey::from_hex("zz"), Err(KeyError::NotHex(_))));
        assert!(matches!(TeamKey::from_hex("abc"), Err(KeyError::NotHex(_))));
    }

    proptest! {
        /// Whatever order counters arrive in, each is accepted at most
        /// once, and every counter above the highest seen is accepted.
        #[test]
        fn window_accepts_each_counter_at_most_once(
            cs in proptest::collection::vec(0u64..3 * WINDOW_US, 1..400),
        ) {
            let mut w = Window::default();
            let mut accepted = std::collections::BTreeSet::new();
            for c in cs {
                let fresh = c > w.top;
                match w.check(c) {
                    Ok(()) => {
                        prop_assert!(accepted.insert(c), "counter {} accepted twice", c);
                        w.accept(c);
                    }
                    // A counter seen again within the window is a replay.
                    Err(Reject::Replay) => prop_assert!(accepted.contains(&c)),
                    Err(_) => prop_assert!(!fresh),
                }
                prop_assert!(w.seen.len() <= MAX_REMEMBERED);
            }
        }

        /// Random bytes never open and never panic.
        #[test]
        fn random_bytes_never_open(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
            let mut o = Opener::new(key(1), sc("t"), 1, 3);
            prop_assert!(o.open(&bytes, None, NOW).is_err());
        }
    }
}
