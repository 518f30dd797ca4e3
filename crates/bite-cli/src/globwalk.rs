//! File patterns (`configs/*.yaml`, `runs/**/best.yaml`) matched by a walk
//! with a bound on the directory entries it reads.
//!
//! `glob::glob` walks everything a pattern could reach: `/**/*.yaml` in an
//! experiment spec read the whole file system before the command said a
//! word. Here the pattern is split into its literal folder (read with no
//! listing) and the components after it, each matched with
//! [`glob::Pattern`] as the `glob` crate does (`*` stays within a
//! component, `**` is any run of folders), and the walk stops with
//! [`GlobError::TooWide`] once it has read [`WALK_BUDGET`] entries.
//! Symbolic links to folders are not followed by `**`, so a link that
//! points back up cannot make the walk go round.

use std::ffi::OsString;
use std::fmt;
use std::path::{Component, Path, PathBuf};

/// The directory entries one pattern may read: far more than any folder
/// of missions, configurations or runs holds, far fewer than a whole file
/// system (about a second to read).
pub const WALK_BUDGET: usize = 100_000;

/// Why a pattern gave no list of files.
#[derive(Debug)]
pub enum GlobError {
    /// Not a pattern (`[` unclosed, `***`).
    Pattern(glob::PatternError),
    /// The walk read more than its budget of entries under `base`.
    TooWide { budget: usize, base: PathBuf },
}

impl fmt::Display for GlobError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            GlobError::Pattern(e) => write!(f, "{e}"),
            GlobError::TooWide { budget, base } => write!(
                f,
                "matching it reads more than {budget} directory entries under `{}`: name a narrower folder",
                if base.as_os_str().is_empty() {
                    Path::new(".")
                } else {
                    base
                }
                .display()
            ),
        }
    }
}

impl std::error::Error for GlobError {}

impl From<glob::PatternError> for GlobError {
    fn from(e: glob::PatternError) -> Self {
        GlobError::Pattern(e)
    }
}

/// True when `s` holds a pattern character (`*`, `?`, `[`).
pub fn is_pattern(s: &str) -> bool {
    s.contains(['*', '?', '['])
}

/// The paths matching `pattern`, sorted, read within [`WALK_BUDGET`].
pub fn glob_files(pattern: &str) -> Result<Vec<PathBuf>, GlobError> {
    glob_within(pattern, WALK_BUDGET)
}

/// One component of a pattern after its literal folder.
enum Part {
    /// A name without pattern characters: joined, not listed.
    Literal(OsString),
    /// A pattern for one name.
    Name(glob::Pattern),
    /// `**`: any run of folders, none included.
    Folders,
}

const OPTIONS: glob::MatchOptions = glob::MatchOptions {
    case_sensitive: true,
    require_literal_separator: true,
    require_literal_leading_dot: false,
};

fn glob_within(pattern: &str, budget: usize) -> Result<Vec<PathBuf>, GlobError> {
    // The whole pattern first, for the `glob` crate's own messages.
    glob::Pattern::new(pattern)?;
    let mut base = PathBuf::new();
    let mut parts = Vec::new();
    for c in Path::new(pattern).components() {
        let text = c.as_os_str().to_string_lossy();
        if parts.is_empty() && !is_pattern(&text) {
            base.push(c);
        } else if matches!(c, Component::Normal(_)) && text == "**" {
            parts.push(Part::Folders);
        } else if matches!(c, Component::Normal(_)) && is_pattern(&text) {
            parts.push(Part::Name(glob::Pattern::new(&text)?));
        } else {
            parts.push(Part::Literal(c.as_os_str().to_owned()));
        }
    }
    let mut walk = Walk {
        budget,
        read: 0,
        base: base.clone(),
        found: Vec::new(),
    };
    if parts.is_empty() {
        // No pattern character: the path itself, if it is there.
        if base.symlink_metadata().is_ok() {
            walk.found.push(base);
        }
    } else {
        walk.fill(&base, &parts)?;
    }
    walk.found.sort();
    walk.found.dedup();
    Ok(walk.found)
}

struct Walk {
    budget: usize,
    read: usize,
    base: PathBuf,
    found: Vec<PathBuf>,
}

impl Walk {
    /// Adds the paths under `dir` (which exists) that match `parts`.
    fn fill(&mut self, dir: &Path, parts: &[Part]) -> Result<(), GlobError> {
        match parts.first() {
            None => self.found.push(dir.to_path_buf()),
            Some(Part::Literal(name)) => {
                let p = dir.join(name);
                if p.symlink_metadata().is_ok() {
                    self.fill(&p, &parts[1..])?;
                }
            }
            Some(Part::Name(_) | Part::Folders) => {
                let names = self.list(dir)?;
                self.fill_listed(dir, &names, parts)?;
            }
        }
        Ok(())
    }

