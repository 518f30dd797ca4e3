//! How a team shares what its robots perceive (the world-model section of
//! a graph or configuration): which of the paper's algorithms, and its
//! budget. The world model (`crate::wm`) runs it.

use serde::{Deserialize, Serialize};
use std::fmt;

/// Which information-sharing algorithm a team runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Policy {
    /// No world-model messages (each robot believes what it perceives).
    #[default]
    None,
    /// Every change of every belief to every teammate.
    Broadcast,
    /// Algorithm 2.
    Focused,
    /// Algorithm 3.
    Helpful,
    /// Algorithms 2 and 3, obligatory messages first.
    FocusedHelpful,
}

impl Policy {
    /// All policies, for help texts.
    pub const NAMES: [&'static str; 5] =
        ["none", "broadcast", "focused", "helpful", "focused+helpful"];

    /// Parse a policy name.
    pub fn parse(s: &str) -> Option<Policy> {
        Some(match s {
            "none" => Policy::None,
            "broadcast" => Policy::Broadcast,
            "focused" => Policy::Focused,
            "helpful" => Policy::Helpful,
            "focused+helpful" | "helpful+focused" => Policy::FocusedHelpful,
            _ => return None,
        })
    }
    /// A policy that sends what either sends: broadcast with either
    /// broadcasting, else Algorithm 2 if either runs it and Algorithm 3 if
    /// either runs it (a mission whose commands need different sharing
    /// gets all of it).
    pub fn union(self, other: Policy) -> Policy {
        if self == Policy::Broadcast || other == Policy::Broadcast {
            return Policy::Broadcast;
        }
        match (
            self.focused() || other.focused(),
            self.helpful() || other.helpful(),
        ) {
            (true, true) => Policy::FocusedHelpful,
            (true, false) => Policy::Focused,
            (false, true) => Policy::Helpful,
            (false, false) => Policy::None,
        }
    }

    pub(crate) fn focused(self) -> bool {
        matches!(self, Policy::Focused | Policy::FocusedHelpful)
    }
    pub(crate) fn helpful(self) -> bool {
        matches!(self, Policy::Helpful | Policy::FocusedHelpful)
    }
}

impl fmt::Display for Policy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Policy::None => "none",
            Policy::Broadcast => "broadcast",
            Policy::Focused => "focused",
            Policy::Helpful => "helpful",
            Policy::FocusedHelpful => "focused+helpful",
        })
    }
}

/// A team's world-model settings (`world_model:` in a graph or a
/// configuration).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sharing {
    /// The algorithm.
    pub policy: Policy,
    /// How often it decides what to share, per second.
    pub hz: f64,
    /// Messages per second each robot may send (one per recipient);
    /// `None`: unlimited.
    pub budget: Option<f64>,
}

impl Default for Sharing {
    fn default() -> Self {
        Sharing {
            policy: Policy::None,
            hz: 10.0,
            budget: None,
        }
    }
}

impl Sharing {
    /// These settings with a `world_model:` section laid over them;
    /// mistakes are reported at the section.
    pub fn with_spec(
        self,
        file: &std::sync::Arc<str>,
        spec: &serde_saphyr::Spanned<crate::graph::spec::WorldModelSpec>,
        diags: &mut Vec<crate::diag::Diagnostic>,
    ) -> Sharing {
        use crate::diag::{Diagnostic, Loc, did_you_mean};
        let loc = Loc::from(spec.referenced);
        let w = &spec.value;
        let mut out = self;
        // Each value's error at the value, not at the section.
        let at = |l: serde_saphyr::Location| match Loc::from(l) {
            l if l.is_known() => l,
            _ => loc,
        };
        if let Some(spanned) = &w.sharing {
            let name = &spanned.value;
            match Policy::parse(name) {
                Some(p) => out.policy = p,
                None => {
                    let mut d = Diagnostic::error(
                        file,
                        at(spanned.referenced),
                        "bad-sharing",
                        format!("unknown sharing policy `{name}`"),
                    );
                    d.hint = did_you_mean(name, Policy::NAMES).or_else(|| {
                        Some(format!("the policies are: {}", Policy::NAMES.join(", ")))
                    });
                    diags.push(d);
                }
            }
        }
        if let Some(spanned) = &w.hz {
            let hz = spanned.value;
            if hz.is_finite() && hz > 0.0 && hz <= 1000.0 {
                out.hz = hz;
            } else {
                diags.push(Diagnostic::error(
                    file,
                    at(spanned.referenced),
                    "bad-value",
                    format!("`hz` is decisions per second, above 0 and at most 1000, found {hz}"),
                ));
            }
        }
        if let Some(spanned) = &w.budget {
            let b = spanned.value;
            if b.is_finite() && b > 0.0 {
                out.budget = Some(b);
            } else {
                diags.push(Diagnostic::error(
                    file,
                    at(spanned.referenced),
                    "bad-value",
                    format!("`budget` is messages per second, above 0, found {b}"),
                ));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::Policy;

    #[test]
    fn a_union_sends_what_either_sends() {
        use Policy::*;
        let all = [None, Broadcast, Focused, Helpful, FocusedHelpful];
        for a in all {
            assert_eq!(a.union(None), a);
            assert_eq!(a.union(a), a);
            assert_eq!(a.union(Broadcast), Broadcast);
            for b in all {
                let u = a.union(b);
                assert_eq!(u, b.union(a));
                if u != Broadcast {
                    assert_eq!(u.focused(), a.focused() || b.focused());
                    assert_eq!(u.helpful(), a.helpful() || b.helpful());
                }
            }
        }
        assert_eq!(Focused.union(Helpful), FocusedHelpful);
    }
}
