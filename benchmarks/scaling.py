#!/usr/bin/env python3
"""Scaling study: EDC-CIF and EC-CKF (adequate L, fixed L) for N = 3 ... 1024.

Drives ``edccif-scaling`` (time per network step, position RMSE, parallel
speed-up; see its doc comment) and counts instructions per node-step under
``valgrind --tool=callgrind`` (collected inside ``edccif_bench::run_steps``
only). Writes the raw outputs into ``benchmarks/results/``:

- ``scaling_timing.json``: the timing binary's JSON (every repetition);
- ``scaling_instr.json``: instructions per (topology, N, row), measured or
  projected;
- ``scaling.json`` / ``scaling.csv``: one record per (topology, N, row) with the
  median time per step and its spread, instructions per node-step, RMSE and
  whether each figure was measured or projected.

EC-CKF with the adequate L grows as N^2 iterations on a ring (L = 1433 at
N = 64, 366 950 at N = 1024); where a step does not fit the budgets it is
*projected* from the cost of one iteration measured at the same N
(``t(L=1) + (L - 1) * b``, ``b`` from L = 1 and L = 21), and marked so.

Usage::

    python3 benchmarks/scaling.py                       # everything (~15-25 min)
    python3 benchmarks/scaling.py --nodes 3,4,8,16 --topology ring --reps 3
    python3 benchmarks/scaling.py --timing-json benchmarks/results/scaling_timing.json  # reuse timings
    python3 benchmarks/plot_scaling_study.py            # docs/figures/scaling.png
"""

from __future__ import annotations

import argparse
import csv
import json
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
NODES = "3,4,8,16,32,64,128,256,512,1024"
# Slowdown of callgrind against the native run, for choosing how many steps to count.
CALLGRIND_SLOWDOWN = 60.0


