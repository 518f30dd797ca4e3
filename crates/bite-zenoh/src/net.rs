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
        refuse_low_latency(&c)?;
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

/// Zenoh's low-latency transport (`transport/unicast/lowlatency`) is
/// refused: with it, one robot process of ten hung at its start in two runs
/// of six (`bite bench zenoh`, 2026-11-28; docs/performance.md), and it was
/// slower per protocol hop in all of them. A configuration that the robot
/// runtime was seen to hang with is an error, not a surprise in the field.
fn refuse_low_latency(c: &zenoh::Config) -> Result<(), ConfigError> {
    let on = c
        .get_json("transport/unicast/lowlatency")
        .is_ok_and(|v| v.trim() == "true");
    if on {
        return Err(ConfigError(
            "transport/unicast/lowlatency = true is not supported by the robot runtime \
             (robot processes were seen to hang at start with it; see docs/zenoh-interface.md): \
             remove it"
                .into(),
        ));
    }
    Ok(())
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

/// The lowest port of the range the OS hands out for outgoing connections
/// (`/proc/sys/net/ipv4/ip_local_port_range` on Linux; elsewhere 32768,
/// Linux's default, which is below the IANA range from 49152 that other
/// systems use).
fn ephemeral_low() -> u16 {
    std::fs::read_to_string("/proc/sys/net/ipv4/ip_local_port_range")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .unwrap_or(32768)
}

/// Where [`free_ports`] looks first.
const PORT_BASE: u16 = 10_000;

/// `n` distinct TCP ports free on 127.0.0.1 now, for robots to listen on.
///
/// They are taken below the range the OS gives outgoing connections. A port
/// the OS picked (`127.0.0.1:0`) is in that range: released at once, it
/// could be taken by a teammate's outgoing connection before the robot
/// meant to listen on it started (`Address already in use`: the robot was
/// missing from its team). Below the range, only a process that binds that
/// very port can take it. Where to start is spread by the process id, so
/// that launches side by side look in different places, and by the ports
/// this process asked for before. Where the range leaves no room below it
/// (it was configured to start low), the OS picks, as before.
pub fn free_ports(n: usize) -> std::io::Result<Vec<u16>> {
    use std::net::TcpListener;
    let low = ephemeral_low();
    // Every port is held until all are chosen: no port twice.
    let mut held: Vec<TcpListener> = Vec::with_capacity(n);
    if low >= PORT_BASE + 4096 {
        // Successive calls in one process (tests running side by side)
        // start further on, past the ports handed out before.
        static CALLS: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let call = CALLS.fetch_add(n as u32, std::sync::atomic::Ordering::Relaxed);
        let span = u32::from(low - PORT_BASE);
        let start = std::process::id().wrapping_mul(7919).wrapping_add(call) % span;
        for k in 0..span {
            if held.len() == n {
                break;
            }
            let port = PORT_BASE + ((start + k) % span) as u16;
            if let Ok(l) = TcpListener::bind(("127.0.0.1", port)) {
                held.push(l);
            }
        }
    }
    while held.len() < n {
        held.push(TcpListener::bind("127.0.0.1:0")?);
    }
    held.iter()
        .map(|l| l.local_addr().map(|a| a.port()))
        .collect()
}

#[cfg(test)]
mod config_tests {
    use super::*;

    fn with_file(text: &str) -> Result<zenoh::Config, ConfigError> {
        let dir = std::env::temp_dir().join(format!(
            "bite-zenoh-config-{}-{}",
            std::process::id(),
            text.len()
        ));
        std::fs::create_dir_all(&dir).expect("dir");
        let p = dir.join("zenoh.json5");
        std::fs::write(&p, text).expect("write");
        let opts = NetOptions {
            config: Some(p),
            ..NetOptions::default()
        };
        let c = opts.zenoh_config();
        let _ = std::fs::remove_dir_all(&dir);
        c
    }

    #[test]
    fn the_low_latency_transport_is_refused_with_a_reason() {
        let e =
            with_file("{ transport: { unicast: { lowlatency: true, qos: { enabled: false } } } }")
                .expect_err("refused");
        assert!(e.to_string().contains("lowlatency"), "{e}");
        // Off, or not said: accepted, and multicast scouting is off.
        let c = with_file("{ transport: { unicast: { lowlatency: false } } }").expect("off");
        assert_eq!(
            c.get_json("scouting/multicast/enabled")
                .expect("key")
                .trim(),
            "false"
        );
        NetOptions::default().zenoh_config().expect("default");
    }
}

#[cfg(test)]
mod port_tests {
    use super::*;

    #[test]
    fn free_ports_are_distinct_bindable_and_below_outgoing_ports() {
        let ports = free_ports(12).expect("ports");
        assert_eq!(ports.len(), 12);
        let mut sorted = ports.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), 12, "distinct: {ports:?}");
        let low = ephemeral_low();
        for p in &ports {
            if low >= PORT_BASE + 4096 {
                assert!(
                    (PORT_BASE..low).contains(p),
                    "{p} not in {PORT_BASE}..{low}"
                );
            }
            std::net::TcpListener::bind(("127.0.0.1", *p)).expect("still free");
        }
    }
}
