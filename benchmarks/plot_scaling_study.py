#!/usr/bin/env python3
"""Plot the scaling study (``benchmarks/scaling.py``) into docs/figures/scaling.png.

Three panels against N (log-log): thread-CPU time per network step (median,
bars = interquartile range), instructions per node-step, position RMSE.
Ring: solid lines; random geometric graph: dashed. EDC-CIF, EC-CKF with the
adequate L and EC-CKF with the fixed L; projected values (not measured) are
drawn as open markers on dotted lines.

    python3 benchmarks/plot_scaling_study.py [--data benchmarks/results/scaling.json]
        [-o docs/figures/scaling.png]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
COLORS = {"edc-cif": "tab:blue", "ec-ckf": "tab:red"}


def series(records: list[dict], topo: str, row: str, key: str, flag: str | None):
    pts = sorted((r["nodes"], r[key], True if flag is None else bool(r[flag]))
                 for r in records if r["topology"] == topo and r["row"] == row and r[key] is not None)
    return pts


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=ROOT / "benchmarks/results/scaling.json")
    ap.add_argument("-o", "--out", type=Path, default=ROOT / "docs/figures/scaling.png")
    args = ap.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = json.loads(args.data.read_text())
    records = data["records"]
    fixed = data["settings"]["fixed_l"]
    rows = [("edc-cif", "EDC-CIF", "o"), ("ec-ckf", "EC-CKF, adequate L", "s"),
            (f"ec-ckf@L{fixed}", f"EC-CKF, L = {fixed}", "^")]
    fig, axes = plt.subplots(1, 3, figsize=(16, 5.2))
    panels = [
        ("step_cpu_us_median", "time_measured", "thread CPU µs per network step", 1.0),
        ("instr_per_node_step", "instr_measured", "instructions per node-step (k)", 1e-3),
        ("rmse_m", None, "position RMSE (m), one seeded run", 1.0),
    ]
    for ax, (key, flag, ylabel, scale) in zip(axes, panels):
        for topo, ls in (("ring", "-"), ("rgg", "--")):
            for row, label, marker in rows:
                color = COLORS["edc-cif" if row == "edc-cif" else "ec-ckf"]
                alpha = 0.55 if row.startswith("ec-ckf@") else 1.0
                pts = series(records, topo, row, key, flag)
                if not pts:
                    continue
                meas = [(n, v * scale) for n, v, m in pts if m]
                proj = [(n, v * scale) for n, v, m in pts if not m]
                lab = f"{label} ({topo})"
                if meas:
                    ax.plot(*zip(*meas), ls=ls, marker=marker, color=color, alpha=alpha,
                            label=lab, ms=5)
                if proj:
                    joined = ([meas[-1]] if meas else []) + proj
                    ax.plot(*zip(*joined), ls=":", color=color, alpha=alpha)
                    ax.plot(*zip(*proj), ls="none", marker=marker, mfc="none", color=color,
                            alpha=alpha, ms=6, label=f"{lab}, projected")
                if key == "step_cpu_us_median":
                    for r in records:
                        if (r["topology"] == topo and r["row"] == row and r["time_measured"]
                                and r["step_cpu_us_q1"] is not None):
                            ax.plot([r["nodes"]] * 2, [r["step_cpu_us_q1"], r["step_cpu_us_q3"]],
                                    color=color, alpha=alpha, lw=2)
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel("nodes N")
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_title("time per step (solid: ring, dashed: RGG)")
    axes[1].set_title("instructions per node-step")
    axes[2].set_title("accuracy")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.12, 1, 1))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
