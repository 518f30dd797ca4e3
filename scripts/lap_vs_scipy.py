#!/usr/bin/env python3
"""Time `alloc.optimal`'s assignment solver against SciPy on the same matrices.

Generates cost matrices of several kinds and shapes from a fixed seed, runs
SciPy's `linear_sum_assignment` on each and the project's solver (through
`bite bench lap`, which reads the same matrix from a file and reports its
best-of-K solve time and total cost), checks that the two totals agree, and
prints a table of both times and their ratio (ours / SciPy), or JSON.

Setup (once):

    python3 -m venv ~/.cache/bite-rs/venv
    ~/.cache/bite-rs/venv/bin/pip install -r scripts/requirements-lap.txt

or let the script do it: `python3 scripts/lap_vs_scipy.py --setup-venv`.
Build the binary first: `cargo build --release -p bite-cli` (the script
looks for `$CARGO_TARGET_DIR/release/bite`, then `target/release/bite`;
`--bite PATH` to choose).

    ~/.cache/bite-rs/venv/bin/python scripts/lap_vs_scipy.py            # up to 5,000
    ~/.cache/bite-rs/venv/bin/python scripts/lap_vs_scipy.py --max 1000 # quick
    ~/.cache/bite-rs/venv/bin/python scripts/lap_vs_scipy.py --json

Exit status: 0 if every total agreed, 1 if one did not, 2 on a setup error.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
VENV = Path.home() / ".cache" / "bite-rs" / "venv"
REQUIREMENTS = ROOT / "scripts" / "requirements-lap.txt"

KINDS = ("uniform", "distances", "int0-10", "constant")
# (rows, cols): square, then rectangular both ways.
SHAPES = (
    (100, 100),
    (1000, 1000),
    (2000, 2000),
    (5000, 5000),
    (300, 1000),
    (1000, 300),
    (2000, 5000),
    (5000, 2000),
)


def setup_venv() -> Path:
    """Create the venv and install the pinned requirements; its python."""
    py = VENV / "bin" / "python"
    if not py.exists():
        subprocess.run([sys.executable, "-m", "venv", str(VENV)], check=True)
    subprocess.run(
        [str(py), "-m", "pip", "install", "-q", "-r", str(REQUIREMENTS)], check=True
    )
    return py


def matrix(np, kind: str, rows: int, cols: int, seed: int):
    """One cost matrix; the same seed, kind and shape give the same matrix."""
    rng = np.random.default_rng([seed, rows, cols, KINDS.index(kind)])
    if kind == "uniform":
        return rng.random((rows, cols)) * 1000.0
    if kind == "distances":
        # Robots and tasks at random points of a 100 m square, cost =
        # distance (what `bite bench protocols --large` allocates).
        robots = rng.random((rows, 2)) * 100.0
        tasks = rng.random((cols, 2)) * 100.0
        return np.sqrt(((robots[:, None, :] - tasks[None, :, :]) ** 2).sum(axis=2))
    if kind == "int0-10":
        return rng.integers(0, 11, (rows, cols)).astype(np.float64)
    if kind == "constant":
        return np.full((rows, cols), 7.0)
    raise ValueError(kind)


def write_matrix(np, path: Path, a) -> None:
    """`bite bench lap`'s format: a line `rows cols`, then little-endian f64."""
    with open(path, "wb") as f:
        f.write(b"%d %d\n" % a.shape)
        f.write(np.ascontiguousarray(a, dtype="<f8").tobytes())


def find_bite(arg: str | None) -> Path:
    if arg:
        return Path(arg)
    candidates = []
    if os.environ.get("CARGO_TARGET_DIR"):
        candidates.append(Path(os.environ["CARGO_TARGET_DIR"]) / "release" / "bite")
    candidates.append(ROOT / "target" / "release" / "bite")
    for c in candidates:
        if c.exists():
            return c
    sys.exit(
        "lap_vs_scipy: no `bite` binary at "
        + " or ".join(str(c) for c in candidates)
        + ": build it with `cargo build --release -p bite-cli`, or pass --bite PATH"
    )


