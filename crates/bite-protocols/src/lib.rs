//! # bite-protocols
//!
//! The library of social interaction behaviors: coordination protocols that
//! BITE's kernel runs at synchronization, allocation and termination points.
//! Each is a [`bite_core::interaction::Protocol`], registered by name in
//! [`registry`]; a graph or configuration file binds it to points.
//!
//! | name | paper | kind | messages per decision (team of n ≥ 2, no faults) |
//! |---|---|---|---|
//! | `sync.by-rule` | SF1 | sync | 0 |
//! | `sync.vote` | SF8 | sync | n + 1 (call, n−1 votes, result) |
//! | `alloc.by-id` | SF2 | allocate | 0 |
//! | `term.local` | — | terminate | 0 |
//! | `term.wait-all` | S3 | terminate | 2n − 1 (n−1 arrivals, n−1 acks, release) |
//!
//! The silent rules live in `bite-core` (they are also the kernel's
//! fallbacks); this crate adds the communicating protocols. Every protocol
//! here coordinates through the team leader (the lowest-id member), retries
//! on its binding's `retry` interval until answered, answers retransmissions
//! idempotently after deciding, and decides from what it knows when its
//! deadline passes.

#![warn(missing_docs)]

pub mod lap;
mod vote;
mod wait_all;

pub use vote::Vote;
pub use wait_all::WaitAll;

use bite_core::interaction::Registry;
use std::sync::Arc;

/// Every protocol of the library, with the kernel's silent rules.
pub fn registry() -> Registry {
    let mut r = Registry::core();
    r.register(Arc::new(WaitAll));
    r.register(Arc::new(Vote));
    r
}
