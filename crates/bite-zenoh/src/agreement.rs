//! Do the robots' run logs agree on every joint decision?
//!
//! A joint decision is a protocol instance (team, behavior, kind, epoch,
//! round) decided by two or more robots: a synchronization's choice, an
//! allocation's assignment, a termination. Every robot that logged an
//! `interaction_decided` record for the same instance must have logged the
//! same outcome (the agreement invariant of `../shared/DESIGN.md`).

use serde_json::Value;
use std::collections::BTreeMap;

/// What the check found.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Agreement {
    /// Instances decided by two or more robots.
    pub decisions: usize,
    /// Each instance on which robots disagree, described.
    pub disagreements: Vec<String>,
}

/// Check the logs of a team, each as (robot, records).
pub fn check(logs: &[(String, Vec<Value>)]) -> Agreement {
    let mut by_instance: BTreeMap<String, Vec<(&str, &Value)>> = BTreeMap::new();
    for (robot, records) in logs {
        for r in records {
            if r["event"] == "interaction_decided" {
                by_instance
                    .entry(r["instance"].to_string())
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
        if outcomes.iter().any(|(_, o)| *o != first) {
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
        let d = |o: &str| json!({"event": "interaction_decided", "instance": {"team": "root", "epoch": 1}, "outcome": {"choice": o}});
        let agree = check(&[("a".into(), vec![d("x")]), ("b".into(), vec![d("x")])]);
        assert_eq!(
            agree,
            Agreement {
                decisions: 1,
                disagreements: vec![]
            }
        );
        let differ = check(&[("a".into(), vec![d("x")]), ("b".into(), vec![d("y")])]);
        assert_eq!(differ.decisions, 1);
        assert_eq!(differ.disagreements.len(), 1);
        let alone = check(&[("a".into(), vec![d("x")]), ("b".into(), vec![])]);
        assert_eq!(alone.decisions, 0);
    }
}
