"""Figures of the reproduction (matplotlib, Agg backend; every function writes a PNG
and returns its path)."""

from __future__ import annotations

from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def _wrap_line(line: str, fits) -> List[str]:
    """``line`` in pieces that each ``fits``, broken after ``"; "`` or ``", "``
    where it can (so ``"A = B = C"`` stays on one line), otherwise between
    words; a single word longer than the width stays whole."""
    if fits(line):
        return [line]
    for sep in ("; ", ", ", " "):
        parts = line.split(sep)
        if len(parts) == 1:
            continue
        out, cur = [], parts[0]
        for part in parts[1:]:
            trial = cur + sep + part
            if fits(trial.rstrip()):
                cur = trial
            else:
                out.append((cur + sep).rstrip())
                cur = part
        out.append(cur)
        if all(fits(x) for x in out):
            return out
        return [y for x in out for y in _wrap_line(x, fits)] if sep != " " else out
    return [line]


def fit_titles(fig: plt.Figure) -> None:
    """Breaks every axes title and the figure's suptitle into lines that fit
    the width of the figure (a title of long algorithm names or a long
    coincidence note would otherwise run off both edges of the PNG)."""
    renderer = fig.canvas.get_renderer()
    # an axes title may use the axes' width (a little more, as tight_layout
    # widens the axes), the suptitle the figure's
    texts = [(t, min(fig.bbox.width, ax.bbox.width * 1.1) * 0.97)
             for ax in fig.axes for t in (ax.title, ax._left_title, ax._right_title)]
    if fig._suptitle is not None:
        texts.append((fig._suptitle, fig.bbox.width * 0.97))
    for text, width in texts:
        s = text.get_text()
        if not s:
            continue
        probe = text.get_fontproperties()

        def fits(line: str, probe=probe, width=width) -> bool:
            w, _, _ = renderer.get_text_width_height_descent(line, probe, ismath=False)
            return w <= width

        text.set_text("\n".join(x for line in s.split("\n") for x in _wrap_line(line, fits)))


