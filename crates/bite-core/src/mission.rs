//! A mission: a behavior graph with a protocol resolved and configured at
//! every coordination point. Shared (behind an `Arc`) by all kernels of a
//! team running in one process.

use crate::diag::{Diagnostic, Diagnostics, Loc, did_you_mean};
use crate::graph::{BehaviorGraph, Binding};
use crate::ids::BehaviorId;
use crate::interaction::{ChildSlot, Factory, Params, Protocol, Registry, Setup};
use crate::msg::Kind;
use std::fmt;
use std::sync::Arc;
use std::time::Duration;

/// Retransmission interval when a binding does not give one.
pub const DEFAULT_RETRY: Duration = Duration::from_millis(500);

/// The protocol bound at one point, configured.
#[derive(Clone)]
pub struct Bound {
    /// Point name (label or `behavior.kind`).
    pub point: String,
    /// The protocol.
    pub protocol: Arc<dyn Protocol>,
    /// Creates instances configured with the binding's parameters.
    pub factory: Factory,
    /// Deadline of each instance.
    pub deadline: Duration,
    /// Retransmission interval.
    pub retry: Duration,
    /// The parameters as written.
    pub params: Params,
}

impl fmt::Debug for Bound {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Bound")
            .field("point", &self.point)
            .field("protocol", &self.protocol.name())
            .field("deadline", &self.deadline)
            .field("retry", &self.retry)
            .finish()
    }
}

/// A graph ready to run.
#[derive(Debug)]
pub struct Mission {
    graph: Arc<BehaviorGraph>,
    bound: Vec<[Option<Bound>; 3]>,
    slots: Vec<Vec<ChildSlot>>,
}

impl Mission {
    /// Resolve every point's binding against `registry`: the protocol must
    /// exist, be of the point's kind, and accept its parameters.
    pub fn new(mut graph: BehaviorGraph, registry: &Registry) -> Result<Mission, Diagnostics> {
        let mut diags = Vec::new();
        // Expressions in protocol parameters may name beliefs no condition
        // of the graph mentions: they join the symbol table.
        let mut symbols = (**graph.symbols()).clone();
        let mut bound: Vec<[Option<Bound>; 3]> = Vec::with_capacity(graph.len());
        for b in graph.behaviors() {
            let mut row: [Option<Bound>; 3] = [None, None, None];
            for kind in Kind::ALL {
                if graph.is_point(b.id, kind) {
                    let mut setup = Setup::new(&graph, &mut symbols, b.id, kind);
                    row[kind.index()] = resolve(registry, &mut setup, &mut diags);
                }
            }
            bound.push(row);
        }
        // Defaults that no point uses are still checked, so that a typo in
        // a configuration is not silently ignored.
        for kind in Kind::ALL {
            if let Some(d) = graph.default_binding(kind)
                && let Some(name) = &d.protocol
            {
                check_protocol(
                    registry,
                    name,
                    kind,
                    &format!("default {kind}"),
                    d,
                    &mut diags,
                );
            }
        }
        if !diags.is_empty() {
            return Err(Diagnostics(diags));
        }
        graph.set_symbols(Arc::new(symbols));
        let slots = graph
            .behaviors()
            .iter()
            .map(|b| {
                b.children
                    .iter()
                    .map(|c| {
                        let (min, max) = graph.behavior(*c).members;
                        ChildSlot {
                            behavior: *c,
                            min,
                            max,
                        }
                    })
                    .collect()
            })
            .collect();
        Ok(Mission {
            graph: Arc::new(graph),
            bound,
            slots,
        })
    }

    /// The graph.
    pub fn graph(&self) -> &Arc<BehaviorGraph> {
        &self.graph
    }
    /// The protocol bound at point (`b`, `kind`), if `b` is such a point.
    pub fn bound(&self, b: BehaviorId, kind: Kind) -> Option<&Bound> {
        self.bound
            .get(b.index())
            .and_then(|r| r[kind.index()].as_ref())
    }
    /// The children of `b` with their member counts.
    pub fn child_slots(&self, b: BehaviorId) -> &[ChildSlot] {
        self.slots.get(b.index()).map_or(&[], Vec::as_slice)
    }
    /// Every point with its bound protocol, in graph order.
    pub fn points(&self) -> Vec<(crate::graph::Point, &Bound)> {
        self.graph
            .points()
            .into_iter()
            .filter_map(|p| self.bound(p.behavior, p.kind).map(|b| (p, b)))
            .collect()
    }
}

