//! # bite-core
//!
//! The sans-IO core of BITE (Bar Ilan Teamwork Engine) in Rust, after
//! Kaminka & Frenkel, *Integration of Coordination Mechanisms in the BITE
//! Multi-Robot Architecture*.
//!
//! - [`graph`]: the task behavior graph ⟨B, S, V, b0⟩, its YAML format,
//!   validation, and the automatic analysis of synchronization, allocation
//!   and termination points;
//! - [`cond`] and [`belief`]: the condition language of preconditions and
//!   termination conditions, and the belief store it reads;
//! - [`org`] and [`members`]: the organization (team) hierarchy and its
//!   links to behaviors; sets of robots and allocations of them;
//! - [`interaction`] and [`rules`]: the social interaction behaviors — the
//!   pluggable protocol interface, its registry, and the silent rules built
//!   into the kernel;
//! - [`kernel`]: Algorithm 1, one state machine per robot;
//! - [`msg`]: coordination messages and their wire encoding.
//!
//! Nothing in this crate reads a clock, a socket or an OS random source.
//! Runtimes (the simulators, the Zenoh robot process) drive it.

#![warn(missing_docs)]

pub mod belief;
pub mod cond;
pub mod diag;
pub mod event;
pub mod graph;
pub mod hint;
pub mod ids;
pub mod interaction;
pub mod kernel;
pub mod members;
pub mod mission;
pub mod msg;
pub mod org;
pub mod roster;
pub mod rules;
pub mod time;
pub mod value;
pub mod wm;
pub mod yaml;

pub use graph::{BehaviorGraph, Config};
pub use ids::{BehaviorId, BeliefId, RobotId, TeamId};
pub use kernel::{Input, Kernel, Output};
pub use mission::Mission;
pub use time::Time;
pub use value::Value;