def log(msg: str) -> None:
    print(f"[scaling.py {time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def target_dir() -> Path:
    meta = subprocess.run(["cargo", "metadata", "--format-version", "1", "--no-deps"],
                          cwd=ROOT, capture_output=True, text=True, check=True)
    return Path(json.loads(meta.stdout)["target_directory"])


def build() -> Path:
    log("cargo build --release -p edccif-bench --bin edccif-scaling")
    subprocess.run(["cargo", "build", "--release", "-q", "-p", "edccif-bench",
                    "--bin", "edccif-scaling"], cwd=ROOT, check=True)
    return target_dir() / "release" / "edccif-scaling"


def callgrind(exe: Path, row: str, topology: str, nodes: int, steps: int, adequate_l: int) -> int:
    """Instructions of `steps` network steps of `row` (from the start of the run)."""
    with tempfile.TemporaryDirectory() as d:
        r = subprocess.run(
            ["valgrind", "--tool=callgrind", f"--callgrind-out-file={d}/cg.out",
             "--collect-atstart=no", "--toggle-collect=edccif_bench::run_steps",
             str(exe), "--instr", row, "--nodes", str(nodes), "--topology", topology,
             "--steps", str(steps), "--adequate-l", str(adequate_l)],
            capture_output=True, text=True, check=True,
        )
    m = re.search(r"Collected : (\d+)", r.stderr)
    if not m:
        raise RuntimeError(f"no callgrind summary for {row} {topology} N={nodes}:\n{r.stderr[-800:]}")
    return int(m.group(1))


def instructions(exe: Path, timing: dict, budget_s: float, max_steps: int) -> dict:
    """Instructions per node-step of every row of every case, measured where a
    callgrind run of at least one step fits `budget_s`, otherwise projected."""
    out: dict = {"budget_s": budget_s, "cases": []}
    fixed_l, probe_l = timing["settings"]["fixed_l"], timing["settings"]["probe_l"]
    for case in timing["cases"]:
        topo, n, lad = case["topology"], case["nodes"], case["adequate_l"]
        rec = {"topology": topo, "nodes": n, "adequate_l": lad, "rows": {}}
        for row, r in case["rows"].items():
            if not r["measured"]:
                continue
            step_s = r["step_cpu_us"]["median"] * 1e-6
            steps = int(min(max_steps, budget_s / (CALLGRIND_SLOWDOWN * step_s)))
            if steps < 1:
                log(f"{topo} N={n} {row}: one step would take ~{CALLGRIND_SLOWDOWN * step_s:.0f} s "
                    "under callgrind; not counted")
                continue
            t0 = time.time()
            ir = callgrind(exe, row, topo, n, steps, lad)
            per = ir / (steps * n)
            rec["rows"][row] = {"measured": True, "steps": steps, "instructions": ir,
                                "per_node_step": per, "iterations": r["iterations"]}
            log(f"{topo} N={n} {row}: {per / 1e3:.1f} k instructions per node-step "
                f"({steps} steps, {time.time() - t0:.0f} s)")
        lo, hi = rec["rows"].get(f"ec-ckf@L{fixed_l}"), rec["rows"].get(f"ec-ckf@L{probe_l}")
        if "ec-ckf" not in rec["rows"] and lo and hi:
            b = (hi["per_node_step"] - lo["per_node_step"]) / (probe_l - fixed_l)
            rec["rows"]["ec-ckf"] = {
                "measured": False, "iterations": lad,
                "per_node_step": lo["per_node_step"] + (lad - fixed_l) * b,
                "projection": f"I(L={fixed_l}) + (L - {fixed_l}) * b, b = (I(L={probe_l}) - "
                              f"I(L={fixed_l})) / {probe_l - fixed_l} per node and iteration, "
                              "counted at this N",
                "per_node_iteration": b,
            }
        out["cases"].append(rec)
    return out


def merge(timing: dict, instr: dict) -> list[dict]:
    """One flat record per (topology, N, row)."""
    by_case = {(c["topology"], c["nodes"]): c for c in instr["cases"]} if instr else {}
    records = []
    for case in timing["cases"]:
        key = (case["topology"], case["nodes"])
        ins = by_case.get(key, {}).get("rows", {})
        for row, r in case["rows"].items():
            i = ins.get(row, {})
            rec = {
                "topology": case["topology"], "nodes": case["nodes"], "row": row,
                "label": r["label"], "iterations": r["iterations"],
                "mean_degree": round(case["mean_degree"], 2),
                "time_measured": r["measured"],
                "step_cpu_us_median": r["step_cpu_us"]["median"] if r["measured"]
                else r["projected_step_cpu_us"],
                "step_cpu_us_q1": r["step_cpu_us"]["q1"] if r["measured"] else None,
                "step_cpu_us_q3": r["step_cpu_us"]["q3"] if r["measured"] else None,
                "step_cpu_us_min": r["step_cpu_us"]["min"] if r["measured"] else None,
                "step_cpu_us_max": r["step_cpu_us"]["max"] if r["measured"] else None,
                "step_wall_us_median": r["step_wall_us"]["median"] if r["measured"] else None,
                "steps_timed": r.get("steps_timed"),
                "instr_per_node_step": i.get("per_node_step"),
                "instr_measured": i.get("measured"),
                "rmse_m": r.get("rmse_m"),
            }
            par = (case.get("parallel") or {}).get(row)
            if par:
                rec["par_serial_wall_us"] = par["serial"]["step_wall_us"]["median"]
                rec["par_1_wall_us"] = par["parallel_1"]["step_wall_us"]["median"]
                rec["par_n_wall_us"] = par["parallel_n"]["step_wall_us"]["median"]
                rec["par_threads"] = par["threads"]
                rec["par_speedup_wall"] = par["speedup_wall"]
                rec["par_serial_wall_us_min"] = par["serial"]["step_wall_us"]["min"]
                rec["par_n_wall_us_min"] = par["parallel_n"]["step_wall_us"]["min"]
                rec["par_1_wall_us_min"] = par["parallel_1"]["step_wall_us"]["min"]
                rec["par_speedup_wall_min"] = par.get("speedup_wall_min")
                rec["par_process_cpu_ratio"] = par.get("process_cpu_ratio")
                rec["par_bit_identical"] = par["bit_identical"]
            records.append(rec)
    return records


def fmt_us(v: float | None) -> str:
    if v is None:
        return "–"
    if v >= 1e6:
        return f"{v / 1e6:.3g} s"
    if v >= 1e3:
        return f"{v / 1e3:.3g} ms"
    return f"{v:.3g} µs"


def markdown(records: list[dict], fixed_l: int) -> str:
    """The tables of docs/performance.md: time per step, instructions per
    node-step, RMSE (columns: topology x row), and the parallel speed-ups."""
    cols = [(t, r) for t in ("ring", "rgg") for r in ("edc-cif", "ec-ckf", f"ec-ckf@L{fixed_l}")]
    names = {"edc-cif": "EDC-CIF", "ec-ckf": "EC-CKF adequate L", f"ec-ckf@L{fixed_l}": f"EC-CKF L = {fixed_l}"}
    get = {(r["topology"], r["nodes"], r["row"]): r for r in records}
    nodes = sorted({r["nodes"] for r in records})
    head = "| N | " + " | ".join(f"{t} {names[r]}" for t, r in cols) + " |"
    rule = "|---" * (len(cols) + 1) + "|"

    def table(title: str, cell) -> list[str]:
        out = [f"\n{title}\n", head, rule]
        for n in nodes:
            cells = []
            for t, row in cols:
                r = get.get((t, n, row))
                cells.append("" if r is None else cell(r))
            out.append(f"| {n} | " + " | ".join(cells) + " |")
        return out

    def t_cell(r: dict) -> str:
        lp = f" (L = {r['iterations']})" if r["row"] == "ec-ckf" else ""
        if not r["time_measured"]:
            return f"*{fmt_us(r['step_cpu_us_median'])} projected*{lp}"
        return (f"{fmt_us(r['step_cpu_us_median'])} [{fmt_us(r['step_cpu_us_q1'])}–"
                f"{fmt_us(r['step_cpu_us_q3'])}]{lp}")

    def i_cell(r: dict) -> str:
        v = r["instr_per_node_step"]
        if v is None:
            return "–"
        return f"{v / 1e3:.1f} k" if r["instr_measured"] else f"*{v / 1e3:.0f} k projected*"

    def e_cell(r: dict) -> str:
        return "–" if r["rmse_m"] is None else f"{r['rmse_m']:.3f}"

    lines = table("Thread-CPU time per network step, median [IQR]:", t_cell)
    lines += table("Instructions per node-step (callgrind):", i_cell)
    lines += table("Position RMSE (m) of one whole seeded run:", e_cell)
    par = [r for r in records if "par_speedup_wall" in r]
    if par:
        lines += ["\nParallel step (wall clock per step: median, and the fastest repetition; "
                  "serial = network_step_sparse):\n",
                  "| topology | N | row | serial | parallel, 1 thread | parallel, 2 threads | "
                  "speed-up (medians) | speed-up (fastest) | 2-thread CPU / serial CPU | identical |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for r in sorted(par, key=lambda r: (r["topology"] != "ring", r["nodes"], r["row"])):
            best = r.get("par_serial_wall_us_min")
            fastest = (f"{best / r['par_n_wall_us_min']:.2f}" if best else "–")
            cpu = r.get("par_process_cpu_ratio")
            lines.append(
                f"| {r['topology']} | {r['nodes']} | {r['label']} | {fmt_us(r['par_serial_wall_us'])} | "
                f"{fmt_us(r['par_1_wall_us'])} | {fmt_us(r['par_n_wall_us'])} | "
                f"{r['par_serial_wall_us'] / r['par_n_wall_us']:.2f} | {fastest} | "
                f"{'–' if cpu is None else f'{cpu:.2f}'} | {r['par_bit_identical']} |")
    return "\n".join(lines) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", type=Path, help="edccif-scaling binary (default: build it)")
    ap.add_argument("--nodes", default=NODES)
    ap.add_argument("--topology", default="ring,rgg")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--budget-s", type=float, default=1.0,
                    help="timed seconds per row and case (steps per run chosen to fit)")
    ap.add_argument("--max-step-s", type=float, default=3.0,
                    help="largest EC-CKF (adequate L) step measured; beyond: projected")
    ap.add_argument("--rmse-budget-s", type=float, default=60.0,
                    help="largest whole run for the RMSE (0: no RMSE)")
    ap.add_argument("--extra", default="", help="more arguments for edccif-scaling, e.g. '--threads 2'")
    ap.add_argument("--timing-json", type=Path, help="reuse this timing JSON instead of running")
    ap.add_argument("--rmse-json", type=Path,
                    help="take RMSE values from this earlier timing JSON (the numbers do not depend "
                         "on speed) where the new one has none")
    ap.add_argument("--no-instr", action="store_true", help="skip the callgrind counts")
    ap.add_argument("--instr-budget-s", type=float, default=20.0,
                    help="native seconds x slowdown allowed per callgrind run")
    ap.add_argument("--instr-max-steps", type=int, default=200)
    ap.add_argument("--out-dir", type=Path, default=RESULTS)
    args = ap.parse_args()

    exe = args.bin or build()
    args.out_dir.mkdir(parents=True, exist_ok=True)
    timing_path = args.out_dir / "scaling_timing.json"
    if args.timing_json:
        timing = json.loads(args.timing_json.read_text())
    else:
        cmd = [str(exe), "--nodes", args.nodes, "--topology", args.topology,
               "--reps", str(args.reps), "--budget-s", str(args.budget_s),
               "--max-step-s", str(args.max_step_s), "--rmse-budget-s", str(args.rmse_budget_s),
               "--out", str(timing_path), *args.extra.split()]
        log(" ".join(cmd))
        subprocess.run(cmd, check=True)  # progress on stderr
        timing = json.loads(timing_path.read_text())
    if args.rmse_json:
        old = {(c["topology"], c["nodes"]): c for c in json.loads(args.rmse_json.read_text())["cases"]}
        for c in timing["cases"]:
            prev = old.get((c["topology"], c["nodes"]), {}).get("rows", {})
            for row, r in c["rows"].items():
                if r.get("rmse_m") is None and prev.get(row, {}).get("rmse_m") is not None:
                    r["rmse_m"] = prev[row]["rmse_m"]
                    r["rmse_from"] = str(args.rmse_json.name)
        timing_path.write_text(json.dumps(timing, indent=2) + "\n")

    instr = None
    if not args.no_instr:
        if shutil.which("valgrind") is None:
            log("valgrind is not installed: no instruction counts")
        else:
            instr = instructions(exe, timing, args.instr_budget_s, args.instr_max_steps)
            (args.out_dir / "scaling_instr.json").write_text(json.dumps(instr, indent=1) + "\n")
    elif (args.out_dir / "scaling_instr.json").exists():
        instr = json.loads((args.out_dir / "scaling_instr.json").read_text())

    records = merge(timing, instr)
    (args.out_dir / "scaling.json").write_text(json.dumps(
        {"settings": timing["settings"], "records": records}, indent=1) + "\n")
    with open(args.out_dir / "scaling.csv", "w", newline="") as f:
        keys = sorted({k for r in records for k in r}, key=lambda k: list(records[0]).index(k)
                      if k in records[0] else 100)
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(records)
    print(markdown(records, timing["settings"]["fixed_l"]))
    log(f"wrote {args.out_dir}/scaling.json, scaling.csv")
    return 0


if __name__ == "__main__":
    sys.exit(main())