def _save(fig: plt.Figure, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fit_titles(fig)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def coincident_groups(curves: Mapping[str, np.ndarray], rtol: float = 1e-9, atol: float = 0.0) -> List[List[str]]:
    """Groups of curves that coincide (every point within ``rtol`` of the
    curves' scale plus ``atol``), in the order of ``curves``; a curve alone is a
    group of one.

    >>> a = np.array([1.0, 2.0])
    >>> coincident_groups({"A": a, "B": a.copy(), "C": a + 1})
    [['A', 'B'], ['C']]
    """
    groups: List[List[str]] = []
    for label, c in curves.items():
        c = np.asarray(c, dtype=float)
        for g in groups:
            ref = np.asarray(curves[g[0]], dtype=float)
            scale = max(float(np.nanmax(np.abs(ref))) if ref.size else 0.0, 1e-300)
            if ref.shape == c.shape and bool(np.all(np.abs(ref - c) <= rtol * scale + atol)):
                g.append(label)
                break
        else:
            groups.append([label])
    return groups


def coincidence_note(groups: Sequence[Sequence[str]], exact: Optional[Sequence[Sequence[str]]] = None) -> str:
    """``"EC-EKF = EC-UKF = EC-CKF; D-CIF = DC-CIF"`` for the groups of more
    than one curve (empty when no curves coincide). With ``exact`` (the groups
    of equal curves), members of a group that are not equal are joined by ``≈``."""
    def same(a: str, b: str) -> bool:
        return exact is None or any(a in g and b in g for g in exact)

    return "; ".join(g[0] + "".join((" = " if same(g[0], x) else " ≈ ") + x for x in g[1:])
                     for g in groups if len(g) > 1)


VISUAL_TOL = 0.02
"""Curves closer than this fraction of their panel's range at every point are
drawn as one group in :func:`rmse_over_time` (at the figure's size they overlap)."""


def _panel_normalised(curves: Mapping[str, np.ndarray]) -> Dict[str, np.ndarray]:
    """The curves scaled to their panel's range (0 = lowest point, 1 = highest)."""
    arrs = {k: np.asarray(c, dtype=float) for k, c in curves.items()}
    vals = np.concatenate([a.ravel() for a in arrs.values()]) if arrs else np.zeros(1)
    lo, hi = float(np.nanmin(vals)), float(np.nanmax(vals))
    span = hi - lo if hi > lo else 1.0
    return {k: (a - lo) / span for k, a in arrs.items()}


_STYLES: Tuple[Tuple[str, str], ...] = (("-", ""), ("--", "o"), (":", "x"), ("-.", "s"))


def trajectory_3d(
    truth: np.ndarray, estimate: np.ndarray, sensors: np.ndarray, path: Path, label: str = "EDC-CIF",
    context: str = "",
) -> Path:
    """Truth (T, n) against one node's estimate (T, n) in 3-D, with the sensors
    (N, 3); ``context`` (scenario, nodes, run) is added to the title."""
    fig = plt.figure(figsize=(6.5, 5.5))
    ax = fig.add_subplot(projection="3d")
    ax.plot(truth[:, 0], truth[:, 1], truth[:, 2], "k-", lw=1.5, label="truth")
    ax.plot(estimate[:, 0], estimate[:, 1], estimate[:, 2], "C1--", lw=1.2, label=f"{label} (node 0)")
    ax.scatter(sensors[:, 0], sensors[:, 1], sensors[:, 2], c="C0", marker="^", s=40, label="sensors")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.legend(loc="upper left")
    ax.set_title("Target trajectory and fused estimate" + (f"\n{context}" if context else ""), fontsize=10)
    return _save(fig, path)


def rmse_over_time(
    pos_curves: Mapping[str, np.ndarray], vel_curves: Mapping[str, np.ndarray], dt: float, path: Path,
    context: str = "",
) -> Path:
    """Position and velocity RMSE over time per algorithm; ``context`` (scenario,
    nodes, runs) is added to the title. Curves that lie on each other in both
    panels (within :data:`VISUAL_TOL` of the panel's range at every point) share
    a colour and are drawn with different line styles and markers, and the title
    says which lie on which (``=`` equal, ``≈`` within that tolerance)."""
    fig, axes = plt.subplots(2, 1, figsize=(7.5, 6.6), sharex=True)
    both = {lab: np.concatenate([np.asarray(c, float), np.asarray(vel_curves[lab], float)])
            for lab, c in pos_curves.items()}
    pn, vn = _panel_normalised(pos_curves), _panel_normalised(vel_curves)
    groups = coincident_groups({lab: np.concatenate([pn[lab], vn[lab]]) for lab in pos_curves},
                               rtol=0.0, atol=VISUAL_TOL)
    exact = coincident_groups(both)
    for gi, g in enumerate(groups):
        for j, label in enumerate(g):
            c = np.asarray(pos_curves[label])
            t = np.arange(1, len(c) + 1) * dt
            ls, mk = _STYLES[j % len(_STYLES)]
            if len(g) == 1:
                ls, mk = ("-" if "CIF" in label else "--"), ""
            every = max(1, len(c) // 12)
            kw = dict(color=f"C{gi % 10}", lw=1.1 if j == 0 else 1.0, marker=mk or None,
                      markevery=(j * every // 3, every), ms=4, mfc="none")
            rel = "=" if all(any(label in e and x in e for e in exact) for x in g) else "≈"
            shown = label if len(g) == 1 else f"{label} ({rel} {', '.join(x for x in g if x != label)})"
            axes[0].plot(t, c, ls, label=shown, **kw)
            axes[1].plot(t, vel_curves[label], ls, **kw)
    axes[0].set_ylabel("position RMSE (m)")
    axes[1].set_ylabel("velocity RMSE (m/s)")
    axes[1].set_xlabel("time (s)")
    longest = max((len(t.get_label()) for t in axes[0].get_lines()), default=0)
    axes[0].legend(ncol=3 if longest <= 24 else 2 if longest <= 40 else 1, fontsize=7)
    title = "RMSE over time (Monte Carlo, node-averaged)"
    if context:
        title += f"\n{context}"
    note = coincidence_note(groups, exact)
    if note:
        title += f"\ncurves on top of each other (= equal, ≈ within {100 * VISUAL_TOL:.0f} % of the axis):\n{note}"
    axes[0].set_title(title, fontsize=9)
    return _save(fig, path)


def trigger_instants(triggered: np.ndarray, dt: float, path: Path, steps: int = 100, context: str = "") -> Path:
    """Trigger instants (T, N) bool of the first `steps` steps, one row per node;
    ``context`` (scenario, run) is added to the title."""
    trig = triggered[:steps]
    fig, ax = plt.subplots(figsize=(7.5, 0.5 + 0.45 * trig.shape[1]))
    for i in range(trig.shape[1]):
        k = np.nonzero(trig[:, i])[0]
        ax.vlines((k + 1) * dt, i + 0.6, i + 1.4, color=f"C{i % 10}")
    ax.set_yticks(np.arange(1, trig.shape[1] + 1))
    ax.set_yticklabels([f"node {i}" for i in range(trig.shape[1])])
    ax.set_xlabel("time (s)")
    rate = trig.mean()
    title = f"Trigger instants, first {len(trig)} steps (rate {100 * rate:.0f} %)"
    ax.set_title(title + (f"\n{context}" if context else ""), fontsize=9)
    return _save(fig, path)


def delta_sweep(
    deltas: Sequence[float],
    pos_rmse: Mapping[str, Sequence[float]],
    trigger_rate: Mapping[str, Sequence[float]],
    path: Path,
    context: str = "",
    unit: str = "squared raw units: m², rad²",
) -> Path:
    """Position RMSE and trigger rate against the threshold δ (in ``unit``);
    ``context`` (scenario, nodes, runs) is added to the title. Both panels have
    a legend; curves that coincide in a panel are drawn with different line
    styles and markers and the legend says so."""
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4.2))
    for ax, curves, scale in ((a, pos_rmse, 1.0), (b, trigger_rate, 100.0)):
        data = {lab: scale * np.asarray(curves[lab], float) for lab in pos_rmse}
        groups = coincident_groups(data)
        color = {lab: f"C{i % 10}" for i, lab in enumerate(pos_rmse)}
        for g in groups:
            for j, label in enumerate(g):
                ls, mk = _STYLES[j % len(_STYLES)]
                shown = label if len(g) == 1 else f"{label} (= {', '.join(x for x in g if x != label)})"
                ax.plot(deltas, data[label], ls, marker=mk or "o", color=color[label], mfc="none" if j else None,
                        ms=5 + 2 * (len(g) - 1 - j), label=shown)
        ax.set_xlabel(f"δ ({unit})")
        ax.legend(fontsize=7)
    a.set_ylabel("position RMSE (m)")
    b.set_ylabel("trigger rate (%)")
    fig.suptitle("Effect of the trigger threshold δ" + (f" — {context}" if context else ""), fontsize=10)
    return _save(fig, path)


def computation_time(times_ms: Mapping[int, Mapping[str, float]], path: Path, context: str = "") -> Path:
    """Median time of a whole run per algorithm, grouped by node count;
    ``context`` (scenario, repetitions) is added to the title."""
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
    ax.set_title("Computation time per algorithm (one core)" + (f"\n{context}" if context else ""), fontsize=9)
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
