//! A new version of a running mission's graph, numbered like the old one.
//!
//! Robots of a team switch to a new version of their mission at different
//! times (each subteam at its own safe point), and until then they talk about
//! behaviors by id: instance keys, positions, team ids all carry
//! [`BehaviorId`]s, and beliefs are stored by [`BeliefId`]. A new version
//! is therefore *aligned* to the one it replaces before it runs:
//!
//! - a behavior kept (same name) keeps its id; a new behavior gets a new id
//!   after every old one;
//! - a behavior the new version removes stays in the graph, *retired*: an
//!   exact copy of its old definition that nothing in the new version leads
//!   to. Robots that are inside it when they switch finish it as they
//!   started it and go on to its successors; nobody selects it again;
//! - belief names keep their ids; new names are added after the old ones.
//!
//! Conditions are parsed again from their source against the aligned
//! names (they parsed once, so they parse again).
//!
//! A version that cannot be aligned is refused with the reason: another
//! roster, or a behavior kept by name that changes from composite to atomic
//! or from team to individual (robots inside it would be left with frames
//! the new version cannot end as the old one would).

use super::{Behavior, BehaviorGraph};
use crate::belief::Symbols;
use crate::cond::{Expr, Resolver};
use crate::ids::{BehaviorId, BeliefId};
use std::collections::BTreeMap;
use std::sync::Arc;

/// Why a new version of a mission cannot replace the running one.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct Refused(pub String);

struct Aligned<'a> {
    symbols: &'a mut Symbols,
    by_name: &'a BTreeMap<String, BehaviorId>,
}

impl Resolver for Aligned<'_> {
    fn belief(&mut self, name: &str) -> BeliefId {
        self.symbols.intern(name)
    }
    fn behavior(&self, name: &str) -> Option<BehaviorId> {
        self.by_name.get(name).copied()
    }
    fn behavior_names(&self) -> Vec<&str> {
        self.by_name.keys().map(String::as_str).collect()
    }
}

impl BehaviorGraph {
    /// This graph, a new version of `base` (the running one), renumbered
    /// like it (see the module documentation).
    pub fn aligned_to(&self, base: &BehaviorGraph) -> Result<BehaviorGraph, Refused> {
        if self.roster.names() != base.roster.names() {
            return Err(Refused(format!(
                "the team differs: the mission runs with [{}], the new version names [{}]",
                base.roster.names().join(", "),
                self.roster.names().join(", ")
            )));
        }
        // Ids: the old ones first, then the new names in file order.
        let mut by_name: BTreeMap<String, BehaviorId> = BTreeMap::new();
        for b in &base.behaviors {
            by_name.insert(b.name.clone(), b.id);
        }
        let mut next = base.behaviors.len() as u32;
        for b in &self.behaviors {
            if !by_name.contains_key(&b.name) {
                by_name.insert(b.name.clone(), BehaviorId(next));
                next += 1;
            }
        }
        let remap = |id: BehaviorId| by_name[&self.behaviors[id.index()].name];
        for old in &base.behaviors {
            let Some(new) = self.find(&old.name).map(|id| self.behavior(id)) else {
                continue;
            };
            if !old.is_atomic() && new.is_atomic() {
                return Err(Refused(format!(
                    "behavior `{}` has children in the running version and none in the new one: \
                     robots inside it could not end it; give the new behavior another name",
                    old.name
                )));
            }
            if old.team != new.team {
                return Err(Refused(format!(
                    "behavior `{}` changes from {} to {} behavior: its members could not agree \
                     how it ends; give the new behavior another name",
                    old.name,
                    if old.team { "a team" } else { "an individual" },
                    if new.team { "a team" } else { "an individual" },
                )));
            }
        }
        let mut symbols: Symbols = (*base.symbols).clone();
        let mut out: Vec<Option<Behavior>> = vec![None; next as usize];
        let mut retired = base.retired.clone();
        for old in &base.behaviors {
            if self.find(&old.name).is_none() {
                out[old.id.index()] = Some(old.clone());
                if !retired.contains(&old.id) {
                    retired.push(old.id);
                }
            }
        }
        for b in &self.behaviors {
            let id = by_name[&b.name];
            let mut resolver = Aligned {
                symbols: &mut symbols,
                by_name: &by_name,
            };
            let mut reparse = |e: &Option<Box<Expr>>| -> Result<Option<Box<Expr>>, Refused> {
                e.as_ref()
                    .map(|e| {
                        Expr::parse(e.source(), &mut resolver).map(Box::new).map_err(|err| {
                            Refused(format!(
                                "a condition of `{}` does not read alike in the running version: {err:?}",
                                b.name
                            ))
                        })
                    })
                    .transpose()
            };
            let aligned = Behavior {
                id,
                children: b.children.iter().map(|c| remap(*c)).collect(),
                next: b.next.iter().map(|c| remap(*c)).collect(),
                pre: reparse(&b.pre)?,
                until: reparse(&b.until)?,
                urgent: reparse(&b.urgent)?,
                utility: reparse(&b.utility)?,
                ..b.clone()
            };
            retired.retain(|r| *r != id);
            out[id.index()] = Some(aligned);
        }
        let start = remap(self.start);
        let behaviors: Vec<Behavior> = out.into_iter().flatten().collect();
        debug_assert_eq!(behaviors.len(), next as usize);
        retired.sort();
        Ok(BehaviorGraph {
            names: super::NameIndex::new(behaviors.len(), |i| &behaviors[i].name),
            behaviors,
            start,
            symbols: Arc::new(symbols),
            retired,
            ..self.clone()
        })
    }

