//! # bite-agent
//!
//! One robot's mind, with no physics engine and no transport: what a robot
//! process runs (over Zenoh, `bite-zenoh`) and what the simulator runs for
//! each of its robots (`bite-sim`), the same code either way.
//!
//! - [`agent`]: the [`Agent`](agent::Agent): Algorithm 1's kernel
//!   (`bite-core`) driven one control tick at a time, every input through
//!   one `Input`, every duty through `AgentOutput`;
//! - [`pilot`]: behavior selection in the second paper's sense: the
//!   percepts a robot has, the beliefs they give, and the motor schemas of
//!   the leaf behavior;
//! - [`schema`]: motor schemas and command fusion (priority layers 0-3);
//! - [`plan`]: the route planner schemas use around obstacles;
//! - [`swarm`]: splitting an area among a swarm;
//! - [`spec`]: the robot's body and sensors as the scenario describes them;
//! - [`timed`]: timed skills, for worlds without physics;
//! - [`detector`]: the heartbeat failure detector (sans-IO);
//! - [`log`]: run-log records (events with names);
//! - [`record`]: a robot's inputs written down, and replayed;
//! - [`scenario`] and [`netmodel`]: the scenario file the mind reads.
//!
//! Architecture invariant: this crate never links a physics engine (rapier)
//! or a transport (zenoh), and reads no clock, socket or random source of
//! its own: time, messages, sensor readings and seeds come in as inputs
//! (checked by `tests/architecture.rs` in `bite-cli`).

#![warn(missing_docs)]

pub mod agent;
pub mod detector;
pub mod log;
pub mod netmodel;
pub mod pilot;
pub mod plan;
pub mod record;
pub mod scenario;
pub mod schema;
pub mod spec;
pub mod swarm;
pub mod timed;

pub use agent::{Agent, AgentOutput, Input, Shared, TIMER_SPIN_LIMIT};
pub use scenario::{MissionParts, Scenario};
