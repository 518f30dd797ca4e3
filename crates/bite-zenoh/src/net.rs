//! The Zenoh session's configuration and the team clock.

use bite_core::time::Time;
use std::path::Path;
use std::time::Duration;

/// How a process joins the Zenoh network.
#[derive(Clone, Debug, Default)]
pub struct NetOptions {
    /// A Zenoh configuration file (JSON5): TLS, access control, routers...
    /// The options below are laid over it.
    pub config: Option<std::path::PathBuf>,
    /// Endpoints to listen on, e.g. `tcp/127.0.0.1:7447`.
    pub listen: Vec<String>,
    /// Endpoints to connect to.
    pub connect: Vec<String>,
    /// Multicast scouting (off unless asked for; it may be unavailable,
    /// and it must never be pointed at a real network card in tests).
    pub multicast: bool,
    /// The interface multicast scouting uses (e.g. `lo`).
    pub multicast_interface: Option<String>,
    /// `peer` (default) or `client` (through a `zenohd` router).
    pub mode: Option<String>,
}

/// Why a configuration could not be made.
#[derive(Debug, thiserror::Error)]
#[error("zenoh configuration: {0}")]
pub struct ConfigError(pub String);

impl NetOptions {
    /// The Zenoh configuration.
    pub fn zenoh_config(&self) -> Result<zenoh::Config, ConfigError> {
        let mut c = match &self.config {
            Some(p) => load(p)?,
            None => zenoh::Config::default(),
        };
        let set = |c: &mut zenoh::Config, k: &str, v: String| {
            c.insert_json5(k, &v)
                .map_err(|e| ConfigError(format!("{k} = {v}: {e}")))
        };
        if let Some(m) = &self.mode {
            set(&mut c, "mode", json(m))?;
        } else if self.config.is_none() {
            set(&mut c, "mode", json("peer"))?;
        }
        // Off unless asked for, whatever the file says (Zenoh's own
        // default is on).
        set(
            &mut c,
            "scouting/multicast/enabled",
            self.multicast.to_string(),
        )?;
        if let Some(i) = &self.multicast_interface {
            set(&mut c, "scouting/multicast/interface", json(i))?;
        }
        if !self.listen.is_empty() {
            set(&mut c, "listen/endpoints", list(&self.listen))?;
        }
        if !self.connect.is_empty() {
            set(&mut c, "connect/endpoints", list(&self.connect))?;
        }
        Ok(c)
    }

    /// Open a session.
    pub fn open(&self) -> Result<zenoh::Session, ConfigError> {
        use zenoh::Wait;
        let c = self.zenoh_config()?;
        zenoh::open(c)
            .wait()
            .map_err(|e| ConfigError(format!("cannot open the session: {e}")))
    }
}

fn load(p: &Path) -> Result<zenoh::Config, ConfigError> {
    if !p.exists() {
        return Err(ConfigError(format!("{} does not exist", p.display())));
    }
    zenoh::Config::from_file(p).map_err(|e| ConfigError(format!("{}: {e}", p.display())))
}

fn json(s: &str) -> String {
    serde_json::Value::String(s.to_string()).to_string()
}

fn list(v: &[String]) -> String {
    serde_json::Value::from(v.to_vec()).to_string()
}

/// Microseconds since the Unix epoch, from the system clock. The one place
/// the Zenoh runtime reads the wall clock.
#[allow(clippy::disallowed_methods)]
pub fn unix_micros() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64)
}

/// The team's clock: time since a shared origin, optionally sped up (for
/// tests against a simulator server running faster than real time).
#[derive(Clone, Copy, Debug)]
pub struct Clock {
    /// Origin, microseconds since the Unix epoch.
    pub origin_us: u64,
    /// Team seconds per wall second.
    pub speed: f64,
}

impl Clock {
    /// Team time now (zero before the origin).
    pub fn now(&self) -> Time {
        self.at(unix_micros())
    }

    /// Team time at wall time `us`.
    pub fn at(&self, us: u64) -> Time {
        let wall = us.saturating_sub(self.origin_us) as f64 / 1e6;
        Time::from_secs_f64(wall * self.speed)
    }

    /// The wall time (µs since the Unix epoch) at which team time `t` comes.
    pub fn wall_at(&self, t: Time) -> u64 {
        let after = (t.as_secs_f64() / self.speed * 1e6) as u64;
        self.origin_us.saturating_add(after)
    }

    /// The wall duration of `d` of team time.
    pub fn wall(&self, d: Duration) -> Duration {
        Duration::from_secs_f64(d.as_secs_f64() / self.speed)
    }
}
