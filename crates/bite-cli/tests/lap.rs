//! `bite bench lap`: the assignment solver timed on matrices read from a
//! file (what `scripts/lap_vs_scipy.py` drives), and a malformed file
//! reported by name rather than a panic.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn scratch(name: &str) -> PathBuf {
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("bite-lap-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("scratch dir");
    d
}

/// One matrix in the file format: a line `rows cols`, then little-endian f64.
fn matrix(rows: usize, cols: usize, costs: &[f64]) -> Vec<u8> {
    let mut b = format!("{rows} {cols}\n").into_bytes();
    for c in costs {
        b.extend_from_slice(&c.to_le_bytes());
    }
    b
}

fn bench_lap(file: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_bite"))
        .args(["bench", "lap", "--repeat", "2", "--input"])
        .arg(file)
        .output()
        .expect("bite runs")
}

#[test]
fn bench_lap_prints_the_cost_of_each_matrix() {
    let d = scratch("ok");
    let file = d.join("m.bin");
    let mut bytes = matrix(3, 3, &[4.0, 1.0, 3.0, 2.0, 0.0, 5.0, 3.0, 2.0, 2.0]);
    // Rectangular, more rows than columns: 2 of the 3 rows assigned.
    bytes.extend(matrix(3, 2, &[1.0, 9.0, 9.0, 1.0, 5.0, 5.0]));
    std::fs::write(&file, bytes).expect("write");
    let o = bench_lap(&file);
    assert!(
        o.status.success(),
        "exit {:?}\n{}",
        o.status.code(),
        String::from_utf8_lossy(&o.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    let m = v["matrices"].as_array().expect("matrices");
    assert_eq!(m.len(), 2);
    assert_eq!(
        (m[0]["rows"].as_u64(), m[0]["cols"].as_u64()),
        (Some(3), Some(3))
    );
    assert_eq!(m[0]["cost"].as_f64(), Some(5.0));
    assert_eq!(m[1]["cost"].as_f64(), Some(2.0));
    assert_eq!(m[1]["assigned"].as_u64(), Some(2));
    assert_eq!(m[1]["repeat"].as_u64(), Some(2));
    assert!(m[1]["best_s"].as_f64().is_some_and(|t| t >= 0.0));
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn bench_lap_names_the_file_and_what_it_expected() {
    let d = scratch("bad");
    let file = d.join("short.bin");
    // The header promises 2 × 2, the data holds 3 numbers.
    std::fs::write(&file, matrix(2, 2, &[1.0, 2.0, 3.0])).expect("write");
    let o = bench_lap(&file);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("short.bin"), "{err}");
    assert!(err.contains("expected 32 bytes"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    let o = bench_lap(&d.join("missing.bin"));
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("missing.bin"));
    let _ = std::fs::remove_dir_all(&d);
}
