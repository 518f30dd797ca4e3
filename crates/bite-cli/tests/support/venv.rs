//! A Python virtual environment for the tests that check BITE against
//! independent implementations (PyPI packages), made once per target
//! directory. Shared by test files of several crates (`#[path]`).

use std::path::{Path, PathBuf};
use std::process::Command;

/// The Python of virtual environment `name` under the target directory's
/// test scratch space, with `packages` installed: made (and the packages
/// installed) unless `import` (Python statements) already runs in it.
pub fn python_venv(name: &str, import: &str, packages: &[&str]) -> PathBuf {
    let venv = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let py = venv.join("bin/python");
    let ok = |py: &Path| {
        Command::new(py)
            .args(["-c", import])
            .status()
            .is_ok_and(|s| s.success())
    };
    if !ok(&py) {
        let s = Command::new("python3")
            .args(["-m", "venv"])
            .arg(&venv)
            .status()
            .expect("python3 is needed for the tests against independent implementations");
        assert!(s.success(), "python3 -m venv {} failed", venv.display());
        let s = Command::new(&py)
            .args(["-m", "pip", "install", "--quiet"])
            .args(packages)
            .status()
            .expect("pip runs");
        assert!(s.success(), "pip install {packages:?} failed");
    }
    assert!(ok(&py), "`{import}` does not run in {}", venv.display());
    py
}
