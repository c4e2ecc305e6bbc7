#!/usr/bin/env python3
"""Load-independent cost of every algorithm row: instructions per whole run.

Wall times on a shared 2-core machine are noisy; instruction counts are not.
This runs the timing binary under ``valgrind --tool=callgrind`` for each
(row, N), collecting only inside ``edccif_bench::run_steps`` (the timed network steps,
nothing else), and prints instructions per 200-step run and per node-step,
with the reduction of every row against EC-CKF.

Usage::

    cargo build --release -p edccif-bench --bin edccif-timing
    python3 benchmarks/instruction_counts.py [--bin PATH] [--nodes 3,4,8] [--rows edc-cif,...]
        [--topology ring|rgg] [--json OUT.json]
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROWS = ["c-ckf", "ec-ekf", "ec-ukf", "ec-ckf", "dec-ckf", "d-cif", "dc-cif", "ed-cif", "edc-cif"]
ROOT = Path(__file__).resolve().parent.parent


def default_bin() -> Path:
    meta = subprocess.run(["cargo", "metadata", "--format-version", "1", "--no-deps"],
                          cwd=ROOT, capture_output=True, text=True, check=True)
    return Path(json.loads(meta.stdout)["target_directory"]) / "release" / "edccif-timing"


def instructions_per_run(exe: Path, row: str, nodes: int, topology: str = "ring") -> float:
    # --reps 1 runs the case twice (one warm-up pass, one timed repetition).
    with tempfile.TemporaryDirectory() as d:
        r = subprocess.run(
            ["valgrind", "--tool=callgrind", f"--callgrind-out-file={d}/cg.out",
             "--collect-atstart=no", "--toggle-collect=edccif_bench::run_steps",
             str(exe), "--rows", row, "--nodes", str(nodes), "--topology", topology,
             "--reps", "1", "--json"],
            capture_output=True, text=True, check=True,
        )
    m = re.search(r"Collected : (\d+)", r.stderr)
    if not m:
        raise RuntimeError(f"no callgrind summary for {row} N={nodes}:\n{r.stderr[-1000:]}")
    return int(m.group(1)) / 2


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", type=Path, help="edccif-timing binary (default: cargo's target dir)")
    ap.add_argument("--nodes", default="3,4,8")
    ap.add_argument("--rows", default=",".join(ROWS), help="comma-separated rows (default all)")
    ap.add_argument("--topology", default="ring", choices=["ring", "rgg"])
    ap.add_argument("--steps", type=int, default=200, help="steps per run (for per-step figures)")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    if shutil.which("valgrind") is None:
        print("valgrind is not installed (apt-get install valgrind)", file=sys.stderr)
        return 1
    exe = args.bin or default_bin()
    nodes = [int(n) for n in args.nodes.split(",")]
    rows = [r.strip() for r in args.rows.split(",")]
    result: dict[str, dict[str, float]] = {}
    for n in nodes:
        result[str(n)] = {row: instructions_per_run(exe, row, n, args.topology) for row in rows}
        base = result[str(n)].get("ec-ckf")
        print(f"N = {n} ({args.topology}): instructions per {args.steps}-step run "
              "(callgrind, edccif_bench::run_steps only: the timed network steps)")
        print(f"  {'row':<8} {'Mi/run':>9} {'ki/node-step':>13} {'vs EC-CKF':>10}")
        for row in rows:
            ir = result[str(n)][row]
            vs = f"{100 * (1 - ir / base):>9.1f}%" if base else f"{'-':>10}"
            print(f"  {row:<8} {ir / 1e6:>9.2f} {ir / (n * args.steps) / 1e3:>13.1f} {vs}")
    if args.json:
        args.json.write_text(json.dumps({"instructions_per_run": result}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
