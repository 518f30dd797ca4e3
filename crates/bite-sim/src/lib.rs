//! # bite-sim
//!
//! Simulators that drive BITE kernels. This crate holds the
//! coordination-only simulator: a deterministic discrete-event runner in
//! which N kernels talk over a seeded simulated network (latency, jitter,
//! loss, duplication, reordering, partitions) and act in a *timed-skill
//! world*, where a skill sets its completion beliefs after a duration drawn
//! from the scenario. No physics: this is what lets teams of thousands be
//! studied and tested.
//!
//! - [`scenario`]: scenario files;
//! - [`net`]: the simulated network;
//! - [`world`]: the timed-skill world;
//! - [`runner`]: the event loop, run logs and reports;
//! - [`summary`]: what a run cost;
//! - [`check`]: invariants checked as a run goes, on every run;
//! - [`fault`]: faults as one-line specs laid over a scenario;
//! - [`sweep`]: the fault matrix as a plan of independent runs;
//! - [`stall`]: runs that make no progress or go round in circles;
//! - [`probe`]: one coordination point under one protocol, measured.

#![warn(missing_docs)]

pub mod agent;
pub mod check;
pub mod fault;
pub mod log;
pub mod net;
pub mod physics;
pub mod probe;
pub mod record;
pub mod runner;
pub mod scenario;
pub mod stall;
pub mod summary;
pub mod sweep;
pub mod world;

pub use runner::{RunOptions, RunReport, prepare, run};
pub use scenario::{MissionParts, Scenario};
