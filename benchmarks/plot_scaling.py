#!/usr/bin/env python3
"""Plot the time of one network step against the number of nodes N.

Reads the JSON of the timing binary (``edccif-timing --json``: seconds per whole
run, ``{"nodes": {"3": {"edc-cif": s, ...}, ...}}``) for every row it holds, and
optionally more such files for the EDC-CIF scaling study (ring and random
geometric graph). Without scaling files it falls back to criterion's
``scaling/edc-cif/{ring,rgg}/N`` estimates (median, ``--criterion DIR``).

    T="cargo run -q --release -p edccif-bench --bin edccif-timing --"
    $T --json --clock cpu > timing.json
    $T --rows edc-cif --nodes 3,4,8,16,32,64 --reps 11 --json --clock cpu > scaling_ring.json
    $T --rows edc-cif --nodes 16,32,64 --topology rgg --reps 11 --json --clock cpu > scaling_rgg.json
    python3 benchmarks/plot_scaling.py --clock cpu --timing timing.json \\
        --ring scaling_ring.json --rgg scaling_rgg.json -o docs/figures/step_time_vs_nodes.png

The paper's Table III (whole-run ms, divided by its 200 steps) is drawn as open
markers for EDC-CIF and EC-CKF, and the 8-node target (10 µs per step) as a star.
With ``--instr`` (``benchmarks/instruction_counts.py --json``; ``--instr-ring`` /
``--instr-rgg`` for the EDC-CIF scaling) a second panel shows instructions per
step, which do not depend on the load of the machine.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ROWS = ["c-ckf", "ec-ekf", "ec-ukf", "ec-ckf", "dec-ckf", "d-cif", "dc-cif", "ed-cif", "edc-cif"]
LABELS = {r: r.upper() for r in ROWS}
PAPER_MS = {  # appendix Table III, whole 200-step run
    "edc-cif": {3: 0.96, 4: 1.32, 8: 1.85},
    "ec-ckf": {3: 1.38, 4: 2.50, 8: 4.94},
}


def load_paper(steps: int) -> dict[str, dict[int, float]]:
    """Table III from crates/edccif-sim/data/paper_tables.json when present."""
    path = ROOT / "crates/edccif-sim/data/paper_tables.json"
    table = PAPER_MS
    try:
        by_nodes = json.loads(path.read_text())["tables"]["table3_time"]["by_nodes"]
        table = {
            row: {int(n): v[row.upper()] for n, v in by_nodes.items() if row.upper() in v}
            for row in PAPER_MS
        }
    except (OSError, KeyError, ValueError):
        pass
    return {row: {n: ms * 1e3 / steps for n, ms in d.items()} for row, d in table.items()}


def per_step_us(path: Path, steps: int) -> dict[str, dict[int, float]]:
    data = json.loads(path.read_text())["nodes"]
    out: dict[str, dict[int, float]] = {}
    for n, rows in data.items():
        for row, seconds in rows.items():
            out.setdefault(row, {})[int(n)] = seconds * 1e6 / steps
    return out


def criterion_scaling(crit: Path, name: str) -> dict[int, float]:
    """Median ns per step of criterion's scaling/edc-cif/<name>/N, in µs."""
    out = {}
    base = crit / "scaling" / f"edc-cif_{name}"
    for d in sorted(base.glob("*")) if base.exists() else []:
        est = d / "new" / "estimates.json"
        if est.exists() and d.name.isdigit():
            out[int(d.name)] = json.loads(est.read_text())["median"]["point_estimate"] / 1e3
    return out


def default_criterion_dir() -> Path:
    try:
        meta = subprocess.run(["cargo", "metadata", "--format-version", "1", "--no-deps"],
                              cwd=ROOT, capture_output=True, text=True, check=True)
        return Path(json.loads(meta.stdout)["target_directory"]) / "criterion"
    except (OSError, subprocess.CalledProcessError):
        return ROOT / "target" / "criterion"


def instructions_per_step(path: Path, steps: int) -> dict[str, dict[int, float]]:
    """instruction_counts.py --json output, in thousands of instructions per step."""
    data = json.loads(path.read_text())["instructions_per_run"]
    out: dict[str, dict[int, float]] = {}
    for n, rows in data.items():
        for row, ir in rows.items():
            out.setdefault(row, {})[int(n)] = ir / steps / 1e3
    return out


