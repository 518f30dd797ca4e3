//! Output files that would destroy a command's own inputs: `bite log
//! convert run.jsonl -o run.jsonl`, `bite run g.yaml --log g.yaml`, `bite
//! compile m.rtcl -o m.rtcl`, `--log X --mcap X`. Every command that writes
//! files made from input files asks [`check`] first, before it reads or
//! writes anything, and is refused with the two flags that name one file.

use anyhow::Result;
use std::path::{Path, PathBuf};

/// What makes two paths one file.
#[derive(Debug, PartialEq, Eq)]
enum Identity {
    /// An existing file: its device and inode (a hard link, a symbolic
    /// link or another spelling of the path is the same file).
    #[cfg(unix)]
    Inode(u64, u64),
    /// An existing file where inodes are unknown, or a file not there
    /// yet: its absolute path, through the symbolic links of its
    /// directory.
    Path(PathBuf),
}

/// The identity of the file at `p`; `None` for what is no regular file or
/// directory (`/dev/null`, a terminal, a FIFO: any number of outputs may
/// go there, and reading one is no loss).
fn identity(p: &Path) -> Option<Identity> {
    match std::fs::metadata(p) {
        Ok(m) if !(m.is_file() || m.is_dir()) => None,
        #[cfg(unix)]
        Ok(m) => {
            use std::os::unix::fs::MetadataExt as _;
            Some(Identity::Inode(m.dev(), m.ino()))
        }
        #[cfg(not(unix))]
        Ok(_) => Some(Identity::Path(
            p.canonicalize().unwrap_or_else(|_| p.to_path_buf()),
        )),
        Err(_) => {
            let abs = std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
            let resolved = match (abs.parent(), abs.file_name()) {
                (Some(dir), Some(name)) => dir
                    .canonicalize()
                    .map_or_else(|_| abs.clone(), |d| d.join(name)),
                _ => abs,
            };
            Some(Identity::Path(resolved))
        }
    }
}

/// Refuse `outputs` (flag, path) that are the same file as one of `inputs`
/// (flag, path) or the `--protocols` files, or as another of `outputs`: a
/// clear error naming both, before anything is written.
pub fn check(inputs: &[(&str, &Path)], outputs: &[(&str, &Path)]) -> Result<()> {
    let protocols: Vec<(&str, &Path)> = crate::protocol_files()
        .iter()
        .map(|p| ("--protocols", p.as_path()))
        .collect();
    let inputs: Vec<(&str, &Path, Option<Identity>)> = inputs
        .iter()
        .chain(&protocols)
        .map(|&(what, p)| (what, p, identity(p)))
        .collect();
    let mut seen: Vec<(&str, &Path, Option<Identity>)> = Vec::new();
    for &(what, p) in outputs {
        let id = identity(p);
        if id.is_none() {
            continue;
        }
        let name = |w: &str, q: &Path| {
            if w.is_empty() {
                q.display().to_string()
            } else {
                format!("{w} {}", q.display())
            }
        };
        if let Some((w, q, _)) = inputs.iter().find(|(_, _, i)| *i == id) {
            anyhow::bail!(
                "{} would overwrite the input {}: they are the same file; write elsewhere",
                name(what, p),
                name(w, q)
            );
        }
        if let Some((w, q, _)) = seen.iter().find(|(_, _, i)| *i == id) {
            anyhow::bail!(
                "{} and {} are the same file: each output needs its own",
                name(w, q),
                name(what, p)
            );
        }
        seen.push((what, p, id));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("bite-outputs-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("scratch dir");
        d
    }

    #[cfg(unix)]
    #[test]
    fn an_output_that_is_an_input_under_another_name_is_refused() {
        let d = scratch("alias");
        let input = d.join("g.yaml");
        std::fs::write(&input, "x").expect("write");
        let other = d.join("log.jsonl");
        // The same path, another spelling of it, a hard link to it.
        let spelled = d.join(".").join("g.yaml");
        let linked = d.join("link.yaml");
        std::fs::hard_link(&input, &linked).expect("hard link");
        for out in [&input, &spelled, &linked] {
            let e = check(&[("graph", &input)], &[("--log", out)]).expect_err("refused");
            assert!(
                e.to_string().contains("would overwrite the input graph"),
                "{e}"
            );
        }
        check(&[("graph", &input)], &[("--log", &other)]).expect("another file");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn two_outputs_to_one_new_file_are_refused_and_devices_are_not() {
        let d = scratch("twice");
        let out = d.join("run.out");
        let e =
            check(&[], &[("--log", &out), ("--mcap", &d.join("./run.out"))]).expect_err("refused");
        assert!(e.to_string().contains("are the same file"), "{e}");
        let null = Path::new("/dev/null");
        if null.exists() {
            check(&[("graph", null)], &[("--log", null), ("--mcap", null)])
                .expect("a device takes any number of outputs");
        }
        let _ = std::fs::remove_dir_all(&d);
    }
}
