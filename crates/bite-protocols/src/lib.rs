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
//! | `sync.leader` | SF4 | sync | 1 |
//! | `sync.elected-leader` | SF5 | sync | n |
//! | `sync.round-robin` | SF7 | sync | 0 |
//! | `sync.vote` | SF8 | sync | n + 1 |
//! | `sync.ranked-vote` | SF9 | sync | n + 1 |
//! | `alloc.by-id` | SF2 | allocate | 0 |
//! | `alloc.by-value` | SF3 | allocate | n |
//! | `alloc.by-attribute` | SF6 | allocate | n |
//! | `alloc.auction` | S2 | allocate | P calls + bids (≤ P(n−1)) + 1, P places |
//! | `alloc.optimal` | — | allocate | n |
//! | `alloc.token` | — | allocate | 2P + passes + 1 − (leader's own); 2n − 1 with n places and no passes |
//! | `term.local` | — | terminate | 0 |
//! | `term.wait-all` | S3 | terminate | 2n − 1 |
//! | `term.majority` | — | terminate | ≈ 2⌊n/2⌋ + ⌈n/2⌉ |
//! | `term.first-wins` | — | terminate | n (goal seen) |
//!
//! The silent rules `sync.by-rule`, `alloc.by-id` and `term.local` live in
//! `bite-core` (they are also the kernel's fallbacks); this crate adds the
//! rest. Every communicating protocol here coordinates through the team
//! leader (the lowest-id live member), retries on its binding's `retry`
//! interval until answered, answers retransmissions idempotently after
//! deciding, decides from what it knows when its deadline passes, and goes
//! on without members presumed lost (a new leader takes over a lost one).
//! `docs/protocols.md` is the user's reference, with measured counts.

#![warn(missing_docs)]

mod alloc;
mod auction;
mod barrier;
mod gather;
pub mod graphdef;
pub mod lap;
mod sync;
mod token;

pub use alloc::{ByAttribute, ByValue, Optimal};
pub use auction::Auction;
pub use barrier::{FirstWins, Majority, WaitAll};
pub use sync::{ElectedLeader, Leader, RankedVote, RoundRobin, Vote};
pub use token::TokenPassing;

use bite_core::interaction::Registry;
use std::sync::Arc;

/// Every protocol of the library, with the kernel's silent rules.
pub fn registry() -> Registry {
    let mut r = Registry::core();
    r.register(Arc::new(Vote));
    r.register(Arc::new(RankedVote));
    r.register(Arc::new(Leader));
    r.register(Arc::new(ElectedLeader));
    r.register(Arc::new(RoundRobin));
    r.register(Arc::new(ByValue));
    r.register(Arc::new(ByAttribute));
    r.register(Arc::new(Optimal));
    r.register(Arc::new(Auction));
    r.register(Arc::new(TokenPassing));
    r.register(Arc::new(WaitAll));
    r.register(Arc::new(Majority));
    r.register(Arc::new(FirstWins));
    // The graph-defined protocols of `examples/protocols/` (parsed once).
    let builtins = r.clone();
    for p in graphdef::shipped(&builtins) {
        r.register(p.clone());
    }
    r
}

/// Add the protocols of these files (graph-defined, in order: a file may
/// `use` the protocols before it) to `registry`.
pub fn load_protocol_files(
    registry: &mut Registry,
    files: &[std::path::PathBuf],
) -> Result<(), bite_core::diag::Diagnostics> {
    for f in files {
        let p = graphdef::GraphProtocol::load(f, registry)?;
        graphdef::register(registry, p);
    }
    Ok(())
}