fn check_protocol<'r>(
    registry: &'r Registry,
    name: &str,
    kind: Kind,
    point: &str,
    at: &Binding,
    diags: &mut Vec<Diagnostic>,
) -> Option<&'r Arc<dyn Protocol>> {
    let Some(p) = registry.get(name) else {
        let hint = did_you_mean(name, registry.names()).or_else(|| {
            let names: Vec<&str> = registry
                .iter()
                .filter(|p| p.kind() == kind)
                .map(|p| p.name())
                .collect();
            Some(format!("{} protocols: {}", kind, names.join(", ")))
        });
        let mut d = Diagnostic::error(
            &at.file,
            at.loc,
            "unknown-protocol",
            format!("no protocol called `{name}` (bound at {point})"),
        );
        d.hint = hint;
        diags.push(d);
        return None;
    };
    if p.kind() != kind {
        diags.push(
            Diagnostic::error(
                &at.file,
                at.loc,
                "binding-kind-mismatch",
                format!(
                    "`{}` is {} protocol, but `{point}` is {} point",
                    p.name(),
                    p.kind().a_noun(),
                    kind.a_noun()
                ),
            )
            .with_hint(format!(
                "bind {} protocol here, e.g. `{}`",
                kind.a_noun(),
                Registry::default_for(kind)
            )),
        );
        return None;
    }
    Some(p)
}

fn resolve(
    registry: &Registry,
    setup: &mut Setup<'_>,
    diags: &mut Vec<Diagnostic>,
) -> Option<Bound> {
    let (graph, b, kind) = (setup.graph(), setup.point(), setup.kind());
    let point = graph.point_name(b, kind);
    let own = graph.own_binding(b, kind);
    let def = graph.default_binding(kind);
    let (name, from): (String, Option<&Binding>) = match (
        own.and_then(|o| o.protocol.clone()),
        def.and_then(|d| d.protocol.clone()),
    ) {
        (Some(n), _) => (n, own),
        (None, Some(n)) => (n, def),
        (None, None) => (Registry::default_for(kind).to_string(), None),
    };
    let fallback_at = Binding {
        protocol: None,
        deadline: None,
        retry: None,
        params: Params::Null,
        file: graph.file().clone(),
        loc: graph.behavior(b).loc,
    };
    let at = from.or(own).unwrap_or(&fallback_at);
    let protocol = check_protocol(registry, &name, kind, &point, at, diags)?.clone();
    // Parameters written on the point win; otherwise a protocol that came
    // from the defaults keeps the defaults' parameters.
    let params = match own {
        Some(o) if !o.params.is_null() => o.params.clone(),
        Some(o) if o.protocol.is_some() => Params::Null,
        _ => def.map_or(Params::Null, |d| d.params.clone()),
    };
    let (file, loc) = (at.file.clone(), at.loc);
    let factory = match protocol.configure(&params, setup) {
        Ok(f) => f,
        Err(e) => {
            diags.push(Diagnostic::error(
                &file,
                loc,
                "bad-params",
                format!("parameters of `{}` at {point}: {e}", protocol.name()),
            ));
            return None;
        }
    };
    let pick = |f: fn(&Binding) -> Option<Duration>| own.and_then(f).or_else(|| def.and_then(f));
    let deadline = pick(|x| x.deadline).unwrap_or_else(|| protocol.default_deadline());
    let retry = pick(|x| x.retry).unwrap_or(DEFAULT_RETRY);
    if deadline.is_zero() || retry < Duration::from_millis(1) {
        diags.push(Diagnostic::error(
            &at.file,
            if at.loc.is_known() {
                at.loc
            } else {
                Loc::UNKNOWN
            },
            "bad-duration",
            format!(
                "at {point}: the deadline must be positive and the retry interval at least 1ms"
            ),
        ));
        return None;
    }
    Some(Bound {
        point,
        protocol,
        factory,
        deadline,
        retry,
        params,
    })
}
