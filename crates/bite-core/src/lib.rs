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

/// A map of `pairs`, the last of equal keys kept (as inserting them in
/// order would); sorted on rayon's pool when `parallel` (the graph loader
/// and the mission compiler fill their large maps this way).
pub fn sorted_map<K: Ord + Send, V: Send>(
    mut pairs: Vec<(K, V)>,
    parallel: bool,
) -> std::collections::BTreeMap<K, V> {
    if parallel {
        use rayon::prelude::*;
        // Stable: equal keys stay in order, and the map keeps the last.
        pairs.par_sort_by(|a, b| a.0.cmp(&b.0));
    }
    pairs.into_iter().collect()
}

pub use graph::{BehaviorGraph, Config};
pub use ids::{BehaviorId, BeliefId, RobotId, TeamId};
pub use kernel::{Input, Kernel, Output};
pub use mission::Mission;
pub use time::Time;
pub use value::Value;
