#!/usr/bin/env python3
"""Table III, fair: EDC-CIF vs EC-CKF (adequate L, and fixed L = 1, 2) at N = 3, 4, 8.

Runs ``edccif-timing --fair --json`` (whole 200-step runs, interleaved
repetitions, every sample kept) and ``benchmarks/instruction_counts.py`` for the
same rows plus EC-CKF at L = 21 (the per-iteration cost), writes the raw outputs
to ``benchmarks/results/table3_fair.json`` and ``table3_fair_instr.json``, and
prints the markdown table of docs/performance.md with the cost model

    EC-CKF per node-step = a + L * b,   EDC-CIF per node-step = d,
    break-even L* = (d - a) / b

fitted on the instruction counts at L = 1 and L = 21 (deterministic).

    python3 benchmarks/table3_fair.py [--reps 51] [--nodes 3,4,8]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
PAPER = {3: 0.3043, 4: 0.4720, 8: 0.6255}
PROBE = 21


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=51)
    ap.add_argument("--nodes", default="3,4,8")
    ap.add_argument("--fixed-l", default="1,2")
    ap.add_argument("--no-instr", action="store_true", help="reuse table3_fair_instr.json")
    args = ap.parse_args()
    subprocess.run(["cargo", "build", "--release", "-q", "-p", "edccif-bench", "--bin", "edccif-timing"],
                   cwd=ROOT, check=True)
    meta = subprocess.run(["cargo", "metadata", "--format-version", "1", "--no-deps"],
                          cwd=ROOT, capture_output=True, text=True, check=True)
    exe = Path(json.loads(meta.stdout)["target_directory"]) / "release" / "edccif-timing"
    print(f"timing ({args.reps} interleaved repetitions) ...", file=sys.stderr)
    out = subprocess.run([str(exe), "--fair", "--reps", str(args.reps), "--nodes", args.nodes,
                          "--fixed-l", args.fixed_l, "--json"], capture_output=True, text=True,
                         check=True).stdout
    timing = json.loads(out)
    (RESULTS / "table3_fair.json").write_text(json.dumps(timing, indent=1) + "\n")
    fixed = [int(x) for x in args.fixed_l.split(",")]
    rows = ["edc-cif", "ec-ckf", *[f"ec-ckf@L{f}" for f in fixed], f"ec-ckf@L{PROBE}"]
    instr_path = RESULTS / "table3_fair_instr.json"
    if args.no_instr and not instr_path.exists():
        sys.exit(f"table3_fair.py: --no-instr reuses {instr_path}, which does not exist; run once without it")
    if not args.no_instr:
        print("instructions (callgrind) ...", file=sys.stderr)
        subprocess.run([sys.executable, str(ROOT / "benchmarks/instruction_counts.py"), "--bin", str(exe),
                        "--nodes", args.nodes, "--rows", ",".join(rows), "--json", str(instr_path)],
                       check=True, stdout=sys.stderr)
    instr = json.loads(instr_path.read_text())["instructions_per_run"]

    print("| N | row | L | wall ms, median [IQR] | thread-CPU ms, median [IQR] | k instr / node-step "
          "| EDC-CIF vs row, CPU | EDC-CIF vs row, instr | paper |")
    print("|---|---|---|---|---|---|---|---|---|")
    models = []
    for n_s, case in timing["nodes"].items():
        n = int(n_s)
        steps = case["steps"]
        ins = {r: v / (n * steps) for r, v in instr[n_s].items()}
        edc_cpu = case["rows"]["edc-cif"]["cpu"]["median"]
        order = ["edc-cif", "ec-ckf", *[f"ec-ckf@L{f}" for f in fixed]]
        for row in order:
            r = case["rows"][row]
            w, c = r["wall"], r["cpu"]
            red_cpu = "–" if row == "edc-cif" else f"{100 * (1 - edc_cpu / c['median']):+.1f} %"
            red_ins = "–" if row == "edc-cif" else f"{100 * (1 - ins['edc-cif'] / ins[row]):+.1f} %"
            paper = f"{100 * PAPER[n]:.2f} %" if row == "ec-ckf" and n in PAPER else ""
            label = r["label"] if row != "ec-ckf" else "EC-CKF (adequate L)"
            lcol = "–" if row == "edc-cif" else str(r["iterations"])
            print(f"| {n} | {label} | {lcol} | {1e3 * w['median']:.3f} [{1e3 * w['q1']:.3f}–{1e3 * w['q3']:.3f}] "
                  f"| {1e3 * c['median']:.3f} [{1e3 * c['q1']:.3f}–{1e3 * c['q3']:.3f}] "
                  f"| {ins[row] / 1e3:.1f} | {red_cpu} | {red_ins} | {paper} |")
        b = (ins[f"ec-ckf@L{PROBE}"] - ins["ec-ckf@L1"]) / (PROBE - 1)
        a = ins["ec-ckf@L1"] - b
        d = ins["edc-cif"]
        tm = case.get("per_node_step_model_cpu") or {}
        models.append((n, case["adequate_l"], a, b, d, (d - a) / b, tm))
    print()
    print("| N | adequate L | EC-CKF outside the iterations a | one iteration b | EDC-CIF d "
          "| b / d | break-even L* = (d − a)/b | timing model (CPU): b, L* |")
    print("|---|---|---|---|---|---|---|---|")
    for n, lad, a, b, d, le, tm in models:
        t = (f"{1e9 * tm['b_s']:.0f} ns, {tm['break_even_l']:.1f}" if tm and tm.get("b_s", 0) > 0
             else "below the noise")
        print(f"| {n} | {lad} | {a / 1e3:.2f} k | {b:.0f} | {d / 1e3:.2f} k | {100 * b / d:.1f} % "
              f"| {le:.1f} | {t} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