def run_bite(bite: Path, path: Path, repeat: int) -> dict:
    out = subprocess.run(
        [str(bite), "bench", "lap", "--input", str(path), "--repeat", str(repeat)],
        capture_output=True,
        text=True,
    )
    if out.returncode != 0:
        sys.exit(f"lap_vs_scipy: `bite bench lap` failed ({out.returncode}): {out.stderr}")
    return json.loads(out.stdout)["matrices"][0]


def run_scipy(np, lsa, a, repeat: int) -> tuple[float, float]:
    best, total = float("inf"), 0.0
    for _ in range(repeat):
        t = time.perf_counter()
        r, c = lsa(a)
        best = min(best, time.perf_counter() - t)
        total = float(a[r, c].sum())
    return best, total


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--setup-venv", action="store_true",
                   help=f"create {VENV} with the pinned numpy and scipy, then run in it")
    p.add_argument("--bite", help="the bite binary (default: the release build)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--repeat", type=int, default=3,
                   help="best of this many runs per solver and matrix (1 above 4M cells)")
    p.add_argument("--max", type=int, default=5000, help="skip shapes with a side above this")
    p.add_argument("--kinds", default=",".join(KINDS), help="comma-separated: " + ", ".join(KINDS))
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    args = p.parse_args()

    if args.setup_venv:
        py = setup_venv()
        rest = [a for a in sys.argv[1:] if a != "--setup-venv"]
        os.execv(str(py), [str(py), str(Path(__file__).resolve()), *rest])
    try:
        import numpy as np
        from scipy.optimize import linear_sum_assignment as lsa
    except ImportError as e:
        print(f"lap_vs_scipy: {e}; set up the venv (see --help) or run with --setup-venv",
              file=sys.stderr)
        return 2
    import scipy

    kinds = [k for k in args.kinds.split(",") if k]
    unknown = [k for k in kinds if k not in KINDS]
    if unknown:
        print(f"lap_vs_scipy: unknown kind(s) {unknown}; known: {', '.join(KINDS)}", file=sys.stderr)
        return 2
    bite = find_bite(args.bite)
    rows_out = []
    ok = True
    if not args.json:
        print(f"scipy {scipy.__version__}, numpy {np.__version__}, seed {args.seed}, "
              f"best of {args.repeat} (1 above 4M cells)")
        print("| kind | rows × cols | scipy | bite | ratio (bite / scipy) | totals agree |")
        print("| --- | ---: | ---: | ---: | ---: | --- |")
    with tempfile.TemporaryDirectory(prefix="lap-vs-scipy-") as tmp:
        for rows, cols in SHAPES:
            if max(rows, cols) > args.max:
                continue
            for kind in kinds:
                a = matrix(np, kind, rows, cols, args.seed)
                repeat = 1 if rows * cols > 4_000_000 else args.repeat
                path = Path(tmp) / "m.bin"
                write_matrix(np, path, a)
                ours = run_bite(bite, path, repeat)
                t_scipy, c_scipy = run_scipy(np, lsa, a, repeat)
                agree = abs(ours["cost"] - c_scipy) <= 1e-9 * max(1.0, abs(c_scipy))
                ok &= agree
                row = {
                    "kind": kind, "rows": rows, "cols": cols, "repeat": repeat,
                    "scipy_s": t_scipy, "bite_s": ours["best_s"],
                    "ratio": ours["best_s"] / t_scipy if t_scipy > 0 else None,
                    "scipy_cost": c_scipy, "bite_cost": ours["cost"], "agree": agree,
                }
                rows_out.append(row)
                if not args.json:
                    print(f"| {kind} | {rows} × {cols} | {fmt(t_scipy)} | {fmt(ours['best_s'])} "
                          f"| {row['ratio']:.2f}× | {'yes' if agree else 'NO: %r vs %r' % (ours['cost'], c_scipy)} |",
                          flush=True)
    if args.json:
        print(json.dumps({"scipy": scipy.__version__, "numpy": np.__version__,
                          "seed": args.seed, "rows": rows_out}))
    return 0 if ok else 1


def fmt(s: float) -> str:
    return f"{s * 1e3:.2f} ms" if s < 1 else f"{s:.2f} s"


if __name__ == "__main__":
    sys.exit(main())