def draw(ax, rows, ring, rgg, paper, target, ylabel, title):
    import matplotlib.pyplot as plt

    cmap = plt.get_cmap("tab10")
    colors = {row: cmap(i) for i, row in enumerate(ROWS)}
    for row in (r for r in ROWS if r in rows):
        pts = sorted(rows[row].items())
        bold = row in ("edc-cif", "ec-ckf")
        ax.plot([p[0] for p in pts], [p[1] for p in pts], marker="o", color=colors[row],
                lw=2.4 if bold else 1.0, alpha=1.0 if bold else 0.6, label=f"{LABELS[row]} (ring)")
    if ring:
        pts = sorted(ring.items())
        ax.plot([p[0] for p in pts], [p[1] for p in pts], ls="--", marker="s",
                color=colors["edc-cif"], lw=1.6, label="EDC-CIF, ring (scaling run)")
    if rgg:
        pts = sorted(rgg.items())
        ax.plot([p[0] for p in pts], [p[1] for p in pts], ls=":", marker="^",
                color=colors["edc-cif"], lw=1.8, label="EDC-CIF, random geometric graph")
    for row, d in (paper or {}).items():
        pts = sorted(d.items())
        ax.plot([p[0] for p in pts], [p[1] for p in pts], ls="none", marker="D", ms=8,
                mfc="none", mec=colors[row], mew=1.6, label=f"paper Table III {LABELS[row]} (ms/200)")
    if target:
        ax.plot([8], [target], marker="*", ms=14, color="k", ls="none",
                label="target: 8-node EDC-CIF step")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ns = sorted({n for d in list(rows.values()) + [ring, rgg] for n in d})
    ax.set_xticks(ns)
    ax.set_xticklabels([str(n) for n in ns])
    ax.set_xlabel("nodes N")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6.5, ncol=2, loc="upper left")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--timing", type=Path, required=True, help="edccif-timing --json output")
    ap.add_argument("--ring", type=Path, help="edccif-timing --json for EDC-CIF on rings")
    ap.add_argument("--rgg", type=Path, help="edccif-timing --json for EDC-CIF on random geometric graphs")
    ap.add_argument("--criterion", type=Path, help="criterion output dir (fallback for the scaling)")
    ap.add_argument("--instr", type=Path, help="instruction_counts.py --json (all rows): adds a panel")
    ap.add_argument("--instr-ring", type=Path, help="instruction_counts.py --json, EDC-CIF rings")
    ap.add_argument("--instr-rgg", type=Path, help="instruction_counts.py --json, EDC-CIF rgg")
    ap.add_argument("--steps", type=int, default=200, help="steps per run in the JSON (default 200)")
    ap.add_argument("--clock", choices=["wall", "cpu"], default="wall",
                    help="which clock the JSON files hold (edccif-timing --clock), for the label")
    ap.add_argument("-o", "--output", type=Path,
                    default=ROOT / "docs/figures/step_time_vs_nodes.png")
    args = ap.parse_args()

    try:
        import matplotlib
    except ImportError:
        subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "matplotlib"], check=True)
        import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = per_step_us(args.timing, args.steps)
    crit = args.criterion or default_criterion_dir()
    ring = per_step_us(args.ring, args.steps).get("edc-cif", {}) if args.ring else criterion_scaling(crit, "ring")
    rgg = per_step_us(args.rgg, args.steps).get("edc-cif", {}) if args.rgg else criterion_scaling(crit, "rgg")
    paper = load_paper(args.steps)
    clock = "thread CPU time" if args.clock == "cpu" else "wall time"

    panels = 2 if args.instr else 1
    fig, axes = plt.subplots(1, panels, figsize=(7.5 * panels, 5.5), dpi=120, squeeze=False)
    draw(axes[0][0], rows, ring, rgg, paper, 10.0,
         f"{clock} per network step (µs, median)", f"Time per network step ({clock})")
    if args.instr:
        irows = instructions_per_step(args.instr, args.steps)
        iring = instructions_per_step(args.instr_ring, args.steps).get("edc-cif", {}) if args.instr_ring else {}
        irgg = instructions_per_step(args.instr_rgg, args.steps).get("edc-cif", {}) if args.instr_rgg else {}
        if iring and "edc-cif" in irows:
            iring = {**{n: v for n, v in irows["edc-cif"].items()}, **iring}
        draw(axes[0][1], irows, iring, irgg, None, None,
             "thousand instructions per network step (callgrind)",
             "Instructions per network step (deterministic)")
    fig.suptitle("edccif: one synchronous network step of the default scenario", fontsize=12)
    fig.tight_layout()
    args.output.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.output)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
