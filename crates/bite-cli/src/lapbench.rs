//! `bite bench lap`: time `alloc.optimal`'s assignment solver
//! ([`bite_protocols::lap::solve`]) on cost matrices read from a file, so
//! that another implementation (SciPy's `linear_sum_assignment`, in
//! `scripts/lap_vs_scipy.py`) can be timed on the very same matrices.
//!
//! The file holds one or more matrices back to back, each a text header
//! line `rows cols` (ASCII, ended by `\n`) followed by `rows × cols`
//! little-endian `f64`, row-major. It is the simplest format that NumPy
//! writes without a library (`f.write(b"%d %d\n" % a.shape);
//! f.write(a.astype("<f8").tobytes())`) and that carries large matrices
//! exactly. The result is one JSON document on standard output.

use anyhow::{Result, bail};
use serde_json::json;
use std::path::Path;
use std::process::ExitCode;

/// Largest matrix accepted (elements): 10⁸ `f64` are 800 MB already.
const MAX_ELEMENTS: usize = 100_000_000;

/// One matrix of the file.
#[derive(Debug)]
struct Matrix {
    rows: usize,
    cols: usize,
    cost: Vec<f64>,
}

/// Parse the whole file; the error says where and what was expected.
fn parse(bytes: &[u8]) -> Result<Vec<Matrix>> {
    let mut out = Vec::new();
    let mut at = 0usize;
    while at < bytes.len() {
        let index = out.len();
        let Some(nl) = bytes[at..].iter().position(|b| *b == b'\n') else {
            bail!(
                "matrix {index} at byte {at}: expected a header line `rows cols` ended by a newline, found {} bytes without one",
                bytes.len() - at
            );
        };
        let line = std::str::from_utf8(&bytes[at..at + nl]).ok();
        let dims: Option<Vec<usize>> = line.and_then(|l| {
            l.split_ascii_whitespace()
                .map(|t| t.parse::<usize>().ok())
                .collect()
        });
        let (rows, cols) = match dims.as_deref() {
            Some([r, c]) => (*r, *c),
            _ => bail!(
                "matrix {index} at byte {at}: expected a header line `rows cols` (two non-negative integers), found {:?}",
                String::from_utf8_lossy(&bytes[at..at + nl.min(80)])
            ),
        };
        let elements = rows
            .checked_mul(cols)
            .filter(|n| *n <= MAX_ELEMENTS)
            .ok_or_else(|| {
                anyhow::anyhow!(
                    "matrix {index} at byte {at}: {rows} × {cols} is larger than the {MAX_ELEMENTS} elements accepted"
                )
            })?;
        at += nl + 1;
        let need = elements * 8;
        let have = bytes.len() - at;
        if have < need {
            bail!(
                "matrix {index} ({rows} × {cols}) at byte {at}: expected {need} bytes of little-endian f64, found only {have}"
            );
        }
        let cost = bytes[at..at + need]
            .chunks_exact(8)
            .map(|c| {
                let mut b = [0u8; 8];
                b.copy_from_slice(c);
                f64::from_le_bytes(b)
            })
            .collect();
        at += need;
        out.push(Matrix { rows, cols, cost });
    }
    if out.is_empty() {
        bail!(
            "expected at least one matrix (a header line `rows cols` then little-endian f64), found an empty file"
        );
    }
    Ok(out)
}

/// `bite bench lap --input FILE [--repeat K]`: per matrix, the best of K
/// solve times and the total cost, as JSON. A malformed file is reported
/// (naming the file and what was expected) with exit code 2.
#[allow(clippy::disallowed_methods)] // a benchmark measures wall time
pub fn cmd_bench_lap(input: &Path, repeat: usize) -> Result<ExitCode> {
    let matrices = match std::fs::read(input) {
        Err(e) => Err(anyhow::Error::new(e).context("cannot read it")),
        Ok(bytes) => parse(&bytes),
    };
    let matrices = match matrices {
        Ok(m) => m,
        Err(e) => {
            eprintln!("error: {}: {e:#}", input.display());
            return Ok(ExitCode::from(2));
        }
    };
    let repeat = repeat.max(1);
    let mut rows = Vec::new();
    for (index, m) in matrices.iter().enumerate() {
        let mut best = f64::INFINITY;
        let mut cost = 0.0;
        let mut assigned = 0;
        for _ in 0..repeat {
            let start = std::time::Instant::now();
            let s = bite_protocols::lap::solve(m.rows, m.cols, std::hint::black_box(&m.cost));
            best = best.min(start.elapsed().as_secs_f64());
            cost = s.cost;
            assigned = s.row_to_col.iter().flatten().count();
        }
        rows.push(json!({
            "index": index, "rows": m.rows, "cols": m.cols, "repeat": repeat,
            "best_s": best, "cost": cost, "assigned": assigned,
        }));
    }
    outln!("{}", json!({ "matrices": rows }));
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(parts: &[(&str, &[f64])]) -> Vec<u8> {
        let mut b = Vec::new();
        for (h, xs) in parts {
            b.extend_from_slice(h.as_bytes());
            for x in *xs {
                b.extend_from_slice(&x.to_le_bytes());
            }
        }
        b
    }

    #[test]
    fn reads_matrices_back_to_back() {
        let b = file(&[
            ("2 2\n", &[1.0, 2.0, 3.0, 4.0]),
            ("1 3\n", &[5.0, 6.0, 7.0]),
        ]);
        let m = parse(&b).expect("parses");
        assert_eq!((m.len(), m[1].rows, m[1].cols), (2, 1, 3));
        assert_eq!(m[1].cost, vec![5.0, 6.0, 7.0]);
    }

    #[test]
    fn malformed_files_say_what_was_expected() {
        let cases: [(Vec<u8>, &str); 5] = [
            (Vec::new(), "empty file"),
            (b"2 2".to_vec(), "without one"),
            (b"two 2\n".to_vec(), "two non-negative integers"),
            (file(&[("2 2\n", &[1.0, 2.0, 3.0])]), "expected 32 bytes"),
            (b"99999999999 99999999999\n".to_vec(), "larger than"),
        ];
        for (b, want) in cases {
            let e = parse(&b).expect_err("malformed");
            assert!(format!("{e:#}").contains(want), "{e:#} lacks {want:?}");
        }
    }
}
