//! Configuration files: protocol bindings per named point.
//!
//! One graph runs under many configurations (the paper's Table II) with no
//! code change: a configuration names points — by label (`A`) or as
//! `behavior.kind` (`search.sync`) — and binds a protocol to each.
//!
//! ```yaml
//! config: table2-row5
//! bindings:
//!   A: sync.vote
//!   C: { protocol: alloc.by-id, deadline: 2s }
//!   walk.terminate: term.local
//! defaults:
//!   terminate: term.wait-all
//! ```

use super::load::make_binding;
use super::spec::ConfigSpec;
use super::{BehaviorGraph, Binding};
use crate::diag::{Diagnostic, Diagnostics, Loc, did_you_mean};
use crate::ids::{BehaviorId, Kind};
use std::path::Path;
use std::sync::Arc;

/// A parsed configuration file.
#[derive(Clone, Debug)]
pub struct Config {
    /// Its name (`config:`), or the file stem.
    pub name: String,
    /// Free text.
    pub description: Option<String>,
    /// File it came from.
    pub file: Arc<str>,
    defaults: [Option<Binding>; 3],
    bindings: Vec<(String, Binding)>,
    world_model: Option<serde_saphyr::Spanned<super::spec::WorldModelSpec>>,
}

impl Config {
    /// Load a configuration file.
    pub fn load(path: &Path) -> Result<Config, Diagnostics> {
        let (file, text) = crate::yaml::read_file(path)?;
        Self::load_str(&file, &text)
    }

    /// Parse a configuration from text; `file` names it in messages.
    pub fn load_str(file: &Arc<str>, text: &str) -> Result<Config, Diagnostics> {
        let spec: ConfigSpec = crate::yaml::parse(file, text)?;
        let mut diags = Vec::new();
        let mut defaults: [Option<Binding>; 3] = [None, None, None];
        for (kind, b) in [
            (Kind::Sync, &spec.defaults.sync),
            (Kind::Allocate, &spec.defaults.allocate),
            (Kind::Terminate, &spec.defaults.terminate),
        ] {
            if let Some(b) = b {
                defaults[kind.index()] = Some(make_binding(file, b, &mut diags));
            }
        }
        let mut bindings = Vec::new();
        for (name, b) in &spec.bindings.0 {
            if let Some(p) = &b.value.point {
                diags.push(Diagnostic::error(
                    file,
                    Loc::from(p.referenced),
                    "bad-binding",
                    "a configuration binds protocols to points; it cannot relabel them (`point:`)",
                ));
            }
            let mut binding = make_binding(file, b, &mut diags);
            binding.loc = Loc::from(name.referenced);
            bindings.push((name.value.clone(), binding));
        }
        if diags.iter().any(Diagnostic::is_error) {
            return Err(Diagnostics(diags));
        }
        let name = spec.config.unwrap_or_else(|| {
            Path::new(&**file)
                .file_stem()
                .map_or_else(|| file.to_string(), |s| s.to_string_lossy().into_owned())
        });
        if let Some(w) = &spec.world_model {
            // Checked now, applied over the graph's settings later.
            crate::graph::Sharing::default().with_spec(file, w, &mut diags);
        }
        if diags.iter().any(|d| d.is_error()) {
            return Err(Diagnostics(diags));
        }
        Ok(Config {
            name,
            description: spec.description,
            file: file.clone(),
            defaults,
            bindings,
            world_model: spec.world_model,
        })
    }

    /// The point names it binds, in file order.
    pub fn points(&self) -> impl Iterator<Item = &str> {
        self.bindings.iter().map(|(n, _)| n.as_str())
    }
}

impl BehaviorGraph {
    /// This graph with the configuration's bindings applied. Every point the
    /// configuration names must exist and be of a kind the binding fits.
    pub fn with_config(&self, cfg: &Config) -> Result<BehaviorGraph, Diagnostics> {
        let mut g = self.clone();
        let mut diags = Vec::new();
        let all_points: Vec<String> = self.points().into_iter().map(|p| p.name).collect();
        // Every name a point answers to: its label and `behavior.kind`.
        let mut known = all_points.clone();
        for p in self.points() {
            known.push(format!("{}.{}", self.name_of(p.behavior), p.kind));
        }
        let mut bound: std::collections::BTreeMap<(BehaviorId, Kind), (&str, Loc)> =
            std::collections::BTreeMap::new();
        for (name, binding) in &cfg.bindings {
            match self.find_point(name) {
                None => {
                    let mut d = Diagnostic::error(
                        &cfg.file,
                        binding.loc,
                        "unknown-point",
                        format!("`{name}` is not a point of graph `{}`", self.name()),
                    );
                    d.hint = did_you_mean(name, known.iter().map(String::as_str))
                        .or_else(|| Some(format!("the points are: {}", all_points.join(", "))));
                    diags.push(d);
                }
                Some((b, kind)) if !self.is_point(b, kind) => {
                    diags.push(
                        Diagnostic::error(
                            &cfg.file,
                            binding.loc,
                            "not-a-point",
                            format!(
                                "`{}` is not {} point of graph `{}`",
                                name,
                                kind.a_noun(),
                                self.name()
                            ),
                        )
                        .with_hint(format!("the points are: {}", all_points.join(", "))),
                    );
                }
                Some((b, kind)) => {
                    // A point answers to its label and to `behavior.kind`
                    // (and `alloc` for `allocate`): two of its names bound
                    // in one file were read silently, the last one winning.
                    if let Some((first, at)) = bound.get(&(b, kind)) {
                        diags.push(
                            Diagnostic::error(
                                &cfg.file,
                                binding.loc,
                                "duplicate-binding",
                                format!(
                                    "`{name}` is the point `{first}` bound at line {} already",
                                    at.line
                                ),
                            )
                            .with_hint("bind each point once"),
                        );
                        continue;
                    }
                    bound.insert((b, kind), (name.as_str(), binding.loc));
                    g.behaviors[b.index()].bindings[kind.index()] = Some(Box::new(binding.clone()));
                }
            }
        }
        for kind in Kind::ALL {
            if let Some(d) = &cfg.defaults[kind.index()] {
                g.defaults[kind.index()] = Some(d.clone());
            }
        }
        if let Some(w) = &cfg.world_model {
            g.sharing = g.sharing.with_spec(&cfg.file, w, &mut diags);
        }
        if !diags.is_empty() {
            return Err(Diagnostics(diags));
        }
        g.config = Some(cfg.name.clone());
        Ok(g)
    }
}
