#!/usr/bin/env python3
"""Builds and runs the numeris peer: the timing run, then the instruction
counts of every case under callgrind; writes OUT.txt (the raw outputs) and
OUT.json (the timing JSON with the instruction counts added).

Usage (from the repository root)::

    python3 benchmarks/numeris-peer/run.py [--rounds 301] [--passes 5] [--out benchmarks/results/numeris]

The cargo project builds in its own target directory unless CARGO_TARGET_DIR
is set. Callgrind is skipped with a message when valgrind is not installed.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
CASES = ("numeris", "edccif-cov-local", "edccif-predict-update", "edccif-cov-local-fast")
STEPS_PER_PASS = 200


def sh(cmd: list[str], **kw) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, check=True, text=True, capture_output=True, **kw)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=301)
    ap.add_argument("--passes", type=int, default=5, help="passes of 200 steps per case under callgrind")
    ap.add_argument("--out", default="benchmarks/results/numeris", help="output path without extension")
    args = ap.parse_args()

    subprocess.run(["cargo", "build", "--release", "--quiet"], cwd=HERE, check=True)
    target = Path(os.environ.get("CARGO_TARGET_DIR", HERE / "target"))
    binary = str(target / "release" / "numeris-peer")
    rev = sh(["git", "rev-parse", "--short", "HEAD"], cwd=HERE).stdout.strip()
    dirty = sh(["git", "status", "--porcelain", "--", "../../crates", "."], cwd=HERE).stdout.strip()

    text = [f"$ numeris-peer --rounds {args.rounds}   (commit {rev}{' + uncommitted changes' if dirty else ''})"]
    with tempfile.TemporaryDirectory() as tmp:
        js = os.path.join(tmp, "t.json")
        text.append(sh([binary, "--rounds", str(args.rounds), "--json", js]).stdout.rstrip())
        doc = json.loads(Path(js).read_text())
        doc["commit"] = rev + ("+dirty" if dirty else "")

        if shutil.which("valgrind") and shutil.which("callgrind_annotate"):
            text.append(f"\ninstructions per step (callgrind, {args.passes} passes x {STEPS_PER_PASS} steps per case, "
                        "collected inside numeris_peer::pass_*):")
            instr = {}
            for case in CASES:
                out = os.path.join(tmp, f"cg.{case}.out")
                sh(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", "--collect-atstart=no",
                    "--toggle-collect=numeris_peer::pass_*", binary, "--count", case, "--passes", str(args.passes)])
                ann = sh(["callgrind_annotate", out]).stdout
                m = re.search(r"^\s*([\d,]+)\s.*PROGRAM TOTALS", ann, re.M)
                if m is None:
                    sys.exit(f"no PROGRAM TOTALS in callgrind_annotate output for {case}")
                per_step = int(m.group(1).replace(",", "")) / (args.passes * STEPS_PER_PASS)
                instr[case] = per_step
                text.append(f"  {case:<24} {per_step:10,.0f}")
            for case in CASES[1:]:
                text.append(f"  numeris / {case}: {instr['numeris'] / instr[case]:.2f}")
            doc["instructions_per_step"] = instr
        else:
            text.append("\n(valgrind not found: no instruction counts)")

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".txt").write_text("\n".join(text) + "\n")
    out.with_suffix(".json").write_text(json.dumps(doc, indent=2) + "\n")
    print("\n".join(text))


if __name__ == "__main__":
    main()