    /// True when `b` belongs to an older version only (see
    /// [`BehaviorGraph::aligned_to`]).
    pub fn is_retired(&self, b: BehaviorId) -> bool {
        self.retired.binary_search(&b).is_ok()
    }

    /// The behaviors whose definition differs between `base` and this
    /// aligned version of it (added, removed or edited), by name.
    pub fn changed_since(&self, base: &BehaviorGraph) -> Vec<String> {
        let differs = |a: &Behavior, b: &Behavior| {
            let src = |e: &Option<Box<Expr>>| e.as_ref().map(|e| e.source().to_string());
            a.children != b.children
                || a.next != b.next
                || a.team != b.team
                || src(&a.pre) != src(&b.pre)
                || src(&a.until) != src(&b.until)
                || src(&a.urgent) != src(&b.urgent)
                || src(&a.utility) != src(&b.utility)
                || a.skill != b.skill
                || a.members != b.members
                || a.critical != b.critical
                || !a
                    .bindings
                    .iter()
                    .zip(&b.bindings)
                    .all(|(x, y)| match (x, y) {
                        (Some(x), Some(y)) => {
                            (&x.protocol, x.deadline, x.retry, &x.params)
                                == (&y.protocol, y.deadline, y.retry, &y.params)
                        }
                        (x, y) => x.is_none() && y.is_none(),
                    })
        };
        let mut out = Vec::new();
        for b in &self.behaviors {
            let was = base.get(b.id).filter(|o| !base.is_retired(o.id));
            match was {
                Some(o) if self.is_retired(b.id) || differs(o, b) => out.push(b.name.clone()),
                None if !self.is_retired(b.id) => out.push(b.name.clone()),
                _ => {}
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn graph(text: &str) -> BehaviorGraph {
        super::super::load_str(&Arc::from("t.yaml"), text).expect("loads")
    }

    const OLD: &str = "
graph: course
team: {robots: 3}
start: go
behaviors:
  go: {team: true, children: [a], until: done}
  a: {next: [b], until: at_a}
  b: {until: at_b}
";
    const NEW: &str = "
graph: course
team: {robots: 3}
start: go
behaviors:
  c: {until: at_c and ready}
  go: {team: true, children: [a], until: done}
  a: {next: [c], until: at_a}
";

    #[test]
    fn kept_behaviors_and_beliefs_keep_their_ids_and_removed_ones_retire() {
        let old = graph(OLD);
        let new = graph(NEW).aligned_to(&old).expect("aligns");
        for name in ["go", "a", "b"] {
            assert_eq!(new.find(name), old.find(name), "{name}");
        }
        let c = new.find("c").expect("c is there");
        assert_eq!(c.index(), 3, "a new behavior comes after the old ones");
        let b = new.find("b").expect("b is kept, retired");
        assert!(new.is_retired(b) && !new.is_retired(c));
        assert_eq!(new.behavior(new.find("a").unwrap()).next, vec![c]);
        for (id, name) in old.symbols().iter() {
            assert_eq!(new.symbols().get(name), Some(id), "{name}");
        }
        assert!(new.symbols().get("ready").is_some());
        for b in new.behaviors() {
            assert_eq!(new.find(&b.name), Some(b.id));
        }
        let mut changed = new.changed_since(&old);
        changed.sort();
        assert_eq!(changed, ["a", "b", "c"]);
        // Aligning again to the aligned version is the identity.
        let again = graph(NEW).aligned_to(&new).expect("aligns");
        assert!(again.changed_since(&new).is_empty());
        assert!(again.is_retired(b));
    }

    #[test]
    fn unsafe_versions_are_refused_with_the_reason() {
        let old = graph(OLD);
        let atomic = OLD.replace("children: [a], ", "");
        let e = graph(&atomic.replace("  a: {next: [b], until: at_a}\n  b: {until: at_b}\n", ""))
            .aligned_to(&old)
            .unwrap_err();
        assert!(e.0.contains("`go` has children"), "{e}");
        let e = graph(&OLD.replace("robots: 3", "robots: 4"))
            .aligned_to(&old)
            .unwrap_err();
        assert!(e.0.contains("team differs"), "{e}");
        let e = graph(&OLD.replace("go: {team: true,", "go: {"))
            .aligned_to(&old)
            .unwrap_err();
        assert!(e.0.contains("`go` changes from a team"), "{e}");
    }
}
