//! # bite-sim
//!
//! The deterministic simulator of BITE teams: a discrete-event runner that
//! drives one [`bite_agent::Agent`] per robot (the same mind a robot
//! process runs) over a seeded simulated network (latency, jitter, loss,
//! duplication, reordering, partitions), in one of two worlds: the
//! *timed-skill world* (skills take a drawn time; no physics, so teams of
//! thousands can be studied) or the *physical world* (a 2-D arena on
//! rapier2d with range sensors and a camera: the robots' bodies).
//!
//! The mind (behavior selection, motor schemas, command fusion, timed
//! skills, the scenario it reads) lives in `bite-agent`; this crate keeps
//! the scheduler, the simulated network, the bodies and reporting.
//!
//! - [`net`]: the simulated network;
//! - [`physics`]: the bodies: rapier2d arena, sensors, pictures;
//! - [`runner`]: the event loop, run logs and reports;
//! - [`summary`]: what a run cost;
//! - [`check`]: invariants checked as a run goes, on every run;
//! - [`fault`]: faults as one-line specs laid over a scenario;
//! - [`sweep`]: the fault matrix as a plan of independent runs;
//! - [`stall`]: runs that make no progress or go round in circles;
//! - [`probe`]: one coordination point under one protocol, measured.

#![warn(missing_docs)]

pub mod chatter;
pub mod check;
pub mod fault;
pub mod log;
pub mod net;
pub mod physics;
pub mod probe;
mod queue;
pub mod runner;
pub mod stall;
pub mod summary;
pub mod sweep;

/// The scenario a run is made of (from `bite-agent`, where the mind reads it).
pub use bite_agent::scenario::{MissionParts, Scenario};
pub use runner::{RunOptions, RunReport, prepare, run};
