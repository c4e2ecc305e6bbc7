"""Figures of the reproduction (matplotlib, Agg backend; every function writes a PNG
and returns its path)."""

from __future__ import annotations

from pathlib import Path
from typing import Dict, List, Mapping, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def _save(fig: plt.Figure, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def trajectory_3d(
    truth: np.ndarray, estimate: np.ndarray, sensors: np.ndarray, path: Path, label: str = "EDC-CIF"
) -> Path:
    """Truth (T, n) against one node's estimate (T, n) in 3-D, with the sensors (N, 3)."""
    fig = plt.figure(figsize=(6.5, 5.5))
    ax = fig.add_subplot(projection="3d")
    ax.plot(truth[:, 0], truth[:, 1], truth[:, 2], "k-", lw=1.5, label="truth")
    ax.plot(estimate[:, 0], estimate[:, 1], estimate[:, 2], "C1--", lw=1.2, label=f"{label} (node 0)")
    ax.scatter(sensors[:, 0], sensors[:, 1], sensors[:, 2], c="C0", marker="^", s=40, label="sensors")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.legend(loc="upper left")
    ax.set_title("Target trajectory and fused estimate")
    return _save(fig, path)


def rmse_over_time(
    pos_curves: Mapping[str, np.ndarray], vel_curves: Mapping[str, np.ndarray], dt: float, path: Path
) -> Path:
    """Position and velocity RMSE over time per algorithm."""
    fig, axes = plt.subplots(2, 1, figsize=(7.5, 6), sharex=True)
    for i, (label, c) in enumerate(pos_curves.items()):
        t = np.arange(1, len(c) + 1) * dt
        style = "-" if "CIF" in label else "--"
        axes[0].plot(t, c, style, color=f"C{i % 10}", lw=1.1, label=label)
        axes[1].plot(t, vel_curves[label], style, color=f"C{i % 10}", lw=1.1)
    axes[0].set_ylabel("position RMSE (m)")
    axes[1].set_ylabel("velocity RMSE (m/s)")
    axes[1].set_xlabel("time (s)")
    axes[0].legend(ncol=3, fontsize=8)
    axes[0].set_title("RMSE over time (Monte Carlo, node-averaged)")
    return _save(fig, path)


def trigger_instants(triggered: np.ndarray, dt: float, path: Path, steps: int = 100) -> Path:
    """Trigger instants (T, N) bool of the first `steps` steps, one row per node."""
    trig = triggered[:steps]
    fig, ax = plt.subplots(figsize=(7.5, 0.5 + 0.45 * trig.shape[1]))
    for i in range(trig.shape[1]):
        k = np.nonzero(trig[:, i])[0]
        ax.vlines((k + 1) * dt, i + 0.6, i + 1.4, color=f"C{i % 10}")
    ax.set_yticks(np.arange(1, trig.shape[1] + 1))
    ax.set_yticklabels([f"node {i}" for i in range(trig.shape[1])])
    ax.set_xlabel("time (s)")
    rate = trig.mean()
    ax.set_title(f"Trigger instants, first {len(trig)} steps (rate {100 * rate:.0f} %)")
    return _save(fig, path)


def delta_sweep(
    deltas: Sequence[float],
    pos_rmse: Mapping[str, Sequence[float]],
    trigger_rate: Mapping[str, Sequence[float]],
    path: Path,
) -> Path:
    """Position RMSE and trigger rate against the threshold δ."""
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.6))
    for i, label in enumerate(pos_rmse):
        a.plot(deltas, pos_rmse[label], "o-", color=f"C{i}", label=label)
        b.plot(deltas, 100 * np.asarray(trigger_rate[label]), "o-", color=f"C{i}", label=label)
    a.set_xlabel("δ")
    a.set_ylabel("position RMSE (m)")
    b.set_xlabel("δ")
    b.set_ylabel("trigger rate (%)")
    a.legend(fontsize=8)
    fig.suptitle("Effect of the trigger threshold δ")
    return _save(fig, path)


def computation_time(times_ms: Mapping[int, Mapping[str, float]], path: Path) -> Path:
    """Median time of a whole run per algorithm, grouped by node count."""
    nodes: List[int] = sorted(times_ms)
    labels: List[str] = list(next(iter(times_ms.values())).keys())
    width = 0.8 / max(1, len(nodes))
    fig, ax = plt.subplots(figsize=(9, 3.8))
    x = np.arange(len(labels))
    for j, n in enumerate(nodes):
        ax.bar(x + j * width, [times_ms[n][lab] for lab in labels], width, label=f"{n} nodes")
    ax.set_xticks(x + width * (len(nodes) - 1) / 2)
    ax.set_xticklabels(labels, rotation=30, ha="right")
    ax.set_ylabel("median time per 200-step run (ms)")
    ax.legend()
    ax.set_title("Computation time per algorithm (one core)")
    return _save(fig, path)


def time_rows(
    sc_by_nodes: Dict[int, object], algorithms: Sequence[str], reps: int = 11, progress: bool = True
) -> Dict[int, Dict[str, float]]:
    """Median wall time (ms) of a whole run per algorithm and node count: every row
    runs on the same simulated data, repetitions interleaved, one thread."""
    from tqdm import tqdm

    from . import _edccif

    out: Dict[int, Dict[str, float]] = {}
    total = len(sc_by_nodes) * reps * len(algorithms)
    with tqdm(total=total, desc="timing", disable=not progress, unit="run") as bar:
        for n, sc in sc_by_nodes.items():
            _, z, x0 = sc.simulate(seed=0)  # type: ignore[attr-defined]
            samples: Dict[str, List[float]] = {a: [] for a in algorithms}
            for _ in range(reps):
                for a in algorithms:
                    r = _edccif.run(a, sc, z, x0=x0, record_covariances=False)  # type: ignore[arg-type]
                    samples[a].append(r.elapsed_s)
                    bar.update(1)
            out[n] = {a: 1e3 * float(np.median(s)) for a, s in samples.items()}
    return out
