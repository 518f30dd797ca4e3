//! BITE robots as separate processes over Zenoh.
//!
//! - [`robot`]: one robot's runtime (`bite robot`): an [`bite_agent::agent::Agent`]
//!   (kernel, world model, skills, pilot) driven by wall-clock timers and
//!   Zenoh messages, with heartbeats for lost-teammate detection.
//! - [`server`]: the simulator as a server (`bite sim serve`): owns the
//!   physical world, publishes each robot's sensor readings, takes its
//!   velocity commands.
//! - [`auth`]: authenticated frames (HMAC-SHA256 over the team key, per-sender
//!   counters, anti-replay windows); sans-IO.
//! - [`wire`]: payloads inside frames (binary, versioned) and the JSON outside
//!   interface (status, run-log records, mission submission, membership),
//!   documented in `docs/zenoh-interface.md`.
//! - [`net`]: the Zenoh session configuration (explicit endpoints, multicast
//!   scouting off unless asked for) and the team clock.

pub mod agreement;
pub mod auth;
pub mod net;
pub mod robot;
pub mod ros2;
#[cfg(feature = "sim-server")]
pub mod server;
pub mod wire;

pub use zenoh;

/// Key expressions of a team, all under `bite/<team>/`.
#[derive(Clone, Debug)]
pub struct Keys {
    prefix: String,
}

impl Keys {
    /// The keys of team `team` (a single key-expression chunk).
    pub fn new(team: &str) -> Keys {
        Keys {
            prefix: format!("bite/{team}"),
        }
    }
    /// Authenticated frames from `robot` to the whole team (heartbeats,
    /// team multicasts).
    pub fn net(&self, robot: &str) -> String {
        format!("{}/net/{robot}", self.prefix)
    }
    /// Authenticated frames from `robot` to one teammate, `to`: only `to`
    /// subscribes to them, so no other robot's process wakes for them.
    pub fn net_to(&self, robot: &str, to: &str) -> String {
        format!("{}/net/{robot}/{to}", self.prefix)
    }
    /// What `robot` subscribes to for the frames addressed to it alone.
    pub fn net_for(&self, robot: &str) -> String {
        format!("{}/net/*/{robot}", self.prefix)
    }
    /// The sender named by a frame's key (`bite/T/net/<sender>` or
    /// `bite/T/net/<sender>/<to>`); empty for any other key.
    pub fn sender_of(key: &str) -> &str {
        let mut chunks = key.split('/');
        match (chunks.next(), chunks.next(), chunks.next(), chunks.next()) {
            (Some("bite"), Some(_), Some("net"), Some(sender)) => sender,
            _ => "",
        }
    }
    /// Status (JSON) of `robot`.
    pub fn status(&self, robot: &str) -> String {
        format!("{}/status/{robot}", self.prefix)
    }
    /// Run-log records (JSON) of `robot`.
    pub fn log(&self, robot: &str) -> String {
        format!("{}/log/{robot}", self.prefix)
    }
    /// Mission submissions (JSON).
    pub fn mission(&self) -> String {
        format!("{}/mission", self.prefix)
    }
    /// Membership queries answered by `robot`.
    pub fn members(&self, robot: &str) -> String {
        format!("{}/members/{robot}", self.prefix)
    }
    /// Sensor readings (JSON) for `robot`, from the simulator or its body.
    pub fn sensors(&self, robot: &str) -> String {
        format!("{}/sim/sensors/{robot}", self.prefix)
    }
    /// Velocity commands (JSON) from `robot` to its body.
    pub fn cmd(&self, robot: &str) -> String {
        format!("{}/sim/cmd/{robot}", self.prefix)
    }
    /// The simulated world's state (JSON), about once a second.
    pub fn world(&self) -> String {
        format!("{}/sim/world", self.prefix)
    }
    /// `<prefix>/<what>/*`: every robot's key of one kind.
    pub fn all(&self, what: &str) -> String {
        format!("{}/{what}/*", self.prefix)
    }
    /// The last chunk of a key expression (the robot's name).
    pub fn robot_of(key: &str) -> &str {
        key.rsplit('/').next().unwrap_or("")
    }
}

/// Check what a robot or the server is started with: team and robot names
/// usable as key-expression chunks, a clock speed in 0.01..=100.
pub(crate) fn check_team(team: &str, robots: &[&str], speed: f64) -> Result<(), String> {
    if let Some(bad) = std::iter::once(team)
        .chain(robots.iter().copied())
        .find(|n| !valid_chunk(n))
    {
        return Err(format!(
            "`{bad}`: team and robot names are letters, digits, `-`, `_` or `.`"
        ));
    }
    if !(speed.is_finite() && (0.01..=100.0).contains(&speed)) {
        return Err("--speed must be between 0.01 and 100".into());
    }
    Ok(())
}

/// A JSON-lines log file, its directory made if need be.
pub(crate) fn create_log(
    p: &std::path::Path,
) -> std::io::Result<std::io::BufWriter<std::fs::File>> {
    if let Some(d) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d)?;
    }
    Ok(std::io::BufWriter::new(std::fs::File::create(p)?))
}

/// Is `name` usable as a key-expression chunk (team or robot name)?
pub fn valid_chunk(name: &str) -> bool {
    !name.is_empty()
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_' || b == b'.')
}

#[cfg(test)]
mod tests {
    use super::Keys;

    #[test]
    fn frame_keys_name_their_sender() {
        let k = Keys::new("t");
        assert_eq!(Keys::sender_of(&k.net("r3")), "r3");
        assert_eq!(Keys::sender_of(&k.net_to("r3", "r7")), "r3");
        assert_eq!(Keys::sender_of("bite/t/status/r3"), "");
        assert_eq!(Keys::sender_of("bite/t/net"), "");
        assert_eq!(Keys::sender_of("other/t/net/r3"), "");
        assert_eq!(k.net_for("r7"), "bite/t/net/*/r7");
    }
}