    /// [`Walk::fill`] with `dir` listed already (`names`): each folder is
    /// read once, `**` and the name after it matched on one listing.
    fn fill_listed(
        &mut self,
        dir: &Path,
        names: &[(OsString, bool)],
        parts: &[Part],
    ) -> Result<(), GlobError> {
        let Some((first, rest)) = parts.split_first() else {
            self.found.push(dir.to_path_buf());
            return Ok(());
        };
        match first {
            Part::Literal(_) => self.fill(dir, parts)?,
            Part::Name(pat) => {
                for (name, _) in names {
                    if pat.matches_with(&name.to_string_lossy(), OPTIONS) {
                        self.fill(&dir.join(name), rest)?;
                    }
                }
            }
            Part::Folders => {
                // No folder: what follows, here.
                self.fill_listed(dir, names, rest)?;
                // One or more: each folder in turn.
                for (name, is_dir) in names {
                    if *is_dir {
                        self.fill(&dir.join(name), parts)?;
                    }
                }
            }
        }
        Ok(())
    }

    /// The names in `dir` (the current folder when empty) and whether each
    /// is a folder (a link to one is not), sorted; none when it cannot be
    /// read (not a folder, no permission). Each counts against the budget.
    fn list(&mut self, dir: &Path) -> Result<Vec<(OsString, bool)>, GlobError> {
        let at = if dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            dir
        };
        let Ok(entries) = std::fs::read_dir(at) else {
            return Ok(Vec::new());
        };
        let mut out = Vec::new();
        for e in entries.flatten() {
            self.read += 1;
            if self.read > self.budget {
                return Err(GlobError::TooWide {
                    budget: self.budget,
                    base: self.base.clone(),
                });
            }
            let is_dir = e.file_type().is_ok_and(|t| t.is_dir());
            out.push((e.file_name(), is_dir));
        }
        out.sort();
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh folder under the system's temporary folder, removed on drop.
    struct Dir(PathBuf);
    impl Drop for Dir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    fn tree(name: &str, files: &[&str]) -> Dir {
        let root =
            std::env::temp_dir().join(format!("bite-globwalk-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        for f in files {
            let p = root.join(f);
            std::fs::create_dir_all(p.parent().expect("a parent")).expect("mkdir");
            std::fs::write(&p, "x").expect("write");
        }
        Dir(root)
    }

    fn names(root: &Path, found: &[PathBuf]) -> Vec<String> {
        (found.iter())
            .map(|p| {
                p.strip_prefix(root)
                    .expect("under root")
                    .display()
                    .to_string()
            })
            .collect()
    }

    #[test]
    fn matches_as_the_glob_crate_does() {
        let d = tree(
            "same",
            &[
                "a.yaml",
                "b.yaml",
                "c.txt",
                "sub/d.yaml",
                "sub/deep/e.yaml",
                ".h.yaml",
            ],
        );
        let root = d.0.display().to_string();
        for pattern in [
            "*.yaml",
            "**/*.yaml",
            "sub/*.yaml",
            "s?b/**/*.yaml",
            "[ab].yaml",
            "*/deep/*",
        ] {
            let full = format!("{root}/{pattern}");
            let ours = glob_files(&full).expect("matches");
            let mut theirs: Vec<PathBuf> = (glob::glob(&full).expect("pattern"))
                .filter_map(Result::ok)
                .collect();
            theirs.sort();
            assert_eq!(ours, theirs, "{pattern}");
        }
        let all = glob_files(&format!("{root}/**/*.yaml")).expect("matches");
        assert_eq!(
            names(&d.0, &all),
            [
                ".h.yaml",
                "a.yaml",
                "b.yaml",
                "sub/d.yaml",
                "sub/deep/e.yaml"
            ]
        );
    }

    #[test]
    fn a_walk_past_its_budget_is_an_error_naming_the_folder() {
        let d = tree("wide", &["a/1", "a/2", "b/3", "b/4", "c/5", "c/6"]);
        let pattern = format!("{}/**/*.yaml", d.0.display());
        assert!(glob_within(&pattern, 9).is_ok_and(|v| v.is_empty()));
        match glob_within(&pattern, 8) {
            Err(e @ GlobError::TooWide { .. }) => {
                let text = e.to_string();
                assert!(text.contains("more than 8 directory entries"), "{text}");
                assert!(text.contains(&d.0.display().to_string()), "{text}");
            }
            other => panic!("{other:?}"),
        }
        // The literal folder is joined, not listed: a narrow pattern under
        // the same tree reads two entries.
        let narrow = format!("{}/a/*", d.0.display());
        assert_eq!(glob_within(&narrow, 2).map(|v| v.len()).ok(), Some(2));
    }

    #[test]
    fn bad_patterns_and_plain_paths() {
        assert!(matches!(glob_files("a/[b"), Err(GlobError::Pattern(_))));
        let d = tree("plain", &["x.yaml"]);
        let plain = d.0.join("x.yaml").display().to_string();
        assert_eq!(glob_files(&plain).map(|v| v.len()).ok(), Some(1));
        let missing = d.0.join("y.yaml").display().to_string();
        assert_eq!(glob_files(&missing).map(|v| v.len()).ok(), Some(0));
    }
}
