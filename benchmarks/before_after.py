#!/usr/bin/env python3
"""Two builds of ``edccif-timing`` measured side by side: the speed targets before and after.

Wall times on a shared machine drift by tens of percent between runs minutes
apart, so the two binaries are run alternately (ABBA order, ``--rounds`` times)
in one session and every figure is a median over the rounds, with its
interquartile range; the ratio after/before is taken per round and its median
given. Instruction counts (callgrind, deterministic) are given beside the times.

Measured for each binary:

* one node's local step of every case of ``edccif-timing --local-step``
  (ET-CIF sent / not sent, CIF, CKF, EKF, UKF), thread-CPU and wall µs;
* a whole 200-step run of EDC-CIF and EC-CKF at N = 3, 4, 8 (``--clock cpu``), as
  µs per network step;
* instructions per local step (callgrind around ``LocalFixture::step``, the
  difference of two batch sizes so that set-up and warm-up cancel) and per
  node-step of a network run (around ``Network::step_with``).

Usage::

    python3 benchmarks/before_after.py --before OLD/edccif-timing --after NEW/edccif-timing \\
        [--rounds 7] [--no-instructions] [--json OUT.json] [--markdown OUT.md] \\
        [--after-args=--fast-trig] [--pair ekf/chained=ekf/always]
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

NODES = (3, 4, 8)
ROWS = ("edc-cif", "ec-ckf")
STEPS = 200


def run_json(exe: Path, args: list[str], extra: list[str]) -> dict:
    out = subprocess.run([str(exe), *args, *extra, "--json"], capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout)


def quartiles(xs: list[float]) -> tuple[float, float, float]:
    if len(xs) < 2:
        return xs[0], xs[0], xs[0]
    q = statistics.quantiles(xs, n=4, method="inclusive")
    return q[0], statistics.median(xs), q[2]


def one_round(exe: Path, reps: int, extra: list[str]) -> dict[str, dict[str, float]]:
    """One measurement of every figure with one binary: {name: {clock: µs}}."""
    out: dict[str, dict[str, float]] = {}
    local = run_json(exe, ["--local-step", "--reps", str(reps)], extra)["local_step_us"]
    for case, t in local.items():
        out[f"local {case}"] = {"cpu": t["cpu_us"], "wall": t["wall_us"]}
    nodes = ",".join(str(n) for n in NODES)
    rows = ",".join(ROWS)
    for clock in ("cpu", "wall"):
        net = run_json(exe, ["--rows", rows, "--nodes", nodes, "--reps", str(reps), "--clock", clock],
                       extra)
        for n, per_row in net["nodes"].items():
            for row, seconds in per_row.items():
                out.setdefault(f"step {row} N={n}", {})[clock] = seconds * 1e6 / STEPS
    return out


def callgrind(exe: Path, toggle: str, args: list[str], extra: list[str]) -> int:
    with tempfile.TemporaryDirectory() as d:
        r = subprocess.run(
            ["valgrind", "--tool=callgrind", f"--callgrind-out-file={d}/cg.out",
             "--collect-atstart=no", f"--toggle-collect={toggle}", str(exe), *args, *extra,
             "--json"],
            capture_output=True, text=True, check=True,
        )
    m = re.search(r"Collected : (\d+)", r.stderr)
    if not m:
        raise RuntimeError(f"no callgrind summary for {exe} {args}:\n{r.stderr[-800:]}")
    return int(m.group(1))


def instructions(exe: Path, cases: list[str], known: set[str], extra: list[str],
                 label: str) -> dict[str, float]:
    """Instructions per local step (per case in ``known``) and per node-step (per row and N)."""
    out: dict[str, float] = {}
    small, large = 200, 400
    for case in cases:
        if case not in known:
            continue  # a case this build does not have (e.g. added after it)
        # --reps 1 runs a warm-up batch and one timed batch: 2 × batch steps.
        a = callgrind(exe, "*LocalFixture::step", ["--local-step", "--cases", case, "--reps", "1",
                                                  "--batch", str(small)], extra)
        b = callgrind(exe, "*LocalFixture::step", ["--local-step", "--cases", case, "--reps", "1",
                                                  "--batch", str(large)], extra)
        out[f"local {case}"] = (b - a) / (2 * (large - small))
        print(f"  instructions {label} local {case}: {out[f'local {case}']:.0f}",
              file=sys.stderr)
    for row in ROWS:
        for n in NODES:
            # --reps 1 runs the case twice (warm-up and timed).
            total = callgrind(exe, "edccif_sim::runner::Network*step*_with",
                              ["--rows", row, "--nodes", str(n), "--reps", "1"], extra)
            out[f"step {row} N={n}"] = total / 2 / STEPS / n
            print(f"  instructions {label} {row} N={n}: "
                  f"{out[f'step {row} N={n}']:.0f} per node-step", file=sys.stderr)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--before", type=Path, required=True, help="edccif-timing of the old build")
    ap.add_argument("--after", type=Path, required=True, help="edccif-timing of the new build")
    ap.add_argument("--rounds", type=int, default=7, help="ABBA rounds (default 7)")
    ap.add_argument("--reps", type=int, default=5, help="--reps passed to each run (default 5)")
    ap.add_argument("--no-instructions", action="store_true", help="skip callgrind")
    ap.add_argument("--before-args", default="", help="extra options of every before run")
    ap.add_argument("--after-args", default="",
                    help="extra options of every after run (e.g. --fast-trig)")
    ap.add_argument("--pair", action="append", default=[], metavar="AFTER=BEFORE",
                    help="also compare local case AFTER of the new build with case BEFORE "
                         "of the old one (e.g. ekf/chained=ekf/always); repeatable")
    ap.add_argument("--json", type=Path, help="write every sample to this file")
    ap.add_argument("--markdown", type=Path, help="write the table to this file")
    args = ap.parse_args()
    for exe in (args.before, args.after):
        if not exe.is_file():
            ap.error(f"no such binary: {exe}")

    before_extra, after_extra = args.before_args.split(), args.after_args.split()
    order = [("before", args.before, before_extra), ("after", args.after, after_extra)]
    samples: dict[str, dict[str, dict[str, list[float]]]] = {"before": {}, "after": {}}
    for r in range(args.rounds):
        abba = list(order)
        if r % 2:
            abba.reverse()
        for label, exe, extra in abba:
            for name, clocks in one_round(exe, args.reps, extra).items():
                for clock, us in clocks.items():
                    samples[label].setdefault(name, {}).setdefault(clock, []).append(us)
        print(f"round {r + 1}/{args.rounds} done", file=sys.stderr)

    instr: dict[str, dict[str, float]] = {}
    if not args.no_instructions:
        cases = sorted(k.removeprefix("local ") for k in samples["after"] if k.startswith("local "))
        for label, exe, extra in order:
            known = {k.removeprefix("local ") for k in samples[label] if k.startswith("local ")}
            instr[label] = instructions(exe, cases, known, extra, label)

    lines = [
        "| figure | clock | before µs (IQR) | after µs (IQR) | after/before (IQR) | instr before | instr after |",
        "|---|---|---|---|---|---|---|",
    ]
    summary = {}
    figures = [(name, name, name) for name in samples["after"]]
    for pair in args.pair:
        after_case, _, before_case = pair.partition("=")
        figures.append((f"local {after_case} vs {before_case}", f"local {after_case}",
                        f"local {before_case}"))
    for name, after_name, before_name in figures:
        for clock in ("cpu", "wall"):
            b = samples["before"].get(before_name, {}).get(clock)
            a = samples["after"].get(after_name, {}).get(clock)
            if not a or not b:
                continue
            ratios = [x / y for x, y in zip(a, b)]
            qb, qa, qr = quartiles(b), quartiles(a), quartiles(ratios)
            ib = instr.get("before", {}).get(before_name)
            ia = instr.get("after", {}).get(after_name)
            summary[f"{name} {clock}"] = {"before": qb, "after": qa, "ratio": qr,
                                          "instr_before": ib, "instr_after": ia}
            fmt = lambda v: "" if v is None else f"{v / 1000:.1f} k"  # noqa: E731
            lines.append(
                f"| {name} | {clock} | {qb[1]:.3f} ({qb[0]:.3f}–{qb[2]:.3f}) | "
                f"{qa[1]:.3f} ({qa[0]:.3f}–{qa[2]:.3f}) | {qr[1]:.3f} ({qr[0]:.3f}–{qr[2]:.3f}) | "
                f"{fmt(ib) if clock == 'cpu' else ''} | {fmt(ia) if clock == 'cpu' else ''} |"
            )
    table = "\n".join(lines)
    print(table)
    if args.markdown:
        args.markdown.write_text(table + "\n")
    if args.json:
        args.json.write_text(json.dumps({"samples": samples, "instructions": instr,
                                         "summary": summary, "rounds": args.rounds,
                                         "reps": args.reps, "before_args": before_extra,
                                         "after_args": after_extra}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
