//! Do the robots' run logs agree on every joint decision?
//!
//! A joint decision is a protocol instance (team, behavior, kind, epoch,
//! round) decided by two or more robots: a synchronization's choice, an
//! allocation's assignment, a termination. Every robot that logged an
//! `interaction_decided` record for the same instance must have logged the
//! same outcome (the agreement invariant of `../shared/DESIGN.md`) — when
//! the protocol communicates and decided before its deadline. A silent
//! rule decides from what each robot perceives: robots that perceived
//! differently may differ (a *split*, healed through the heartbeats; the
//! full invariant checker, `bite_sim::check::check_logs`, holds them to
//! exactly what `docs/protocols.md` promises), so they are only counted.

use serde_json::Value;
use std::collections::BTreeMap;

/// What the check found.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Agreement {
    /// Instances decided by two or more robots.
    pub decisions: usize,
    /// Each instance of a communicating protocol on which robots disagree
    /// (without a deadline), described.
    pub disagreements: Vec<String>,
    /// Instances of silent rules (or decided at a deadline) on which
    /// robots differ: splits, which the team heals.
    pub splits: usize,
}

/// Check the logs of a team, each as (robot, records); `communicates`
/// tells a protocol (by name) that exchanges messages from a silent rule.
pub fn check(logs: &[(String, Vec<Value>)], communicates: impl Fn(&str) -> bool) -> Agreement {
    let mut by_instance: BTreeMap<String, Vec<(&str, &Value)>> = BTreeMap::new();
    let mut silent = std::collections::BTreeSet::new();
    for (robot, records) in logs {
        for r in records {
            if r["event"] == "interaction_decided" {
                let key = r["instance"].to_string();
                if r["timed_out"] == true || !communicates(r["protocol"].as_str().unwrap_or("")) {
                    silent.insert(key.clone());
                }
                by_instance
                    .entry(key)
                    .or_default()
                    .push((robot.as_str(), &r["outcome"]));
            }
        }
    }
    let mut a = Agreement::default();
    for (instance, outcomes) in &by_instance {
        let robots: std::collections::BTreeSet<&str> = outcomes.iter().map(|(r, _)| *r).collect();
        if robots.len() < 2 {
            continue;
        }
        a.decisions += 1;
        let first = outcomes[0].1;
        if outcomes.iter().any(|(_, o)| *o != first) && silent.contains(instance) {
            a.splits += 1;
        } else if outcomes.iter().any(|(_, o)| *o != first) {
            let said: Vec<String> = outcomes.iter().map(|(r, o)| format!("{r}: {o}")).collect();
            a.disagreements
                .push(format!("{instance}: {}", said.join("; ")));
        }
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn agreement_and_disagreement() {
        let d = |o: &str| json!({"event": "interaction_decided", "protocol": "sync.vote", "instance": {"team": "root", "epoch": 1}, "outcome": {"choice": o}});
        let all = |_: &str| true;
        let agree = check(
            &[("a".into(), vec![d("x")]), ("b".into(), vec![d("x")])],
            all,
        );
        assert_eq!(
            agree,
            Agreement {
                decisions: 1,
                disagreements: vec![],
                splits: 0,
            }
        );
        let differ = check(
            &[("a".into(), vec![d("x")]), ("b".into(), vec![d("y")])],
            all,
        );
        assert_eq!(differ.decisions, 1);
        assert_eq!(differ.disagreements.len(), 1);
        // The same under a silent rule: a split, not a disagreement.
        let split = check(
            &[("a".into(), vec![d("x")]), ("b".into(), vec![d("y")])],
            |_| false,
        );
        assert_eq!((split.disagreements.len(), split.splits), (0, 1));
        let alone = check(&[("a".into(), vec![d("x")]), ("b".into(), vec![])], all);
        assert_eq!(alone.decisions, 0);
    }
}
